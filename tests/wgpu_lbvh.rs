//! The wgpu LBVH backend's own mechanisms: its tree, stage by stage against its CPU twins
//! (`aarbf::backend::shaders::cpu`), refit and rebuilt; steps, trees, images and voxel grids
//! split over bindings; a device with WebGPU's default limits; both ways a step reaches the
//! device; and the splatter's poisoned accumulation. What every GPU backend must do is checked
//! in `gpu_backends`.
//!
//! Every GPU output is poisoned (0xFF bytes) before the run that writes it, inputs are fresh
//! random data of awkward sizes. All tests share one wgpu device (`GpuContext::shared`). With
//! no adapter they fail.
//!
//! Tolerances (why each is what it is):
//! - keys, sort, hierarchy, parents, leaf count, depth: bit-exact.
//! - cluster boxes: |gpu - cpu| <= 4e-7 (|value| + R) per coordinate (the radius-map lookup
//!   `a + (b - a) f` may be fused into an FMA on the GPU, a rounding apart), emptiness exact.
//! - bottom-up bounds: exactly equal (as floats) to the twin's over the GPU's own boxes (min and
//!   max round nothing).
//! - field queries vs the f64 reference: as `gpu_backends::check_queries` says.

use std::sync::Arc;

use aarbf::accel::ClusterSize;
use aarbf::backend::shaders::cpu::lbvh::{
    self, GpuBox, LBVH_NONE, LBVH_SENTINEL, Lbvh, box_is_empty,
};
use aarbf::backend::shaders::cpu::rbf::RadiusRule;
use aarbf::backend::shaders::cpu::{lbvh_boxes, lbvh_keys, radix_sort};
use aarbf::backend::wgpu_lbvh::{BuildStage, GpuContext, WgpuBackend};
use aarbf::backend::{Backend, Precision, StepInput};
use aarbf::field::FieldSettings;
use aarbf::scene::maps::RadiusMap;
use aarbf::values::Step;
use glam::DVec3;

use crate::common::{self, GpuBackend, assert_no_driver_messages, wgpu_context as gpu};
use crate::gpu_backends::{
    assert_prepared_like_the_cpu, bounds_of, check_queries, maps_field, simulation_input,
    simulation_step, unit_cube_step, upload,
};

/// The CPU twin's cluster boxes for what the backend holds.
fn twin_boxes(backend: &WgpuBackend) -> Vec<GpuBox> {
    let d = backend.step_data().unwrap();
    let particles = backend.sorted_particles().unwrap();
    let rule = RadiusRule {
        field: d.field,
        radius_table: d.radius_map_varies.then_some(&d.tables.radius[..]),
        radius_attribute: particles.radius_attribute.as_deref(),
    };
    lbvh_boxes::lbvh_boxes(&particles.points, d.cluster.get(), &rule)
}

fn assert_boxes_close(gpu: &[GpuBox], cpu: &[GpuBox], radius: f32, what: &str) {
    assert_eq!(gpu.len(), cpu.len(), "{what}: box count");
    for (c, (g, e)) in gpu.iter().zip(cpu).enumerate() {
        assert_eq!(
            box_is_empty(g),
            box_is_empty(e),
            "{what}: cluster {c}: {g:?} vs {e:?}"
        );
        if box_is_empty(e) {
            assert!(
                g[0][..3].iter().all(|v| *v == f32::INFINITY)
                    && g[1][..3].iter().all(|v| *v == f32::NEG_INFINITY),
                "{what}: empty cluster {c} is {g:?}"
            );
            continue;
        }
        for side in 0..2 {
            for i in 0..3 {
                let (a, b) = (g[side][i], e[side][i]);
                assert!(
                    (a - b).abs() <= 4e-7 * (b.abs() + radius),
                    "{what}: cluster {c} coordinate {side}/{i}: gpu {a} cpu {b}"
                );
            }
        }
    }
}

