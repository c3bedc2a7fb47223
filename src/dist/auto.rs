//! The automatic values that come from the series' first step, Phi_ref and the mean overlap
//! that chooses the cluster size ([`crate::render::auto`]), computed by P ranks of which each
//! holds only its part of the step (`[rN/P, (r+1)N/P)`, [`crate::io::Part`]): no rank reads the
//! whole step, and every rank finds the single rank's number, up to the order Phi's terms are
//! summed in (the overlap, a count, exactly).
//!
//! Both estimates sample the same records as the single rank (every k-th of the whole step,
//! by global index) under the same rules ([`Estimate`]), in four collectives:
//! 1. one all-gather of each part's length and bounds: the whole step's record count, each
//!    part's first record (the whole step's records are the parts' in rank order) and the
//!    whole step's bounds, so that each rank lays its part in the whole step's grid;
//! 2. for Phi_ref, whose k depends on how crowded that grid is ([`mean_candidates`]): one
//!    all-to-all of each part's (cell, count) pairs to the rank that owns the cell, which adds
//!    its cells' counts and squares them, and one all-gather of those sums: the whole grid's
//!    number, exactly, so the same k;
//! 3. one all-gather of the centres each part samples: every rank has them all, in order;
//! 4. each rank sums at every centre its own particles' terms, and the sums are added over the
//!    ranks in rank order (reduce-scatter by one all-to-all, each rank adding one slice of the
//!    centres, then one all-gather of the slices), so every rank has the same values and takes
//!    the same percentile.

use std::ops::AddAssign;

use bytemuck::Pod;
use glam::DVec3;
use rayon::prelude::*;

use super::DistError;
use super::comm::{Comm, CommExt};
use super::knn::RankLengths;
use crate::field::FieldSettings;
use crate::io::Part;
use crate::render::AutoValues;
use crate::render::auto::{
    Estimate, bounds_of, mean_candidates, mean_count, overlap_stride, phi_percentile,
    phi_ref_stride,
};
use crate::scene::TimeSeries;
use crate::values::Step;

/// The values [`AutoValues::with_phi_ref`] finds for `field` over `series`, each rank reading
/// only its part of the first step where Phi_ref is not `given` (and none where it is). Every
/// rank calls it and gets the same values.
pub fn auto_values(
    comm: &dyn Comm,
    series: &TimeSeries,
    field: &FieldSettings,
    given: Option<f64>,
) -> Result<AutoValues, DistError> {
    AutoValues::estimated(series, field, given, |estimate| {
        phi_ref_of_part(comm, estimate, &*first_part(comm, series)?)
    })
}

/// The mean overlap [`crate::render::auto::mean_overlap`] finds for `field` over `series`, each
/// rank reading only its part of the first step. Every rank calls it and gets the same value.
pub fn mean_overlap(
    comm: &dyn Comm,
    series: &TimeSeries,
    field: &FieldSettings,
) -> Result<f64, DistError> {
    if series.is_empty() {
        return Ok(0.0);
    }
    overlap_of_part(
        comm,
        &Estimate::new(series, field),
        &*first_part(comm, series)?,
    )
}

/// The particles' spacing in the series' first step as
/// [`crate::accel::spacing::median_nearest_distance`] measures it over the whole step, each
/// rank holding its part: the same evenly strided sample by global index, each sample's
/// nearest neighbours found by every rank among its own particles and the nearest of them
/// kept, so every rank finds the single process's value, exactly. Three collectives: the
/// parts' lengths; the sample's points; each sample's distances sent to the rank that merges
/// them, and the merged nearest distances to every rank.
pub fn first_step_spacing(comm: &dyn Comm, series: &TimeSeries) -> Result<Option<f64>, DistError> {
    if series.is_empty() {
        return Ok(None);
    }
    let part = first_part(comm, series)?;
    median_nearest_distance(comm, &part.positions)
}

