//! HDF5 snapshots written the way SWIFT, GADGET and AREPO write them (their groups, header
//! attributes, chunked and compressed datasets, several files per snapshot), read back; one
//! file written by h5py; and every bad file with the text of its error.
#![cfg(feature = "hdf5")]

use std::path::{Path, PathBuf};

use aarbf::io::{self, AttributeSelection, Format, ParticleType, ReadOptions};
use aarbf::scene::{OpenOptions, TimeSeries};
use aarbf::values::Step;
use glam::DVec3;
use hdf5::types::VarLenUnicode;
use hdf5::{Group, H5Type, Location};

/// How a dataset is laid out: chunk rows (None: contiguous) and gzip + shuffle.
#[derive(Clone, Copy)]
struct Layout {
    chunk: Option<usize>,
    gzip: bool,
}

const CONTIGUOUS: Layout = Layout {
    chunk: None,
    gzip: false,
};
const COMPRESSED: Layout = Layout {
    chunk: Some(100),
    gzip: true,
};

fn dataset<T: H5Type + Copy>(group: &Group, name: &str, data: &[T], cols: usize, layout: Layout) {
    let rows = data.len() / cols;
    let builder = group.new_dataset::<T>();
    let builder = if cols == 1 {
        builder.shape([rows])
    } else {
        builder.shape([rows, cols])
    };
    let builder = match layout.chunk {
        Some(c) if cols == 1 => builder.chunk([c.min(rows.max(1))]),
        Some(c) => builder.chunk([c.min(rows.max(1)), cols]),
        None => builder,
    };
    let builder = if layout.gzip {
        builder.shuffle().deflate(4)
    } else {
        builder
    };
    builder.create(name).unwrap().write_raw(data).unwrap();
}

fn attr<T: H5Type + Copy>(loc: &Location, name: &str, values: &[T]) {
    loc.new_attr::<T>()
        .shape([values.len()])
        .create(name)
        .unwrap()
        .write_raw(values)
        .unwrap();
}

fn string_attr(loc: &Location, name: &str, value: &str) {
    let v: VarLenUnicode = value.parse().unwrap();
    loc.new_attr::<VarLenUnicode>()
        .create(name)
        .unwrap()
        .write_scalar(&v)
        .unwrap();
}

/// Particle `i`'s position: distinct, inside [0, 10)^3.
fn position(i: usize) -> [f64; 3] {
    let f = i as f64;
    [
        (f * 0.618).rem_euclid(10.0),
        (f * 0.377 + 1.0).rem_euclid(10.0),
        (f * 0.129 + 2.0).rem_euclid(10.0),
    ]
}

fn positions(range: std::ops::Range<usize>) -> Vec<f64> {
    range.flat_map(position).collect()
}

fn per_particle(range: std::ops::Range<usize>, scale: f64) -> Vec<f64> {
    range.map(|i| scale * (1.0 + i as f64)).collect()
}

fn as_f32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|x| *x as f32).collect()
}

/// A SWIFT snapshot of `n` gas and `n_dm` dark-matter particles: SWIFT's `Header`, `Units`,
/// `Cosmology` (a = 0.5) and `Code` groups, datasets with their `a-scale exponent`.
fn write_swift(path: &Path, n: usize, n_dm: usize) {
    write_swift_with(path, n, n_dm, |_| {});
}