/// Both ways a step reaches the device: written straight into mappable storage buffers where
/// device memory is the host's (lavapipe here: no staging copy), and through staging buffers
/// and a copy (a discrete GPU's way, forced here): the same preparation, in one part and split
/// over several, outputs poisoned between steps.
#[test]
fn a_step_reaches_the_device_alike_with_and_without_a_staging_copy() {
    let shared = gpu();
    let unified = matches!(
        shared.info.device_type,
        wgpu::DeviceType::Cpu | wgpu::DeviceType::IntegratedGpu
    ) && shared
        .adapter
        .features()
        .contains(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS);
    assert_eq!(shared.unified_memory, unified);
    if shared.info.driver == "llvmpipe" && shared.info.backend == wgpu::Backend::Vulkan {
        assert!(shared.unified_memory, "lavapipe maps its storage buffers");
    }
    let mut copying = GpuContext::with_limits(shared.limits.clone()).unwrap();
    copying.unified_memory = false;
    let copying = Arc::new(copying);
    let mut with_radius = maps_field(0.01, true);
    with_radius.attribute_range = None;
    with_radius.radius_attribute = Some("h".into());
    for (name, ctx) in [("unified", &shared), ("staged", &copying)] {
        for limit in [None, Some(65_536)] {
            let mut b = GpuBackend::Wgpu(Box::new(backend(ctx, limit)));
            for (i, &n) in [10_001usize, 4097, 9000].iter().enumerate() {
                let step = Arc::new(simulation_step(n, 700 + i as u64));
                let precision = if i == 1 {
                    Precision::RENDER
                } else {
                    Precision::DoubleSingle
                };
                let input = simulation_input(&step, &with_radius, precision);
                if i > 0 {
                    b.poison_prepared();
                }
                b.upload(&input).unwrap();
                assert_prepared_like_the_cpu(
                    &mut b,
                    &input,
                    &format!("{name}, binding limit {limit:?}, step {i} ({n} particles)"),
                );
            }
        }
    }
    assert_no_driver_messages();
}

/// A step split over bindings (16-byte particles in parts of 65,536 bytes: 4096 particles) is
/// prepared as the CPU prepares it, over poisoned outputs.
#[test]
fn a_step_split_over_parts_is_prepared_as_on_the_cpu() {
    let mut with_radius = maps_field(0.01, true);
    with_radius.attribute_range = None;
    with_radius.radius_attribute = Some("h".into());
    let mut split = backend(&gpu(), Some(65_536));
    let step = Arc::new(simulation_step(10_001, 500));
    let input = simulation_input(&step, &with_radius, Precision::DoubleSingle);
    split.upload(&input).unwrap();
    split.poison_prepared().unwrap();
    split.upload(&input).unwrap();
    split.build().unwrap();
    assert_eq!(split.split_parts().map(|p| p.0), Some(3));
    assert_prepared_like_the_cpu(
        &mut GpuBackend::Wgpu(Box::new(split)),
        &input,
        "split over 3 parts",
    );
    assert_no_driver_messages();
}

/// A backend on the shared device; with `limit`, binding at most that many bytes per storage
/// buffer (so that small steps split their arrays over several bindings).
fn backend(ctx: &Arc<GpuContext>, limit: Option<u64>) -> WgpuBackend {
    match limit {
        Some(l) => WgpuBackend::with_max_binding(ctx.clone(), l),
        None => WgpuBackend::with_context(ctx.clone()),
    }
}