/// [`first_step_spacing`] over the parts `mine` of the ranks' positions, in rank order.
pub fn median_nearest_distance(comm: &dyn Comm, mine: &[DVec3]) -> Result<Option<f64>, DistError> {
    use crate::accel::spacing::{NEIGHBOURS, SAMPLE, median_of, nearest_apart};
    use kiddo::{ImmutableKdTree, SquaredEuclidean};
    let lengths = one_each(comm.all_gather_of(&[mine.len() as u64])?, "a part's length")?;
    let n: u64 = lengths.iter().sum();
    if n < 2 {
        return Ok(None);
    }
    let first: u64 = lengths[..comm.rank()].iter().sum();
    let stride = n.div_ceil(SAMPLE as u64);
    // This part's samples: the whole step's records 0, stride, 2 stride, ... that it holds.
    let start = first.div_ceil(stride) * stride;
    let samples: Vec<[f64; 3]> = (start..first + mine.len() as u64)
        .step_by(stride as usize)
        .map(|i| mine[(i - first) as usize].to_array())
        .collect();
    let samples: Vec<[f64; 3]> = comm.all_gather_of(&samples)?.concat();
    let k = NEIGHBOURS.min(n as usize);
    // Each sample's k nearest squared distances among this part's particles (fewer where the
    // part holds fewer), padded with +inf, sent to the sample's merging rank s mod P.
    let size = comm.size();
    let mut send: Vec<Vec<f64>> = vec![Vec::new(); size];
    let points: Vec<[f64; 3]> = mine.iter().map(|p| p.to_array()).collect();
    let tree: Option<ImmutableKdTree<f64, 3>> =
        (!points.is_empty()).then(|| ImmutableKdTree::new_from_slice(&points));
    for (s, q) in samples.iter().enumerate() {
        let mut d: Vec<f64> = match (&tree, std::num::NonZero::new(k.min(points.len()))) {
            (Some(tree), Some(kk)) => tree
                .nearest_n::<SquaredEuclidean>(q, kk)
                .into_iter()
                .map(|nn| nn.distance)
                .collect(),
            _ => Vec::new(),
        };
        d.resize(k, f64::INFINITY);
        send[s % size].extend(d);
    }
    let received = comm.all_to_all_of(&send)?;
    // The samples this rank merges, in order: the k nearest over every part, and the first
    // of them at a distance (the single process's rule).
    let mine_merged: Vec<f64> = (0..samples.len())
        .filter(|s| s % size == comm.rank())
        .enumerate()
        .map(|(j, _)| {
            let mut all: Vec<f64> = received
                .iter()
                .flat_map(|r| r.get(j * k..(j + 1) * k).unwrap_or(&[]).iter().copied())
                .collect();
            all.sort_by(f64::total_cmp);
            all.truncate(k);
            // Every part pads to k with +inf; the k nearest over all parts are finite.
            nearest_apart(all).unwrap_or(f64::NAN)
        })
        .collect();
    let merged = comm.all_gather_of(&mine_merged)?;
    // Back in sample order; NaN: a sample with no particle at a distance.
    let mut nearest: Vec<f64> = (0..samples.len())
        .map(|s| merged[s % size].get(s / size).copied().unwrap_or(f64::NAN))
        .filter(|d| !d.is_nan())
        .collect();
    Ok(median_of(&mut nearest))
}

/// This rank's part of the series' first step, read once for the spacing, the mean overlap
/// and Phi_ref ([`TimeSeries::step_part_kept`]; the render loop clears it with the series'
/// cache once its automatic values are known).
fn first_part(comm: &dyn Comm, series: &TimeSeries) -> Result<std::sync::Arc<Step>, DistError> {
    Ok(series.step_part_kept(
        0,
        Part::new(comm.rank(), comm.size()),
        &RankLengths { comm },
    )?)
}

