//! The `aarbf` binary as a user runs it: generate → info → field/slice, scene files, errors.

use std::path::Path;
use std::process::{Command, Output};

use aarbf::accel::ClusterSize;
use aarbf::field::{Classification, FieldSettings, ReferenceField};
use aarbf::io::{At, npy};
use aarbf::scene::{OpenOptions, TimeSeries};
use glam::DVec3;

fn aarbf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .output()
        .expect("the binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = aarbf(args);
    assert!(
        out.status.success(),
        "aarbf {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn fails(args: &[&str]) -> String {
    let out = aarbf(args);
    assert!(!out.status.success(), "aarbf {args:?} should fail");
    String::from_utf8(out.stderr).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn generate_info_and_field_agree_with_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("db")),
        "--count",
        "800",
        "--steps",
        "3",
        "--seed",
        "5",
    ]);
    let header = header.trim();
    assert!(header.ends_with("dambreak-demo.particles"), "{header}");
    let vtp = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("vtp")),
        "--count",
        "800",
        "--steps",
        "3",
        "--seed",
        "5",
        "--format",
        "vtk-xml",
    ]);

    let info = ok(&["info", header]);
    assert!(
        info.contains("steps:      3")
            && info.contains("800 at most per step")
            && info.contains("attribute"),
        "{info}"
    );
    let info_vtp = ok(&["info", vtp.trim()]);
    assert!(
        info_vtp.contains("velocity") && info_vtp.contains("neighbours"),
        "{info_vtp}"
    );

    // Queries: a line through the data, float32.
    let queries: Vec<f32> = (0..64).flat_map(|i| [i as f32 / 64.0, 0.1, 0.15]).collect();
    let q = d.join("q.npy");
    npy::write_matrix(&q, 64, 3, &queries).unwrap();
    for (classification, cols) in [("post", 2), ("pre", 4)] {
        let out = d.join(format!("f_{classification}.npy"));
        ok(&[
            "field",
            "--data",
            vtp.trim(),
            "--step",
            "2",
            "--attribute",
            "velocity",
            "--radius",
            "0.05",
            "--radius-map",
            "0:0.5,1:1",
            "--classification",
            classification,
            "--cluster",
            "4",
            "--queries",
            s(&q),
            "--out",
            s(&out),
        ]);
        let m = npy::read_matrix(At::new(&out, None)).unwrap();
        assert_eq!((m.rows, m.cols), (64, cols));
        // The same field through the library.
        let series = TimeSeries::open(Path::new(vtp.trim()), &OpenOptions::default()).unwrap();
        let mut settings = FieldSettings::new(Some("velocity"), 0.05);
        settings.radius_map =
            aarbf::scene::maps::RadiusMap::new("0:0.5,1:1".parse().unwrap()).unwrap();
        settings.classification = if classification == "pre" {
            Classification::Pre
        } else {
            Classification::Post
        };
        let a = series.attribute("velocity").unwrap();
        let field = ReferenceField::of_step(
            &series.step(2).unwrap(),
            &settings,
            ClusterSize::new(4).unwrap(),
            series.bounds(),
            Some((a.min as f64, a.max as f64)),
        )
        .unwrap();
        let mut hits = 0;
        for i in 0..64 {
            let x = DVec3::new(
                queries[i * 3] as f64,
                queries[i * 3 + 1] as f64,
                queries[i * 3 + 2] as f64,
            );
            let expect = field.eval_brute_force(x);
            let row = m.row(i);
            assert!(
                (row[0] - expect.phi).abs() <= 1e-12 * expect.phi.abs(),
                "{row:?} vs {expect:?}"
            );
            for (got, want) in row[1..].iter().zip(&expect.theta) {
                assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0) && got.is_finite());
            }
            hits += usize::from(row[0] > 0.0);
        }
        assert!(hits > 5, "the line should pass through fluid ({hits} hits)");
    }

    // The slice image exists and is not black.
    let png = d.join("slice.png");
    ok(&[
        "slice",
        "--data",
        header,
        "--attribute",
        "attribute",
        "--width",
        "64",
        "--out",
        s(&png),
    ]);
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.width(), 64);
    assert!(img.pixels().any(|p| p.0.iter().any(|&c| c > 40)));
}

