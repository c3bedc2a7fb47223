//! How many particles can reach one point: the number of terms a field sum adds there, which
//! bounds the rounding error of adding them up in f32 (`backend::precision`). An upper bound,
//! not an estimate: a sampled mean or percentile would miss the densest clump of a halo, and the
//! error bound it feeds must hold at every point.

use glam::DVec3;
use rayon::prelude::*;

use crate::values::Bounds;

/// Cells per axis at most (a grid of 64³ counts in 1 MiB and is summed in a few ms), and about
/// one per cube root of the particles (so a small step's grid costs next to nothing).
const MAX_CELLS_PER_AXIS: f64 = 64.0;

/// An upper bound on how many of `centres` lie within `reach` of any single point, inside their
/// bounds or not. The centres are counted on a grid of cubic cells at least `reach / m` wide;
/// every centre within `reach` of a point lies within `m` cells of the point's cell on each axis,
/// so the largest count over a window of `(2m + 1)³` cells bounds it (a point outside the grid
/// sees a subset of an edge cell's window). Cells narrower than `reach` (small grids of wide
/// radii) make `m` larger and the bound tighter. O(centres + cells).
pub fn max_reach_count(centres: &[DVec3], reach: f64) -> usize {
    let n = centres.len();
    if n == 0 || reach.is_nan() || reach <= 0.0 || !reach.is_finite() {
        return 0;
    }
    let bounds = Bounds::of_points(centres);
    let extent = bounds.max - bounds.min;
    let most = (n as f64).cbrt().ceil().clamp(1.0, MAX_CELLS_PER_AXIS);
    // As wide as the longest axis allows with `most` cells, and never wider than needed.
    let side = (extent.max_element() / most)
        .max(reach / most)
        .max(f64::MIN_POSITIVE);
    let m = (reach / side).ceil() as i64;
    // At most `most` + 1 cells per axis.
    let dims = ((extent / side).floor() + 1.0).as_i64vec3();
    let (gx, gy, gz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    let cell_of = |p: DVec3| -> usize {
        let c = ((p - bounds.min) / side)
            .floor()
            .as_i64vec3()
            .clamp(glam::I64Vec3::ZERO, dims - 1);
        (c.x as usize * gy + c.y as usize) * gz + c.z as usize
    };
    let cells = gx * gy * gz;
    let counts = centres
        .par_chunks(1 << 16)
        .fold(
            || vec![0u32; cells],
            |mut counts, chunk| {
                for &p in chunk {
                    counts[cell_of(p)] += 1;
                }
                counts
            },
        )
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        })
        .unwrap_or_default();
    // Summed-area table with a zero border: sat[(x+1, y+1, z+1)] = Σ counts[..=x, ..=y, ..=z].
    let (sy, sz) = (gy + 1, gz + 1);
    let at = |x: usize, y: usize, z: usize| (x * sy + y) * sz + z;
    let mut sat = vec![0u64; (gx + 1) * sy * sz];
    for x in 0..gx {
        for y in 0..gy {
            for z in 0..gz {
                let c = u64::from(counts[(x * gy + y) * gz + z]);
                sat[at(x + 1, y + 1, z + 1)] = c
                    + sat[at(x, y + 1, z + 1)]
                    + sat[at(x + 1, y, z + 1)]
                    + sat[at(x + 1, y + 1, z)]
                    - sat[at(x, y, z + 1)]
                    - sat[at(x, y + 1, z)]
                    - sat[at(x + 1, y, z)]
                    + sat[at(x, y, z)];
            }
        }
    }
    let window = |c: usize, g: usize| {
        let lo = (c as i64 - m).max(0) as usize;
        let hi = ((c as i64 + m + 1) as usize).min(g);
        (lo, hi)
    };
    let mut best = 0u64;
    for x in 0..gx {
        let (x0, x1) = window(x, gx);
        for y in 0..gy {
            let (y0, y1) = window(y, gy);
            for z in 0..gz {
                let (z0, z1) = window(z, gz);
                let sum = sat[at(x1, y1, z1)]
                    + sat[at(x0, y0, z1)]
                    + sat[at(x0, y1, z0)]
                    + sat[at(x1, y0, z0)]
                    - sat[at(x0, y1, z1)]
                    - sat[at(x1, y0, z1)]
                    - sat[at(x1, y1, z0)]
                    - sat[at(x0, y0, z0)];
                best = best.max(sum);
            }
        }
    }
    (best as usize).min(n)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;

    /// The most centres within `reach` of any of `probes` (brute force).
    fn brute(centres: &[DVec3], probes: &[DVec3], reach: f64) -> usize {
        probes
            .iter()
            .map(|&x| {
                centres
                    .iter()
                    .filter(|&&c| (c - x).length() <= reach)
                    .count()
            })
            .max()
            .unwrap_or(0)
    }

    /// The bound is never below what brute force finds at the centres themselves, at random
    /// points and beyond the bounds, on clumps in a halo and co-located points; and it is not
    /// vacuous (within 30x of the densest point found) where the reach is the grid's cells'.
    #[test]
    fn bounds_every_point_and_is_not_vacuous() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for case in 0..12 {
            let n = [0usize, 1, 7, 333, 1001, 2500][case % 6];
            let mut centres: Vec<DVec3> = (0..n)
                .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * 10.0 + 1e6)
                .collect();
            // A tight clump of a fifth of them, and some exact copies.
            for c in centres.iter_mut().take(n / 5) {
                *c = DVec3::splat(1e6 + 5.0) + (*c - 1e6 - 5.0) * 1e-3;
            }
            for i in 0..n / 50 {
                centres[i + n / 2] = centres[i];
            }
            let reach = [1e-4, 0.05, 0.7, 3.0, 25.0][case % 5];
            let mut probes = centres.clone();
            probes.extend(
                (0..200).map(|_| {
                    DVec3::new(rng.random(), rng.random(), rng.random()) * 14.0 + 1e6 - 2.0
                }),
            );
            let bound = max_reach_count(&centres, reach);
            let found = brute(&centres, &probes, reach);
            assert!(bound >= found, "case {case}: bound {bound} < found {found}");
            assert!(bound <= n);
            // Where cells are about as wide as the reach the window is tight; far below the
            // grid's resolution it counts whole cells (a bound on the sums' rounding that is
            // loose there costs a compensated sum at most).
            if found > 0 && reach >= 0.7 {
                assert!(
                    bound <= 30 * found.max(8),
                    "case {case}: {bound} vs {found}"
                );
            }
        }
        assert_eq!(max_reach_count(&[DVec3::ONE], 0.0), 0);
        assert_eq!(max_reach_count(&[DVec3::ONE; 5], 1.0), 5);
    }
}