/// [`write_swift`], then `extra` on the open file (one handle: reopening a file just written
/// can meet HDF5's file lock while the library still holds it).
fn write_swift_with(path: &Path, n: usize, n_dm: usize, extra: impl FnOnce(&hdf5::File)) {
    let f = hdf5::File::create(path).unwrap();
    let h = f.create_group("Header").unwrap();
    attr(
        &h,
        "NumPart_ThisFile",
        &[n as u64, n_dm as u64, 0, 0, 0, 0, 0],
    );
    attr(&h, "NumPart_Total", &[n as u64, n_dm as u64, 0, 0, 0, 0, 0]);
    attr(&h, "NumPart_Total_HighWord", &[0u64; 7]);
    attr(&h, "NumFilesPerSnapshot", &[1i32]);
    attr(&h, "BoxSize", &[10.0f64, 10.0, 10.0]);
    attr(&h, "Time", &[0.5f64]);
    attr(&h, "Redshift", &[1.0f64]);
    attr(&h, "Scale-factor", &[0.5f64]);
    attr(&h, "MassTable", &[0.0f64; 7]);
    string_attr(&h, "Code", "SWIFT");
    let code = f.create_group("Code").unwrap();
    string_attr(&code, "Code", "SWIFT");
    let units = f.create_group("Units").unwrap();
    attr(&units, "Unit length in cgs (U_L)", &[3.08567758e24f64]);
    attr(&units, "Unit mass in cgs (U_M)", &[1.98841e43f64]);
    // SWIFT's used run-time parameters, as text. The fixture's smoothing lengths (up to 6)
    // exceed half its box, which a periodic field refuses: the run is an open box.
    let parameters = f.create_group("Parameters").unwrap();
    string_attr(&parameters, "InitialConditions:periodic", "0");
    let cosmo = f.create_group("Cosmology").unwrap();
    attr(&cosmo, "Cosmological run", &[1i32]);
    attr(&cosmo, "Scale-factor", &[0.5f64]);
    attr(&cosmo, "h", &[0.6777f64]);
    let gas = f.create_group("PartType0").unwrap();
    let exponent = |g: &Group, name: &str, e: f32| {
        attr(&g.dataset(name).unwrap(), "a-scale exponent", &[e]);
    };
    dataset(&gas, "Coordinates", &positions(0..n), 3, COMPRESSED);
    exponent(&gas, "Coordinates", 1.0);
    let h_values = as_f32(&per_particle(0..n, 0.01));
    dataset(&gas, "SmoothingLengths", &h_values, 1, COMPRESSED);
    exponent(&gas, "SmoothingLengths", 1.0);
    dataset(&gas, "Masses", &as_f32(&vec![2.5; n]), 1, CONTIGUOUS);
    exponent(&gas, "Masses", 0.0);
    dataset(
        &gas,
        "Densities",
        &as_f32(&per_particle(0..n, 0.5)),
        1,
        COMPRESSED,
    );
    exponent(&gas, "Densities", -3.0);
    let velocities: Vec<f32> = (0..n).flat_map(|i| [3.0, 4.0, i as f32]).collect();
    dataset(&gas, "Velocities", &velocities, 3, COMPRESSED);
    exponent(&gas, "Velocities", 0.0);
    dataset(
        &gas,
        "InternalEnergies",
        &per_particle(0..n, 100.0),
        1,
        CONTIGUOUS,
    );
    dataset(
        &gas,
        "Temperatures",
        &as_f32(&per_particle(0..n, 1e4)),
        1,
        COMPRESSED,
    );
    let ids: Vec<u64> = (0..n as u64).map(|i| 1_000_000 + i).collect();
    dataset(&gas, "ParticleIDs", &ids, 1, COMPRESSED);
    let dm = f.create_group("PartType1").unwrap();
    dataset(
        &dm,
        "Coordinates",
        &positions(5000..5000 + n_dm),
        3,
        CONTIGUOUS,
    );
    dataset(&dm, "Masses", &vec![7.0f64; n_dm], 1, CONTIGUOUS);
    extra(&f);
}

fn read_with(
    path: &Path,
    read: ReadOptions,
    selection: &AttributeSelection,
) -> Result<Step, io::DataError> {
    let steps = io::list_steps_reading(path, None, read)?;
    io::read_step(&steps[0], selection)
}

fn read(path: &Path) -> Result<Step, io::DataError> {
    read_with(path, ReadOptions::default(), &AttributeSelection::All)
}

fn err_text(path: &Path) -> String {
    read(path).expect_err("the read should fail").to_string()
}

fn only(names: &[&str]) -> AttributeSelection {
    AttributeSelection::Only(names.iter().map(|n| n.to_string()).collect())
}

fn expected_positions(range: std::ops::Range<usize>) -> Vec<DVec3> {
    range.map(|i| DVec3::from_array(position(i))).collect()
}