/// Builds over `step` stage by stage, comparing each stage with its twin.
fn check_build_stages(
    ctx: &Arc<GpuContext>,
    step: &Arc<Step>,
    field: &FieldSettings,
    k: u32,
    what: &str,
    limit: Option<u64>,
) {
    let mut b = backend(ctx, limit);
    upload(&mut b, step, field, k);
    let clusters = ClusterSize::new(k).unwrap().clusters_for(step.len());
    let radius = field.radius as f32;
    let grid = b.key_grid().unwrap();

    // Stage 1: boxes.
    b.poison_tree().unwrap();
    b.build_until(BuildStage::Bounds).unwrap();
    let s = b.snapshot().unwrap();
    let twin = twin_boxes(&b);
    assert_boxes_close(&s.boxes, &twin, radius, what);
    let boxes = s.boxes;

    // Stage 2: keys (unsorted), identity values, leaf count, no cluster linked yet.
    b.poison_tree().unwrap();
    b.build_until(BuildStage::Keys).unwrap();
    let s = b.snapshot().unwrap();
    assert_eq!(s.boxes, boxes, "{what}: boxes are deterministic");
    let keys = lbvh_keys::morton_keys(&boxes, &grid);
    assert_eq!(s.keys, keys, "{what}: keys");
    assert_eq!(
        s.values,
        (0..clusters as u32).collect::<Vec<_>>(),
        "{what}: values"
    );
    let leaves = boxes.iter().filter(|b| !box_is_empty(b)).count() as u32;
    assert_eq!(s.counters[0], leaves, "{what}: leaf count");
    assert!(
        s.lbvh.leaf_parents.iter().all(|&p| p == LBVH_NONE),
        "{what}"
    );

    // Stage 3: sorted.
    b.poison_tree().unwrap();
    b.build_until(BuildStage::Sort).unwrap();
    let s = b.snapshot().unwrap();
    let (sorted_keys, sorted_values) = radix_sort::sort_pairs(&keys);
    assert!(s.keys == sorted_keys, "{what}: sorted keys");
    assert!(s.values == sorted_values, "{what}: sorted values");

    // Stage 4: hierarchy (children, parents, header), bounds words still LBVH_SENTINEL.
    b.poison_tree().unwrap();
    b.build_until(BuildStage::Hierarchy).unwrap();
    let s = b.snapshot().unwrap();
    let twin = Lbvh::hierarchy(&sorted_keys, &sorted_values);
    assert_eq!(s.lbvh.leaves, twin.leaves, "{what}");
    for (j, (g, e)) in s.lbvh.nodes.iter().zip(&twin.nodes).enumerate() {
        assert_eq!([g[3], g[7]], [e[3], e[7]], "{what}: children of node {j}");
        if j > 0 {
            assert!(
                [0, 1, 2, 4, 5, 6].iter().all(|&w| g[w] == LBVH_SENTINEL),
                "{what}: node {j} bounds not reset: {g:?}"
            );
        }
    }
    assert_eq!(s.lbvh.nodes.len(), twin.nodes.len(), "{what}: node count");
    assert_eq!(
        s.lbvh.node_parents, twin.node_parents,
        "{what}: node parents"
    );
    assert_eq!(
        s.lbvh.leaf_parents, twin.leaf_parents,
        "{what}: leaf parents"
    );

    // Stage 5: the whole build.
    b.poison_tree().unwrap();
    let report = b.build_until(BuildStage::Fit).unwrap();
    let s = b.snapshot().unwrap();
    let mut twin = Lbvh::hierarchy(&sorted_keys, &sorted_values);
    twin.fit(&boxes);
    assert_eq!(report.leaves, twin.leaves, "{what}");
    assert_eq!(report.depth, twin.depth, "{what}: depth");
    assert_same_tree(&s.lbvh, &twin, what);
    s.lbvh
        .validate(&boxes, true)
        .unwrap_or_else(|e| panic!("{what}: invalid tree: {e}"));
}

/// Same topology and bounds equal as floats (a signed zero may come out either way).
fn assert_same_tree(gpu: &Lbvh, cpu: &Lbvh, what: &str) {
    assert_eq!(gpu.nodes.len(), cpu.nodes.len(), "{what}: node count");
    for j in 1..cpu.nodes.len() {
        assert_eq!(
            lbvh::children(&gpu.nodes[j]),
            lbvh::children(&cpu.nodes[j]),
            "{what}: children of node {j}"
        );
        assert_eq!(
            gpu.node_box(j),
            cpu.node_box(j),
            "{what}: bounds of node {j}"
        );
    }
    assert_eq!(gpu.root(), cpu.root(), "{what}: root");
    assert_eq!(gpu.node_parents, cpu.node_parents, "{what}: node parents");
    assert_eq!(gpu.leaf_parents, cpu.leaf_parents, "{what}: leaf parents");
}