/// Phi_ref under `estimate`'s rules, `first` being this rank's part of the first step.
pub(crate) fn phi_ref_of_part(
    comm: &dyn Comm,
    estimate: &Estimate,
    first: &Step,
) -> Result<f64, DistError> {
    let layout = Layout::gather(comm, &first.positions)?;
    if layout.count == 0 || !estimate.reaches() {
        return Ok(1.0);
    }
    let grid = estimate.grid(&first.positions, layout.bounds);
    let squares = squared_cell_counts(comm, &grid.cell_counts())?;
    let stride = phi_ref_stride(layout.count, mean_candidates(squares, layout.count));
    let centres = layout.centres(comm, &first.positions, stride)?;
    let particles = estimate.particles(first);
    let mine: Vec<f64> = centres
        .par_iter()
        .map(|&x| particles.phi_at(x, &grid))
        .collect();
    Ok(phi_percentile(sum_over_ranks(comm, &mine)?))
}

/// The mean overlap under `estimate`'s rules, `first` being this rank's part of the first step.
pub(crate) fn overlap_of_part(
    comm: &dyn Comm,
    estimate: &Estimate,
    first: &Step,
) -> Result<f64, DistError> {
    let layout = Layout::gather(comm, &first.positions)?;
    if layout.count == 0 || !estimate.reaches() {
        return Ok(0.0);
    }
    let grid = estimate.grid(&first.positions, layout.bounds);
    let centres = layout.centres(comm, &first.positions, overlap_stride(layout.count))?;
    let particles = estimate.particles(first);
    let mine: Vec<u64> = centres
        .par_iter()
        .map(|&x| particles.reaching(x, &grid))
        .collect();
    Ok(mean_count(&sum_over_ranks(comm, &mine)?))
}

/// What each rank says of its part in the first collective.
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct PartSummary {
    records: u64,
    least: [f64; 3],
    greatest: [f64; 3],
}

/// Where this rank's part lies in the whole step.
struct Layout {
    /// The whole step's records.
    count: usize,
    /// The global index of this part's first record.
    offset: usize,
    /// The whole step's least and greatest corner.
    bounds: (DVec3, DVec3),
}

impl Layout {
    fn gather(comm: &dyn Comm, positions: &[DVec3]) -> Result<Layout, DistError> {
        let (least, greatest) = bounds_of(positions);
        let mine = PartSummary {
            records: positions.len() as u64,
            least: least.to_array(),
            greatest: greatest.to_array(),
        };
        let all = one_each(comm.all_gather_of(&[mine])?, "part summaries")?;
        let records = |s: &PartSummary| s.records as usize;
        Ok(Layout {
            count: all.iter().map(records).sum(),
            offset: all[..comm.rank()].iter().map(records).sum(),
            bounds: all
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), s| {
                    (
                        lo.min(DVec3::from(s.least)),
                        hi.max(DVec3::from(s.greatest)),
                    )
                }),
        })
    }

    /// The centres of records `0, stride, 2 stride, ...` of the whole step, in that order:
    /// this part's among them are the ones whose global index is a multiple of `stride`.
    fn centres(
        &self,
        comm: &dyn Comm,
        positions: &[DVec3],
        stride: usize,
    ) -> Result<Vec<DVec3>, DistError> {
        let first = self.offset.next_multiple_of(stride) - self.offset;
        let mine: Vec<[f64; 3]> = positions
            .iter()
            .skip(first)
            .step_by(stride)
            .map(|p| p.to_array())
            .collect();
        let all: Vec<DVec3> = comm
            .all_gather_of(&mine)?
            .concat()
            .into_iter()
            .map(DVec3::from)
            .collect();
        let expected = self.count.div_ceil(stride);
        if all.len() != expected {
            return Err(DistError::Malformed(format!(
                "the ranks sampled {} centres of {} records, every {stride}th: expected \
                 {expected}",
                all.len(),
                self.count
            )));
        }
        Ok(all)
    }
}