#[test]
fn scene_file_settings_and_flag_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&[
        "generate",
        "uniform",
        "--out",
        s(&d.join("u")),
        "--count",
        "500",
    ]);
    std::fs::write(
        d.join("scene.toml"),
        "[data]\npath = \"u/uniform.particles\"\nattribute = \"attribute\"\n[field]\nradius = 0.2\nclassification = \"pre\"\ncolormap = \"grayscale\"\n",
    )
    .unwrap();
    let q = d.join("q.npy");
    npy::write_matrix(&q, 2, 3, &[0.5, 0.5, 0.5, 0.25, 0.5, 0.5]).unwrap();
    let out = d.join("o.npy");
    ok(&[
        "field",
        "--scene",
        s(&d.join("scene.toml")),
        "--queries",
        s(&q),
        "--out",
        s(&out),
    ]);
    assert_eq!(
        npy::read_matrix(At::new(&out, None)).unwrap().cols,
        4,
        "pre-classification from the scene file"
    );
    let e = fails(&[
        "field",
        "--scene",
        s(&d.join("scene.toml")),
        "--queries",
        s(&q),
        "--out",
        s(&out),
    ]);
    assert!(e.contains("exists; pass --force"), "{e}");
    ok(&[
        "field",
        "--force",
        "--scene",
        s(&d.join("scene.toml")),
        "--classification",
        "post",
        "--queries",
        s(&q),
        "--out",
        s(&out),
    ]);
    assert_eq!(
        npy::read_matrix(At::new(&out, None)).unwrap().cols,
        2,
        "the flag overrides the file"
    );
}

#[test]
fn bad_input_gives_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "uniform",
        "--out",
        s(&d.join("u")),
        "--count",
        "100",
    ]);
    let header = header.trim();
    let q = d.join("q.npy");
    npy::write_matrix(&q, 1, 3, &[0.5; 3]).unwrap();
    let out = d.join("o.npy");
    let field = |extra: &[&str]| {
        let mut args = vec![
            "field",
            "--data",
            header,
            "--queries",
            s(&q),
            "--out",
            s(&out),
        ];
        args.extend_from_slice(extra);
        fails(&args)
    };
    let e = field(&[]);
    assert!(
        e.contains("--attribute is required") && e.contains("(the data has: attribute)"),
        "{e}"
    );
    let e = field(&["--attribute", "velocity"]);
    assert!(
        e.contains("attribute 'velocity' not found") && e.contains("'attribute'"),
        "{e}"
    );
    let e = field(&["--attribute", "attribute", "--step", "7"]);
    assert!(
        e.contains("step 7 does not exist") && e.contains("1 steps"),
        "{e}"
    );
    let e = field(&["--attribute", "attribute", "--cluster", "3"]);
    assert!(
        e.contains("cluster size 3 is not one of 1, 2, 4, 8, 16"),
        "{e}"
    );
    let e = field(&["--attribute", "attribute", "--radius-map", "0:2,1:1"]);
    assert!(e.contains("radius map") && e.contains("[0, 1]"), "{e}");
    let e = field(&["--attribute", "attribute", "--colormap", "rainbow"]);
    assert!(e.contains("'rainbow'") && e.contains("viridis"), "{e}");
    let e = field(&["--attribute", "attribute", "--radius=-1"]);
    assert!(e.contains("radius '-1' must be positive"), "{e}");
    npy::write_matrix(&q, 1, 2, &[0.5; 2]).unwrap();
    let e = field(&["--attribute", "attribute"]);
    assert!(e.contains("q.npy") && e.contains("M x 3"), "{e}");
    npy::write_matrix(&q, 1, 3, &[0.5, f64::NAN, 0.5]).unwrap();
    let e = field(&["--attribute", "attribute"]);
    assert!(e.contains("query 0 is not finite"), "{e}");
    let e = fails(&["info", s(&d.join("missing.vtp"))]);
    assert!(
        e.contains("missing.vtp") && e.contains("no such file"),
        "{e}"
    );
    let truncated = d.join("short.raw");
    std::fs::write(&truncated, [0u8; 20]).unwrap();
    let e = fails(&["info", s(&truncated)]);
    assert_eq!(
        e.matches("file is truncated").count(),
        1,
        "the problem is said once: {e}"
    );
    let e = fails(&["info", s(&d.join("u/uniform.particles_0000"))]);
    assert!(e.contains("unknown format"), "{e}");
    let render = |extra: &[&str]| {
        let png = d.join("r.png");
        let mut args = vec![
            "render",
            "--data",
            header,
            "--backend",
            "cpu",
            "--out",
            s(&png),
        ];
        args.extend_from_slice(extra);
        fails(&args)
    };
    let e = render(&["--optical-map", "0:-0.2,1:1"]);
    assert!(
        e.contains("optical-density map") && e.contains("extinction must be >= 0"),
        "{e}"
    );
    let e = render(&["--density-scale=-2"]);
    assert!(e.contains("density scale") && e.contains("-2"), "{e}");
    let e = render(&["--precision", "f16"]);
    assert!(e.contains("precision 'f16'") && e.contains("ds"), "{e}");
}

