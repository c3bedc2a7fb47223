//! Each rank of a distributed render reads its part of a step (`io::read_step_part`, issue 49):
//! on files as NumPy, h5py, GADGET-style writers and text writers make them, for P = 1..9 and
//! 16 ranks, the parts put together in rank order are the whole step's records, and each part
//! decoded no more than its share: exactly its records `[rN/P, (r+1)N/P)` for fixed-size
//! records and HDF5; for CSV the records whose first byte lies in its share of the body's bytes,
//! at most `ceil(N/P · longest row / shortest row) + 1`. Formats read whole decode N records on
//! every rank, and say so.

use std::path::Path;

use aarbf::io::{self, AttributeSelection, Part, ReadOptions, StepRef};
use aarbf::values::{Attribute, Step};
use glam::DVec3;

use crate::common;

const RANKS: [usize; 10] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 16];

/// How many records a part may decode.
#[derive(Clone, Copy, Debug)]
enum Bound {
    /// Exactly its own records.
    Exact,
    /// Records by bytes: at most ceil(N/P · longest / shortest record) + 1.
    Bytes { longest: usize, shortest: usize },
    /// Every record (the format is read whole).
    Whole,
}

fn only(names: &[&str]) -> AttributeSelection {
    AttributeSelection::Only(names.iter().map(|n| n.to_string()).collect())
}

fn the_step(path: &Path) -> StepRef {
    let mut steps = io::list_steps(path, None).unwrap();
    assert_eq!(steps.len(), 1, "{}", path.display());
    steps.remove(0)
}

/// The records of `parts`, one after another.
fn joined(parts: &[Step], like: &Step) -> Step {
    Step {
        name: like.name.clone(),
        positions: parts.iter().flat_map(|p| p.positions.clone()).collect(),
        attributes: like
            .attributes
            .iter()
            .enumerate()
            .map(|(k, a)| Attribute {
                name: a.name.clone(),
                values: parts
                    .iter()
                    .flat_map(|p| {
                        assert_eq!(p.attributes[k].name, a.name);
                        p.attributes[k].values.clone()
                    })
                    .collect(),
            })
            .collect(),
    }
}

/// Every part count of [`RANKS`]: the parts joined are `io::read_step`'s step, bit for bit,
/// and each decoded what `bound` allows. `records`: the records the file holds (N, before
/// non-finite ones are dropped).
fn check_parts(step: &StepRef, selection: &AttributeSelection, records: usize, bound: Bound) {
    let whole = io::read_step(step, selection).unwrap();
    for ranks in RANKS {
        let mut parts = Vec::new();
        let mut decoded = 0;
        for rank in 0..ranks {
            let part = io::read_step_part(step, selection, Part::new(rank, ranks))
                .unwrap_or_else(|e| panic!("{}: rank {rank} of {ranks}: {e}", step.name));
            let share = Part::new(rank, ranks).range(records).len();
            let limit = match bound {
                Bound::Exact => share,
                Bound::Bytes { longest, shortest } => {
                    (records * longest).div_ceil(ranks * shortest) + 1
                }
                Bound::Whole => records,
            };
            match bound {
                Bound::Exact => assert_eq!(part.decoded, share, "{} {rank}/{ranks}", step.name),
                Bound::Whole => assert_eq!(part.decoded, records, "{} {rank}/{ranks}", step.name),
                Bound::Bytes { .. } => assert!(
                    part.decoded <= limit,
                    "{}: rank {rank} of {ranks} decoded {} records, more than {limit}",
                    step.name,
                    part.decoded
                ),
            }
            assert!(part.step.len() <= part.decoded.min(limit));
            decoded += part.decoded;
            parts.push(part.step);
        }
        if !matches!(bound, Bound::Whole) {
            assert_eq!(decoded, records, "{}: {ranks} ranks", step.name);
        }
        let together = joined(&parts, &whole);
        assert_eq!(together.positions, whole.positions, "{} {ranks}", step.name);
        assert_eq!(
            together.attributes, whole.attributes,
            "{} {ranks}",
            step.name
        );
    }
}

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Row lengths of a text file's body (the lines after its first), newline included.
fn row_lengths(path: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let lengths: Vec<usize> = text
        .split_inclusive('\n')
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(str::len)
        .collect();
    (
        *lengths.iter().max().unwrap(),
        *lengths.iter().min().unwrap(),
    )
}

