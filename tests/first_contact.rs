//! What a scientist meets first: `aarbf info` and `aarbf render` on a simulation's output
//! folder as the code wrote it, with no flags beyond the data and the output.
//!
//! The folders under `tests/data/sph_runs/` were written by VTK's own XML writer and NumPy
//! (`write_sph_folders.py` beside them): PySPH's fluid steps with a `boundary.vtp` and the run's
//! log and info files, a SWIFT-like run directory (snapshots with statistics, parameter files, a
//! dependency-graph CSV and restart files), and a GADGET-like one (snapshots, initial
//! conditions, a restart snapshot). They are copied to a temporary folder first, so the index
//! aarbf writes beside the data never lands in the repository.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use aarbf::scene::{Camera, UpAxis};
use aarbf::scene_file::resolve::{DataArgs, FieldOptions, resolve};
use glam::DVec3;

fn aarbf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "info")
        .env("NO_COLOR", "1")
        .output()
        .expect("the binary runs")
}

/// Runs aarbf, which must succeed; returns stdout and stderr.
fn ok(args: &[&str]) -> (String, String) {
    let out = aarbf(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "aarbf {args:?} failed:\n{err}");
    (String::from_utf8(out.stdout).unwrap(), err)
}

fn fails(args: &[&str]) -> String {
    let out = aarbf(args);
    assert!(!out.status.success(), "aarbf {args:?} should fail");
    String::from_utf8(out.stderr).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A copy of `tests/data/sph_runs/<name>` in a fresh temporary folder.
fn run_folder(name: &str) -> (tempfile::TempDir, PathBuf) {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let entry = entry.unwrap();
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), target).unwrap();
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let source = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/sph_runs")
        .join(name);
    let copy_at = dir.path().join(name);
    copy(&source, &copy_at);
    (dir, copy_at)
}

/// `--data FOLDER [--step STEP]` as the library takes it.
fn data_args(folder: &Path, step: Option<usize>) -> DataArgs {
    DataArgs {
        scene: None,
        data: Some(folder.to_path_buf()),
        format: None,
        step,
        time: None,
        cache_mib: 64,
        particle_type: None,
        physical: false,
        smoothing: None,
        rescan: false,
        periodic: None,
        no_periodic: false,
    }
}

/// The step names `aarbf info` lists.
fn step_names(info: &str) -> Vec<String> {
    info.lines()
        .skip_while(|l| !l.starts_with("steps:"))
        .skip(1)
        .filter_map(|l| {
            let mut words = l.split_whitespace();
            words.next()?.parse::<usize>().ok()?;
            words.next().map(str::to_owned)
        })
        .collect()
}

#[test]
fn a_simulation_folder_opens_as_its_longest_series_and_says_what_it_left_out() {
    // (folder, the series' steps, files the warning must name)
    let cases: [(&str, Vec<&str>, Vec<&str>); 3] = [
        (
            "pysph_dam_break",
            vec![
                "fluid_00000",
                "fluid_00037",
                "fluid_00074",
                "fluid_00120",
                "fluid_00171",
                "fluid_00230",
            ],
            vec!["boundary.vtp"],
        ),
        (
            "swift_like",
            vec!["output_0000", "output_0001", "output_0002", "output_0003"],
            vec!["dependency_graph_*.csv"],
        ),
        (
            "gadget_like",
            vec![
                "snapshot_000",
                "snapshot_001",
                "snapshot_002",
                "snapshot_003",
                "snapshot_004",
            ],
            vec!["ics.npy", "restart_snapshot_*.npy"],
        ),
    ];
    for (name, steps, left_out) in cases {
        let (_keep, folder) = run_folder(name);
        let (info, log) = ok(&["info", s(&folder)]);
        assert_eq!(step_names(&info), steps, "{name}:\n{info}");
        for file in &left_out {
            assert!(
                log.contains(file),
                "{name}: the warning names {file}:\n{log}"
            );
        }
        assert!(
            log.contains("--data"),
            "{name}: says how to pick another:\n{log}"
        );
        // The glob a user writes for the whole folder picks the same series.
        let ext = Path::new(left_out[0])
            .extension()
            .unwrap()
            .to_str()
            .unwrap();
        let glob = folder.join(format!("*.{ext}"));
        let (info, _) = ok(&["info", s(&glob)]);
        assert_eq!(step_names(&info), steps, "{name} by glob");
    }

    // The group left out opens when named, and a glob for the series alone warns of nothing.
    let (_keep, folder) = run_folder("pysph_dam_break");
    let (info, _) = ok(&["info", s(&folder.join("boundary.vtp"))]);
    assert_eq!(step_names(&info), ["boundary"]);
    assert!(info.contains("kind"), "{info}");
    let (info, log) = ok(&["info", s(&folder.join("fluid_*.vtp"))]);
    assert_eq!(step_names(&info).len(), 6);
    assert!(!log.contains("left out"), "{log}");
}