#[test]
fn render_writes_images_and_sequences() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("db")),
        "--count",
        "1500",
        "--steps",
        "4",
    ]);
    let header = header.trim();
    let png = d.join("one.png");
    let common = [
        "--attribute",
        "attribute",
        "--radius",
        "2%",
        "--width",
        "40",
        "--height",
        "30",
        "--spp",
        "2",
        "--backend",
        "cpu",
    ];
    let mut args = vec!["render", "--data", header, "--step", "3", "--out", s(&png)];
    args.extend_from_slice(&common);
    ok(&args);
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (40, 30));
    assert!(
        img.pixels().any(|p| p.0.iter().any(|&c| c > 30)),
        "the fluid shows"
    );
    // An existing output is not overwritten without --force.
    let e = fails(&args);
    assert!(e.contains("exists") && e.contains("--force"), "{e}");
    args.push("--force");
    ok(&args);
    // Settings that leave no density anywhere render (a background image) but say why.
    for (flag, value, says) in [
        ("--radius-map", "0", "every particle has radius 0"),
        ("--density-map", "0", "gives every particle weight 0"),
    ] {
        let mut a = args.clone();
        a.extend([flag, value]);
        let out = aarbf(&a);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && stderr.contains(says), "{stderr}");
    }

    let seq = d.join("seq.png");
    let mut args = vec![
        "render",
        "--data",
        header,
        "--steps",
        "1..=2",
        "--integrator",
        "marching",
        "--orbit",
        "3/50",
        "--out",
        s(&seq),
    ];
    args.extend_from_slice(&common);
    ok(&args);
    assert!(d.join("seq_0001.png").exists() && d.join("seq_0002.png").exists());
    assert!(!d.join("seq_0003.png").exists());
    let e = fails(&[
        "render",
        "--data",
        header,
        "--steps",
        "2..9",
        "--out",
        s(&seq),
    ]);
    assert!(e.contains("beyond the series' 4 steps"), "{e}");
    let e = fails(&[
        "render",
        "--data",
        header,
        "--camera",
        "0,0,0,0,0,0,0,1,0,40",
        "--out",
        s(&seq),
    ]);
    assert!(e.contains("eye and target coincide"), "{e}");
}

