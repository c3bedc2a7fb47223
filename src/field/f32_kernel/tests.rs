//! The f32 kernel's tests: every build against the lanes and against f64.

#[cfg(target_arch = "x86_64")]
use super::x86_group::*;
#[cfg(target_arch = "x86_64")]
use super::x86_lanes::*;
#[cfg(target_arch = "x86_64")]
use super::x86_point::*;
use super::*;

/// A reproducible stream of floats in [0, 1) (a linear congruential generator).
fn uniform(seed: u32) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// Points evaluated together ([`Packed::group_sums`]) get the bits each gets alone
/// ([`Packed::sums`] over the same runs), in both SIMD builds, for every combination of a
/// common or own radius and weight and every number of channels, with particles placed on
/// the points' spheres to the last few floats (where a box test that rounded past the
/// point test would leave one out); groups of one to eight points, close or spread.
#[test]
fn a_group_gives_each_point_the_bits_it_has_alone() {
    let mut next = uniform(777);
    let mut scratch = GroupScratch::default();
    let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
    let mut compared = 0;
    for round in 0..96 {
        let channels = [0, 1, 3][round % 3];
        let (own_radius, own_w) = ((round / 3) % 2 == 1, (round / 6) % 2 == 1);
        let r0 = 0.05f64 as f32;
        let spread = [0.002, 0.03, 0.2, 0.0][(round / 12) % 4];
        let centre = [next(), next(), next()].map(|v| 0.3 * (v - 0.5));
        let points = 1 + round % 8;
        let qs: Vec<[f32; 3]> = (0..points)
            .map(|_| [0, 1, 2].map(|a| centre[a] + spread * (next() - 0.5)))
            .collect();
        let mut p = Packed {
            channels,
            ..Packed::default()
        };
        for i in 0..257 + round {
            let r = if own_radius { r0 * (0.5 + next()) } else { r0 };
            let c = if i % 3 == 0 {
                // On a point's sphere, to a few floats: the particle's own radius along a
                // random direction, that distance stepped by -3..3 ulps.
                let q = qs[i % points];
                let u = [next() - 0.5, next() - 0.5, next() - 0.5];
                let norm = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt().max(1e-3);
                let step = (i / 3 % 7) as i32 - 3;
                let d = f32::from_bits((r.to_bits() as i32 + step) as u32);
                [0, 1, 2].map(|a| q[a] + u[a] / norm * d)
            } else {
                [0, 1, 2].map(|a| centre[a] + 0.4 * (next() - 0.5))
            };
            let w = if own_w { 0.5 + next() } else { 1.0 };
            let theta = [next(), next() - 0.5, next()];
            push(&mut p, c, r, w, &theta[..channels]);
        }
        p.pad();
        let n = p.x.len() as u32 - LANES as u32;
        let runs = [(0u32, 7u32), (9, n / 2), (n / 2, n), (7, 9)];
        let alone: Vec<_> = qs.iter().map(|&q| bits(p.sums(&runs, q))).collect();
        assert!(alone.iter().any(|a| f64::from_bits(a.0) > 0.0));
        let mut out = vec![(f64::NAN, [f64::NAN; 3]); points];
        p.group_sums(&runs, &qs, &mut scratch, &mut out);
        let together: Vec<_> = out.iter().map(|&s| bits(s)).collect();
        assert_eq!(together, alone, "round {round}");
        // The AVX2 build where the dispatch chose AVX-512.
        #[cfg(target_arch = "x86_64")]
        if avx512_in_use() {
            macro_rules! avx2 {
                ($c:literal) => {
                    match (p.one_radius.is_some(), p.same_w.is_some()) {
                        (true, true) => group_sums_avx2::<$c, true, true>,
                        (true, false) => group_sums_avx2::<$c, true, false>,
                        (false, true) => group_sums_avx2::<$c, false, true>,
                        (false, false) => group_sums_avx2::<$c, false, false>,
                    }
                };
            }
            let build = match channels {
                0 => avx2!(0),
                1 => avx2!(1),
                _ => avx2!(3),
            };
            let mut out = vec![(f64::NAN, [f64::NAN; 3]); points];
            // SAFETY: `avx512_in_use` implies AVX2, FMA and POPCNT.
            unsafe { build(&p, &runs, &qs, &mut scratch, &mut out) };
            let narrow: Vec<_> = out.iter().map(|&s| bits(s)).collect();
            assert_eq!(narrow, alone, "round {round}, AVX2 build");
        }
        compared += points;
    }
    assert!(compared > 300);
}