/// The sum over the whole step's occupied cells of their particle counts squared, from each
/// part's `counts` ((cell key, count), as [`crate::render::auto::Grid::cell_counts`] gives
/// them): a cell's particles may lie in several parts, so each cell's counts go to the rank
/// that owns its key, which adds them up before squaring.
fn squared_cell_counts(comm: &dyn Comm, counts: &[(u64, u64)]) -> Result<u128, DistError> {
    let size = comm.size();
    // A multiplicative hash spreads the keys (cells along one axis) evenly over the ranks.
    let owner = |key: u64| ((key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) as usize) % size;
    let mut send: Vec<Vec<[u64; 2]>> = vec![Vec::new(); size];
    for &(key, count) in counts {
        send[owner(key)].push([key, count]);
    }
    let mut owned: Vec<[u64; 2]> = comm.all_to_all_of(&send)?.concat();
    drop(send);
    owned.sort_unstable_by_key(|pair| pair[0]);
    let squares: u128 = owned
        .chunk_by(|a, b| a[0] == b[0])
        .map(|cell| {
            let count: u128 = cell.iter().map(|pair| u128::from(pair[1])).sum();
            count * count
        })
        .sum();
    Ok(comm.all_gather_of(&[squares])?.concat().iter().sum())
}

/// The element-wise sums over the ranks of `mine` (the same length on every rank), added in
/// rank order, on every rank: rank r adds slice r of the values ([`Part::range`]'s rule), one
/// all-to-all bringing it every rank's slice r, and one all-gather shares the slices.
fn sum_over_ranks<T: Pod + Default + AddAssign>(
    comm: &dyn Comm,
    mine: &[T],
) -> Result<Vec<T>, DistError> {
    let size = comm.size();
    let slice = |r: usize| Part::new(r, size).range(mine.len());
    let send: Vec<Vec<T>> = (0..size).map(|r| mine[slice(r)].to_vec()).collect();
    let received = comm.all_to_all_of(&send)?;
    let own = slice(comm.rank());
    let mut sums = vec![T::default(); own.len()];
    for (from, values) in received.iter().enumerate() {
        if values.len() != own.len() {
            return Err(DistError::Malformed(format!(
                "rank {from} sent {} partial sums for a slice of {}",
                values.len(),
                own.len()
            )));
        }
        for (sum, &value) in sums.iter_mut().zip(values) {
            *sum += value;
        }
    }
    let all = comm.all_gather_of(&sums)?.concat();
    if all.len() != mine.len() {
        return Err(DistError::Malformed(format!(
            "{} sums gathered for {} values",
            all.len(),
            mine.len()
        )));
    }
    Ok(all)
}