/// `aarbf field --grid` gives what `--queries` gives at the same points (the grid's cell
/// centres over the series' bounds, x fastest), and refuses malformed grids by name.
#[test]
fn a_grid_export_equals_point_queries_at_its_points() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two steps as post-processing writes them: CSV with 17 significant digits, positions
    // far from the origin, a count that is not a power of two.
    let series_dir = d.join("csv");
    std::fs::create_dir(&series_dir).unwrap();
    for step in 0..2 {
        let mut text = String::from("x,y,z,attribute\n");
        for i in 0..2500 {
            let t = (i * 7919 + step * 31) as f64 * 0.618_033_988_749_894_9;
            text.push_str(&format!(
                "{:.16e},{:.16e},{:.16e},{:.16e}\n",
                1.0e4 + 2.0 * t.fract(),
                -3.0e3 + (1.3 * t).sin().abs(),
                0.7 * (0.77 * t).cos().abs(),
                250.0 + 40.0 * (0.1 * t).sin(),
            ));
        }
        std::fs::write(series_dir.join(format!("snap_{step}.csv")), text).unwrap();
    }
    let header = s(&series_dir);
    let series = TimeSeries::open(Path::new(header), &OpenOptions::default()).unwrap();
    let b = series.bounds();
    let grid = aarbf::field::RegularGrid::cell_centred(b.min, b.max, [17, 11, 6]);
    let points: Vec<f64> = grid.points().iter().flat_map(|p| p.to_array()).collect();
    let q = d.join("grid_points.npy");
    npy::write_matrix(&q, grid.len(), 3, &points).unwrap();
    let run = |how: &[&str], name: &str| {
        let out = d.join(name);
        let mut args = vec![
            "field",
            "--data",
            header,
            "--step",
            "1",
            "--attribute",
            "attribute",
            "--radius",
            "4%",
            "--classification",
            "pre",
            "--out",
            s(&out),
        ];
        args.extend_from_slice(how);
        ok(&args);
        npy::read_matrix(At::new(&out, None)).unwrap()
    };
    let scattered = run(&["--grid", "17x11x6"], "scattered.npy");
    let queried = run(&["--queries", s(&q)], "queried.npy");
    assert_eq!((scattered.rows, scattered.cols), (17 * 11 * 6, 4));
    let mut inside = 0;
    for i in 0..scattered.rows {
        let (a, e) = (scattered.row(i), queried.row(i));
        assert!(
            (a[0] - e[0]).abs() <= 1e-12 * e[0],
            "point {i}: {a:?} vs {e:?}"
        );
        for c in 1..4 {
            assert!((a[c] - e[c]).abs() <= 1e-11, "point {i}: {a:?} vs {e:?}");
        }
        inside += usize::from(e[0] > 0.0);
    }
    assert!(inside > 100, "{inside} points see the fluid");

    let out = d.join("bad.npy");
    for (grid, says) in [
        ("0x3x3", "1..=4096"),
        ("3x3", "NXxNYxNZ"),
        ("ax3x3", "positive integers"),
    ] {
        let e = fails(&[
            "field",
            "--data",
            header,
            "--attribute",
            "attribute",
            "--grid",
            grid,
            "--out",
            s(&out),
        ]);
        assert!(e.contains(says), "--grid {grid}: {e}");
    }
    let e = fails(&[
        "field",
        "--data",
        header,
        "--attribute",
        "attribute",
        "--grid",
        "4",
        "--queries",
        s(&q),
        "--out",
        s(&out),
    ]);
    assert!(e.contains("cannot be used with"), "{e}");
    let e = fails(&[
        "field",
        "--data",
        header,
        "--attribute",
        "attribute",
        "--out",
        s(&out),
    ]);
    assert!(e.contains("--queries") && e.contains("--grid"), "{e}");
}