#[test]
fn render_with_no_flags_gives_the_fluid_joined_upright_and_says_its_defaults() {
    let (_keep, folder) = run_folder("pysph_dam_break");
    let out = folder.parent().unwrap().join("a.png");
    let (_, log) = ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--width",
        "96",
        "--height",
        "80",
        "--spp",
        "2",
    ]);
    let image = image::open(&out).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (96, 80));
    // Every default is said: the series, the colour, the radius and where it came from.
    for said in [
        "left out: 'boundary.vtp'",
        "colour: 'rho', the data's first attribute (no --attribute given); the others: p, vel_x",
        "colour: 'rho' over [997.24, 1004.56], the series' least to largest value",
        "2 x the median smoothing length 'h' in step 0",
        "--radius-attribute h gives each particle its own",
    ] {
        assert!(log.contains(said), "missing '{said}' in:\n{log}");
    }

    // One automatic Phi_ref for the series: slices along any axis use the render's.
    let phi_ref = |log: &str, key: &str| -> f64 {
        let at = log
            .find(key)
            .unwrap_or_else(|| panic!("no '{key}' in:\n{log}"))
            + key.len();
        log[at..]
            .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let rendered = phi_ref(&log, "settings used: phi_ref ");
    for axis in ["x", "y", "z"] {
        let slice = folder.parent().unwrap().join(format!("slice-{axis}.png"));
        let (_, slice_log) = ok(&[
            "slice",
            "--data",
            s(&folder),
            "--axis",
            axis,
            "--width",
            "64",
            "--out",
            s(&slice),
        ]);
        let sliced = phi_ref(&slice_log, "Phi_ref ");
        assert!(
            (sliced - rendered).abs() <= 1e-4 * rendered,
            "slice along {axis}: Phi_ref {sliced}, render {rendered}"
        );
    }

    // The legend is drawn unless asked not to, and it names the attribute: the same render
    // without it differs only in the bottom-left corner.
    let bare = folder.parent().unwrap().join("bare.png");
    ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&bare),
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "1",
        "--no-legend",
    ]);
    let with = folder.parent().unwrap().join("with.png");
    ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&with),
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "1",
    ]);
    let (bare, with) = (
        image::open(&bare).unwrap().to_rgb8(),
        image::open(&with).unwrap().to_rgb8(),
    );
    let differ = |y0: u32, y1: u32| {
        (0..160)
            .flat_map(|x| (y0..y1).map(move |y| (x, y)))
            .filter(|&(x, y)| bare.get_pixel(x, y) != with.get_pixel(x, y))
            .count()
    };
    assert!(differ(120 - 60, 120) > 1000, "a legend is drawn by default");
    assert_eq!(differ(0, 120 - 62), 0);

    // The library's resolution of the same flags: the radius is the SPH kernel's support,
    // 2h = 0.104 over the 0.04 lattice (not 1% of the diagonal, 0.0099), and the view is z-up.
    let resolved = resolve(&data_args(&folder, None), &FieldOptions::default()).unwrap();
    assert!(
        (resolved.field.radius - 2.0 * 0.052).abs() < 1e-12,
        "{}",
        resolved.field.radius
    );
    let camera = Camera::default_for(resolved.series.bounds());
    assert_eq!(camera.up, DVec3::Z);
    // With a smoothing length per particle, the radius is 2h.
    let with_h = resolve(
        &data_args(&folder, None),
        &FieldOptions {
            radius_attribute: Some("h".into()),
            ..FieldOptions::default()
        },
    )
    .unwrap();
    assert_eq!(with_h.field.radius, 2.0);

    // The up axis is the user's to set, and it changes the view (and the image).
    let turned = folder.parent().unwrap().join("b.png");
    ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&turned),
        "--width",
        "96",
        "--height",
        "80",
        "--spp",
        "2",
        "--up",
        "y",
    ]);
    assert_ne!(
        image::open(&turned).unwrap().to_rgb8().into_raw(),
        image.into_raw(),
        "--up y shows another view"
    );
    // --camera-from places the camera by angles about the up axis.
    let from = folder.parent().unwrap().join("c.png");
    ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&from),
        "--width",
        "32",
        "--height",
        "32",
        "--spp",
        "1",
        "--camera-from",
        "0,0",
        "--save-scene",
        s(&folder.parent().unwrap().join("c.toml")),
    ]);
    let saved =
        aarbf::scene_file::SceneFile::load(&folder.parent().unwrap().join("c.toml")).unwrap();
    let eye = DVec3::from(saved.camera.eye.unwrap());
    let at = DVec3::from(saved.camera.at.unwrap());
    assert!(
        (eye - at).normalize().dot(DVec3::NEG_Y) > 0.999,
        "0,0 looks from -y"
    );
    assert_eq!(saved.camera.up, Some(UpAxis::Z.vector().to_array()));
    // The light's elevation is about the scene's vertical too: 60 degrees above the x-y plane.
    assert_eq!(saved.camera.up_axis, Some(UpAxis::Z));
    let settings = saved.render_settings(resolved.series.bounds()).unwrap();
    assert_eq!(settings.up_axis, UpAxis::Z);
    let (side, front) = settings.up_axis.horizontal();
    let light = settings.light.direction_about(DVec3::Z, side, front);
    assert!(
        (light.z - settings.light.elevation.to_radians().sin()).abs() < 1e-12,
        "{light}"
    );
}