#[test]
fn a_swift_snapshot_reads_every_dataset_of_the_chosen_type() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snap_0007.hdf5");
    write_swift(&path, 1237, 301);
    let step = read(&path).unwrap();
    assert_eq!(step.name, "snap_0007");
    assert_eq!(step.positions, expected_positions(0..1237));
    let names = step.attribute_names();
    for name in [
        "Densities",
        "InternalEnergies",
        "Masses",
        "ParticleIDs",
        "SmoothingLengths",
        "Temperatures",
        "Velocities_x",
        "Velocities_magnitude",
    ] {
        assert!(names.contains(&name), "{name} missing from {names:?}");
    }
    assert!(!names.contains(&"Coordinates_x"), "{names:?}");
    let h = &step.attribute("SmoothingLengths").unwrap().values;
    assert_eq!(h[1236], f64::from((0.01 * 1237.0) as f32));
    assert_eq!(
        step.attribute("Velocities_magnitude").unwrap().values[0],
        5.0
    );
    assert_eq!(
        step.attribute("ParticleIDs").unwrap().values[10],
        1_000_010.0
    );
    assert_eq!(step.attribute("InternalEnergies").unwrap().values[2], 300.0);

    // Dark matter, and only what a selection names.
    let dm = read_with(
        &path,
        ReadOptions {
            particle_type: "dm".parse().unwrap(),
            physical: false,
        },
        &only(&["Masses"]),
    )
    .unwrap();
    assert_eq!(dm.positions, expected_positions(5000..5301));
    assert_eq!(dm.attributes.len(), 1);
    assert_eq!(dm.attribute("Masses").unwrap().values, vec![7.0; 301]);

    // Physical units: a^1 for positions and smoothing lengths, a^-3 for densities, a = 0.5.
    let physical = read_with(
        &path,
        ReadOptions {
            particle_type: ParticleType::GAS,
            physical: true,
        },
        &only(&["SmoothingLengths", "Densities", "Masses"]),
    )
    .unwrap();
    assert_eq!(physical.positions[3], DVec3::from_array(position(3)) * 0.5);
    assert_eq!(
        physical.attribute("SmoothingLengths").unwrap().values[5],
        h[5] * 0.5
    );
    assert_eq!(
        physical.attribute("Densities").unwrap().values[5],
        f64::from((0.5 * 6.0) as f32) * 8.0
    );
    assert_eq!(physical.attribute("Masses").unwrap().values[5], 2.5);

    // A type the snapshot does not hold says which it does.
    let e = read_with(
        &path,
        ReadOptions {
            particle_type: "stars".parse().unwrap(),
            physical: false,
        },
        &AttributeSelection::All,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("no stars particles") && e.contains("1237 gas"),
        "{e}"
    );
}

