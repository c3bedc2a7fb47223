use super::*;
use rand::{Rng, SeedableRng};

/// A clump of `count` particles of radius r to 2r in a cube of side `side` from (0.5, 0.5,
/// 0.5), then `halo` particles of radius `big_r` over the unit cube: what SPH
/// smoothing lengths make of a dense region in a sparse one.
fn clump_in_halo(
    rng: &mut impl Rng,
    (count, side, r): (usize, f64, f64),
    (halo, big_r): (usize, f64),
) -> (Vec<DVec3>, Vec<f64>) {
    let mut centers = Vec::new();
    let mut radii = Vec::new();
    for _ in 0..count {
        centers
            .push(DVec3::splat(0.5) + DVec3::new(rng.random(), rng.random(), rng.random()) * side);
        radii.push(r * (1.0 + rng.random::<f64>()));
    }
    for _ in 0..halo {
        centers.push(DVec3::new(rng.random(), rng.random(), rng.random()));
        radii.push(big_r);
    }
    (centers, radii)
}

/// A dense clump of small particles in a halo of large ones (as SPH smoothing lengths make
/// them): the clump's points get their clump neighbours, not the whole clump, and every
/// particle that reaches a point is among its candidates; along a ray, every point some
/// particle reaches lies in an occupied interval.
#[test]
fn levels_of_radii_keep_a_clump_from_flooding_its_cells() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let (mut centers, mut radii) = clump_in_halo(&mut rng, (20_000, 0.05, 0.002), (2_000, 0.1));
    centers.push(DVec3::splat(0.2));
    radii.push(0.0);
    let (grid, order) = CellGrid::build(&centers, &radii);
    assert_eq!(order.len(), centers.len() - 1, "radius 0 is left out");
    assert!(grid.levels.len() >= 2, "{} levels", grid.levels.len());
    let mut scratch = CellRuns::default();
    let mut most = 0;
    for _ in 0..500 {
        let x = DVec3::splat(0.5) + DVec3::new(rng.random(), rng.random(), rng.random()) * 0.05;
        let runs = grid.runs_at(x, &mut scratch);
        let candidates: Vec<u32> = runs
            .iter()
            .flat_map(|&(a, b)| (a..b).map(|p| order[p as usize]))
            .collect();
        most = most.max(candidates.len());
        for (i, (c, r)) in centers.iter().zip(&radii).enumerate() {
            if *r > 0.0 && (x - *c).length_squared() <= r * r {
                assert!(candidates.contains(&(i as u32)), "particle {i} reaches {x}");
            }
        }
    }
    // One level as wide as the halo's radius would hand every point the whole clump.
    assert!(most < 2_000, "{most} candidates at most");
    // A ray through the clump: wherever a particle reaches, an interval holds it.
    let (origin, dir) = (DVec3::new(0.0, 0.52, 0.53), DVec3::X);
    let mut intervals = Vec::new();
    grid.occupied(origin, dir, 0.0, 1.0, &mut intervals);
    assert!(
        intervals.windows(2).all(|w| w[0].1 < w[1].0),
        "{intervals:?}"
    );
    for k in 0..10_000 {
        let t = k as f64 / 1e4;
        let x = origin + dir * t;
        let reached = centers
            .iter()
            .zip(&radii)
            .any(|(c, r)| *r > 0.0 && (x - *c).length_squared() <= r * r);
        if reached {
            assert!(
                intervals.iter().any(|&(a, b)| a <= t && t <= b),
                "t = {t} is reached but in no interval"
            );
        }
    }
}

