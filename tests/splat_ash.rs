//! Knoll et al.'s splatter on the ash backend, through the RT pipeline (`splat.rgen`: a ray per
//! slab, the any-hit shader filling the slab's buffer) and through the LBVH kernel
//! (`lbvh_splat.comp`), against its CPU twin (`backend::cpu::splat`, the f64 reference's
//! hits): equal within f32 where no buffer overflows (which hits overflow depends on the
//! traversal's order, which differs between the three), different once k is small enough to
//! lose hits, every pixel written (the accumulation is poisoned before a first frame), no
//! validation message, and a clear error for a buffer a payload cannot hold.

use aarbf::accel::ClusterSize;
use aarbf::backend::ash_rt::{self, AshBackend, Traversal};
use aarbf::backend::{self, Backend, BackendKind, Precision};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::shader_constants::SPLAT_K_MAX;
use aarbf::values::{Attribute, Image, Integrator, NoiseKind, Step};
use glam::DVec3;

use crate::common;

fn ash(traversal: Traversal) -> Box<dyn Backend> {
    let mut b = common::require(
        "a Vulkan device with ray-tracing pipelines",
        AshBackend::new(),
    );
    b.set_traversal(traversal);
    Box::new(b)
}

fn splat(session: &mut RenderSession, settings: &RenderSettings, k: usize) -> Image {
    let frame = session.frame_params(settings, 0).unwrap();
    let backend = session.backend_mut();
    backend.reset();
    backend.render_splat(&frame, k).unwrap();
    let image = backend.image().unwrap();
    assert!(
        image.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())),
        "every pixel is written"
    );
    image
}

fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0, f32::max)
}

fn sessions(
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: u32,
) -> [RenderSession; 3] {
    let cluster = ClusterSize::new(cluster).unwrap();
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), series);
    cpu.set_precision(Precision::F64);
    let mut out = [
        cpu,
        RenderSession::new(ash(Traversal::RtPipeline), series),
        RenderSession::new(ash(Traversal::Lbvh), series),
    ];
    for s in &mut out {
        s.show(series, step, field, cluster).unwrap();
    }
    out
}

#[test]
fn particles_apart_splat_alike_on_the_rt_pipeline_the_lbvh_and_the_cpu() {
    // As tests/splat_baseline.rs: seven particles apart, in double precision off the origin.
    let offset = DVec3::new(1.0e4 + 0.123_456_789_012_345_6, -2.5e3, 7.0 / 3.0);
    let step = Step {
        name: "apart".into(),
        positions: (0..7)
            .map(|i| offset + DVec3::new(0.3 * i as f64, 0.07 * (i % 3) as f64, 0.05 * i as f64))
            .collect(),
        attributes: vec![Attribute {
            name: "a".into(),
            values: vec![3.0, -1.5, 0.25, 7.0, 2.0, 5.5, 0.0],
        }],
    };
    let series = TimeSeries::from_steps(vec![step]);
    let field = FieldSettings::new(Some("a"), 0.1);
    let settings = RenderSettings {
        width: 40,
        height: 40,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        phi_ref: Some(2.0),
        ..RenderSettings::default()
    };
    let [mut cpu, mut rt, mut lbvh] = sessions(&series, 0, &field, 1);
    let reference = splat(&mut cpu, &settings, 15);
    assert!(reference.pixels.iter().filter(|p| p[3] > 0.05).count() > 20);
    for (name, session) in [("rt pipeline", &mut rt), ("lbvh", &mut lbvh)] {
        let image = splat(session, &settings, 15);
        let (rmse, worst) = (
            image.rmse(&reference),
            largest_difference(&image, &reference),
        );
        eprintln!("particles apart, ash {name} vs cpu: RMSE {rmse:.2e}, largest {worst:.2e}");
        assert!(rmse < 1e-6 && worst < 1e-5, "{name}: {rmse} {worst}");
    }
    let messages = ash_rt::validation_messages();
    assert!(messages.is_empty(), "{messages:?}");
}

#[test]
fn the_dam_break_splats_alike_until_buffers_overflow() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let settings = RenderSettings {
        width: 32,
        height: 32,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    for cluster in [1, 4] {
        let [mut cpu, mut rt, mut lbvh] = sessions(&series, 7, &field, cluster);
        let k = SPLAT_K_MAX as usize;
        let reference = splat(&mut cpu, &settings, k);
        assert!(reference.pixels.iter().any(|p| p[3] > 0.3));
        for (name, session) in [("rt pipeline", &mut rt), ("lbvh", &mut lbvh)] {
            let image = splat(session, &settings, k);
            let rmse = image.rmse(&reference);
            eprintln!("dam break, K = {cluster}, k = {k}, ash {name} vs cpu: RMSE {rmse:.2e}");
            assert!(rmse < 1e-6, "{name}, K = {cluster}: {rmse}");
            // One hit per slab loses most of them: a different image.
            let lossy = splat(session, &settings, 1);
            let change = lossy.rmse(&image);
            eprintln!("  k = 1 against k = {k}: RMSE {change:.2e}");
            assert!(change > 1e-3, "{name}, K = {cluster}: {change}");
        }
    }
    let messages = ash_rt::validation_messages();
    assert!(messages.is_empty(), "{messages:?}");
}

#[test]
fn a_buffer_a_payload_cannot_hold_is_refused() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(500, 2, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let mut session = RenderSession::new(ash(Traversal::RtPipeline), &series);
    session
        .show(&series, 1, &field, ClusterSize::new(1).unwrap())
        .unwrap();
    let frame = session
        .frame_params(
            &RenderSettings {
                width: 8,
                height: 8,
                ..RenderSettings::default()
            },
            0,
        )
        .unwrap();
    for k in [0, SPLAT_K_MAX as usize + 1] {
        let e = session
            .backend_mut()
            .render_splat(&frame, k)
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("1..={SPLAT_K_MAX}")), "{e}");
    }
}