/// Appends a particle at `c` of radius `r`, weight `w` and theta per channel.
fn push(p: &mut Packed, c: [f32; 3], r: f32, w: f32, theta: &[f32]) {
    p.x.push(c[0]);
    p.y.push(c[1]);
    p.z.push(c[2]);
    p.r2.push(r * r);
    p.k.push(4.5 / (r * r));
    p.w.push(w);
    for (ch, &t) in theta.iter().enumerate() {
        p.theta[ch].push(t);
    }
}

/// A scene of one radius and no density map (every k and every w the same, as a global
/// radius writes them): `pad` notes each, and the AVX2 point kernel's broadcasts give the
/// bits its gathers give; one particle of another radius or weight ends each.
#[test]
fn a_common_radius_and_weight_are_broadcast_to_the_same_bits() {
    let mut p = Packed {
        channels: 3,
        ..Packed::default()
    };
    let mut next = uniform(4242);
    // 0.1 as a data file gives it (the f64 value rounded once), 301 particles.
    let r = 0.1f64 as f32;
    for _ in 0..301 {
        let c = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.4 * v);
        push(&mut p, c, r, 1.0, &[next(), next() - 0.5, next()]);
    }
    p.pad();
    assert_eq!(
        (p.one_radius, p.same_w),
        (
            Some(OneRadius {
                k: 4.5 / (r * r),
                r2: r * r
            }),
            Some(1.0)
        )
    );
    if simd_in_use() {
        let runs = [(0u32, 7u32), (7, 150), (150, 301), (3, 4)];
        for _ in 0..40 {
            let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.3 * v);
            let (k, w) = (p.one_radius.unwrap(), p.same_w.unwrap());
            // SAFETY: `simd_in_use` checked the CPU's features.
            let gathered =
                unsafe { sums_avx2::<3, false, false>(&p, &runs, q, OneRadius::default(), 0.0) };
            let each = unsafe {
                [
                    sums_avx2::<3, true, true>(&p, &runs, q, k, w),
                    sums_avx2::<3, true, false>(&p, &runs, q, k, 0.0),
                    sums_avx2::<3, false, true>(&p, &runs, q, OneRadius::default(), w),
                ]
            };
            assert!(gathered.0 > 0.0);
            let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
            for broadcast in each {
                assert_eq!(bits(broadcast), bits(gathered), "at {q:?}");
            }
            assert_eq!(bits(p.sums(&runs, q)), bits(gathered));
        }
    }
    // One particle of its own radius, then one of its own weight.
    let mut p2 = Packed {
        channels: 0,
        ..Packed::default()
    };
    push(&mut p2, [0.0; 3], r, 1.0, &[]);
    push(&mut p2, [0.01; 3], 0.2, 1.0, &[]);
    p2.pad();
    assert_eq!((p2.one_radius, p2.same_w), (None, Some(1.0)));
    let mut p3 = Packed::default();
    push(&mut p3, [0.0; 3], r, 1.0, &[]);
    push(&mut p3, [0.01; 3], r, 0.5, &[]);
    p3.pad();
    assert_eq!(
        (p3.one_radius, p3.same_w),
        (
            Some(OneRadius {
                k: 4.5 / (r * r),
                r2: r * r
            }),
            None
        )
    );
}

