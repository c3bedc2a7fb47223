//! Space without particles is not empty when the optical-density map gives density 0 an
//! extinction (`--optical-map 0:0.3,1:1`): every backend marches it. The CPU backend skips the
//! gaps between cluster boxes only where D(0) = 0; before, it skipped them always and its images
//! lacked the haze the GPU backends drew.

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{OpticalDensityMap, PiecewiseLinear};
use aarbf::scene::synth::Generator;
use aarbf::values::{Image, Integrator, NoiseKind};

use crate::common;

fn render(kind: BackendKind, series: &TimeSeries, settings: &RenderSettings, spp: u32) -> Image {
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let b = common::require(&format!("the {kind} backend"), backend::create(kind));
    let mut s = RenderSession::new(b, series);
    s.show(series, 5, &field, ClusterSize::new(4).unwrap())
        .unwrap();
    s.render(settings, spp).unwrap()
}

#[test]
fn every_backend_marches_the_extinction_of_empty_space() {
    common::capture_driver_messages();
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    for (integrator, spp, bound) in [(Integrator::Ea, 2, 2e-4), (Integrator::Marching, 8, 4e-3)] {
        let hazy = RenderSettings {
            width: 40,
            height: 32,
            integrator,
            noise: NoiseKind::Stbn,
            seed: 2,
            optical: OpticalDensityMap::new("0:0.3,1:1".parse().unwrap(), None).unwrap(),
            background: [0.2, 0.4, 0.8],
            ..RenderSettings::default()
        };
        let clear = RenderSettings {
            optical: OpticalDensityMap::new(PiecewiseLinear::ramp(0.0, 1.0), None).unwrap(),
            ..hazy.clone()
        };
        let cpu = render(BackendKind::Cpu, &series, &hazy, spp);
        let cpu_clear = render(BackendKind::Cpu, &series, &clear, spp);
        // The haze dims the background seen through the empty part of the march box.
        let haze = cpu.rmse(&cpu_clear);
        assert!(
            haze > 0.02,
            "{integrator:?}: the haze changes the CPU image by {haze}"
        );
        for kind in [BackendKind::Wgpu, BackendKind::Ash] {
            let gpu = render(kind, &series, &hazy, spp);
            let e = gpu.rmse(&cpu);
            eprintln!("{integrator:?} {kind}: RMSE against cpu {e:.2e} (haze {haze:.3})");
            assert!(
                e < bound,
                "{integrator:?}: {kind} and cpu differ by RMSE {e} with D(0) > 0"
            );
        }
    }
    common::assert_no_driver_messages();
}