/// Sequences as users run them: every n-th step, resumed after an interruption without
/// re-rendering what is written, a camera orbit, and 16-bit PNG / OpenEXR with alpha for
/// compositing (the background taken out).
#[test]
fn render_sequences_resume_orbit_and_write_images_with_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("db")),
        "--count",
        "1200",
        "--steps",
        "7",
    ]);
    let header = header.trim();
    let common = [
        "--attribute",
        "attribute",
        "--radius",
        "3%",
        "--width",
        "36",
        "--height",
        "24",
        "--spp",
        "1",
        "--backend",
        "cpu",
    ];
    let render = |extra: &[&str]| {
        let mut a = vec!["render", "--data", header];
        a.extend_from_slice(&common);
        a.extend_from_slice(extra);
        ok(&a)
    };
    // Every third step of 1..=6: 1, 4.
    let seq = d.join("seq.png");
    render(&["--steps", "1..=6:3", "--out", s(&seq)]);
    let written = |prefix: &str| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(prefix))
            .collect();
        v.sort();
        v
    };
    assert_eq!(written("seq_"), ["seq_0001.png", "seq_0004.png"]);
    let e = fails(&[
        "render",
        "--data",
        header,
        "--steps",
        "0..4:0",
        "--out",
        s(&seq),
    ]);
    assert!(e.contains("stride"), "{e}");

    // Resuming: a frame already written is kept as it is (a stand-in proves it was not
    // rendered again), the missing ones are rendered; --force renders everything.
    let stand_in = std::fs::read(d.join("seq_0001.png")).unwrap();
    std::fs::write(d.join("seq_0004.png"), b"stand-in").unwrap();
    std::fs::remove_file(d.join("seq_0001.png")).unwrap();
    render(&["--steps", "1..=6:3", "--out", s(&seq)]);
    assert_eq!(std::fs::read(d.join("seq_0004.png")).unwrap(), b"stand-in");
    assert_eq!(std::fs::read(d.join("seq_0001.png")).unwrap(), stand_in);
    render(&["--steps", "1..=6:3", "--out", s(&seq), "--force"]);
    assert!(image::open(d.join("seq_0004.png")).is_ok());

    // An orbit: 4 frames around the data, each a different view of the same step; with a
    // step range the steps advance with the frames.
    let orbit = d.join("orbit.png");
    render(&["--step", "5", "--orbit-sequence", "4", "--out", s(&orbit)]);
    assert_eq!(
        written("orbit_"),
        [
            "orbit_0000.png",
            "orbit_0001.png",
            "orbit_0002.png",
            "orbit_0003.png"
        ]
    );
    let frames: Vec<_> = (0..4)
        .map(|k| {
            image::open(d.join(format!("orbit_{k:04}.png")))
                .unwrap()
                .to_rgb8()
        })
        .collect();
    for k in 1..4 {
        assert_ne!(frames[0], frames[k], "frame {k} shows the same view");
    }
    // Frame 0 of the orbit is the step's ordinary render.
    let plain = d.join("plain.png");
    render(&["--step", "5", "--out", s(&plain)]);
    assert_eq!(image::open(&plain).unwrap().to_rgb8(), frames[0]);
    let walk = d.join("walk.png");
    render(&[
        "--steps",
        "2..4",
        "--orbit-sequence",
        "3",
        "--out",
        s(&walk),
    ]);
    assert_eq!(written("walk_").len(), 3);

    // With alpha: over a grey background the 8-bit PNG shows grey where there is no data;
    // the 16-bit PNG and the EXR carry the data alone, transparent there.
    let grey = ["--step", "5", "--background", "0.5,0.5,0.5"];
    let opaque = d.join("opaque.png");
    render(&[&grey[..], &["--out", s(&opaque)]].concat());
    let png16 = d.join("alpha.png");
    render(&[&grey[..], &["--bit-depth", "16", "--out", s(&png16)]].concat());
    let exr = d.join("alpha.exr");
    render(&[&grey[..], &["--out", s(&exr)]].concat());
    let opaque = image::open(&opaque).unwrap().to_rgb8();
    let rgba16 = image::open(&png16).unwrap().to_rgba16();
    let rgba32 = image::open(&exr).unwrap().to_rgba32f();
    assert_eq!(rgba16.dimensions(), (36, 24));
    assert_eq!(rgba32.dimensions(), (36, 24));
    let corner = (0, 0);
    assert_eq!(opaque.get_pixel(corner.0, corner.1).0, [188, 188, 188]); // sRGB of 0.5
    assert_eq!(rgba16.get_pixel(corner.0, corner.1).0[3], 0);
    assert_eq!(rgba32.get_pixel(corner.0, corner.1).0, [0.0; 4]);
    // Somewhere the data is opaque enough to see, and its colour composited back over the
    // grey gives the 8-bit image (to its rounding).
    let mut seen = 0;
    for (x, y, p) in rgba32.enumerate_pixels() {
        let [r, g, b, a] = p.0;
        if a > 0.2 {
            seen += 1;
            let over = |c: f32| {
                let linear = f64::from(c) + (1.0 - f64::from(a)) * 0.5;
                aarbf::values::color_space::linear_to_srgb(linear.clamp(0.0, 1.0)) * 255.0
            };
            let expect = opaque.get_pixel(x, y).0;
            for (k, c) in [r, g, b].into_iter().enumerate() {
                assert!(
                    (over(c) - f64::from(expect[k])).abs() <= 1.0,
                    "pixel {x},{y}: {} vs {}",
                    over(c),
                    expect[k]
                );
            }
        }
    }
    assert!(seen > 20, "{seen} pixels with data");
    let e = fails(&["render", "--data", header, "--out", s(&d.join("x.tiff"))]);
    assert!(e.contains("unknown image type"), "{e}");
    let e = fails(&[
        "render",
        "--data",
        header,
        "--bit-depth",
        "12",
        "--out",
        s(&d.join("x.png")),
    ]);
    assert!(e.contains("8 or 16"), "{e}");
}