#[test]
fn without_a_smoothing_length_the_radius_is_twice_the_particles_spacing() {
    // The GADGET-like snapshots carry masses and densities but no smoothing length.
    let (_keep, folder) = run_folder("gadget_like");
    let data = data_args(&folder, None);
    let resolved = resolve(&data, &FieldOptions::default()).unwrap();
    // Brute force over every particle of step 0 (1000, so the sample is all of them): the
    // distance to the nearest particle at another position, the upper median of those.
    let step = resolved.series.step(0).unwrap();
    let p = &step.positions;
    let mut nearest: Vec<f64> = (0..p.len())
        .filter_map(|i| {
            (0..p.len())
                .map(|j| p[i].distance(p[j]))
                .filter(|&d| d > 0.0)
                .min_by(f64::total_cmp)
        })
        .collect();
    nearest.sort_by(f64::total_cmp);
    let expected = 2.0 * nearest[nearest.len() / 2];
    assert!(
        (resolved.field.radius - expected).abs() <= 1e-12 * expected,
        "{} against {expected}",
        resolved.field.radius
    );
    let (info, _) = ok(&["info", s(&folder)]);
    assert!(
        info.contains("2 x the particles' spacing in step 0"),
        "{info}"
    );
}

#[test]
fn a_targeted_render_prints_one_truth_about_its_samples_and_step() {
    let (_keep, folder) = run_folder("pysph_dam_break");
    let out = folder.parent().unwrap().join("t.png");
    let (_, log) = ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--width",
        "24",
        "--height",
        "24",
        "--time-budget",
        "1",
        "--backend",
        "cpu",
    ]);
    // "... at step size S and N spp, in ..." (the estimate) and "(24x24, N spp, step size S,
    // ...)" (the image written) must name the same N and S.
    let estimate = log
        .lines()
        .find(|l| l.contains("estimated error"))
        .expect(&log);
    let written = log.lines().find(|l| l.contains("(24x24, ")).expect(&log);
    let spp = |line: &str, before: &str| -> String {
        let end = line.find(" spp").expect(line);
        line[line[..end].rfind(before).expect(line) + before.len()..end].to_owned()
    };
    assert_eq!(spp(estimate, "and "), spp(written, ", "), "{log}");
    let step_of = |line: &str| -> f64 {
        let at = line.find("step size ").expect(line) + "step size ".len();
        line[at..]
            .split([' ', ','])
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let (a, b) = (step_of(estimate), step_of(written));
    assert!((a - b).abs() <= 1e-3 * a, "{log}");
    let settings = log
        .lines()
        .find(|l| l.contains("settings used"))
        .expect(&log);
    assert!(
        settings.contains("step size chosen per image"),
        "{settings}"
    );
}

