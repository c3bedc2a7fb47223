//! ParaView `.pvd` collections, and choosing a step by its time (`--time`) in every format.

use std::path::Path;

use aarbf::io::{self, AttributeSelection, Format};
use aarbf::scene::{OpenOptions, TimeSeries};
use aarbf::scene_file::resolve::{DataArgs, FieldOptions, resolve};
use aarbf::values::{Attribute, Step};
use glam::DVec3;

/// Step `k`: `n` particles on a line, offset by k, with attribute `temperature` = k.
fn step(k: usize, n: usize) -> Step {
    Step {
        name: format!("s{k}"),
        positions: (0..n)
            .map(|i| DVec3::new(i as f64 * 0.1, k as f64, 0.5 * (i % 3) as f64))
            .collect(),
        attributes: vec![Attribute {
            name: "temperature".into(),
            values: vec![k as f64; n],
        }],
    }
}

fn data_args(data: &Path, step: Option<usize>, time: Option<f64>) -> DataArgs {
    DataArgs {
        scene: None,
        data: Some(data.to_path_buf()),
        format: None,
        step,
        time,
        cache_mib: 64,
        particle_type: None,
        physical: false,
        smoothing: None,
        rescan: false,
        periodic: None,
        no_periodic: false,
    }
}

/// A collection in `dir` whose files lie in `dir/run/` (relative paths), listed out of time
/// order as hand-written collections can be.
fn write_collection(dir: &Path) -> std::path::PathBuf {
    let steps: Vec<Step> = [(0, 37), (1, 41), (2, 29)]
        .into_iter()
        .map(|(k, n)| step(k, n))
        .collect();
    io::write_series(
        &dir.join("run"),
        "fluid",
        &steps,
        Format::VtkXml,
        "temperature",
    )
    .unwrap();
    let pvd = dir.join("fluid.pvd");
    std::fs::write(
        &pvd,
        r#"<?xml version="1.0"?>
<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">
  <Collection>
    <DataSet timestep="0.25" group="" part="0" file="run/fluid_0001.vtp"/>
    <DataSet timestep="0" group="" part="0" file="run/fluid_0000.vtp"/>
    <DataSet timestep="1.5e0" group="" part="0" file="run/fluid_0002.vtp"/>
  </Collection>
</VTKFile>
"#,
    )
    .unwrap();
    pvd
}

#[test]
fn a_pvd_collection_is_a_series_with_times_and_relative_paths() {
    let dir = tempfile::tempdir().unwrap();
    let pvd = write_collection(dir.path());
    let steps = io::list_steps(&pvd, None).unwrap();
    let names: Vec<&str> = steps.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["fluid_0000", "fluid_0001", "fluid_0002"]);
    let times: Vec<Option<f64>> = steps.iter().map(io::step_time).collect();
    assert_eq!(times, [Some(0.0), Some(0.25), Some(1.5)]);
    assert!(steps.iter().all(|s| s.format == Format::VtkXml));

    let series = TimeSeries::open(&pvd, &OpenOptions::default()).unwrap();
    assert_eq!(series.times(), Some(&[0.0, 0.25, 1.5][..]));
    let counts: Vec<usize> = series.steps().iter().map(|s| s.count).collect();
    assert_eq!(counts, [37, 41, 29]);
    assert_eq!(series.step_at_time(0.2), Some((1, 0.25)));
    assert_eq!(series.step_at_time(-4.0), Some((0, 0.0)));
    assert_eq!(series.step_at_time(99.0), Some((2, 1.5)));

    // --time picks the nearest step; --step still picks by index.
    let field = FieldOptions {
        attribute: Some("temperature".into()),
        radius: Some("5%".parse().unwrap()),
        ..FieldOptions::default()
    };
    let by_time = resolve(&data_args(&pvd, None, Some(1.0)), &field).unwrap();
    assert_eq!(by_time.step, 2);
    let by_index = resolve(&data_args(&pvd, Some(1), None), &field).unwrap();
    assert_eq!(by_index.step, 1);
    let step = by_time.series.step(2).unwrap();
    assert_eq!(step.attribute("temperature").unwrap().values[0], 2.0);
}

#[test]
fn without_recorded_times_a_steps_time_is_its_index() {
    let dir = tempfile::tempdir().unwrap();
    let steps: Vec<Step> = (0..4).map(|k| step(k, 10 + k)).collect();
    let first = io::write_series(dir.path(), "plain", &steps, Format::Csv, "temperature").unwrap();
    let series = TimeSeries::open(&first, &OpenOptions::default()).unwrap();
    assert_eq!(series.times(), None);
    assert_eq!(series.step_at_time(2.4), Some((2, 2.0)));
    let field = FieldOptions {
        attribute: Some("temperature".into()),
        radius: Some("5%".parse().unwrap()),
        ..FieldOptions::default()
    };
    let resolved = resolve(&data_args(&first, None, Some(2.6)), &field).unwrap();
    assert_eq!(resolved.step, 3);
}

#[test]
fn a_pvd_naming_a_missing_file_or_a_bad_time_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let pvd = write_collection(dir.path());
    std::fs::remove_file(dir.path().join("run/fluid_0002.vtp")).unwrap();
    let e = io::list_steps(&pvd, None).unwrap_err().to_string();
    assert!(
        e.contains("fluid.pvd") && e.contains("'run/fluid_0002.vtp' (timestep 1.5) does not exist"),
        "{e}"
    );
    let bad = dir.path().join("bad.pvd");
    std::fs::write(
        &bad,
        r#"<VTKFile type="Collection"><Collection><DataSet timestep="later" file="run/fluid_0000.vtp"/></Collection></VTKFile>"#,
    )
    .unwrap();
    let e = io::list_steps(&bad, None).unwrap_err().to_string();
    assert!(
        e.contains("bad.pvd") && e.contains("timestep 'later' is not a number"),
        "{e}"
    );
    let truncated = dir.path().join("cut.pvd");
    std::fs::write(
        &truncated,
        r#"<VTKFile type="Collection"><Collection><DataSet timestep="0" file="run/"#,
    )
    .unwrap();
    let e = io::list_steps(&truncated, None).unwrap_err().to_string();
    assert!(e.contains("cut.pvd"), "{e}");
    // Reading works through the collection's files' own readers.
    let ok = io::list_steps(&dir.path().join("run/fluid_0000.vtp"), None).unwrap();
    assert_eq!(
        io::read_step(&ok[0], &AttributeSelection::All)
            .unwrap()
            .len(),
        37
    );
}