#[test]
fn every_build_stage_equals_its_cpu_twin_at_awkward_sizes() {
    let ctx = gpu();
    let radius = 0.02;
    for (i, n) in [0usize, 1, 2, 255, 256, 257, 65537].into_iter().enumerate() {
        let step = std::sync::Arc::new(unit_cube_step(n, i as u64, false));
        check_build_stages(
            &ctx,
            &step,
            &maps_field(radius, false),
            1,
            &format!("n {n}, K 1"),
            None,
        );
    }
    // Clusters, zero radii and empty clusters (radius map 0 below t = 0.2), per-particle radii.
    for (i, (n, k)) in [(257usize, 2u32), (4099, 4), (65537, 16), (3000, 8)]
        .into_iter()
        .enumerate()
    {
        let step = std::sync::Arc::new(unit_cube_step(n, 50 + i as u64, false));
        let mut f = maps_field(radius, true);
        if k == 8 {
            f.radius_attribute = Some("h".into());
        }
        check_build_stages(&ctx, &step, &f, k, &format!("n {n}, K {k}, maps"), None);
    }
    assert_no_driver_messages();
}

#[test]
fn a_million_particle_build_equals_its_twin() {
    let ctx = gpu();
    // A non-power-of-two million.
    let step = std::sync::Arc::new(unit_cube_step(1_000_003, 7, false));
    check_build_stages(
        &ctx,
        &step,
        &maps_field(0.004, true),
        1,
        "1000003 particles",
        None,
    );
    assert_no_driver_messages();
}

#[test]
fn bottom_up_bounds_hold_under_load_and_duplicate_keys() {
    // Many equal keys (five tiny blobs) make deep subtrees split by index and long climbs
    // where many threads meet at the same nodes; repeat the build and compare each time.
    let ctx = gpu();
    let step = std::sync::Arc::new(unit_cube_step(300_001, 11, true));
    let f = maps_field(0.01, false);
    let mut b = WgpuBackend::with_context(ctx.clone());
    upload(&mut b, &step, &f, 1);
    let mut first: Option<Lbvh> = None;
    for round in 0..3 {
        b.poison_tree().unwrap();
        let report = b.build_until(BuildStage::Fit).unwrap();
        let s = b.snapshot().unwrap();
        s.lbvh
            .validate(&s.boxes, true)
            .unwrap_or_else(|e| panic!("round {round}: {e}"));
        // ~60K equal keys a blob, split by index: ~16 levels under the blobs' few key bits.
        assert!(
            report.depth >= 18,
            "duplicate keys make a deep tree ({})",
            report.depth
        );
        let twin = Lbvh::build(&s.boxes, &b.key_grid().unwrap());
        assert_same_tree(&s.lbvh, &twin, &format!("round {round}"));
        match &first {
            None => first = Some(s.lbvh),
            Some(f) => assert_same_tree(&s.lbvh, f, "rebuild"),
        }
    }
    assert_no_driver_messages();
}