#[test]
fn bad_input_is_named_before_any_device_is_probed() {
    let (_keep, folder) = run_folder("pysph_dam_break");
    let out = folder.parent().unwrap().join("x.png");
    // A negative number reaches the option's own check.
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--radius",
        "-1",
    ]);
    assert!(e.contains("radius '-1' must be positive"), "{e}");
    assert!(!e.contains("unexpected argument"), "{e}");
    // An image size is checked before the data is opened or a GPU looked for.
    for backend in ["ash", "wgpu"] {
        let e = fails(&[
            "render",
            "--data",
            s(&folder),
            "--out",
            s(&out),
            "--width",
            "0",
            "--backend",
            backend,
        ]);
        assert!(
            e.contains("image size 0x512") && e.contains("--width"),
            "{e}"
        );
        assert!(!e.contains("llvmpipe") && !e.contains("colour:"), "{e}");
    }
    // An attribute only later steps could have: the message says which step was asked for
    // and that the first step is where it is missing.
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--step",
        "3",
        "--attribute",
        "kind",
    ]);
    assert!(
        e.contains("step 3 was asked for") && e.contains("fluid_00000.vtp") && e.contains("'kind'"),
        "{e}"
    );
    // A number column with a word in it is refused alike by every command.
    let csv = folder.parent().unwrap().join("words.csv");
    std::fs::write(
        &csv,
        "x,y,z,temperature\n0.10000000000000001,0.2,0.29999999999999999,1.5\n\
         0.4,0.5,0.59999999999999998,abc\n0.7,0.1,0.9,3.5\n",
    )
    .unwrap();
    let grid = folder.parent().unwrap().join("f.npy");
    for args in [
        vec!["info", s(&csv)],
        vec![
            "field",
            "--data",
            s(&csv),
            "--grid",
            "3x3x3",
            "--out",
            s(&grid),
        ],
        vec![
            "render",
            "--data",
            s(&csv),
            "--out",
            s(&out),
            "--width",
            "8",
            "--height",
            "8",
        ],
        vec!["slice", "--data", s(&csv), "--out", s(&out)],
    ] {
        let e = fails(&args);
        assert!(
            e.contains("words.csv") && e.contains("column 'temperature': 'abc' is not a number"),
            "{args:?}: {e}"
        );
    }
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--camera-from",
        "1",
    ]);
    assert!(e.contains("AZ,EL"), "{e}");
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--up",
        "w",
    ]);
    assert!(e.contains("x, y, z, -x, -y, -z"), "{e}");

    // A step file cut short (a copy interrupted, a file still being written) says so, and
    // where, instead of an XML parser's inner message.
    let step = folder.join("fluid_00074.vtp");
    let bytes = std::fs::read(&step).unwrap();
    let head_end = bytes
        .windows(15)
        .position(|w| w == b"<AppendedData e")
        .unwrap_or(bytes.len() / 2);
    std::fs::write(&step, &bytes[..head_end - 40]).unwrap();
    let e = fails(&["info", s(&folder.join("fluid_*.vtp"))]);
    assert!(
        e.contains("fluid_00074.vtp") && e.contains("the file ends early, at byte"),
        "{e}"
    );
    assert!(!e.contains("MissingEndTag"), "{e}");
}

