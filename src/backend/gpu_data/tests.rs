use std::sync::Arc;

use glam::DVec3;
use rand::{Rng, SeedableRng};

use super::slots::stream_into;
use super::*;
use crate::values::{Attribute, Bounds};

/// `n` particles uniform in a cube of side `side` centred at `offset`, written as f64 the
/// way a simulation would (no f32-exact coordinates).
fn cube(n: usize, side: f64, offset: f64) -> Arc<Step> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let positions: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * side + DVec3::splat(offset))
        .collect();
    let values = (0..n).map(|_| rng.random::<f64>()).collect();
    Arc::new(Step {
        name: "cube".into(),
        positions,
        attributes: vec![Attribute {
            name: "s".into(),
            values,
        }],
    })
}

fn prepared(step: &Arc<Step>, radius: f64, precision: Precision) -> (GpuStepData, SortedParticles) {
    let field = FieldSettings::new(Some("s"), radius);
    GpuStepData::prepare(&StepInput {
        step,
        field: &field,
        cluster: ClusterSize::new(1).unwrap(),
        series_bounds: Bounds::of_points(&step.positions),
        series_range: Some((0.0, 1.0)),
        precision,
    })
    .unwrap()
}

/// Slots over `v` cut at the particle indices `cuts` (ascending), each part with its first
/// particle.
fn split<'a>(v: &'a mut [[f32; 4]], cuts: &[usize]) -> Vec<(usize, Slots16<'a>)> {
    let mut out = Vec::new();
    let mut rest = v;
    let mut first = 0;
    for &cut in cuts {
        let (head, tail) = rest.split_at_mut(cut - first);
        out.push((first, slots16(head)));
        rest = tail;
        first = cut;
    }
    out.push((first, slots16(rest)));
    out
}

/// Streaming stores write exactly the values, at a 16-byte aligned destination (the
/// non-temporal path) and at a misaligned one (the plain copy), over poisoned slots, and
/// leave the slots beyond untouched.
#[test]
fn streamed_slots_hold_the_values_aligned_or_not() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let n = 77;
    let values: Vec<[u8; 16]> = (0..n).map(|_| rng.random()).collect();
    // 16-byte aligned storage, written from slot 0 (aligned) and from byte 4 (misaligned).
    for offset in [0usize, 4] {
        let mut storage = vec![0u128; n + 2];
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut storage);
        bytes.fill(0xA5);
        let slots: &mut [[u8; 16]] = bytemuck::cast_slice_mut(&mut bytes[offset..][..16 * n]);
        stream_into(Slots::from_mut(slots), &values);
        let bytes: &[u8] = bytemuck::cast_slice(&storage);
        assert_eq!(
            &bytes[offset..][..16 * n],
            values.concat().as_slice(),
            "offset {offset}"
        );
        assert!(bytes[..offset].iter().all(|&b| b == 0xA5));
        assert!(bytes[offset + 16 * n..].iter().all(|&b| b == 0xA5));
    }
}