#[test]
fn only_the_datasets_a_scene_uses_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snap_0000.hdf5");
    // A chunked dataset whose chunks were never written: HDF5 would read fill values, the
    // reader refuses it, and a selection without it never touches it.
    write_swift_with(&path, 530, 0, |f| {
        f.group("PartType0")
            .unwrap()
            .new_dataset::<f32>()
            .shape([530])
            .chunk([64])
            .create("Unwritten")
            .unwrap();
    });
    let step = read_with(&path, ReadOptions::default(), &only(&["Temperatures"])).unwrap();
    assert_eq!(step.attribute_names(), ["Temperatures"]);
    let e = read_with(&path, ReadOptions::default(), &only(&["Unwritten"]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("snap_0000.hdf5")
            && e.contains("'/PartType0/Unwritten'")
            && e.contains("stores only"),
        "{e}"
    );
    // A missing attribute lists what the snapshot offers.
    let e = read_with(&path, ReadOptions::default(), &only(&["Temperature"]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("'Temperatures'") && e.contains("'Velocities_magnitude'"),
        "{e}"
    );
}

/// One file of a GADGET-style snapshot split over `counts.len()` files: file `k` holds
/// `counts[k]` gas particles (from `offset`), as float32, gas masses in the mass table.
fn write_gadget_part(
    dir: &Path,
    snap: usize,
    k: usize,
    counts: &[usize],
    first: usize,
    time: f64,
) -> PathBuf {
    let path = dir.join(format!("snap_{snap:03}.{k}.hdf5"));
    let f = hdf5::File::create(&path).unwrap();
    let h = f.create_group("Header").unwrap();
    let n = counts[k];
    let total: usize = counts.iter().sum();
    attr(&h, "NumPart_ThisFile", &[n as u32, 0, 0, 0, 0, 0]);
    attr(&h, "NumPart_Total", &[total as u32, 0, 0, 0, 0, 0]);
    attr(&h, "NumPart_Total_HighWord", &[0u32; 6]);
    attr(&h, "MassTable", &[0.25f64, 0.0, 0.0, 0.0, 0.0, 0.0]);
    attr(&h, "NumFilesPerSnapshot", &[counts.len() as i32]);
    attr(&h, "BoxSize", &[10.0f64]);
    attr(&h, "Time", &[time]);
    attr(&h, "Redshift", &[1.0 / time - 1.0]);
    attr(&h, "HubbleParam", &[0.7f64]);
    if n > 0 {
        // GADGET writes no group for a type a file holds none of.
        let gas = f.create_group("PartType0").unwrap();
        let range = first..first + n;
        dataset(
            &gas,
            "Coordinates",
            &as_f32(&positions(range.clone())),
            3,
            COMPRESSED,
        );
        let v: Vec<f32> = range.clone().flat_map(|i| [i as f32, 0.0, 0.0]).collect();
        dataset(&gas, "Velocities", &v, 3, CONTIGUOUS);
        dataset(
            &gas,
            "SmoothingLength",
            &as_f32(&per_particle(range.clone(), 0.02)),
            1,
            COMPRESSED,
        );
        dataset(
            &gas,
            "Temperature",
            &as_f32(&per_particle(range, 10.0)),
            1,
            COMPRESSED,
        );
    }
    path
}

pub(crate) fn write_gadget_snapshot(dir: &Path, snap: usize, counts: &[usize], time: f64) {
    let mut first = 0;
    for k in 0..counts.len() {
        write_gadget_part(dir, snap, k, counts, first, time);
        first += counts[k];
    }
}

#[test]
fn a_folder_of_multi_file_gadget_snapshots_is_a_series_of_one_step_per_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_gadget_snapshot(d, 0, &[301, 0, 422], 0.5);
    write_gadget_snapshot(d, 1, &[150, 377], 0.6);
    write_gadget_snapshot(d, 2, &[1001], 0.7);
    std::fs::write(d.join("used-values.txt"), "GADGET's log").unwrap();
    let steps = io::list_steps(d, None).unwrap();
    let names: Vec<&str> = steps.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["snap_000", "snap_001", "snap_002"]);
    assert!(steps.iter().all(|s| s.format == Format::Hdf5));

    let first = io::read_step(&steps[0], &AttributeSelection::All).unwrap();
    assert_eq!(first.positions.len(), 723);
    // float32 on disk: the reader's values are the stored floats exactly.
    let stored = |i: usize| DVec3::from_array(position(i).map(|c| f64::from(c as f32)));
    assert_eq!(first.positions[0], stored(0));
    assert_eq!(first.positions[301], stored(301));
    assert_eq!(first.positions[722], stored(722));
    assert_eq!(first.attribute("Masses").unwrap().values, vec![0.25; 723]);
    assert_eq!(first.attribute("Velocities_x").unwrap().values[400], 400.0);

    let series = TimeSeries::open(
        d,
        &OpenOptions {
            attributes: only(&["Temperature", "SmoothingLength"]),
            ..OpenOptions::default()
        },
    )
    .unwrap();
    assert_eq!(series.len(), 3);
    let counts: Vec<usize> = series.steps().iter().map(|s| s.count).collect();
    assert_eq!(counts, [723, 527, 1001]);
    // The header's Time is each step's time (`--time`, the viewer's step slider).
    assert_eq!(series.times(), Some(&[0.5, 0.6, 0.7][..]));
    assert_eq!(series.step_at_time(0.64), Some((1, 0.6)));
    let temperature = series.attribute("Temperature").unwrap();
    assert_eq!(temperature.max, 10.0 * 1001.0);

    // Physical units for GADGET: x a, with a = Time.
    let physical = io::list_steps_reading(
        d,
        None,
        ReadOptions {
            particle_type: ParticleType::GAS,
            physical: true,
        },
    )
    .unwrap();
    let step = io::read_step(&physical[1], &only(&["SmoothingLength"])).unwrap();
    assert!((step.positions[7] - stored(7) * 0.6).length() < 1e-12);
}

