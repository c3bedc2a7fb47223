//! One check of a field's inputs for every backend: on upload, refit and map updates, cpu,
//! wgpu and ash refuse the same bad settings with the same message (the check is
//! `field::FieldInputs::check`; before it was shared, wgpu's refit took a radius map that
//! varies with an attribute the field does not carry).

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, Backend, BackendKind, StepInput};
use aarbf::field::FieldSettings;
use aarbf::scene::maps::{DensityMap, RadiusMap};
use aarbf::values::{Attribute, Step};
use glam::DVec3;

use crate::common;

fn step() -> Step {
    let n = 97;
    Step {
        name: "checks".into(),
        positions: (0..n)
            .map(|i| DVec3::new(f64::from(i) * 0.01, f64::from(i % 7) * 0.013, 0.5))
            .collect(),
        attributes: vec![
            Attribute {
                name: "s".into(),
                values: (0..n).map(f64::from).collect(),
            },
            Attribute {
                name: "h".into(),
                values: (0..n).map(|i| if i == 41 { -0.5 } else { 1.0 }).collect(),
            },
        ],
    }
}

fn upload(b: &mut dyn Backend, step: &std::sync::Arc<Step>, field: &FieldSettings) {
    b.upload(&StepInput {
        step,
        field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: step.bounds(),
        series_range: None,
        precision: aarbf::backend::Precision::FIELD,
    })
    .unwrap();
    b.build().unwrap();
}

#[test]
fn every_backend_refuses_the_same_bad_field_on_upload_refit_and_map_update() {
    common::capture_driver_messages();
    let step = std::sync::Arc::new(step());
    let plain = FieldSettings::new(None, 0.05);
    let mut varying_radius = plain.clone();
    varying_radius.radius_map = RadiusMap::new("0:0.2,1:1".parse().unwrap()).unwrap();
    let mut varying_density = plain.clone();
    varying_density.density_map = DensityMap::new("0:0.2,0.37:1".parse().unwrap()).unwrap();
    let mut negative_h = plain.clone();
    negative_h.radius_attribute = Some("h".into());
    let mut bad_radius = plain.clone();
    bad_radius.radius = -1.0;
    let mut messages: Vec<Vec<String>> = Vec::new();
    for kind in [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash] {
        let mut b = common::require(&format!("the {kind} backend"), backend::create(kind));
        let mut got = Vec::new();
        upload(b.as_mut(), &step, &plain);
        for (what, settings) in [
            ("refit", &varying_radius),
            ("refit", &negative_h),
            ("refit", &bad_radius),
        ] {
            let e = b
                .refit(settings)
                .expect_err(&format!("{kind}: {what} must fail"));
            got.push(e.to_string());
        }
        let e = b
            .update_maps(&varying_density)
            .expect_err(&format!("{kind}: update_maps must fail"));
        got.push(e.to_string());
        // Upload refuses what refit refuses.
        let e = b
            .upload(&StepInput {
                step: &step,
                field: &negative_h,
                cluster: ClusterSize::new(4).unwrap(),
                series_bounds: step.bounds(),
                series_range: None,
                precision: aarbf::backend::Precision::FIELD,
            })
            .expect_err(&format!("{kind}: upload must fail"));
        got.push(e.to_string());
        // The backend still renders queries of the last good field after a refused change.
        upload(b.as_mut(), &step, &plain);
        let _ = b.refit(&varying_radius);
        let q = b.query(&[step.positions[3]]).unwrap();
        assert!(q[0].0 > 0.0, "{kind}: the field survives a refused refit");
        messages.push(got);
    }
    for (kind, m) in [BackendKind::Wgpu, BackendKind::Ash]
        .iter()
        .zip(&messages[1..])
    {
        assert_eq!(m, &messages[0], "{kind} and cpu refuse differently");
    }
    let cpu = &messages[0];
    assert!(cpu[0].contains("radius map varies"), "{}", cpu[0]);
    assert!(
        cpu[1].contains("'h'") && cpu[1].contains("-0.5"),
        "{}",
        cpu[1]
    );
    assert!(cpu[2].contains("-1"), "{}", cpu[2]);
    assert!(cpu[3].contains("density map varies"), "{}", cpu[3]);
    assert_eq!(cpu[4], cpu[1]);
    common::assert_no_driver_messages();
}
