//! The decomposition's promises, for P = 1..9 and 16 ranks of `LocalComm`: each particle owned
//! once, ghosts exactly the brute-force set (and enough for the field), each sample of the
//! frame's lattice owned once by the integrator itself, conservative screen rectangles, and
//! direct send blending every rank's pieces in order.

use std::sync::Mutex;

use glam::DVec3;
use rand::{Rng, SeedableRng};

use super::composite::{TileGrid, direct_send, screen_rect};
use super::exchange::{Brick, decompose, exchange, ghost_reach};
use super::kd::KdTree;
use super::*;
use crate::backend::BrickShare;
use crate::backend::cpu::integrators::{
    FieldSampler, PACKET, PixelScratch, ray_box, render_owned_pixels_with, render_pixels_with,
};
use crate::field::{FieldSettings, particle_reaches};
use crate::scene::Camera;
use crate::values::{
    Attribute, Bounds, ColourMode, FrameParams, HalfOpenBox, Integrator, NoiseKind, PixelRect, Step,
};

const RANKS: [usize; 10] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 16];

/// `n` particles in an anisotropic box, denser in one corner, with an id, a radius attribute
/// h in [0.5, 1.5] and a scalar.
fn cloud(n: usize, seed: u64) -> Step {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let positions: Vec<DVec3> = (0..n)
        .map(|_| {
            DVec3::new(
                2.0 * rng.random::<f64>().powi(2),
                rng.random(),
                0.5 * rng.random::<f64>(),
            )
        })
        .collect();
    let attribute = |name: &str, values: Vec<f64>| Attribute {
        name: name.into(),
        values,
    };
    Step {
        name: "cloud".into(),
        attributes: vec![
            attribute("id", (0..n).map(|i| i as f64).collect()),
            attribute("h", (0..n).map(|_| 0.5 + rng.random::<f64>()).collect()),
            attribute("s", positions.iter().map(|p| p.x + p.y).collect()),
        ],
        positions,
    }
}

fn field() -> FieldSettings {
    let mut field = FieldSettings::new(Some("s"), 0.06);
    field.radius_attribute = Some("h".into());
    field
}

fn ids(brick: &Brick, range: std::ops::Range<usize>) -> Vec<usize> {
    let id = brick.step.attribute("id").unwrap();
    let mut out: Vec<usize> = id.values[range].iter().map(|&v| v as usize).collect();
    out.sort_unstable();
    out
}

#[test]
fn each_particle_is_owned_once_and_the_ghosts_are_the_brute_force_set() {
    let step = cloud(3000, 1);
    let field = field();
    let range = Some((0.0, 3.0));
    let reaches = particle_reaches(&step, &field, range).unwrap();
    for p in RANKS {
        let bricks = run_local(p, |comm| {
            let local = slice_of(&step, comm.rank(), comm.size());
            let local_reaches = particle_reaches(&local, &field, range)?;
            let tree = decompose(comm, &local.positions, Some(&local_reaches), None)?;
            let (brick, _) = exchange(comm, &tree, &local, &local_reaches)?;
            Ok((tree, brick))
        })
        .unwrap();
        let tree: &KdTree = &bricks[0].0;
        assert!(
            bricks.iter().all(|(t, _)| t == tree),
            "P = {p}: trees differ"
        );
        let mut all_owned = Vec::new();
        let mut ghosts_total = 0;
        for (r, (_, brick)) in bricks.iter().enumerate() {
            assert_eq!(brick.leaf, tree.leaves()[r]);
            let owned = ids(brick, 0..brick.owned);
            for &i in &owned {
                assert_eq!(tree.leaf_of(step.positions[i]), r, "P = {p}: particle {i}");
            }
            all_owned.extend(owned);
            // Every record arrives whole.
            for (k, &id) in brick
                .step
                .attribute("id")
                .unwrap()
                .values
                .iter()
                .enumerate()
            {
                let i = id as usize;
                assert_eq!(brick.step.positions[k], step.positions[i]);
                assert_eq!(
                    brick.step.attribute("h").unwrap().values[k],
                    step.attribute("h").unwrap().values[i]
                );
            }
            let expected: Vec<usize> = (0..step.len())
                .filter(|&i| {
                    let c = step.positions[i];
                    tree.leaf_of(c) != r
                        && ghost_reach(c, reaches[i])
                            .is_some_and(|g| brick.leaf.distance_squared(c) <= g * g)
                })
                .collect();
            assert_eq!(
                ids(brick, brick.owned..brick.step.len()),
                expected,
                "P = {p}, rank {r}"
            );
            ghosts_total += expected.len();
        }
        all_owned.sort_unstable();
        assert_eq!(all_owned, (0..step.len()).collect::<Vec<_>>(), "P = {p}");
        assert_eq!(ghosts_total > 0, p > 1, "P = {p}: {ghosts_total} ghosts");
    }
}