#[test]
fn numpy_arrays_are_read_by_row_ranges_in_either_order() {
    // Fortran order, big-endian float64, 1001 x 5 (numpy.save of numpy.asfortranarray).
    let fortran = the_step(&data("numpy_fortran_be.npy"));
    check_parts(&fortran, &AttributeSelection::All, 1001, Bound::Exact);
    check_parts(&fortran, &only(&["col4"]), 1001, Bound::Exact);
    // int64, 7 x 4: fewer rows than ranks, so some parts are empty.
    let small = the_step(&data("numpy_int64.npy"));
    check_parts(&small, &AttributeSelection::All, 7, Bound::Exact);
    let empty = io::read_step_part(&small, &AttributeSelection::All, Part::new(0, 16)).unwrap();
    assert_eq!((empty.step.len(), empty.decoded), (0, 0));
    assert_eq!(empty.step.attributes[0].name, "col3");
    // C order with non-finite rows (numpy.save's layout): dropped within each part as in the
    // whole step.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c_order.npy");
    let n = 1003;
    let mut values = Vec::new();
    for i in 0..n {
        let x = i as f64 * 0.1 + 1.0 / 3.0;
        let bad = if i % 97 == 5 { f64::NAN } else { 1.0 };
        let inf = if i % 211 == 7 { f64::INFINITY } else { 2.0 };
        values.extend([x, bad * x.sin(), -x, x * x, inf]);
    }
    common::write_numpy(&path, n, 5, &values);
    let c = the_step(&path);
    check_parts(&c, &AttributeSelection::All, n, Bound::Exact);
    check_parts(&c, &only(&["col3"]), n, Bound::Exact);
}

#[test]
fn binary_records_are_read_by_byte_ranges() {
    let dir = tempfile::tempdir().unwrap();
    let n = 1009;
    let step = Step {
        name: "s".into(),
        positions: (0..n)
            .map(|i| DVec3::new(i as f64 * 0.25, 1.0 - i as f64, 0.5))
            .collect(),
        attributes: vec![Attribute {
            name: "rho".into(),
            values: (0..n)
                .map(|i| if i == 500 { f32::NAN as f64 } else { i as f64 })
                .collect(),
        }],
    };
    let raw = dir.path().join("knoll.raw");
    io::raw::write_step(&raw, &step, "rho").unwrap();
    check_parts(&the_step(&raw), &AttributeSelection::All, n, Bound::Exact);
    let header = dir.path().join("run.particles");
    io::particles::write_series(&header, std::slice::from_ref(&step), "rho").unwrap();
    check_parts(
        &the_step(&header),
        &AttributeSelection::All,
        n,
        Bound::Exact,
    );
    // Binary big-endian PLY of scalar properties from a NumPy structured array.
    let ply = the_step(&data("numpy_struct_be.ply"));
    check_parts(&ply, &AttributeSelection::All, 1001, Bound::Exact);
    check_parts(&ply, &only(&["id"]), 1001, Bound::Exact);
}

#[test]
fn csv_is_read_by_byte_ranges_moved_to_line_starts() {
    // 17-digit text from NumPy's repr, 1001 rows.
    let path = data("numpy_particles.csv");
    let (longest, shortest) = row_lengths(&path);
    let bound = Bound::Bytes { longest, shortest };
    check_parts(&the_step(&path), &AttributeSelection::All, 1001, bound);
    check_parts(&the_step(&path), &only(&["temperature"]), 1001, bound);

    // Comments and blank lines, CRLF line ends, a missing value (NaN, dropped), a label
    // column (not numeric in the first record: not an attribute), fewer rows than ranks.
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("# written by a script\r\nlabel,x,y,z,rho\r\n");
    for i in 0..11 {
        let rho = if i == 4 {
            String::new()
        } else {
            format!("{}", 0.1 * i as f64)
        };
        text.push_str(&format!(
            "p{i},{:.17e},{},-{i}.5,{rho}\r\n",
            i as f64 / 3.0,
            i * 7
        ));
        if i == 6 {
            text.push_str("# a comment between records\r\n\r\n");
        }
    }
    let odd = dir.path().join("odd.csv");
    std::fs::write(&odd, &text).unwrap();
    let whole = io::read_step(&the_step(&odd), &AttributeSelection::All).unwrap();
    assert_eq!(whole.len(), 10);
    assert_eq!(whole.attribute_names(), ["rho"]);
    // A comment line counts as a record for the byte bound.
    let (longest, shortest) = (row_lengths(&odd).0, 4);
    check_parts(
        &the_step(&odd),
        &AttributeSelection::All,
        11,
        Bound::Bytes { longest, shortest },
    );
}