/// One radius broadcast, not loaded, decides reach as the loaded radii do at the radius
/// itself: particles within 2% of r of a point, and on an axis at r and its neighbouring
/// floats (where `d² <= r²` is decided by the last bit), give the loaded build's bits in
/// both SIMD builds of the point kernel.
#[test]
fn one_radius_decides_reach_at_the_radius_as_the_loaded_radii_do() {
    if !simd_in_use() {
        // The dispatch test (tests/cpu_f32.rs) holds `simd_in_use` to the CPU's features.
        return;
    }
    let r = 0.1f64 as f32;
    let mut p = Packed::default();
    // On the x axis from the origin: d² is x² rounded once, against r² rounded once.
    let mut axis_reached = [0, 0];
    for ulps in -40i32..40 {
        let x = f32::from_bits((r.to_bits() as i32 + ulps) as u32);
        axis_reached[usize::from(x * x <= r * r)] += 1;
        push(&mut p, [x, 0.0, 0.0], r, 1.0, &[]);
    }
    assert!(
        axis_reached[0] > 0 && axis_reached[1] > 0,
        "{axis_reached:?}"
    );
    let mut next = uniform(2718);
    for _ in 0..301 {
        let u = [next() - 0.5, next() - 0.5, next() - 0.5];
        let norm = u.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-3);
        let s = r * (0.98 + 0.04 * next()) / norm;
        push(&mut p, u.map(|v| v * s), r, 1.0, &[]);
    }
    p.pad();
    let radius = p.one_radius.expect("one radius");
    let runs = [(0u32, 80u32), (80, 381), (5, 6), (90, 97)];
    let q = [0.0f32; 3];
    let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
    // SAFETY: `simd_in_use` checked AVX2 and FMA above, `avx512_in_use` AVX-512 below.
    let loaded = unsafe { sums_avx2::<0, false, true>(&p, &runs, q, OneRadius::default(), 1.0) };
    assert!(loaded.0 > 0.0);
    let broadcast = unsafe { sums_avx2::<0, true, true>(&p, &runs, q, radius, 1.0) };
    assert_eq!(bits(broadcast), bits(loaded));
    if avx512_in_use() {
        let wide = unsafe { sums_avx512::<0, true, true>(&p, &runs, q, radius, 1.0) };
        assert_eq!(bits(wide), bits(loaded));
    }
    assert_eq!(bits(p.sums(&runs, q)), bits(loaded));
}

#[test]
fn the_avx2_point_kernel_agrees_with_the_lanes_to_their_roundings() {
    if !simd_in_use() {
        // The dispatch test (tests/cpu_f32.rs) holds `simd_in_use` to the CPU's features.
        return;
    }
    // Particles around the origin, some out of reach; runs of awkward lengths.
    let mut p = Packed {
        channels: 3,
        ..Packed::default()
    };
    let mut next = uniform(12345);
    for _ in 0..203 {
        let r: f32 = 0.2 + 0.3 * next();
        let c = [next() - 0.5, next() - 0.5, next() - 0.5];
        push(&mut p, c, r, 0.5 + next(), &[next(), next(), next()]);
    }
    p.pad();
    let runs = [(0u32, 13u32), (20, 21), (40, 203), (100, 108)];
    for _ in 0..50 {
        let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.6 * v);
        // SAFETY: `simd_in_use` checked the CPU's features above.
        let fast = unsafe { sums_avx2::<3, false, false>(&p, &runs, q, OneRadius::default(), 0.0) };
        let lanes = sums_lanes::<3>(&p, &runs, q);
        assert!(lanes.0 > 0.0);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1e-3);
        assert!(close(fast.0, lanes.0), "phi {} vs {}", fast.0, lanes.0);
        for ch in 0..3 {
            assert!(
                close(fast.1[ch], lanes.1[ch]),
                "{ch}: {:?} vs {:?}",
                fast,
                lanes
            );
        }
    }
}