/// `aarbf bench playback` as a user runs it on a series post-processing wrote: CSV steps with
/// 17 significant digits, far from the origin, a different (awkward) count in each step. The
/// CSV has a row per step and stage with the step's own count; the summary names the data,
/// the steps played, the rate, the floors and the peak memory; a range beyond the series is
/// refused, naming it; results are not overwritten without `--force`.
#[test]
fn bench_playback_reports_every_step_and_stage_of_a_series_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("run");
    std::fs::create_dir(&data).unwrap();
    let counts = [301usize, 257, 419];
    for (k, &n) in counts.iter().enumerate() {
        let mut text = String::from("x,y,z,temperature\n");
        for i in 0..n {
            let u = (i as f64 + 0.5) / n as f64;
            let (x, y, z) = (
                4.0e5 + 0.731 * (u * 37.0).sin() + 0.01 * k as f64,
                -2.5e5 + 0.617 * (u * 53.0).cos(),
                1.0e5 + 0.9 * u,
            );
            text += &format!("{x:.17e},{y:.17e},{z:.17e},{:.17e}\n", 300.0 + 50.0 * u);
        }
        std::fs::write(data.join(format!("step_{k}.csv")), text).unwrap();
    }
    let out = dir.path().join("pb");
    let play = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "playback",
            "--data",
            s(&data),
            "--attribute",
            "temperature",
            "--backend",
            "cpu",
            "--size",
            "24x18",
            "--out",
            s(&out),
        ];
        args.extend_from_slice(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let args = play(&[]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());

    let csv = std::fs::read_to_string(out.join("playback.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("step,particles,bytes,stage,seconds"));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let stages: Vec<&str> = rows.iter().filter(|r| r[0] == "0").map(|r| r[3]).collect();
    for stage in ["read+decode", "prepare (cpu)", "build", "frame"] {
        assert!(stages.contains(&stage), "stage {stage} missing: {stages:?}");
    }
    for (k, &n) in counts.iter().enumerate() {
        let of_step: Vec<_> = rows.iter().filter(|r| r[0] == k.to_string()).collect();
        assert_eq!(of_step.len(), stages.len(), "step {k}: {of_step:?}");
        for r in of_step {
            assert_eq!(r[1], n.to_string(), "step {k}'s count: {r:?}");
            let seconds: f64 = r[4].parse().unwrap();
            assert!(seconds.is_finite() && seconds >= 0.0, "{r:?}");
        }
    }
    assert_eq!(rows.len(), counts.len() * stages.len(), "{csv}");
    // A frame was drawn for every step (the stage is never free).
    assert!(
        rows.iter()
            .filter(|r| r[3] == "frame")
            .all(|r| r[4].parse::<f64>().unwrap() > 0.0)
    );

    let md = std::fs::read_to_string(out.join("playback.md")).unwrap();
    assert!(
        md.starts_with(&format!("# Playback: {}\n", data.display())),
        "{md}"
    );
    assert!(md.contains("3 steps of up to 419 particles"), "{md}");
    assert!(md.contains("steps/s over steps"), "{md}");
    assert!(md.contains("- opening the series for playback: "), "{md}");
    assert!(md.contains("with the settings taken from the data"), "{md}");
    assert!(md.contains("copying the step's bytes in memory"), "{md}");
    assert!(md.contains("Peak resident memory"), "{md}");

    // The results are there: not overwritten without --force, then a sub-range with it.
    let again = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(again.contains("playback"), "{again}");
    let args = play(&["--steps", "1..3", "--force"]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let csv = std::fs::read_to_string(out.join("playback.csv")).unwrap();
    let played: std::collections::BTreeSet<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert_eq!(played.into_iter().collect::<Vec<_>>(), ["1", "2"]);

    let args = play(&["--steps", "2..9", "--force"]);
    let err = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(err.contains("2..9") && err.contains("3 steps"), "{err}");
}

/// `--backend auto` (the default) opens no GPU device where every adapter is a CPU (lavapipe,
/// llvmpipe: this project's machines): opening one loads its compiler into the process for
/// nothing (about 40 MB more a process on lavapipe, kept after the backend is dropped). Where
/// a GPU adapter is found, auto opens a GPU backend.
#[test]
fn auto_opens_no_device_where_every_adapter_is_software() {
    let dir = tempfile::tempdir().unwrap();
    let header = crate::common::generated_dam_break(dir.path());
    let out = crate::common::aarbf_logged(&[
        "render",
        "--data",
        &header,
        "--width",
        "16",
        "--height",
        "16",
        "--out",
        dir.path().join("a.png").to_str().unwrap(),
    ]);
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    let software = aarbf::backend::wgpu_lbvh::adapters_to_choose_from()
        .iter()
        .all(|a| a.info.device_type == wgpu::DeviceType::Cpu);
    if software {
        assert!(log.contains("auto: no GPU adapter"), "{log}");
        // The ash context says its device when it opens one; wgpu's skip names it.
        assert!(
            !log.contains("ash backend:") && !log.contains("skipping"),
            "{log}"
        );
        // Nor does listing them wake the GL driver where Vulkan answers (its EGL errors
        // on a machine without a display).
        assert!(!log.contains("EGL"), "{log}");
    } else {
        assert!(!log.contains("auto: no GPU adapter"), "{log}");
    }
}