#[test]
fn arepo_cells_without_smoothing_length_get_one_from_their_volume() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snap_005.hdf5");
    let n = 77;
    {
        let f = hdf5::File::create(&path).unwrap();
        let h = f.create_group("Header").unwrap();
        attr(&h, "NumPart_ThisFile", &[n as i32, 0, 0, 0, 0, 0]);
        attr(&h, "NumPart_Total", &[n as u32, 0, 0, 0, 0, 0]);
        attr(&h, "MassTable", &[0.0f64; 6]);
        attr(&h, "NumFilesPerSnapshot", &[1i32]);
        attr(&h, "Time", &[1.0f64]);
        attr(&h, "Redshift", &[0.0f64]);
        let gas = f.create_group("PartType0").unwrap();
        dataset(&gas, "Coordinates", &positions(0..n), 3, CONTIGUOUS);
        dataset(&gas, "Masses", &per_particle(0..n, 1.0), 1, CONTIGUOUS);
        dataset(&gas, "Density", &vec![2.0f64; n], 1, COMPRESSED);
    }
    let step = read_with(&path, ReadOptions::default(), &only(&["SmoothingLength"])).unwrap();
    let h = &step.attribute("SmoothingLength").unwrap().values;
    for (i, h) in h.iter().enumerate() {
        // (4/3) pi (2h)^3 holds 32 cells of volume m / rho.
        let cells = 4.0 / 3.0 * std::f64::consts::PI * (2.0 * h).powi(3) / ((i + 1) as f64 / 2.0);
        assert!((cells - 32.0).abs() < 1e-9, "particle {i}: {cells} cells");
    }
}

#[test]
fn nan_positions_are_dropped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan.hdf5");
    {
        let f = hdf5::File::create(&path).unwrap();
        let h = f.create_group("Header").unwrap();
        attr(&h, "NumPart_ThisFile", &[5u32, 0, 0, 0, 0, 0]);
        let gas = f.create_group("PartType0").unwrap();
        let mut p = positions(0..5);
        p[4] = f64::NAN;
        dataset(&gas, "Coordinates", &p, 3, CONTIGUOUS);
    }
    let step = read(&path).unwrap();
    assert_eq!(
        step.positions,
        [0, 2, 3, 4].map(|i| DVec3::from_array(position(i)))
    );
}