#[test]
fn a_bad_record_in_a_part_is_named_by_its_byte_offset() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.csv");
    let mut text = String::from("x,y,z\n");
    for i in 0..100 {
        text.push_str(&format!("{i},{i},{i}\n"));
    }
    let at = text.len();
    text.push_str("1,two,3\n");
    std::fs::write(&path, &text).unwrap();
    let step = the_step(&path);
    let err = io::read_step(&step, &AttributeSelection::All)
        .unwrap_err()
        .to_string();
    assert!(err.contains("line 102") && err.contains("'two'"), "{err}");
    let err = io::read_step_part(&step, &AttributeSelection::All, Part::new(1, 2))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("bad.csv") && err.contains(&format!("byte {at}")) && err.contains("'two'"),
        "{err}"
    );
}

#[test]
fn formats_without_a_partial_read_are_read_whole_and_cut() {
    // VTK XML written by PySPH (appended, base64 or compressed arrays).
    let vtp = the_step(&data("sph_runs/pysph_dam_break/fluid_00000.vtp"));
    let n = io::read_step(&vtp, &AttributeSelection::All).unwrap().len();
    check_parts(&vtp, &AttributeSelection::All, n, Bound::Whole);
    // Ascii PLY: each row must be parsed to find the next.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ascii.ply");
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 13\nproperty float x\nproperty float y\n\
         property float z\nproperty float rho\nend_header\n",
    );
    for i in 0..13 {
        text.push_str(&format!("{i} {} 0.5 {}\n", i * 2, i as f64 / 7.0));
    }
    std::fs::write(&path, text).unwrap();
    check_parts(&the_step(&path), &AttributeSelection::All, 13, Bound::Whole);
}

#[cfg(feature = "hdf5")]
#[test]
fn hdf5_snapshots_are_read_by_hyperslabs_across_their_files() {
    use io::ParticleType;
    // h5py's SWIFT-like snapshot: chunked, gzip + shuffle, 203 gas and 50 dark matter.
    let swift = data("h5py_swift/snap_0000.hdf5");
    check_parts(
        &the_step(&swift),
        &AttributeSelection::All,
        203,
        Bound::Exact,
    );
    check_parts(&the_step(&swift), &only(&["Densities"]), 203, Bound::Exact);
    let dark = io::list_steps_reading(
        &swift,
        None,
        ReadOptions {
            particle_type: "1".parse::<ParticleType>().unwrap(),
            physical: false,
        },
    )
    .unwrap()
    .remove(0);
    check_parts(&dark, &AttributeSelection::All, 50, Bound::Exact);

    // GADGET-style, over three files, one of them empty (compressed coordinates, contiguous
    // float32 velocities read straight from the file, masses from the mass table).
    let dir = tempfile::tempdir().unwrap();
    crate::hdf5_snapshots::write_gadget_snapshot(dir.path(), 0, &[301, 0, 422], 0.5);
    let first = dir.path().join("snap_000.0.hdf5");
    check_parts(
        &the_step(&first),
        &AttributeSelection::All,
        723,
        Bound::Exact,
    );
    let velocities = only(&["Velocities_x", "Masses"]);
    check_parts(&the_step(&first), &velocities, 723, Bound::Exact);
    // Rank 1 of 2 reads only the third file's rows.
    let part = io::read_step_part(&the_step(&first), &velocities, Part::new(1, 2)).unwrap();
    assert_eq!(part.decoded, 723 - 361);
    assert_eq!(part.step.attributes[0].values[0], 361.0);
}