#[test]
fn help_states_every_option_and_the_defaults_the_renderer_uses() {
    let (help, _) = ok(&["render", "--help"]);
    let d = aarbf::render::RenderSettings::default();
    let light = d.light;
    for default in [
        format!(
            "--width <WIDTH>\n          Image width in pixels [default: {}]",
            d.width
        ),
        format!(
            "--height <HEIGHT>\n          Image height in pixels [default: {}]",
            d.height
        ),
        format!("[default: {}]", aarbf::scene_file::DEFAULT_SPP),
        format!("[default: {}]", d.seed),
        format!(
            "[default: {},{},{}]",
            light.azimuth, light.elevation, light.intensity
        ),
        format!("[default: {}]", light.ambient),
        format!(
            "[default: {}]",
            clap::ValueEnum::to_possible_value(&d.integrator)
                .unwrap()
                .get_name()
        ),
    ] {
        assert!(
            help.contains(&default),
            "render --help lacks '{default}':\n{help}"
        );
    }
    // No option is left without a description, and no issue numbers reach users.
    // In the long help an option's line is followed by its description's first line.
    let lines: Vec<&str> = help.lines().collect();
    let options: Vec<usize> = (0..lines.len())
        .filter(|&i| {
            let text = lines[i].trim_start();
            text.starts_with('-') && lines[i].len() - text.len() <= 6
        })
        .collect();
    assert!(options.len() > 40, "{} options in:\n{help}", options.len());
    let blank: Vec<&str> = options
        .iter()
        .filter(|&&i| lines.get(i + 1).is_none_or(|next| next.trim().is_empty()))
        .map(|&i| lines[i])
        .collect();
    assert!(blank.is_empty(), "options without a description: {blank:?}");
    assert!(!help.to_lowercase().contains("issue"), "{help}");
}

#[test]
fn robust_and_per_step_ranges_and_the_legend_say_what_the_colours_mean() {
    use aarbf::io::{self, AttributeSelection};
    use aarbf::scene::index::robust_range;
    let (_keep, folder) = run_folder("pysph_dam_break");
    let dir = folder.parent().unwrap().to_path_buf();
    // The pressure of each step, read straight from its file.
    let steps: Vec<Vec<f64>> = io::list_steps(&folder.join("fluid_*.vtp"), None)
        .unwrap()
        .iter()
        .map(|r| {
            let step = io::read_step(r, &AttributeSelection::Only(vec!["p".into()])).unwrap();
            step.attribute("p").unwrap().values.clone()
        })
        .collect();
    let resolve_range = |range: &str, step: usize| {
        let r = resolve(
            &data_args(&folder, Some(step)),
            &FieldOptions {
                attribute: Some("p".into()),
                attribute_range: Some(range.parse().unwrap()),
                ..FieldOptions::default()
            },
        )
        .unwrap();
        r.field.attribute_range
    };
    // robust: from the lowest step's 1st percentile to the highest step's 99th.
    let per_step: Vec<(f64, f64)> = steps.iter().map(|v| robust_range(v).unwrap()).collect();
    let envelope = per_step
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &(lo, hi)| {
            (a.min(lo), b.max(hi))
        });
    assert_eq!(resolve_range("robust", 0), Some(envelope));
    assert_eq!(resolve_range("robust-step", 3), Some(per_step[3]));
    let (lo3, hi3) = steps[3]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    assert_eq!(resolve_range("step", 3), Some((lo3, hi3)));
    assert_eq!(
        resolve_range("series", 3),
        None,
        "the series' range is the field's default"
    );
    assert_eq!(resolve_range("-5,7.5", 3), Some((-5.0, 7.5)));
    // A step's robust range is far narrower than the series': it shows the step's gradient.
    assert!(per_step[3].1 - per_step[3].0 < 0.2 * (22800.0 + 13800.0));

    // A sequence with a per-step range says each frame's, and the legend draws it.
    let out = dir.join("p.png");
    let (_, log) = ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--attribute",
        "p",
        "--attribute-range",
        "robust-step",
        "--steps",
        "2..=3",
        "--legend",
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "1",
    ]);
    for k in [2, 3] {
        let (lo, hi) = per_step[k];
        assert!(
            log.contains(&format!("range [{lo}, {hi}]")),
            "step {k}:\n{log}"
        );
    }
    let framed = image::open(dir.join("p_0003.png")).unwrap().to_rgb8();
    let plain = dir.join("plain.png");
    ok(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&plain),
        "--attribute",
        "p",
        "--attribute-range",
        "robust-step",
        "--step",
        "3",
        "--width",
        "160",
        "--height",
        "120",
        "--spp",
        "1",
        "--no-legend",
    ]);
    let plain = image::open(&plain).unwrap().to_rgb8();
    // The legend covers the bottom-left corner, and nothing else.
    let differs = |x0: u32, y0: u32, x1: u32, y1: u32| {
        (x0..x1)
            .flat_map(|x| (y0..y1).map(move |y| (x, y)))
            .filter(|&(x, y)| framed.get_pixel(x, y) != plain.get_pixel(x, y))
            .count()
    };
    assert!(differs(8, 120 - 60, 152, 112) > 1000);
    assert_eq!(differs(0, 0, 160, 120 - 62), 0);
    // Its bar runs through the colour map: viridis' dark end on the left, yellow on the right.
    let bar_y = 120 - 8 - 52 + 21 + 5;
    let left = framed.get_pixel(8 + 6, bar_y).0;
    let right = framed.get_pixel(8 + 144 - 7, bar_y).0;
    assert!(
        left[2] > left[1] && right[0] > 200 && right[1] > 200,
        "{left:?} {right:?}"
    );

    // A slice draws one too; outputs meant for compositing and images too small refuse.
    ok(&[
        "slice",
        "--data",
        s(&folder),
        "--attribute",
        "p",
        "--axis",
        "y",
        "--legend",
        "--out",
        s(&dir.join("slice.png")),
    ]);
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&dir.join("x.exr")),
        "--legend",
    ]);
    assert!(e.contains("8-bit PNG"), "{e}");
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--legend",
        "--width",
        "64",
    ]);
    assert!(e.contains("at least 120x64"), "{e}");
    let e = fails(&[
        "render",
        "--data",
        s(&folder),
        "--out",
        s(&out),
        "--attribute-range",
        "5,1",
    ]);
    assert!(e.contains("ascending"), "{e}");

    // The scene file spells ranges the same way, and a saved render reproduces its numbers.
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        format!(
            "[data]\npath = \"{}\"\nattribute = \"p\"\nattribute_range = \"robust\"\n",
            folder.display()
        ),
    )
    .unwrap();
    let saved = dir.join("saved.toml");
    ok(&[
        "render",
        "--scene",
        s(&scene),
        "--out",
        s(&dir.join("scene.png")),
        "--width",
        "16",
        "--height",
        "16",
        "--spp",
        "1",
        "--save-scene",
        s(&saved),
    ]);
    let saved = aarbf::scene_file::SceneFile::load(&saved).unwrap();
    assert_eq!(
        saved.data.attribute_range,
        Some(aarbf::scene_file::RangeSpec::Fixed(envelope.0, envelope.1))
    );
}