/// Whatever reaches a point of a leaf is in that leaf's brick: its field is the whole field.
#[test]
fn every_particle_reaching_a_point_of_a_leaf_is_in_its_brick() {
    let step = cloud(2000, 2);
    let field = field();
    let range = Some((0.0, 3.0));
    let reaches = particle_reaches(&step, &field, range).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    for p in [2, 5, 9] {
        let bricks = run_local(p, |comm| {
            let local = slice_of(&step, comm.rank(), comm.size());
            let local_reaches = particle_reaches(&local, &field, range)?;
            let tree = decompose(comm, &local.positions, None, None)?;
            Ok(exchange(comm, &tree, &local, &local_reaches)?.0)
        })
        .unwrap();
        let tree = run_local(p, |comm| {
            decompose(comm, &slice_of(&step, comm.rank(), p).positions, None, None)
        })
        .unwrap()
        .swap_remove(0);
        let mut checked = 0;
        for _ in 0..600 {
            let x = DVec3::new(
                2.0 * rng.random::<f64>(),
                rng.random(),
                0.5 * rng.random::<f64>(),
            );
            let brick = &bricks[tree.leaf_of(x)];
            let held = ids(brick, 0..brick.step.len());
            for (i, (c, &reach)) in step.positions.iter().zip(&reaches).enumerate() {
                if c.distance(x) <= reach {
                    assert!(
                        held.binary_search(&i).is_ok(),
                        "P = {p}: particle {i} at {x}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 1000, "{checked}");
    }
}

/// Records where the integrator samples, with a constant field.
#[derive(Default)]
struct Recorder(Mutex<Vec<[u64; 3]>>);

impl FieldSampler for Recorder {
    type Ray = ();
    type Packet = ();

    fn begin(&self, _: &mut (), _: DVec3, _: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        out.push((t0, t1));
    }

    fn sample(&self, _: &mut (), x: DVec3) -> (f64, [f64; 3]) {
        self.0.lock().unwrap().push(x.to_array().map(f64::to_bits));
        (1.0, [0.5; 3])
    }
}

pub(super) fn frame(eye: DVec3, at: DVec3, march: Bounds, width: u32, height: u32) -> FrameParams {
    let camera = Camera {
        eye,
        at,
        up: DVec3::Y,
        fovy: 50.0,
    };
    FrameParams {
        width,
        height,
        frame: 3,
        seed: 7,
        camera: camera.frame(width, height).unwrap(),
        box_min: march.min,
        box_max: march.max,
        dt: 0.031,
        // Never reached: every sample is taken.
        opacity_threshold: 2.0,
        phi_ref: 1.0,
        density_scale: 0.01,
        majorant: 0.01,
        light_dir: DVec3::Y,
        light_intensity: 1.0,
        ambient: 0.25,
        background: [0.0; 3],
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        colour: ColourMode::Density,
        optical_table: std::sync::Arc::new(vec![1.0; 64]),
        colour_table: std::sync::Arc::new(vec![[1.0; 3]; 64]),
    }
}

fn sample_points(f: &FrameParams, owned: Option<&HalfOpenBox>) -> Vec<[u64; 3]> {
    let recorder = Recorder::default();
    let mut scratch = PixelScratch::<Recorder>::default();
    let pixels: Vec<(u32, u32)> = (0..f.height)
        .flat_map(|y| (0..f.width).map(move |x| (x, y)))
        .collect();
    let mut out = [[0.0; 4]; PACKET];
    for packet in pixels.chunks(PACKET) {
        match owned {
            Some(b) => {
                let share = BrickShare {
                    owned: b,
                    rect: PixelRect::full(f.width, f.height),
                    index: 0,
                    depth_in_front: None,
                    light: None,
                };
                render_owned_pixels_with(f, &recorder, &share, packet, &mut scratch, &mut out)
            }
            None => render_pixels_with(f, &recorder, packet, &mut scratch, &mut out),
        }
    }
    recorder.0.into_inner().unwrap()
}

/// The integrator's own samples: the leaves' together are the whole frame's, each once.
#[test]
fn each_lattice_sample_is_owned_once() {
    let step = cloud(1500, 4);
    let march = step.bounds().grown(0.1);
    let eyes = [
        (DVec3::new(2.6, 1.5, 1.8), march.center()),
        // Inside the data, looking through many leaves.
        (DVec3::new(0.3, 0.4, 0.2), DVec3::new(2.0, 0.6, 0.4)),
    ];
    for p in RANKS {
        let tree = run_local(p, |comm| {
            decompose(comm, &slice_of(&step, comm.rank(), p).positions, None, None)
        })
        .unwrap()
        .swap_remove(0);
        for (eye, at) in eyes {
            let f = frame(eye, at, march, 32, 24);
            let mut whole = sample_points(&f, None);
            assert!(whole.len() > 5000, "{} samples", whole.len());
            let mut split = Vec::new();
            for leaf in tree.leaves() {
                let points = sample_points(&f, Some(leaf));
                for x in &points {
                    assert!(leaf.contains(DVec3::from_array(x.map(f64::from_bits))));
                }
                split.extend(points);
            }
            whole.sort_unstable();
            split.sort_unstable();
            assert_eq!(whole.len(), split.len(), "P = {p}");
            assert!(
                whole == split,
                "P = {p}: the leaves' samples are not the frame's"
            );
        }
    }
}

#[test]
fn screen_rectangles_hold_every_pixel_whose_ray_meets_the_box() {
    let step = cloud(1000, 5);
    let march = step.bounds().grown(0.1);
    let tree = KdTree::build(
        &step
            .positions
            .iter()
            .map(|p| kd::WeightedPoint {
                at: p.to_array(),
                weight: 1.0,
                reach: 0.0,
            })
            .collect::<Vec<_>>(),
        9,
    );
    let f = frame(DVec3::new(-1.5, 1.8, 2.5), march.center(), march, 90, 70);
    let mut smaller = 0;
    for leaf in tree.leaves() {
        let b = leaf.clipped_to(march);
        let rect = screen_rect(&f, b);
        if rect.len() < PixelRect::full(90, 70).len() {
            smaller += 1;
        }
        for y in 0..f.height {
            for x in 0..f.width {
                let (o, d) = f.primary_ray(x, y);
                if !rect.contains(x, y) {
                    assert!(
                        ray_box(o, d, b.min, b.max).is_none(),
                        "({x}, {y}) outside {rect:?}"
                    );
                }
            }
        }
    }
    assert!(
        smaller >= 8,
        "{smaller} of 9 rectangles are smaller than the image"
    );
}

/// Direct send against blending every rank's whole layer serially, on an image whose size is
/// no multiple of a tile, with rectangles crossing tiles.
#[test]
fn direct_send_blends_every_rank_s_pieces_front_to_back() {
    let (w, h) = (150, 130);
    for p in [1, 2, 3, 5, 16] {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(p as u64);
        let layers: Vec<(PixelRect, Vec<[f64; 4]>)> = (0..p)
            .map(|_| {
                let (x0, y0) = (rng.random_range(0..w), rng.random_range(0..h));
                let rect = PixelRect {
                    x0,
                    y0,
                    x1: rng.random_range(x0..=w),
                    y1: rng.random_range(y0..=h),
                };
                // The data covers a disc of the rectangle; elsewhere the brick changes nothing
                // (the identity [0, 0, 0, 1], which is not sent).
                let (cx, cy) = (rng.random_range(0..w) as f64, rng.random_range(0..h) as f64);
                let r = rng.random_range(10.0..60.0);
                let pixels = (rect.y0..rect.y1)
                    .flat_map(|y| (rect.x0..rect.x1).map(move |x| (x, y)))
                    .map(|(x, y)| {
                        let t: f64 = rng.random();
                        let c = (1.0 - t) * rng.random::<f64>();
                        let inside = (x as f64 - cx).hypot(y as f64 - cy) < r;
                        if inside {
                            [c, c * 0.5, c * 0.25, t]
                        } else {
                            [0.0, 0.0, 0.0, 1.0]
                        }
                    })
                    .collect();
                (rect, pixels)
            })
            .collect();
        let mut order: Vec<usize> = (0..p).collect();
        order.reverse();
        let grid = TileGrid {
            width: w,
            height: h,
            ranks: p,
        };
        let sent = run_local(p, |comm| {
            let (rect, layer) = &layers[comm.rank()];
            let blended = direct_send(comm, &grid, *rect, layer, &order)?;
            Ok((blended.tiles, blended.bytes_sent))
        })
        .unwrap();
        // Each rank sends at most the pixels of the box around those it changed, with a
        // header a piece.
        for (r, (_, bytes)) in sent.iter().enumerate() {
            let (rect, layer) = &layers[r];
            let changed: Vec<(u32, u32)> = (rect.y0..rect.y1)
                .flat_map(|y| (rect.x0..rect.x1).map(move |x| (x, y)))
                .filter(|&(x, y)| layer[rect.index(x, y)] != [0.0, 0.0, 0.0, 1.0])
                .collect();
            let span = |a: &dyn Fn(&(u32, u32)) -> u32| {
                changed.iter().map(a).max().map_or(0, |m| m + 1)
                    - changed.iter().map(a).min().unwrap_or(0)
            };
            let boxed = (span(&|q| q.0) * span(&|q| q.1)) as usize;
            let headers = 20 * grid.touching(*rect).len();
            assert!(*bytes <= 32 * boxed + headers, "rank {r}: {bytes} bytes");
            if changed.is_empty() {
                assert_eq!(*bytes, 0, "rank {r} changed nothing and sent {bytes} bytes");
            }
        }
        let tiles: Vec<_> = sent.into_iter().map(|(t, _)| t).collect();
        for t in 0..grid.count() {
            let tile_rect = grid.rect(t);
            let got = &tiles[grid.owner(t)][t / p];
            for y in tile_rect.y0..tile_rect.y1 {
                for x in tile_rect.x0..tile_rect.x1 {
                    let mut want = [0.0, 0.0, 0.0, 1.0];
                    for &r in &order {
                        let (rect, layer) = &layers[r];
                        if rect.contains(x, y) {
                            let b = layer[rect.index(x, y)];
                            for c in 0..3 {
                                want[c] += want[3] * b[c];
                            }
                            want[3] *= b[3];
                        }
                    }
                    assert_eq!(got[tile_rect.index(x, y)], want, "P = {p} ({x}, {y})");
                }
            }
        }
    }
}

/// More ranks than particles: most bricks are empty, and the image is still the single
/// rank's (to rounding; termination off).
#[test]
fn empty_bricks_render_nothing_and_break_nothing() {
    use crate::backend::cpu::CpuBackend;
    use crate::backend::{Backend, Precision};
    let step = std::sync::Arc::new(cloud(12, 8));
    let field = field();
    let march = step.bounds().grown(0.2);
    let mut f = frame(DVec3::new(2.6, 1.5, 1.8), march.center(), march, 40, 30);
    f.colour = ColourMode::Post;
    f.density_scale = 5.0;
    f.optical_table = std::sync::Arc::new((0..64).map(|i| i as f32 / 63.0).collect());
    let frames = [f];
    let scene = DistScene {
        field: &field,
        cluster: crate::accel::ClusterSize::new(1).unwrap(),
        series_bounds: step.bounds(),
        series_range: Some((0.0, 3.0)),
        precision: Precision::F64,
        periodic: None,
        shadows: DistShadows::default(),
    };
    let mut single = single_rank(&step, &scene);
    single.render(&frames[0]).unwrap();
    let want = single.mean_f64().unwrap();
    assert!(want.iter().any(|p| p[3] > 0.05), "the particles show");
    let got = run_local(16, |comm| {
        let local = slice_of(&step, comm.rank(), comm.size());
        render_distributed(comm, &mut CpuBackend::new(), &local, &scene, &frames)
    })
    .unwrap()
    .swap_remove(0)
    .unwrap();
    assert!(got.reports.iter().filter(|r| r.owned == 0).count() >= 4);
    let diff = got
        .mean
        .iter()
        .zip(&want)
        .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0, f64::max);
    assert!(diff <= 1e-12, "{diff:e}");
}

/// Past a blue-noise mask cycle a single rank weights the cycles by their measured noise
/// (`render::cycles`); the distributed image is that same weighted image: the tiles' owners
/// keep their sums at every frame count the weights can ask for, and rank 0 replays the
/// single rank's choice. The weighted image is not the plain mean, so the test sees it.
#[test]
fn past_a_mask_cycle_the_cycles_are_weighted_as_a_single_rank_weights_them() {
    use crate::backend::cpu::CpuBackend;
    use crate::backend::{Backend, Precision};
    use crate::render::CycleWeights;
    let step = std::sync::Arc::new(cloud(300, 5));
    let field = field();
    let march = step.bounds().grown(0.2);
    let d = crate::noise::BlueNoiseMask::builtin().depth;
    let n = d + d / 2 + 3;
    let frames: Vec<FrameParams> = (0..n)
        .map(|i| {
            let mut f = frame(DVec3::new(2.6, 1.5, 1.8), march.center(), march, 40, 30);
            f.frame = i;
            f.colour = ColourMode::Post;
            f.density_scale = 5.0;
            f.optical_table = std::sync::Arc::new((0..64).map(|i| i as f32 / 63.0).collect());
            f
        })
        .collect();
    let scene = DistScene {
        field: &field,
        cluster: crate::accel::ClusterSize::new(4).unwrap(),
        series_bounds: step.bounds(),
        series_range: Some((0.0, 3.0)),
        precision: Precision::F64,
        periodic: None,
        shadows: DistShadows::default(),
    };
    // The single rank, as `render::RenderSession` accumulates.
    let mut single = single_rank(&step, &scene);
    let mut cycles = CycleWeights::of_frames(NoiseKind::Stbn, Integrator::Ea).unwrap();
    for (i, f) in frames.iter().enumerate() {
        if cycles.wants_mean_at(i as u32) {
            cycles.took_mean(i as u32, single.image().unwrap());
        }
        single.render(f).unwrap();
    }
    let plain = single.image().unwrap();
    let want = cycles.image(n, plain.clone());
    let differ = |a: &crate::values::Image, b: &crate::values::Image| {
        a.pixels
            .iter()
            .zip(&b.pixels)
            .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
            .fold(0.0f32, f32::max)
    };
    assert!(differ(&want, &plain) > 1e-4, "the weights change the image");
    for p in [1, 3] {
        let got = run_local(p, |comm| {
            let local = slice_of(&step, comm.rank(), comm.size());
            render_distributed(comm, &mut CpuBackend::new(), &local, &scene, &frames)
        })
        .unwrap()
        .swap_remove(0)
        .unwrap();
        assert_eq!(got.frames, n);
        let diff = differ(&got.image(), &want);
        assert!(
            diff <= 1e-6,
            "P = {p}: {diff:e} from the weighted single-rank image"
        );
    }
}

/// The whole step on one CPU backend, prepared as every brick of `scene` is.
fn single_rank(
    step: &std::sync::Arc<Step>,
    scene: &DistScene<'_>,
) -> crate::backend::cpu::CpuBackend {
    use crate::backend::Backend;
    let mut single = crate::backend::cpu::CpuBackend::new();
    single
        .upload(&scene.step_input(step, scene.precision))
        .unwrap();
    single.build().unwrap();
    single
}