/// Smoothing lengths from neighbours need the neighbours in other parts: the ranks find them
/// together (`aarbf::dist::knn`), each reading only its part, and each part's lengths are the
/// single process's, bit for bit; they are cached beside the data at each part's offset, and a
/// later read takes each part's share of the cache.
#[test]
fn a_series_with_neighbour_smoothing_reads_only_its_parts() {
    use aarbf::dist::comm::Comm;
    use aarbf::dist::knn::RankLengths;
    use aarbf::scene::smoothing::{self, Smoothing};
    use aarbf::scene::{OpenOptions, TimeSeries};
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs/gadget_like");
    // GADGET-like NumPy, N x 5 float64 (1000 particles), no smoothing length of its own.
    for neighbours in [16, 40] {
        let smoothing = Smoothing { neighbours };
        let (single, ranked) = (
            copied(&runs, &["snapshot_000.npy"]),
            copied(&runs, &["snapshot_000.npy"]),
        );
        let open = |dir: &Path, attributes| {
            TimeSeries::open(
                &dir.join("snapshot_000.npy"),
                &OpenOptions {
                    smoothing: Some(smoothing),
                    attributes,
                    ..OpenOptions::default()
                },
            )
            .unwrap()
        };
        let whole = open(single.path(), AttributeSelection::All)
            .step(0)
            .unwrap();
        let name = smoothing.attribute();
        assert!(whole.attribute(&name).is_some());
        let n = whole.len();
        // The ranks' series, opened from an index the single process did not write (each
        // opening reads the first step whole; the parts are read below, once the cache of
        // whole steps is cleared).
        let series = open(ranked.path(), AttributeSelection::All);
        series.clear_cache();
        let cache_file = || {
            std::fs::read_dir(ranked.path().join(smoothing::CACHE_DIR))
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| {
                    p.to_string_lossy()
                        .ends_with(&format!(".k{neighbours}.f64"))
                })
                .unwrap()
        };
        // No cache: the ranks compute the lengths.
        std::fs::remove_file(cache_file()).unwrap();
        for ranks in RANKS {
            let parts = aarbf::dist::run_local(ranks, |comm| {
                let part = Part::new(comm.rank(), comm.size());
                let read = series.step_part(0, part, &RankLengths { comm })?;
                assert_eq!(read.decoded, part.range(n).len(), "rank {part:?}");
                Ok(read.step)
            })
            .unwrap();
            let together = joined(&parts, &whole);
            assert_eq!(together.positions, whole.positions, "{ranks} ranks");
            assert_eq!(
                together.attributes, whole.attributes,
                "{ranks} ranks, K {neighbours}"
            );
        }
        // The ranks wrote the cache: the whole step's lengths, in the file's order.
        let step = series.step_ref(0).unwrap();
        assert_eq!(
            smoothing::cached_part(step, neighbours, n, 0..n).unwrap(),
            whole.attribute(&name).unwrap().values
        );
        // A later read takes each part's share of it: cached values made recognisable (the
        // header kept) come back in order.
        let path = cache_file();
        let mut bytes = std::fs::read(&path).unwrap();
        let header = bytes.len() - 8 * n;
        for (i, chunk) in bytes[header..].chunks_exact_mut(8).enumerate() {
            chunk.copy_from_slice(&(1.0 + i as f64).to_le_bytes());
        }
        // Written over in place, so that the data file's stamp still matches.
        std::fs::write(&path, &bytes).unwrap();
        let parts = aarbf::dist::run_local(3, |comm| {
            let part = Part::new(comm.rank(), comm.size());
            Ok(series.step_part(0, part, &RankLengths { comm })?.step)
        })
        .unwrap();
        let h: Vec<f64> = parts
            .iter()
            .flat_map(|p| p.attribute(&name).unwrap().values.clone())
            .collect();
        assert_eq!(h, (0..n).map(|i| 1.0 + i as f64).collect::<Vec<_>>());
        // Without the lengths in the selection, the part alone is read.
        let without = open(ranked.path(), only(&["col3"]));
        let part = aarbf::dist::run_local(3, |comm| {
            let part = Part::new(comm.rank(), comm.size());
            Ok(without.step_part(0, part, &RankLengths { comm })?)
        })
        .unwrap()
        .swap_remove(1);
        assert_eq!(part.decoded, Part::new(1, 3).range(n).len());
        assert_eq!(part.step.attribute_names(), ["col3"]);
    }
}

/// Ranks that scan a series from their parts ([`aarbf::dist::step_stats`]) as threads, keeping
/// the most records any rank decoded in one call and the records the whole steps scanned held.
struct ScanByRanks {
    ranks: usize,
    most_decoded: std::sync::Mutex<Vec<(usize, usize)>>,
}

impl aarbf::scene::StepsScan for ScanByRanks {
    fn stats(
        &self,
        steps: &[StepRef],
        which: &[usize],
        selection: &AttributeSelection,
        smoothing: Option<aarbf::scene::smoothing::Smoothing>,
    ) -> Result<Vec<aarbf::scene::index::StepStats>, io::DataError> {
        let found = aarbf::dist::run_local(self.ranks, |comm| {
            aarbf::dist::step_stats::of_parts(comm, steps, which, selection, smoothing)
        })
        .unwrap();
        let records: usize = found[0].0.iter().map(|s| s.count).sum();
        let decoded = found.iter().map(|(_, d)| *d).max().unwrap();
        self.most_decoded.lock().unwrap().push((decoded, records));
        for (stats, _) in &found[1..] {
            assert_eq!(stats, &found[0].0, "every rank finds the same statistics");
        }
        Ok(found.into_iter().next().unwrap().0)
    }
}