/// Large enough that every dataset is read in several blocks (contiguous ones by the reader
/// itself, in parallel; compressed ones by HDF5), and the finiteness found as they are read.
#[test]
fn non_finite_values_in_any_block_of_any_layout_are_found() {
    let n = 200_003;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("snap_0001.hdf5");
    let mut coordinates = positions(0..n);
    coordinates[3 * 150_000 + 2] = f64::NAN;
    let mut temperatures = as_f32(&per_particle(0..n, 1e4));
    temperatures[70_000] = f32::INFINITY;
    let mut densities = as_f32(&per_particle(0..n, 0.5));
    densities[n - 1] = f32::NAN;
    let mut energies = per_particle(0..n, 100.0);
    energies[5] = f64::NEG_INFINITY;
    {
        let f = hdf5::File::create(&path).unwrap();
        let h = f.create_group("Header").unwrap();
        attr(&h, "NumPart_ThisFile", &[n as u32, 0, 0, 0, 0, 0]);
        string_attr(&h, "Code", "SWIFT");
        let cosmology = f.create_group("Cosmology").unwrap();
        attr(&cosmology, "Cosmological run", &[1i32]);
        attr(&cosmology, "Scale-factor", &[0.5f64]);
        let gas = f.create_group("PartType0").unwrap();
        dataset(&gas, "Coordinates", &coordinates, 3, CONTIGUOUS);
        dataset(&gas, "Temperatures", &temperatures, 1, CONTIGUOUS);
        dataset(&gas, "Densities", &densities, 1, COMPRESSED);
        dataset(&gas, "InternalEnergies", &energies, 1, COMPRESSED);
        dataset(&gas, "Masses", &per_particle(0..n, 1.0), 1, CONTIGUOUS);
        // Finite as stored, 8e307 x 0.5^-3 overflows under --physical.
        let mut huge = vec![1.0f64; n];
        huge[100_000] = 8e307;
        dataset(&gas, "Huge", &huge, 1, CONTIGUOUS);
        let exponent = gas.dataset("Huge").unwrap();
        attr(&exponent, "a-scale exponent", &[-3.0f32]);
    }
    let bad = [5, 70_000, 150_000, n - 1];
    let kept: Vec<usize> = (0..n).filter(|i| !bad.contains(i)).collect();
    let step = read(&path).unwrap();
    assert_eq!(step.len(), n - 4);
    let expected: Vec<DVec3> = kept
        .iter()
        .map(|&i| DVec3::from_array(position(i)))
        .collect();
    assert_eq!(step.positions, expected);
    let t = &step.attribute("Temperatures").unwrap().values;
    assert!(
        kept.iter()
            .zip(t)
            .all(|(&i, &t)| t == f64::from(temperatures[i]))
    );
    let e = &step.attribute("InternalEnergies").unwrap().values;
    assert!(kept.iter().zip(e).all(|(&i, &e)| e == energies[i]));

    // Each alone: only its own bad particle goes.
    for (name, bad) in [
        ("Temperatures", 70_000),
        ("Densities", n - 1),
        ("InternalEnergies", 5),
    ] {
        let no_nan_position = (0..n).filter(|&i| i != 150_000);
        let step = read_with(&path, ReadOptions::default(), &only(&[name])).unwrap();
        assert_eq!(step.len(), n - 2, "{name}");
        let values = &step.attribute(name).unwrap().values;
        assert!(values.iter().all(|v| v.is_finite()), "{name}");
        assert_eq!(
            no_nan_position.filter(|&i| i != bad).count(),
            values.len(),
            "{name}"
        );
    }
    let masses = read_with(&path, ReadOptions::default(), &only(&["Masses"])).unwrap();
    assert_eq!(masses.len(), n - 1);
    let physical = ReadOptions {
        physical: true,
        ..ReadOptions::default()
    };
    let huge = read_with(&path, physical, &only(&["Huge"])).unwrap();
    assert_eq!(huge.len(), n - 2);
    assert!(
        huge.attribute("Huge")
            .unwrap()
            .values
            .iter()
            .all(|v| *v == 8.0)
    );
}