/// The AVX-512 build of the point kernel packs the same lanes in the same order as the
/// AVX2 build, so it gives the same bits: for every channel count and every broadcast, over
/// runs of awkward lengths, runs that reach nothing and runs that fill the held candidates
/// several times over (flushes), in a scene of one radius and weight (where the broadcasts
/// apply) and one of each particle's own.
#[test]
fn the_avx512_point_kernel_gives_the_avx2_bits() {
    if !avx512_in_use() {
        // The dispatch test (tests/cpu_f32.rs) holds `avx512_in_use` to the CPU's features.
        return;
    }
    let mut next = uniform(9001);
    let scene = |common: bool, next: &mut dyn FnMut() -> f32| {
        let mut p = Packed {
            channels: 3,
            ..Packed::default()
        };
        // 0..700 a clump about the origin, 700..1301 far away.
        for i in 0..1301 {
            let (spread, shift) = if i < 700 { (0.3, 0.0) } else { (1.0, 10.0) };
            let (r, w) = if common {
                (0.4, 1.0)
            } else {
                (0.3 + 0.2 * next(), 0.25 + next())
            };
            let c = [
                shift + spread * (next() - 0.5),
                spread * (next() - 0.5),
                spread * (next() - 0.5),
            ];
            push(&mut p, c, r, w, &[next(), next() - 0.5, next()]);
        }
        p.pad();
        p
    };
    let runs = [
        (0u32, 7u32),
        (7, 150),
        (150, 613),
        (3, 4),
        (700, 1301),
        (613, 700),
        (17, 17),
    ];
    let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
    // SAFETY (each call below): `avx512_in_use` checked the CPU's features.
    macro_rules! both {
        ($c:literal, $one_radius:literal, $same_w:literal, $p:expr, $q:expr, $k:expr, $w:expr) => {{
            let wide = unsafe { sums_avx512::<$c, $one_radius, $same_w>($p, &runs, $q, $k, $w) };
            let narrow = unsafe { sums_avx2::<$c, $one_radius, $same_w>($p, &runs, $q, $k, $w) };
            assert_eq!(
                bits(wide),
                bits(narrow),
                "C {}, same k {}, same w {}, at {:?}",
                $c,
                $one_radius,
                $same_w,
                $q
            );
            wide.0
        }};
    }
    let mut reached = 0;
    for common in [true, false] {
        let p = scene(common, &mut next);
        assert_eq!(p.one_radius.is_some(), common);
        let (k, w) = (p.one_radius.unwrap_or_default(), p.same_w.unwrap_or(0.0));
        for i in 0..30 {
            let q = if i % 3 == 2 {
                [10.0 + next() - 0.5, next() - 0.5, next() - 0.5]
            } else {
                [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.5 * v)
            };
            let phi = both!(0, false, false, &p, q, OneRadius::default(), 0.0);
            both!(1, false, false, &p, q, OneRadius::default(), 0.0);
            both!(3, false, false, &p, q, OneRadius::default(), 0.0);
            if common {
                both!(0, true, true, &p, q, k, w);
                both!(0, true, false, &p, q, k, 0.0);
                both!(0, false, true, &p, q, OneRadius::default(), w);
                both!(1, true, true, &p, q, k, w);
                both!(3, true, true, &p, q, k, w);
                both!(3, true, false, &p, q, k, 0.0);
                both!(3, false, true, &p, q, OneRadius::default(), w);
            }
            reached += usize::from(phi > 100.0);
        }
    }
    assert!(reached > 10, "the clump reaches most queries ({reached})");
}

/// The AVX-512 dense loop (the peak on a CPU that has it) sums the terms the AVX2 loop and
/// the f64 sum do, to their roundings (sixteen lanes add in another order than eight), over
/// ranges whose ends are not multiples of sixteen, shorter than sixteen, and empty.
#[test]
fn the_avx512_dense_loop_sums_the_avx2_terms() {
    if !avx512_in_use() {
        return;
    }
    let mut p = Packed::default();
    let mut next = uniform(31337);
    for _ in 0..1000 {
        let r: f32 = 0.2 + 0.4 * next();
        push(
            &mut p,
            [next(), next(), next()].map(|v| v - 0.5),
            r,
            0.5 + next(),
            &[],
        );
    }
    p.pad();
    for (from, to) in [
        (0, 1000),
        (3, 613),
        (5, 16),
        (100, 101),
        (40, 40),
        (999, 1000),
    ] {
        for _ in 0..10 {
            let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.5 * v);
            // SAFETY: `avx512_in_use` checked the CPU's features; the padding holds
            // eight (AVX2) floats past `to`, and the AVX-512 loop masks its last lanes.
            let (wide, narrow) = unsafe {
                (
                    dense_sums_avx512(&p, from, to, q),
                    dense_sums_avx2(&p, from, to, q),
                )
            };
            let exact: f64 = (from..to)
                .map(|j| {
                    let d2: f64 = [p.x[j] - q[0], p.y[j] - q[1], p.z[j] - q[2]]
                        .map(|d| f64::from(d) * f64::from(d))
                        .iter()
                        .sum();
                    if d2 <= f64::from(p.r2[j]) {
                        f64::from(p.w[j]) * (-f64::from(p.k[j]) * d2).exp()
                    } else {
                        0.0
                    }
                })
                .sum();
            let tolerance = 1e-5 * exact.max(1e-30);
            assert!(
                (wide - exact).abs() <= tolerance && (narrow - exact).abs() <= tolerance,
                "{from}..{to} at {q:?}: AVX-512 {wide}, AVX2 {narrow}, f64 {exact}"
            );
            if to == from {
                assert_eq!(wide, 0.0);
            }
        }
    }
}