#[test]
fn refit_equals_a_fresh_build() {
    let ctx = gpu();
    let step = std::sync::Arc::new(unit_cube_step(20_011, 21, false));
    for k in [1u32, 4] {
        let what = format!("K {k}");
        let mut f = maps_field(0.02, true);
        let mut b = WgpuBackend::with_context(ctx.clone());
        upload(&mut b, &step, &f, k);
        b.build().unwrap();
        let built = b.snapshot().unwrap();

        // A new global radius: the same boxes up to scale, the same topology.
        // (The refit's reset pass writes LBVH_SENTINEL, a NaN, into every bound it recomputes, so
        // a bound it missed fails `validate`.)
        f.radius = 0.03;
        b.refit(&f).unwrap();
        let refit = b.snapshot().unwrap();
        refit.lbvh.validate(&refit.boxes, true).unwrap();
        let mut twin = built.lbvh.clone();
        assert!(twin.refit(&refit.boxes), "{what}");
        assert_same_tree(&refit.lbvh, &twin, &format!("{what}: refit vs twin refit"));
        assert_boxes_close(&refit.boxes, &twin_boxes(&b), 0.03, &what);

        // A fresh build with the new radius: the same leaf boxes; where the keys (box centres)
        // did not move, the same tree node for node.
        let mut fresh = WgpuBackend::with_context(ctx.clone());
        upload(&mut fresh, &step, &f, k);
        fresh.build().unwrap();
        let fresh = fresh.snapshot().unwrap();
        assert_eq!(fresh.boxes, refit.boxes, "{what}: leaf boxes");
        assert_eq!(
            refit.lbvh.node_box(1),
            fresh.lbvh.node_box(1),
            "{what}: root bounds"
        );
        let grid = b.key_grid().unwrap();
        if lbvh_keys::morton_keys(&built.boxes, &grid)
            == lbvh_keys::morton_keys(&refit.boxes, &grid)
        {
            assert_same_tree(&refit.lbvh, &fresh.lbvh, &format!("{what}: refit vs build"));
        }

        // A radius map that empties more clusters: refit, no rebuild needed.
        f.radius_map = RadiusMap::new("0:0,0.4:0,0.6:1,1:1".parse().unwrap()).unwrap();
        b.refit(&f).unwrap();
        let s = b.snapshot().unwrap();
        assert_eq!(s.counters[2], 0, "{what}: no rebuild");
        s.lbvh.validate(&s.boxes, false).unwrap();
        assert!(s.lbvh.leaves > s.boxes.iter().filter(|b| !box_is_empty(b)).count() as u32);

        // And back to a map with no zeros: clusters outside the tree hold particles again, so
        // the refit rebuilds.
        f.radius_map = RadiusMap::default();
        b.refit(&f).unwrap();
        let s = b.snapshot().unwrap();
        s.lbvh.validate(&s.boxes, true).unwrap();
        assert_eq!(
            s.lbvh.leaves as usize,
            s.boxes.len(),
            "{what}: every cluster a leaf"
        );
    }
    assert_no_driver_messages();
}