#[test]
fn bad_snapshots_name_the_file_and_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    let text = d.join("notes.hdf5");
    std::fs::write(&text, "these are not the snapshots you are looking for\n").unwrap();
    let e = err_text(&text);
    assert!(
        e.contains("notes.hdf5") && e.contains("not an HDF5 file"),
        "{e}"
    );

    let whole = d.join("whole.hdf5");
    write_swift(&whole, 2000, 0);
    let bytes = std::fs::read(&whole).unwrap();
    let truncated = d.join("truncated.hdf5");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let e = err_text(&truncated);
    assert!(e.contains("truncated.hdf5"), "{e}");

    let flat = d.join("flat.hdf5");
    {
        let f = hdf5::File::create(&flat).unwrap();
        let h = f.create_group("Header").unwrap();
        attr(&h, "NumPart_ThisFile", &[4u32, 0, 0, 0, 0, 0]);
        let gas = f.create_group("PartType0").unwrap();
        dataset(&gas, "Coordinates", &[0.0f64; 8], 2, CONTIGUOUS);
    }
    let e = err_text(&flat);
    assert!(
        e.contains("flat.hdf5") && e.contains("'/PartType0/Coordinates' is 4 x 2; expected N x 3"),
        "{e}"
    );

    let miscounted = d.join("miscounted.hdf5");
    {
        let f = hdf5::File::create(&miscounted).unwrap();
        let h = f.create_group("Header").unwrap();
        attr(&h, "NumPart_ThisFile", &[6u32, 0, 0, 0, 0, 0]);
        let gas = f.create_group("PartType0").unwrap();
        dataset(&gas, "Coordinates", &positions(0..5), 3, COMPRESSED);
    }
    let e = err_text(&miscounted);
    assert!(
        e.contains("miscounted.hdf5")
            && e.contains(
                "'/PartType0/Coordinates' has 5 rows but /Header NumPart_ThisFile says 6"
            ),
        "{e}"
    );

    let no_header = d.join("plain.h5");
    hdf5::File::create(&no_header)
        .unwrap()
        .create_group("data")
        .unwrap();
    let e = err_text(&no_header);
    assert!(
        e.contains("plain.h5") && e.contains("no /Header group"),
        "{e}"
    );

    let sets = d.join("sets");
    std::fs::create_dir(&sets).unwrap();
    write_gadget_snapshot(&sets, 4, &[10, 20, 30], 1.0);
    std::fs::remove_file(sets.join("snap_004.1.hdf5")).unwrap();
    let e = err_text(&sets);
    assert!(
        e.contains("snap_004.0.hdf5")
            && e.contains("file 1 of the 3 files")
            && e.contains("snap_004.1.hdf5"),
        "{e}"
    );

    // A header whose total disagrees with the files' own counts.
    let totals = d.join("totals");
    std::fs::create_dir(&totals).unwrap();
    write_gadget_snapshot(&totals, 9, &[10, 20], 1.0);
    // Rewritten as a new file: HDF5 opens files without close-on-exec, so an `aarbf` another
    // test starts meanwhile can inherit the first one's descriptor and hold its lock, and
    // H5Fcreate over it then fails ("unable to lock file").
    std::fs::remove_file(totals.join("snap_009.1.hdf5")).unwrap();
    write_gadget_part(&totals, 9, 1, &[10, 21], 10, 1.0);
    let e = err_text(&totals);
    assert!(
        e.contains("NumPart_Total says 30") && e.contains("add up to 31"),
        "{e}"
    );
}

#[test]
fn a_swift_like_snapshot_written_by_h5py_reads_exactly() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/h5py_swift");
    let steps = io::list_steps(&data, None).unwrap();
    assert_eq!(steps.len(), 2, "{steps:?}");
    let first = io::read_step(&steps[0], &AttributeSelection::All).unwrap();
    let second = io::read_step(&steps[1], &AttributeSelection::All).unwrap();
    // The script's values: see tests/data/write_hdf5_fixture.py.
    assert_eq!(first.len(), 203);
    assert_eq!(second.len(), 197);
    assert_eq!(first.positions[0], DVec3::new(0.0, 0.5, 0.25));
    assert_eq!(
        first.positions[202],
        DVec3::new(202.0 * 0.01, 0.5, 0.25 + 202.0 * 1e-3)
    );
    let t = &first.attribute("Temperatures").unwrap().values;
    assert_eq!(t[100], f64::from(1e4f32 + 100.0));
    let h = &second.attribute("SmoothingLengths").unwrap().values;
    assert_eq!(h[196], f64::from(0.05f32));
    assert_eq!(second.attribute("Velocities_y").unwrap().values[3], -3.0);
}