/// A copy of the series files `names` of `from` in a new directory (no index beside them).
fn copied(from: &Path, names: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for n in names {
        std::fs::copy(from.join(n), dir.path().join(n)).unwrap();
    }
    dir
}

#[test]
fn a_series_without_an_index_is_scanned_from_the_ranks_parts_bit_for_bit() {
    use aarbf::scene::{OpenOptions, TimeSeries};
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs");
    // As SWIFT-like CSV (%.17g, 500, 503, 497, 511 rows), GADGET-like NumPy (N x 5 float64,
    // 1000 .. 1003 rows) and h5py's SWIFT snapshots (HDF5 hyperslabs) hold them.
    let series: [(std::path::PathBuf, Vec<&str>, &str); 3] = [
        (
            runs.join("swift_like"),
            vec![
                "output_0000.csv",
                "output_0001.csv",
                "output_0002.csv",
                "output_0003.csv",
            ],
            "output_*.csv",
        ),
        (
            runs.join("gadget_like"),
            vec![
                "snapshot_000.npy",
                "snapshot_001.npy",
                "snapshot_002.npy",
                "snapshot_003.npy",
                "snapshot_004.npy",
            ],
            "snapshot_*.npy",
        ),
        (
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/h5py_swift"),
            vec!["snap_0000.hdf5", "snap_0001.hdf5"],
            "snap_*.hdf5",
        ),
    ];
    for (from, names, pattern) in &series {
        for selection in [AttributeSelection::All, only(&[])] {
            let options = OpenOptions {
                attributes: selection.clone(),
                ..OpenOptions::default()
            };
            let whole_dir = copied(from, names);
            let whole = TimeSeries::open(&whole_dir.path().join(pattern), &options).unwrap();
            assert!(whole.steps_decoded() >= 1);
            for ranks in [2, 3, 5, 8] {
                let dir = copied(from, names);
                let path = dir.path().join(pattern);
                let scan = ScanByRanks {
                    ranks,
                    most_decoded: Default::default(),
                };
                let by_ranks = TimeSeries::open_scanned_by(&path, &options, &scan).unwrap();
                let what = format!("{} over {ranks} ranks, {selection:?}", from.display());
                assert_eq!(by_ranks.values(), whole.values(), "{what}");
                assert_eq!(by_ranks.steps_decoded(), 0, "{what}: no step read whole");
                // Each call's rank decoded at most its share of each step (CSV: by bytes, rows
                // of similar lengths: within a few records).
                for &(decoded, records) in scan.most_decoded.lock().unwrap().iter() {
                    let steps = names.len();
                    assert!(
                        decoded <= records.div_ceil(ranks) + 4 * steps,
                        "{what}: a rank decoded {decoded} of {records} records"
                    );
                }
                // The index the ranks wrote serves a later open, which reads nothing.
                let reopened = TimeSeries::open(&path, &options).unwrap();
                assert_eq!(reopened.steps_decoded(), 0, "{what}");
                assert_eq!(reopened.values(), whole.values(), "{what}");
            }
        }
    }
    // Smoothing lengths from neighbours: the ranks find them together; the statistics of
    // 'h_knn16' (its robust range and mean set the colours and the radius) are the whole
    // step's, bit for bit, and no step is read whole.
    let (from, names, pattern) = &series[1];
    let options = OpenOptions {
        smoothing: Some("knn:16".parse().unwrap()),
        ..OpenOptions::default()
    };
    let whole = TimeSeries::open(&copied(from, names).path().join(pattern), &options).unwrap();
    assert!(
        whole
            .values()
            .attributes
            .iter()
            .any(|a| a.name == "h_knn16")
    );
    for ranks in [3, 8] {
        let dir = copied(from, names);
        let scan = ScanByRanks {
            ranks,
            most_decoded: Default::default(),
        };
        let by_ranks =
            TimeSeries::open_scanned_by(&dir.path().join(pattern), &options, &scan).unwrap();
        assert_eq!(
            by_ranks.values(),
            whole.values(),
            "knn:16 over {ranks} ranks"
        );
        assert_eq!(by_ranks.steps_decoded(), 0, "knn:16 over {ranks} ranks");
    }
}