/// Point queries in groups: a group takes consecutive points until one in reach of some
/// particle would widen its block of cells past two a side on some level, and its runs
/// hold every candidate of each of its points (so every particle reaching one). Points on
/// two levels of radii, in walks of steps from a tenth of a cell to three cells, some
/// outside every grid.
#[test]
fn a_group_takes_points_until_its_block_would_pass_two_cells() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
    let (centers, radii) = clump_in_halo(&mut rng, (3_000, 0.1, 0.01), (1_000, 0.05));
    let (grid, order) = CellGrid::build(&centers, &radii);
    assert!(grid.levels.len() >= 2, "{} levels", grid.levels.len());
    let cells_of = |l: DVec3| -> Vec<Option<(bool, [usize; 3])>> {
        grid.levels
            .iter()
            .map(|level| level.cell_at(l).map(|(c, ijk)| (level.reached(c), ijk)))
            .collect()
    };
    let widen = |block: &mut ([usize; 3], [usize; 3]), ijk: &[usize; 3]| {
        for (a, &v) in ijk.iter().enumerate() {
            block.0[a] = block.0[a].min(v);
            block.1[a] = block.1[a].max(v);
        }
    };
    let mut scratch = CellRuns::default();
    let (mut grouped, mut cut) = (0, 0);
    for walk in 0..400 {
        let step = [0.001, 0.005, 0.02, 0.1][walk % 4];
        let mut x = DVec3::new(rng.random(), rng.random(), rng.random()) * 1.2 - DVec3::splat(0.1);
        let points: Vec<DVec3> = (0..1 + walk % 20)
            .map(|_| {
                x += (DVec3::new(rng.random(), rng.random(), rng.random()) - DVec3::splat(0.5))
                    * step;
                x
            })
            .collect();
        let (count, reached, runs) = grid.runs_around_prefix(&points, &mut scratch);
        assert!((1..=points.len().min(32)).contains(&count), "{count}");
        // Which points are in reach, and the blocks of those in the group.
        let mut blocks = vec![([usize::MAX; 3], [0; 3]); grid.levels.len()];
        for (i, &p) in points.iter().enumerate().take(count) {
            let cells = cells_of(p);
            let any = cells.iter().any(|c| c.is_some_and(|(r, _)| r));
            assert_eq!((reached >> i) & 1 == 1, any, "point {i} of walk {walk}");
            if any {
                for (block, cell) in blocks.iter_mut().zip(&cells) {
                    if let Some((_, ijk)) = cell {
                        widen(block, ijk);
                    }
                }
            }
        }
        let within = |blocks: &[([usize; 3], [usize; 3])]| {
            blocks
                .iter()
                .all(|(lo, hi)| lo[0] == usize::MAX || (0..3).all(|a| hi[a] - lo[a] <= 1))
        };
        assert!(within(&blocks), "walk {walk}: {blocks:?}");
        if count < points.len().min(32) {
            // The next point is in reach and would widen a block past two cells.
            cut += 1;
            let cells = cells_of(points[count]);
            assert!(cells.iter().any(|c| c.is_some_and(|(r, _)| r)));
            for (block, cell) in blocks.iter_mut().zip(&cells) {
                if let Some((_, ijk)) = cell {
                    widen(block, ijk);
                }
            }
            assert!(!within(&blocks), "walk {walk}: point {count} fits");
        }
        let Some(runs) = runs else {
            assert!(reached.count_ones() < 2);
            continue;
        };
        assert!(reached.count_ones() >= 2);
        grouped += 1;
        let group: Vec<u32> = runs
            .iter()
            .flat_map(|&(a, b)| (a..b).map(|p| order[p as usize]))
            .collect();
        let mut own = CellRuns::default();
        for (i, &p) in points.iter().enumerate().take(count) {
            if (reached >> i) & 1 == 0 {
                continue;
            }
            for &(a, b) in grid.runs_at(p, &mut own) {
                for q in a..b {
                    assert!(group.contains(&order[q as usize]), "walk {walk}, point {i}");
                }
            }
            for (j, (c, r)) in centers.iter().zip(&radii).enumerate() {
                if (p - *c).length_squared() <= r * r {
                    assert!(
                        group.contains(&(j as u32)),
                        "particle {j} reaches point {i}"
                    );
                }
            }
        }
    }
    assert!(
        grouped > 100 && cut > 50,
        "{grouped} groups, {cut} cut short"
    );
}