fn aarbf(args: &[&str]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "aarbf {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Words separated by single spaces: the tests need not know the columns' widths.
    let text = String::from_utf8(out.stdout).unwrap();
    text.lines()
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn info_describes_and_render_draws_a_swift_and_a_multi_file_gadget_series() {
    let dir = tempfile::tempdir().unwrap();
    let swift = dir.path().join("swift");
    let gadget = dir.path().join("gadget");
    std::fs::create_dir_all(&swift).unwrap();
    std::fs::create_dir_all(&gadget).unwrap();
    write_swift(&swift.join("snap_0000.hdf5"), 611, 40);
    write_swift(&swift.join("snap_0001.hdf5"), 590, 40);
    write_gadget_snapshot(&gadget, 10, &[200, 211], 0.5);
    write_gadget_snapshot(&gadget, 11, &[190, 0, 230], 0.6);

    let info = aarbf(&["info", swift.to_str().unwrap()]);
    for expected in [
        "code: SWIFT",
        "scale factor: 0.5",
        "box size: 10 x 10 x 10",
        "Unit length in cgs (U_L) = 3.08567758e24",
        "h = 0.6777",
        "0 gas 611 Densities",
        "1 dm 40 Masses",
        "Temperatures",
        "1 snap_0001 590",
    ] {
        assert!(info.contains(expected), "'{expected}' not in:\n{info}");
    }
    let info = aarbf(&["info", gadget.to_str().unwrap()]);
    for expected in [
        "files: 2",
        "HubbleParam = 0.7",
        "snap_010",
        "snap_011",
        "SmoothingLength",
    ] {
        assert!(info.contains(expected), "'{expected}' not in:\n{info}");
    }

    for (data, attribute) in [(&swift, "Temperatures"), (&gadget, "Temperature")] {
        let out = dir.path().join(format!("{attribute}.png"));
        aarbf(&[
            "render",
            "--data",
            data.to_str().unwrap(),
            "--particle-type",
            "gas",
            "--attribute",
            attribute,
            "--backend",
            "cpu",
            "--width",
            "40",
            "--height",
            "30",
            "--spp",
            "1",
            "--steps",
            "0..2",
            // The GADGET fixture's smoothing lengths (up to 8) exceed half its box (10): a
            // periodic field of it is refused. (SWIFT's says its run is not periodic.)
            "--no-periodic",
            "--out",
            out.to_str().unwrap(),
        ]);
        for step in 0..2 {
            let frame = dir.path().join(format!("{attribute}_{step:04}.png"));
            let image = image::open(&frame).unwrap().to_rgb8();
            assert_eq!(image.dimensions(), (40, 30));
            assert!(
                image.pixels().any(|p| p.0 != image.get_pixel(0, 0).0),
                "{frame:?} is blank"
            );
        }
    }
}

/// A new user's first render of a snapshot with several particle types, no flags: what is read
/// (gas, the default) and what else the snapshot holds is said before anything is drawn.
#[test]
fn a_render_without_flags_says_which_particle_type_it_reads() {
    let dir = tempfile::tempdir().unwrap();
    write_swift(&dir.path().join("snap_0000.hdf5"), 611, 40);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(["render", "--data"])
        .arg(dir.path())
        .args([
            "--backend",
            "cpu",
            "--width",
            "24",
            "--height",
            "16",
            "--spp",
            "1",
        ])
        .arg("--out")
        .arg(dir.path().join("first.png"))
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(
            "particles: gas (/PartType0); the snapshot holds 611 gas (type 0), 40 dm (type 1)"
        ),
        "{stderr}"
    );
}

/// The issue's own command asks a SWIFT run for `Temperature`, which SWIFT calls
/// `Temperatures`: the other number of a name the data has is taken, and the log says so; a
/// name with no such match is the error listing the data's names.
#[test]
fn an_attribute_named_in_the_other_number_is_the_datas() {
    let dir = tempfile::tempdir().unwrap();
    write_swift(&dir.path().join("snap_0000.hdf5"), 611, 40);
    let slice = |attribute: &str, radius_attribute: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(["slice", "--data"])
            .arg(dir.path())
            .args([
                "--attribute",
                attribute,
                "--radius-attribute",
                radius_attribute,
            ])
            .args([
                "--radius",
                "0.1",
                "--width",
                "32",
                "--no-periodic",
                "--force",
                "--out",
            ])
            .arg(dir.path().join(format!("{attribute}.png")))
            .output()
            .unwrap()
    };
    let out = slice("Temperature", "SmoothingLength");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    for said in [
        "attribute 'Temperature': the data has no attribute of that name, but has 'Temperatures': using 'Temperatures'",
        "attribute 'SmoothingLength': the data has no attribute of that name, but has 'SmoothingLengths'",
        "colour: 'Temperatures' over [",
    ] {
        assert!(stderr.contains(said), "'{said}' not in:\n{stderr}");
    }
    // The same image as the data's own names give.
    let own = slice("Temperatures", "SmoothingLengths");
    assert!(own.status.success());
    assert_eq!(
        std::fs::read(dir.path().join("Temperature.png")).unwrap(),
        std::fs::read(dir.path().join("Temperatures.png")).unwrap()
    );
    let out = slice("Pressure", "SmoothingLengths");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && stderr.contains("attribute 'Pressure' not found")
            && stderr.contains("'Temperatures'"),
        "{stderr}"
    );
}