#[test]
fn steps_larger_than_one_binding_are_split_over_parts() {
    // The binding limit lowered so that a small step needs 2-4 parts (of at most 4) for its
    // particles (16 B each), nodes and boxes (32 B per cluster): (K, limit, expected parts).
    let ctx = gpu();
    let n = 40_000;
    let step = std::sync::Arc::new(unit_cube_step(n, 77, false));
    let cases = [
        // 640,000 B of particles in 2 parts; 1,280,000 B of nodes and boxes in 3; the
        // image's accumulation in 1.
        (1u32, 480_000u64, (2usize, 3usize), (48, 40)),
        // 640,000 B of particles in 4 parts; 320,000 B of nodes and boxes in 2; a 128x100
        // image's 204,800 B of accumulation in 2.
        (4, 200_000, (4, 2), (128, 100)),
    ];
    let radius = 0.055;
    for (k, limit, parts, (width, height)) in cases {
        let what = format!("split, K {k}, limit {limit}");
        let mut f = maps_field(radius, true);
        if k == 4 {
            f.radius_attribute = Some("h".into());
        }
        let mut b = backend(&ctx, Some(limit));
        upload(&mut b, &step, &f, k);
        assert_eq!(b.split_parts(), Some((parts.0, parts.1)), "{what}");
        check_build_stages(&ctx, &step, &f, k, &what, Some(limit));
        check_queries(&mut backend(&ctx, Some(limit)), &step, &f, k, &what);

        // The same image, bit for bit, as from a backend with one binding per array.
        let series = aarbf::scene::TimeSeries::from_steps(vec![(*step).clone()]);
        let settings = aarbf::render::RenderSettings {
            width,
            height,
            seed: 5,
            ..aarbf::render::RenderSettings::default()
        };
        let session = |b: WgpuBackend| {
            let mut s = aarbf::render::RenderSession::new(Box::new(b), &series);
            s.show(&series, 0, &f, ClusterSize::new(k).unwrap())
                .unwrap();
            s
        };
        let mut split_session = session(backend(&ctx, Some(limit)));
        let split = split_session.render(&settings, 2).unwrap();
        let whole = session(backend(&ctx, None)).render(&settings, 2).unwrap();
        assert!(
            split.pixels.iter().any(|p| p[3] > 0.0),
            "{what}: the image shows the particles"
        );
        assert!(split == whole, "{what}: split and unsplit images differ");

        // An image beyond 4 parts of accumulation: an error naming the need and the limit.
        let big = aarbf::render::RenderSettings {
            width: 400,
            height: 400,
            ..settings
        };
        let e = split_session.render(&big, 1).unwrap_err().to_string();
        let need = format!("needs 2560000 bytes of accumulation, more than 4 x {limit}");
        assert!(e.contains(&need), "{what}: error {e:?} lacks {need:?}");
    }

    // Beyond 4 parts: a clear error naming the step, the need and the limit.
    let mut b = backend(&ctx, Some(100_000));
    let e = b
        .upload(&StepInput {
            step: &step,
            field: &maps_field(radius, false),
            cluster: ClusterSize::new(1).unwrap(),
            series_bounds: bounds_of(&step),
            series_range: Some((0.0, 1.0)),
            precision: aarbf::backend::Precision::FIELD,
        })
        .unwrap_err()
        .to_string();
    for part in [
        "step 'random40000'",
        "the particles need 640000 bytes, more than 4 x 100000",
        "at most 100000 bytes per storage buffer",
    ] {
        assert!(e.contains(part), "error {e:?} lacks {part:?}");
    }
    assert!(b.build().is_err(), "nothing uploaded after the refusal");
    assert_no_driver_messages();
}

#[test]
fn a_device_with_webgpu_default_limits_runs_steps_that_fit_a_binding() {
    // WebGPU's default limits (8 storage buffers per shader stage, 128 MiB bindings, 16 KiB of
    // workgroup memory) stand in for a small GPU. A step whose arrays each fit one binding runs
    // the one-part kernels, which bind at most 8 storage buffers: it builds, refits, answers
    // queries and renders exactly as on the full device. A step that must be split needs 4
    // parts per array, more buffers than such a device binds: an error says so and what to do.
    let full = gpu();
    let limited = Arc::new(
        GpuContext::with_limits(wgpu::Limits::default())
            .expect("an adapter offering WebGPU's default limits"),
    );
    assert_eq!(limited.limits.max_storage_buffers_per_shader_stage, 8);
    let step = std::sync::Arc::new(unit_cube_step(3_001, 91, false));
    let mut f = maps_field(0.06, true);
    f.radius_attribute = Some("h".into());
    let k = 4;

    // The build stages and queries against their twins and the f64 reference.
    check_build_stages(&limited, &step, &f, k, "WebGPU limits", None);
    check_queries(&mut backend(&limited, None), &step, &f, k, "WebGPU limits");

    // Build, refit and render: the same bits as the full device.
    let series = aarbf::scene::TimeSeries::from_steps(vec![(*step).clone()]);
    let images = |ctx: &Arc<GpuContext>| {
        let mut s = aarbf::render::RenderSession::new(
            Box::new(WgpuBackend::with_context(ctx.clone())),
            &series,
        );
        let mut field = f.clone();
        let mut out = Vec::new();
        for (radius, integrator) in [
            (0.06, aarbf::values::Integrator::Ea),
            // Only the radius changes: the refit path.
            (0.08, aarbf::values::Integrator::Marching),
        ] {
            field.radius = radius;
            s.show(&series, 0, &field, ClusterSize::new(k).unwrap())
                .unwrap();
            assert_eq!(
                s.backend().timings().refit.is_zero(),
                radius == 0.06,
                "a refit exactly when the radius changed"
            );
            let settings = aarbf::render::RenderSettings {
                width: 40,
                height: 24,
                seed: 3,
                integrator,
                ..aarbf::render::RenderSettings::default()
            };
            out.push(s.render(&settings, 2).unwrap());
        }
        out
    };
    let on_limited = images(&limited);
    assert!(
        on_limited[0].pixels.iter().any(|p| p[3] > 0.0),
        "the particles show"
    );
    assert!(
        on_limited == images(&full),
        "the same images as on the full device"
    );

    // Split over parts: a clear error, not a crash (from the upload, whose preparation on
    // the device is the first pass to bind the split arrays).
    let mut b = WgpuBackend::with_max_binding(limited.clone(), 20_000);
    let e = b
        .upload(&StepInput {
            step: &step,
            field: &f,
            cluster: ClusterSize::new(k).unwrap(),
            series_bounds: bounds_of(&step),
            series_range: Some((0.0, 1.0)),
            precision: Precision::FIELD,
        })
        .unwrap_err()
        .to_string();
    for part in [
        "bound in 4 parts",
        "allows 8 storage buffers per shader stage",
        "a larger cluster size",
    ] {
        assert!(e.contains(part), "error {e:?} lacks {part:?}");
    }
    assert_no_driver_messages();
}