/// One value from each rank, in rank order.
fn one_each<T>(gathered: Vec<Vec<T>>, what: &str) -> Result<Vec<T>, DistError> {
    gathered
        .into_iter()
        .enumerate()
        .map(
            |(rank, mut values)| match (values.pop(), values.is_empty()) {
                (Some(value), true) => Ok(value),
                _ => Err(DistError::Malformed(format!(
                    "rank {rank} sent other than one value in the {what}"
                ))),
            },
        )
        .collect()
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::dist::run_local;
    use crate::render::auto::PHI_REF_SAMPLES;
    use crate::scene::OpenOptions;
    use crate::scene::synth::Generator;
    use crate::values::Attribute;

    /// The ranks the distributed values are checked for.
    const RANKS: [usize; 5] = [1, 2, 3, 5, 8];

    fn relative(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(1e-300)
    }

    /// `n` particles far from the origin in an anisotropic box, denser in one corner, with a
    /// radius attribute h in [0.5, 1.5] and a scalar.
    fn cloud(n: usize, seed: u64) -> Step {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let positions: Vec<DVec3> = (0..n)
            .map(|_| {
                DVec3::new(
                    2.0 * rng.random::<f64>().powi(2),
                    rng.random(),
                    0.5 * rng.random::<f64>(),
                ) + 3e4
            })
            .collect();
        Step {
            name: "cloud".into(),
            attributes: vec![
                Attribute {
                    name: "h".into(),
                    values: (0..n).map(|_| 0.5 + rng.random::<f64>()).collect(),
                },
                Attribute {
                    name: "s".into(),
                    values: positions.iter().map(|p| p.x - p.y).collect(),
                },
            ],
            positions,
        }
    }

    /// On every rank count of `ranks`, every rank finds the single rank's automatic values
    /// (Phi_ref within `1e-12` relative, the radii and the mean overlap exactly), the same on
    /// every rank; returns the largest relative difference of Phi_ref.
    fn check_against_the_single_rank(
        what: &str,
        series: &TimeSeries,
        field: &FieldSettings,
    ) -> f64 {
        let single = AutoValues::with_phi_ref(series, field, None).unwrap();
        let single_overlap = crate::render::auto::mean_overlap(series, field).unwrap();
        assert!(
            single.phi_ref > 0.0 && single.phi_ref != 1.0,
            "{what}: {single:?}"
        );
        assert!(
            single_overlap > 1.0,
            "{what}: particles overlap ({single_overlap})"
        );
        let mut worst = 0f64;
        for p in RANKS {
            let got = run_local(p, |comm| {
                Ok((
                    auto_values(comm, series, field, None)?,
                    mean_overlap(comm, series, field)?,
                ))
            })
            .unwrap();
            for (rank, (auto, overlap)) in got.iter().enumerate() {
                assert_eq!(auto, &got[0].0, "{what}, P = {p}: rank {rank} differs");
                assert_eq!(*overlap, single_overlap, "{what}, P = {p}, rank {rank}");
            }
            let auto = got[0].0;
            let difference = relative(auto.phi_ref, single.phi_ref);
            eprintln!(
                "{what}, P = {p}: phi_ref {} against {} (relative difference {difference:.1e})",
                auto.phi_ref, single.phi_ref
            );
            assert!(
                difference <= 1e-12,
                "{what}, P = {p}: {auto:?} against {single:?}"
            );
            assert_eq!(
                (auto.typical_radius, auto.max_radius),
                (single.typical_radius, single.max_radius)
            );
            worst = worst.max(difference);
        }
        worst
    }

    /// The whole step's stride for Phi_ref, from its own grid.
    fn whole_stride(series: &TimeSeries, field: &FieldSettings) -> usize {
        let step = series.step(0).unwrap();
        let estimate = Estimate::new(series, field);
        let grid = estimate.grid(&step.positions, bounds_of(&step.positions));
        let squares = grid
            .cell_counts()
            .iter()
            .map(|&(_, c)| u128::from(c) * u128::from(c))
            .sum();
        phi_ref_stride(step.len(), mean_candidates(squares, step.len()))
    }

    #[test]
    fn ranks_find_the_single_rank_s_values_on_a_dam_break_and_a_cloud() {
        // A dam break whose count is not a power of two: 4096 centres, every 8th record.
        let dam_break = TimeSeries::from_steps(Generator::DambreakDemo.generate(30_011, 2, 5));
        let n = dam_break.step(0).unwrap().len();
        let mut field = FieldSettings::new(Some("velocity"), 0.02 * dam_break.bounds().diagonal());
        field.density_map =
            crate::scene::maps::DensityMap::new("0:0.3,0.7:1,1:0.2".parse().unwrap()).unwrap();
        assert_eq!(
            whole_stride(&dam_break, &field),
            n.div_ceil(PHI_REF_SAMPLES)
        );
        assert!(whole_stride(&dam_break, &field) > 1);
        check_against_the_single_rank("dam break", &dam_break, &field);

        // Radii from an attribute, off-origin positions, and radii so large that the work
        // bound sets the stride (fewer than 4096 centres): the parts' cells must add up to the
        // whole step's.
        let cloud = TimeSeries::from_steps(vec![cloud(10_007, 11)]);
        let mut field = FieldSettings::new(Some("s"), 0.02);
        field.radius_attribute = Some("h".into());
        check_against_the_single_rank("cloud", &cloud, &field);
        field.radius = 0.4;
        let stride = whole_stride(&cloud, &field);
        eprintln!("cloud, large radii: every {stride}th record sampled");
        assert!(
            stride > 10_007usize.div_ceil(PHI_REF_SAMPLES) && stride < 10_007 / 64,
            "the work bound sets the stride: {stride}"
        );
        check_against_the_single_rank("cloud, large radii", &cloud, &field);
    }

    /// Each part's (cell, count) pairs, sent to the cells' owners and added there, square to the
    /// whole step's sum exactly, for parts that split cells among ranks.
    #[test]
    fn the_parts_cells_square_to_the_whole_step_s() {
        let step = cloud(5003, 3);
        let series = TimeSeries::from_steps(vec![step.clone()]);
        let field = FieldSettings::new(None, 0.05);
        let estimate = Estimate::new(&series, &field);
        let bounds = bounds_of(&step.positions);
        let whole: u128 = estimate
            .grid(&step.positions, bounds)
            .cell_counts()
            .iter()
            .map(|&(_, c)| u128::from(c) * u128::from(c))
            .sum();
        assert!(whole > 5003, "cells hold several particles: {whole}");
        for p in RANKS {
            let got = run_local(p, |comm| {
                let part = crate::dist::slice_of(&step, comm.rank(), comm.size());
                let grid = estimate.grid(&part.positions, bounds);
                squared_cell_counts(comm, &grid.cell_counts())
            })
            .unwrap();
            assert!(
                got.iter().all(|&s| s == whole),
                "P = {p}: {got:?} against {whole}"
            );
        }
    }

    /// Sums over ranks are added in rank order and are the same on every rank, for more and
    /// fewer values than ranks.
    #[test]
    fn sums_over_ranks_are_every_rank_s_values_added_in_rank_order() {
        for p in RANKS {
            for len in [0, 1, 3, 17] {
                let values = |rank: usize| -> Vec<f64> {
                    (0..len).map(|i| (rank * 100 + i) as f64).collect()
                };
                let got = run_local(p, |comm| sum_over_ranks(comm, &values(comm.rank()))).unwrap();
                let want: Vec<f64> = (0..len)
                    .map(|i| (0..p).fold(0.0, |sum, r| sum + values(r)[i]))
                    .collect();
                assert!(got.iter().all(|g| g == &want), "P = {p}, {len} values");
            }
        }
    }

    /// A copy of the file `name` of tests/data under `dir` (opening a file writes an index
    /// beside it; the inputs stay untouched).
    fn copy_of(name: &str, dir: &Path) -> std::path::PathBuf {
        let from = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name);
        let to = dir.join(from.file_name().unwrap());
        std::fs::copy(&from, &to).unwrap();
        to
    }

    /// Steps as other programs write them: NumPy's Fortran-order big-endian array (1001 rows,
    /// a millionth of their distance from the origin apart), the same particles as NumPy's
    /// CSV (parts split by bytes, not records) and h5py's SWIFT snapshot. Each rank reads only
    /// its part (exactly its share where the format allows), nothing reads or caches the whole
    /// step, and the ranks' values are the single rank's.
    #[test]
    fn ranks_reading_their_parts_of_files_find_the_single_rank_s_values() {
        let dir = tempfile::tempdir().unwrap();
        let numpy = copy_of("numpy_fortran_be.npy", dir.path());
        let csv = copy_of("numpy_particles.csv", dir.path());
        let swift = copy_of("h5py_swift/snap_0000.hdf5", dir.path());
        let smoothed = {
            let mut field = FieldSettings::new(Some("Temperatures"), 2.0);
            field.radius_attribute = Some("SmoothingLengths".into());
            field
        };
        let cases = [
            (numpy, FieldSettings::new(Some("col3"), 1.5e-4), true),
            (csv, FieldSettings::new(Some("density"), 1.5e-4), false),
            (swift, smoothed, true),
        ];
        for (path, field, exact_share) in cases {
            let what = path.file_name().unwrap().to_string_lossy().into_owned();
            let series = TimeSeries::open(&path, &OpenOptions::default()).unwrap();
            let n = series.step(0).unwrap().len();
            let single = AutoValues::of(&series, &field).unwrap();
            let single_overlap = crate::render::auto::mean_overlap(&series, &field).unwrap();
            series.clear_cache();
            let decoded = series.steps_decoded();
            for p in RANKS {
                let got = run_local(p, |comm| {
                    let part = Part::new(comm.rank(), comm.size());
                    let read = series.step_part(0, part, &RankLengths { comm })?;
                    if exact_share {
                        assert_eq!(read.decoded, part.range(n).len(), "{what}, P = {p}");
                    } else {
                        assert!(read.decoded < n || p == 1, "{what}, P = {p}");
                    }
                    let estimate = Estimate::new(&series, &field);
                    Ok((
                        phi_ref_of_part(comm, &estimate, &read.step)?,
                        overlap_of_part(comm, &estimate, &read.step)?,
                        auto_values(comm, &series, &field, None)?,
                    ))
                })
                .unwrap();
                for (phi_ref, overlap, auto) in &got {
                    assert_eq!(*auto, got[0].2, "{what}, P = {p}");
                    assert_eq!(*phi_ref, auto.phi_ref, "{what}, P = {p}");
                    assert_eq!(*overlap, single_overlap, "{what}, P = {p}");
                }
                let difference = relative(got[0].2.phi_ref, single.phi_ref);
                eprintln!(
                    "{what}, P = {p}: phi_ref {} against {} (relative difference \
                     {difference:.1e}), overlap {single_overlap}",
                    got[0].2.phi_ref, single.phi_ref
                );
                assert!(difference <= 1e-12, "{what}, P = {p}");
            }
            assert!(
                single_overlap > 2.0,
                "{what}: particles overlap ({single_overlap})"
            );
            assert_eq!(
                series.steps_decoded(),
                decoded,
                "{what}: no whole step was read"
            );
            assert!(!series.is_cached(0), "{what}: no whole step is held");
        }
    }

    #[test]
    fn the_spacing_from_parts_is_the_whole_step_s_exactly() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(49);
        // A jittered lattice off the origin with co-located copies (boundary particles written
        // twice), in sizes around and past the sample's 2048 and not powers of two.
        for n in [2usize, 9, 1000, 2049, 5003] {
            let mut points: Vec<DVec3> = (0..n)
                .map(|i| {
                    let (x, y, z) = ((i % 17) as f64, ((i / 17) % 13) as f64, (i / 221) as f64);
                    DVec3::new(1e4 + 0.04 * x, -3.0 + 0.04 * y, 0.04 * z)
                        + DVec3::new(rng.random(), rng.random(), rng.random()) * 1e-6
                })
                .collect();
            for i in (0..n).step_by(7) {
                let copy = points[i];
                points.push(copy);
            }
            let want = crate::accel::spacing::median_nearest_distance(&points);
            for ranks in [1, 2, 3, 4, 5, 8, 9, 16] {
                let got = run_local(ranks, |comm| {
                    let part = Part::new(comm.rank(), comm.size()).range(points.len());
                    median_nearest_distance(comm, &points[part])
                })
                .unwrap();
                for g in got {
                    assert_eq!(
                        g.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "n = {n}, P = {ranks}: {g:?} against {want:?}"
                    );
                }
            }
        }
        // No two particles apart: none, as for the whole step.
        let same = vec![DVec3::ONE; 5];
        assert_eq!(crate::accel::spacing::median_nearest_distance(&same), None);
        let got = run_local(3, |comm| {
            median_nearest_distance(comm, &same[Part::new(comm.rank(), 3).range(5)])
        })
        .unwrap();
        assert!(got.iter().all(Option::is_none));
    }

    #[test]
    fn the_median_over_parts_is_the_whole_sort_s() {
        let values: Vec<f64> = (0..1001)
            .map(|i| ((i * 7919) % 1013) as f64 * 0.01)
            .collect();
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for ranks in [1, 2, 3, 7] {
            let got = run_local(ranks, |comm| {
                crate::dist::order::median(
                    comm,
                    &values[Part::new(comm.rank(), ranks).range(values.len())],
                )
            })
            .unwrap();
            assert!(
                got.iter().all(|m| *m == Some(sorted[values.len() / 2])),
                "{got:?}"
            );
        }
        let none = run_local(2, |comm| crate::dist::order::median(comm, &[])).unwrap();
        assert_eq!(none, vec![None, None]);
    }
}