/// The staging pass writes the same bytes however its output is cut into parts (a split
/// buffer's parts are not multiples of the pass's chunks), with the radius attribute and
/// the lo parts beside them, and sees the same extremes.
#[test]
fn staging_in_parts_equals_staging_in_one() {
    let n = 3 * CHUNK + 1234;
    let mut step = (*cube(n, 2.5, 1e5)).clone();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    step.attributes.push(Attribute {
        name: "h".into(),
        values: (0..n).map(|_| rng.random_range(0.5..1.5)).collect(),
    });
    let step = Arc::new(step);
    let mut field = FieldSettings::new(Some("s"), 0.01);
    field.radius_attribute = Some("h".into());
    let input = StepInput {
        step: &step,
        field: &field,
        cluster: ClusterSize::new(2).unwrap(),
        series_bounds: Bounds::of_points(&step.positions),
        series_range: Some((0.0, 1.0)),
        precision: Precision::DoubleSingle,
    };
    let stage = |cuts: &[usize]| {
        let mut points = vec![[f32::NAN; 4]; n];
        let mut lo = vec![[f32::NAN; 4]; n];
        let mut radius = vec![f32::NAN; n];
        let data = GpuStepData::check(&input)
            .unwrap()
            .write(split(&mut points, cuts), Some(slots4(&mut radius)));
        assert!(data.double_single);
        data.write_lo(&step, split(&mut lo, cuts));
        (data, points, lo, radius)
    };
    let bits =
        |v: &[[f32; 4]]| -> Vec<[u32; 4]> { v.iter().map(|p| p.map(f32::to_bits)).collect() };
    let (one, points, lo, radius) = stage(&[]);
    assert!(
        points
            .iter()
            .chain(&lo)
            .all(|p| p.iter().all(|c| c.is_finite()))
    );
    assert!(radius.iter().all(|h| h.is_finite()));
    let (parts, p2, lo2, radius2) = stage(&[CHUNK + 5, 3 * CHUNK - 1, 3 * CHUNK + 1000]);
    assert_eq!(one, parts);
    assert_eq!(bits(&points), bits(&p2));
    assert_eq!(bits(&lo), bits(&lo2));
    assert_eq!(radius, radius2);
}

/// A scene pays for double-single positions only when its radii and extent need them: an
/// image of a unit-cube scene at a radius of 2% of the domain stays in f32 (16 B a
/// particle), the same scene asked for field values at 1e-5 needs the pairs, and so does
/// an image whose radii are 1e-6 of the domain, or whose domain lies at 1e6 with radii
/// of 1e-4 (offsets alone cost nothing: local coordinates remove them).
#[test]
fn auto_precision_pays_for_pairs_only_where_the_scene_needs_them() {
    let unit = cube(2000, 1.0, 0.0);
    let (image, _) = prepared(&unit, 0.02, Precision::RENDER);
    assert!(
        !image.double_single(),
        "bound {}",
        image.representation.bound.positions
    );
    assert_eq!(image.particle_bytes(), 2000 * 16);
    let (field, _) = prepared(&unit, 0.02, Precision::FIELD);
    assert!(
        field.double_single(),
        "bound {}",
        field.representation.bound.positions
    );
    assert_eq!(field.particle_bytes(), 2000 * 32);
    assert!(prepared(&unit, 1e-6, Precision::RENDER).0.double_single());

    let far = cube(2000, 1.0, 1e6);
    let (far_image, _) = prepared(&far, 0.02, Precision::RENDER);
    assert!(!far_image.double_single(), "an offset alone needs no pairs");
    assert!(
        (far_image.representation.bound.positions - image.representation.bound.positions).abs()
            < 1e-3 * image.representation.bound.positions,
        "the bound depends on the local extent, not the offset: {} vs {}",
        far_image.representation.bound.positions,
        image.representation.bound.positions
    );
    assert!(prepared(&far, 1e-4, Precision::RENDER).0.double_single());

    // The pairs hold what f32 loses: hi + lo equals the f64 local position to ~48 bits.
    let (pairs, sorted) = prepared(&far, 1e-4, Precision::RENDER);
    let lo = sorted.points_lo.as_ref().unwrap();
    for (k, &i) in sorted.order.iter().enumerate().step_by(97) {
        let local = far.positions[i as usize] - pairs.origin;
        for a in 0..3 {
            let sum = f64::from(sorted.points[k][a]) + f64::from(lo[k][a]);
            assert!((sum - local[a]).abs() <= 1e-13, "{sum} vs {}", local[a]);
        }
    }
    // Forced precisions are obeyed either way.
    assert!(!prepared(&unit, 1e-6, Precision::F32).0.double_single());
    assert!(
        prepared(&unit, 0.5, Precision::DoubleSingle)
            .0
            .double_single()
    );
}