/// The voxel baseline's grid with bindings of 8 KiB (the particles split over parts, the slab
/// buffer two layers, the first pass 256 particles at a time) equals the CPU's grid as one made
/// in one binding does, over a poisoned texture; a layer larger than a binding is refused,
/// naming the limit.
#[test]
fn a_voxel_grid_in_many_slabs_and_chunks_equals_one_in_one() {
    use crate::voxel_baseline as voxel;
    let series = voxel::random_series(1237, 5, DVec3::new(0.5, 0.25, -1.0));
    let field = FieldSettings::new(Some("a"), 0.06);
    let settings = aarbf::render::RenderSettings {
        width: 16,
        height: 16,
        ..aarbf::render::RenderSettings::default()
    };
    let (mut cpu, frame) = voxel::frame_of(&series, &field, &settings);
    cpu.backend_mut().voxelize(&frame, 13).unwrap();
    let reference = cpu.backend_mut().voxel_grid().unwrap();
    let mut small = WgpuBackend::with_max_binding(gpu(), 8192);
    voxel::upload(&mut small, &series, &field, 4, Precision::RENDER);
    small.voxelize(&frame, 13).unwrap();
    small.poison_voxels().unwrap();
    small.voxelize(&frame, 13).unwrap();
    let (worst, finite) = voxel::grid_difference(&small.voxel_grid().unwrap(), &reference);
    eprintln!("8 KiB bindings: largest relative difference per channel {worst:?}");
    assert!(finite);
    assert!(worst.iter().all(|&w| w < 1e-5), "{worst:?}");
    let e = small.voxelize(&frame, 64).unwrap_err().to_string();
    assert!(e.contains("slab buffer") && e.contains("8192"), "{e}");
    assert_no_driver_messages();
}

/// A device whose 3D textures are at most 32 texels a side refuses the voxel baseline's
/// 64-cell grid, naming the limit, and makes a 32-cell one.
#[test]
fn a_voxel_grid_beyond_the_3d_texture_limit_is_refused() {
    use crate::voxel_baseline as voxel;
    gpu();
    let series = voxel::random_series(100, 3, DVec3::ZERO);
    let field = FieldSettings::new(Some("a"), 0.06);
    let (_, frame) = voxel::frame_of(&series, &field, &Default::default());
    let limits = wgpu::Limits {
        max_texture_dimension_3d: 32,
        ..wgpu::Limits::default()
    };
    let small = Arc::new(common::require(
        "a wgpu adapter",
        GpuContext::with_limits(limits),
    ));
    let mut b = WgpuBackend::with_context(small);
    voxel::upload(&mut b, &series, &field, 4, Precision::RENDER);
    let e = b.voxelize(&frame, 64).unwrap_err().to_string();
    assert!(
        e.contains("max_texture_dimension_3d") && e.contains("32"),
        "{e}"
    );
    b.voxelize(&frame, 32).unwrap();
    assert_no_driver_messages();
}