#[test]
fn each_study_lists_its_own_options_and_reads_a_radius_as_render_does() {
    let (noise, _) = ok(&["bench", "noise", "--help"]);
    assert!(
        noise.contains("--noise-size") && noise.contains("--reference-spp"),
        "{noise}"
    );
    assert!(
        !noise.contains("--voxel-grids") && !noise.contains("--radii"),
        "{noise}"
    );
    let (all, _) = ok(&["bench", "all", "--help"]);
    for option in [
        "--voxel-grids",
        "--radii",
        "--noise-size",
        "--max-n",
        "--offsets",
    ] {
        assert!(all.contains(option), "bench all lists {option}");
    }
    // Another study's option is ignored, and said so (a script may pass one list to all).
    let scratch = tempfile::tempdir().unwrap();
    let out = aarbf(&[
        "bench",
        "noise",
        "--voxel-grids",
        "64",
        "--data",
        s(&scratch.path().join("no-such-data.csv")),
        "--out",
        s(scratch.path()),
    ]);
    assert!(!out.status.success(), "no data: the study stops");
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains(
            "`aarbf bench noise` does not read --voxel-grids (baselines and accuracy's): ignored"
        ),
        "{e}"
    );

    // "3%" is of the series' diagonal, as for render; a plain number is a length.
    let (_keep, folder) = run_folder("pysph_dam_break");
    let spec = aarbf::study::DataSpec::Path(folder.clone());
    let load = |radius: &str| {
        aarbf::study::Dataset::load(
            &spec,
            None,
            Some(3),
            Some("p"),
            Some(radius.parse().unwrap()),
        )
        .unwrap()
    };
    let ds = load("3%");
    let series_diagonal = ds.series.bounds().diagonal();
    assert!(
        ds.bounds.diagonal() < series_diagonal,
        "step 3 covers less than the series"
    );
    assert!((ds.radius - 0.03 * series_diagonal).abs() < 1e-12 * series_diagonal);
    assert_eq!(load("0.05").radius, 0.05);
}