/// Every build of the point kernel against the sum as written in f64, over runs where far
/// more candidates reach than the kernel holds before computing (its flushes), runs that
/// reach nothing, runs of one particle, a particle in two runs (counted twice), and the
/// dense loop over one run.
#[test]
fn the_point_kernel_sums_every_reached_term_once() {
    let mut p = Packed {
        channels: 1,
        ..Packed::default()
    };
    let mut next = uniform(777);
    // 0..700: a clump within reach of the origin (radius 0.3..0.5, centres within 0.15);
    // 700..1301: far away.
    for i in 0..1301 {
        let (spread, shift) = if i < 700 { (0.3, 0.0) } else { (1.0, 10.0) };
        let r: f32 = 0.3 + 0.2 * next();
        let c = [
            shift + spread * (next() - 0.5),
            spread * (next() - 0.5),
            spread * (next() - 0.5),
        ];
        push(&mut p, c, r, 0.25 + next(), &[next() - 0.5]);
    }
    p.pad();
    let runs = [(0u32, 613u32), (700, 1301), (613, 614), (614, 700), (5, 17)];
    let brute = |q: [f32; 3]| -> (f64, f64) {
        let (mut phi, mut num) = (0.0, 0.0);
        for &(a, b) in &runs {
            for j in a as usize..b as usize {
                let d2 = [p.x[j] - q[0], p.y[j] - q[1], p.z[j] - q[2]]
                    .map(|d| f64::from(d) * f64::from(d))
                    .iter()
                    .sum::<f64>();
                if d2 <= f64::from(p.r2[j]) {
                    let term = f64::from(p.w[j]) * (-f64::from(p.k[j]) * d2).exp();
                    phi += term;
                    num += f64::from(p.theta[0][j]) * term;
                }
            }
        }
        (phi, num)
    };
    // The baseline build, then AVX2, then AVX-512, as far as the CPU has them.
    let builds = [true, simd_in_use(), avx512_in_use()]
        .iter()
        .filter(|&&available| available)
        .count();
    for q in [
        [0.0, 0.0, 0.0],
        [0.05, -0.1, 0.02],
        [10.2, 0.1, -0.3],
        [3.0, 3.0, 3.0],
    ] {
        let (phi, num) = brute(q);
        for simd in 0..builds {
            allow_simd(simd >= 1);
            allow_avx512(simd == 2);
            let (got_phi, got_num) = p.sums(&runs, q);
            allow_simd(true);
            allow_avx512(true);
            let scale = phi.max(1e-30);
            assert!(
                (got_phi - phi).abs() <= 1e-5 * scale,
                "{q:?}, build {simd}: phi {got_phi} vs {phi}"
            );
            assert!(
                (got_num[0] - num).abs() <= 1e-5 * scale,
                "{q:?}, build {simd}: theta {} vs {num}",
                got_num[0]
            );
        }
        match q[0] {
            // Hundreds of terms: the kernel flushes its held candidates several times.
            x if x < 1.0 => assert!(phi > 100.0, "the clump reaches {q:?}: {phi}"),
            x if x > 9.0 => assert!(phi > 1.0, "the far particles reach {q:?}: {phi}"),
            _ => assert_eq!(phi, 0.0, "nothing reaches {q:?}"),
        }
    }
    // The dense loop over one run equals the kernel over it.
    let q = [0.02, 0.01, -0.03];
    let dense = dense_sums(&p, 0, 613, q);
    let kernel = p.sums(&[(0, 613)], q).0;
    assert!(
        (dense - kernel).abs() <= 1e-5 * kernel,
        "{dense} vs {kernel}"
    );
}