/// The splatter writes every pixel: its first frame stores into the accumulation without
/// clearing it, so with the sums poisoned (NaN) a missed pixel would show. At a size that is
/// no multiple of the 8x8 tiles, so the edge tiles' pixels count too. A second frame adds to
/// the first (the image, their mean, is the same deterministic frame).
#[test]
fn every_splatter_pixel_is_written_over_a_poisoned_accumulation() {
    use crate::splat_baseline as splat;
    let (series, field) = splat::dam_break();
    let cpu = splat::cpu_session(&series, 7, &field, 4);
    let mut wgpu = WgpuBackend::with_context(gpu());
    splat::show(&mut wgpu, &series, 7, &field, 4, Precision::RENDER);
    let settings = aarbf::render::RenderSettings {
        width: 37,
        height: 29,
        integrator: aarbf::values::Integrator::Ea,
        noise: aarbf::values::NoiseKind::Stbn,
        ..aarbf::render::RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    let first = splat::gpu_splat(&mut wgpu, &frame, 15);
    assert!(splat::all_finite(&first));
    assert!(first.pixels.iter().any(|p| p[3] > 0.3), "the data shows");
    wgpu.poison_accumulation().unwrap();
    wgpu.render_splat(&frame, 15).unwrap();
    let again = wgpu.image().unwrap();
    assert!(splat::all_finite(&again), "a pixel kept the poison");
    assert_eq!(again.pixels, first.pixels, "the same frame");
    wgpu.render_splat(&frame, 15).unwrap();
    let twice = wgpu.image().unwrap();
    assert_eq!(wgpu.frames(), 2);
    let worst = splat::largest_difference(&twice, &first);
    assert!(worst < 1e-6, "the mean of two equal frames: {worst}");
    assert_no_driver_messages();
}

/// With the binding limit lowered so that the particles, the tree and the accumulation each
/// span several storage bindings, the splatter (its 4-part kernel) draws the same image, bit
/// for bit, as with one binding per array, over a poisoned accumulation.
#[test]
fn a_step_and_image_split_over_bindings_splat_the_same_image() {
    use crate::splat_baseline as splat;
    let (series, field) = splat::dam_break();
    let cpu = splat::cpu_session(&series, 7, &field, 4);
    let mut whole = WgpuBackend::with_context(gpu());
    splat::show(&mut whole, &series, 7, &field, 4, Precision::RENDER);
    // 3000 particles (48,000 B) in 3 parts of 16 KiB, 750 clusters' nodes and boxes (24,000
    // B each) in 2, a 48x40 image's sums (30,720 B) in 2.
    let mut split = WgpuBackend::with_max_binding(gpu(), 16 * 1024);
    splat::show(&mut split, &series, 7, &field, 4, Precision::RENDER);
    assert_eq!(split.split_parts(), Some((3, 2)));
    let settings = aarbf::render::RenderSettings {
        width: 48,
        height: 40,
        ..aarbf::render::RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    let expected = splat::gpu_splat(&mut whole, &frame, 15);
    assert!(expected.pixels.iter().any(|p| p[3] > 0.3), "the data shows");
    splat::gpu_splat(&mut split, &frame, 15);
    split.poison_accumulation().unwrap();
    let image = splat::gpu_splat(&mut split, &frame, 15);
    assert!(
        image == expected,
        "split and unsplit splatter images differ"
    );
    assert_no_driver_messages();
}