/// The packet kernel's narrowing with AVX2 keeps exactly the particles, in the order, that
/// the lanes keep (the same operations), into poisoned candidate slots, over boxes from a
/// point to wider than the particles, and runs of awkward lengths.
#[test]
fn the_avx2_narrowing_keeps_what_the_lanes_keep() {
    if !simd_in_use() {
        return;
    }
    let mut p = Packed::default();
    let mut next = uniform(4242);
    for _ in 0..517 {
        let r: f32 = 0.01 + 0.1 * next();
        push(&mut p, [next(), next(), next()], r, 1.0, &[]);
    }
    p.pad();
    let runs = [(0u32, 1u32), (3, 200), (200, 209), (300, 517), (17, 17)];
    let total: usize = runs.iter().map(|&(a, b)| (b - a) as usize).sum();
    let mut kept_any = false;
    for size in [0.0, 0.01, 0.1, 0.3, 2.0] {
        for _ in 0..20 {
            let lo = [next(), next(), next()];
            let hi = lo.map(|v| v + size * next());
            let mut fast = vec![u32::MAX; total + LANES];
            let mut lanes = vec![u32::MAX - 1; total + LANES];
            // SAFETY: `simd_in_use` checked the CPU's features above.
            let n_fast = unsafe { narrow_avx2(&p, &runs, lo, hi, &mut fast) };
            let n_lanes = narrow_lanes(&p, &runs, lo, hi, &mut lanes);
            assert_eq!(&fast[..n_fast], &lanes[..n_lanes], "box {lo:?} {hi:?}");
            kept_any |= n_fast > 0;
        }
    }
    assert!(kept_any, "some box keeps particles");
}

/// The worst relative error of `exp` over the kernel's range `[-4.5, 0]`, every f32 step
/// of the way (about 4e7 inputs, a stride of them).
fn worst_exp_error(exp: impl Fn(f32) -> f32) -> f64 {
    let mut worst = 0.0f64;
    let mut x = 0.0f32;
    while x >= -4.5 {
        let got = f64::from(exp(x));
        worst = worst.max((got / f64::from(x).exp() - 1.0).abs());
        x = f32::from_bits(x.to_bits() + 37).min(-f32::MIN_POSITIVE);
    }
    worst
}

/// The per-build constants the error bound uses are the exponentials' measured errors
/// (not below them, and not more than 1.5 times above).
#[test]
fn exp_errors_are_as_stated() {
    let baseline = worst_exp_error(exp_neg);
    assert!(
        baseline <= EXP_ERROR_BASELINE && EXP_ERROR_BASELINE <= 1.5 * baseline,
        "baseline build: measured {baseline:e}, stated {EXP_ERROR_BASELINE:e}"
    );
    #[cfg(target_arch = "x86_64")]
    if avx2_available() {
        let fma = worst_exp_error(|x| {
            use core::arch::x86_64::*;
            // SAFETY: AVX2 and FMA are present (checked above).
            unsafe {
                let v = exp_neg_avx2(_mm256_set1_ps(x));
                _mm256_cvtss_f32(v)
            }
        });
        assert!(
            fma <= EXP_ERROR_FMA && EXP_ERROR_FMA <= 1.5 * fma,
            "FMA build: measured {fma:e}, stated {EXP_ERROR_FMA:e}"
        );
    }
}

#[test]
fn exp_neg_is_within_its_stated_error() {
    let mut worst = 0.0f64;
    for i in 0..=1_000_000 {
        let x = -87.0 * f64::from(i) / 1e6;
        let x32 = x as f32;
        let got = f64::from(exp_neg(x32));
        let want = f64::from(x32).exp();
        worst = worst.max((got / want - 1.0).abs());
    }
    assert!(worst < 2.5e-7, "largest relative error {worst:e}");
    assert_eq!(exp_neg(0.0), 1.0);
    assert_eq!(exp_neg(-1e30), exp_neg(-87.0));
}
