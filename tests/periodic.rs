//! Periodic boxes as a cosmologist meets them: `aarbf field` on data written as codes write it
//! (CSV with 17 significant digits, a SWIFT-like HDF5 snapshot in f64 with its `BoxSize` and
//! `InitialConditions:periodic`), against an oracle computed here in f64 by brute force over
//! every particle and its 26 periodic images, owing nothing to the code under test. The box is
//! not a cube and the particle count not a power of two; some particles lie slightly outside
//! the box, as codes write them.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common;

/// The box [0, L) of the generated scenes: no two sides equal.
const L: [f64; 3] = [3.7, 2.9, 4.3];
/// The global radius; each particle's radius is R h, h in [0.5, 1.5).
const R: f64 = 0.6;

struct Scene {
    positions: Vec<DVec3>,
    h: Vec<f64>,
    s: Vec<f64>,
}

/// `n` particles: most uniform in the box, a third within reach of a face (so of an edge or
/// a corner too), a few just outside the box (within a thousandth of its side).
fn scene(n: usize, seed: u64) -> Scene {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let size = DVec3::from_array(L);
    let positions = (0..n)
        .map(|i| {
            let mut p = DVec3::new(rng.random(), rng.random(), rng.random()) * size;
            if i % 3 == 0 {
                // Near one or more faces.
                for a in 0..3 {
                    if rng.random_bool(0.6) {
                        let d = rng.random_range(0.0..0.8);
                        p[a] = if rng.random_bool(0.5) { d } else { L[a] - d };
                    }
                }
            }
            if i % 37 == 5 {
                // Written slightly outside the box.
                let a = i % 3;
                p[a] = if i % 2 == 0 {
                    -1e-3 * rng.random::<f64>()
                } else {
                    L[a] + 1e-3 * rng.random::<f64>()
                };
            }
            p
        })
        .collect();
    let h = (0..n).map(|_| rng.random_range(0.5..1.5)).collect();
    let s = (0..n)
        .map(|_| 10f64.powf(rng.random_range(-2.0..3.0)))
        .collect();
    Scene { positions, h, s }
}

/// The oracle: (Phi, Theta) at `q` as the sum over every particle wrapped into the box and its
/// 26 images (`periodic`), or over the particles as given (open box).
fn oracle(scene: &Scene, q: DVec3, periodic: bool) -> [f64; 2] {
    let size = DVec3::from_array(L);
    let (mut phi, mut num) = (0.0, 0.0);
    for (i, &c) in scene.positions.iter().enumerate() {
        let r = R * scene.h[i];
        let shifts: Vec<DVec3> = if periodic {
            let mut v = Vec::new();
            for x in -1..=1 {
                for y in -1..=1 {
                    for z in -1..=1 {
                        v.push(DVec3::new(x as f64, y as f64, z as f64) * size);
                    }
                }
            }
            v
        } else {
            vec![DVec3::ZERO]
        };
        let c = if periodic {
            let mut w = c - size * (c / size).floor();
            for a in 0..3 {
                if w[a] >= L[a] {
                    w[a] = 0.0;
                }
            }
            w
        } else {
            c
        };
        for shift in shifts {
            let d = common::exact_d2(q, c + shift).sqrt();
            if d <= r {
                let w = (-0.5 * (3.0 * d / r).powi(2)).exp();
                phi += w;
                num += w * scene.s[i];
            }
        }
    }
    [phi, if phi > 0.0 { num / phi } else { 0.0 }]
}

/// Queries near every face, edge and corner (within 1e-9 of a face, and a little inside),
/// and anywhere in the box.
fn queries(count: usize, seed: u64) -> Vec<DVec3> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let size = DVec3::from_array(L);
    (0..count)
        .map(|i| {
            let mut q = DVec3::new(rng.random(), rng.random(), rng.random()) * size;
            if i % 4 != 3 {
                for a in 0..3 {
                    if a == i % 3 || rng.random_bool(0.3) {
                        let d = [1e-9, 1e-4, 0.05, 0.3][rng.random_range(0..4)];
                        q[a] = if rng.random_bool(0.5) { d } else { L[a] - d };
                    }
                }
            }
            q
        })
        .collect()
}

/// The scene as a CSV file with 17 significant digits, as NumPy's `savetxt('%.17g')` writes.
fn write_csv(scene: &Scene, path: &Path) {
    let mut text = String::from("x,y,z,h,s\n");
    for (i, p) in scene.positions.iter().enumerate() {
        text.push_str(&format!(
            "{:.17e},{:.17e},{:.17e},{:.17e},{:.17e}\n",
            p.x, p.y, p.z, scene.h[i], scene.s[i]
        ));
    }
    std::fs::write(path, text).unwrap();
}

fn write_queries(queries: &[DVec3], path: &Path) {
    let flat: Vec<f64> = queries.iter().flat_map(|q| q.to_array()).collect();
    common::write_numpy(path, queries.len(), 3, &flat);
}

fn args(data: &Path, queries: &Path, extra: &[&str]) -> Vec<OsString> {
    let mut a: Vec<OsString> = vec![
        "--data".into(),
        data.into(),
        "--queries".into(),
        queries.into(),
        "--attribute".into(),
        "s".into(),
        "--radius-attribute".into(),
        "h".into(),
        "--radius".into(),
        R.to_string().into(),
    ];
    a.extend(extra.iter().map(OsString::from));
    a
}

/// Relative differences of Phi and Theta against the oracle, where the oracle's Phi is not 0
/// (where it is, both must be 0).
fn worst(got: &[[f64; 2]], want: &[[f64; 2]]) -> (f64, f64) {
    let (mut phi, mut theta) = (0.0f64, 0.0f64);
    for (g, w) in got.iter().zip(want) {
        if w[0] == 0.0 {
            assert_eq!(g[0], 0.0, "Phi where no particle reaches");
            continue;
        }
        phi = phi.max((g[0] - w[0]).abs() / w[0]);
        theta = theta.max((g[1] - w[1]).abs() / w[1].abs());
    }
    (phi, theta)
}

struct Fixture {
    _dir: tempfile::TempDir,
    data: PathBuf,
    queries: PathBuf,
    out: PathBuf,
    scene: Scene,
    points: Vec<DVec3>,
}

fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene(1237, 46);
    let data = dir.path().join("box.csv");
    write_csv(&scene, &data);
    let points = queries(403, 47);
    let queries = dir.path().join("queries.npy");
    write_queries(&points, &queries);
    Fixture {
        out: dir.path().join("out.npy"),
        _dir: dir,
        data,
        queries,
        scene,
        points,
    }
}

const BOX: &str = "3.7,2.9,4.3";

#[test]
fn field_near_faces_is_the_sum_over_every_periodic_image() {
    let f = fixture();
    let periodic: Vec<[f64; 2]> = f
        .points
        .iter()
        .map(|&q| oracle(&f.scene, q, true))
        .collect();
    let open: Vec<[f64; 2]> = f
        .points
        .iter()
        .map(|&q| oracle(&f.scene, q, false))
        .collect();
    // The test means something: at many queries the images change the field.
    let changed = periodic
        .iter()
        .zip(&open)
        .filter(|(p, o)| (p[0] - o[0]).abs() > 0.05 * p[0])
        .count();
    assert!(changed > 100, "only {changed} queries feel an image");

    let (got, log) = common::aarbf_field(
        &args(
            &f.data,
            &f.queries,
            &["--periodic", BOX, "--precision", "f64"],
        ),
        "cpu",
        &f.out,
    );
    assert!(log.contains("periodic box"), "{log}");
    let (phi, theta) = worst(&got, &periodic);
    assert!(
        phi <= 1e-12 && theta <= 1e-12,
        "Phi {phi:.2e}, Theta {theta:.2e}"
    );

    // Without --periodic, the open box's field, which the oracle of the open box also gives.
    let (got, _) = common::aarbf_field(&args(&f.data, &f.queries, &[]), "cpu", &f.out);
    let (phi, theta) = worst(&got, &open);
    assert!(
        phi <= 1e-12 && theta <= 1e-12,
        "open: Phi {phi:.2e}, Theta {theta:.2e}"
    );
}

#[test]
fn no_seam_at_the_faces() {
    let f = fixture();
    // Pairs of points either side of a face: x = eps and x = L - eps (and the same in y, z).
    let eps = 1e-7;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
    let mut points = Vec::new();
    for k in 0..90 {
        let a = k % 3;
        let mut q = DVec3::new(rng.random(), rng.random(), rng.random()) * DVec3::from_array(L);
        q[a] = eps;
        points.push(q);
        q[a] = L[a] - eps;
        points.push(q);
    }
    let dir = tempfile::tempdir().unwrap();
    let queries = dir.path().join("pairs.npy");
    write_queries(&points, &queries);
    let jump = |got: &[[f64; 2]]| {
        got.chunks(2)
            .filter(|p| p[0][0].max(p[1][0]) > 0.0)
            .map(|p| (p[0][0] - p[1][0]).abs() / p[0][0].max(p[1][0]))
            .fold(0.0f64, f64::max)
    };
    let (got, _) = common::aarbf_field(
        &args(&f.data, &queries, &["--periodic", BOX]),
        "cpu",
        &f.out,
    );
    assert!(got.iter().filter(|g| g[0] > 0.0).count() > 150);
    let seam = jump(&got);
    // The field's gradient times 2 eps: far below 1e-4 of the field.
    assert!(
        seam < 1e-4,
        "periodic field jumps by {seam:.2e} across a face"
    );
    let (open, _) = common::aarbf_field(&args(&f.data, &queries, &[]), "cpu", &f.out);
    assert!(
        jump(&open) > 0.5,
        "the open box has a seam: this test must see it"
    );
}

#[test]
fn every_backend_gives_the_periodic_field() {
    let f = fixture();
    let periodic: Vec<[f64; 2]> = f
        .points
        .iter()
        .map(|&q| oracle(&f.scene, q, true))
        .collect();
    for backend in ["cpu", "wgpu", "ash"] {
        let (got, log) = common::aarbf_field(
            &args(&f.data, &f.queries, &["--periodic", BOX]),
            backend,
            &f.out,
        );
        let (phi, theta) = worst(&got, &periodic);
        // The precision promise of `--precision auto` (1e-5), plus a particle's jump where a
        // query lies on its radius to within f32 rounding (none here, so none allowed).
        assert!(
            phi <= 1e-5 && theta <= 1e-5,
            "{backend}: Phi {phi:.2e}, Theta {theta:.2e}\n{log}"
        );
    }
}

#[test]
fn bad_boxes_and_radii_are_clear_errors() {
    let f = fixture();
    let run = |extra: &[&str]| {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .arg("field")
            .args(args(&f.data, &f.queries, extra))
            .args(["--force", "--out"])
            .arg(&f.out)
            .output()
            .unwrap();
        assert!(!output.status.success(), "{extra:?} must fail");
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    for bad in ["0", "-3.7,2.9,4.3", "3.7,inf,4.3", "3.7,2.9", "nan"] {
        let e = run(&[&format!("--periodic={bad}")]);
        assert!(
            e.contains("box size") || e.contains("positive finite"),
            "--periodic {bad}: {e}"
        );
    }
    // Radii up to 0.6 x 1.5 = 0.9: more than half of a box of side 1.7.
    let e = run(&["--periodic", "3.7,1.7,4.3"]);
    assert!(
        e.contains("half the box") && e.contains("y side is 1.7") && e.contains("--no-periodic"),
        "{e}"
    );
    // --periodic alone needs a header with the box.
    let e = run(&["--periodic"]);
    assert!(e.contains("BoxSize") && e.contains("--periodic L"), "{e}");
    // The input is never modified: the CSV still has the particles outside the box.
    let text = std::fs::read_to_string(&f.data).unwrap();
    assert!(text.contains(",-") || text.lines().any(|l| l.starts_with('-')));
}

/// A SWIFT-like snapshot as SWIFT writes it (f64 `Coordinates`, `SmoothingLengths`, a
/// `BoxSize` 3-vector, its used parameters as text in `/Parameters`), of `scene`.
#[cfg(feature = "hdf5")]
fn write_swift(scene: &Scene, path: &Path, periodic: Option<&str>, box_size: [f64; 3]) {
    use hdf5::types::VarLenUnicode;
    let f = hdf5::File::create(path).unwrap();
    let n = scene.positions.len() as u64;
    let h = f.create_group("Header").unwrap();
    let attr = |loc: &hdf5::Location, name: &str, v: &[f64]| {
        loc.new_attr::<f64>()
            .shape([v.len()])
            .create(name)
            .unwrap()
            .write_raw(v)
            .unwrap();
    };
    let text = |loc: &hdf5::Location, name: &str, v: &str| {
        let v: VarLenUnicode = v.parse().unwrap();
        loc.new_attr::<VarLenUnicode>()
            .create(name)
            .unwrap()
            .write_scalar(&v)
            .unwrap();
    };
    h.new_attr::<u64>()
        .shape([7])
        .create("NumPart_ThisFile")
        .unwrap()
        .write_raw(&[n, 0, 0, 0, 0, 0, 0])
        .unwrap();
    h.new_attr::<u64>()
        .shape([7])
        .create("NumPart_Total")
        .unwrap()
        .write_raw(&[n, 0, 0, 0, 0, 0, 0])
        .unwrap();
    attr(&h, "BoxSize", &box_size);
    attr(&h, "Time", &[1.0]);
    text(&h, "Code", "SWIFT");
    if let Some(flag) = periodic {
        let p = f.create_group("Parameters").unwrap();
        text(&p, "InitialConditions:periodic", flag);
        text(&p, "InitialConditions:file_name", "ics.hdf5");
    }
    let g = f.create_group("PartType0").unwrap();
    let coords: Vec<f64> = scene.positions.iter().flat_map(|p| p.to_array()).collect();
    g.new_dataset::<f64>()
        .shape([scene.positions.len(), 3])
        .chunk([100, 3])
        .shuffle()
        .deflate(4)
        .create("Coordinates")
        .unwrap()
        .write_raw(&coords)
        .unwrap();
    for (name, values) in [("SmoothingLengths", &scene.h), ("Densities", &scene.s)] {
        g.new_dataset::<f64>()
            .shape([values.len()])
            .create(name)
            .unwrap()
            .write_raw(values)
            .unwrap();
    }
}

#[cfg(feature = "hdf5")]
fn snapshot_args(data: &Path, queries: &Path, extra: &[&str]) -> Vec<OsString> {
    let mut a: Vec<OsString> = vec![
        "--data".into(),
        data.into(),
        "--queries".into(),
        queries.into(),
        "--attribute".into(),
        "Densities".into(),
        "--radius-attribute".into(),
        "SmoothingLengths".into(),
        "--radius".into(),
        R.to_string().into(),
    ];
    a.extend(extra.iter().map(OsString::from));
    a
}

#[cfg(feature = "hdf5")]
#[test]
fn a_swift_snapshot_is_periodic_by_default_and_no_periodic_opens_it() {
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let periodic: Vec<[f64; 2]> = f
        .points
        .iter()
        .map(|&q| oracle(&f.scene, q, true))
        .collect();
    let open: Vec<[f64; 2]> = f
        .points
        .iter()
        .map(|&q| oracle(&f.scene, q, false))
        .collect();
    let snap = dir.path().join("snap_0000.hdf5");
    write_swift(&f.scene, &snap, Some("1"), L);
    let (got, log) = common::aarbf_field(&snapshot_args(&snap, &f.queries, &[]), "cpu", &f.out);
    assert!(
        log.contains("periodic box") && log.contains("InitialConditions:periodic"),
        "{log}"
    );
    let (phi, theta) = worst(&got, &periodic);
    assert!(
        phi <= 1e-12 && theta <= 1e-12,
        "Phi {phi:.2e}, Theta {theta:.2e}"
    );
    let (got, _) = common::aarbf_field(
        &snapshot_args(&snap, &f.queries, &["--no-periodic"]),
        "cpu",
        &f.out,
    );
    let (phi, theta) = worst(&got, &open);
    assert!(
        phi <= 1e-12 && theta <= 1e-12,
        "--no-periodic: Phi {phi:.2e}, Theta {theta:.2e}"
    );

    // `aarbf info` says so.
    let info = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .arg("info")
        .arg(&snap)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        text.contains("box size:     3.7 x 2.9 x 4.3")
            && text.contains("periodic:     yes (/Parameters InitialConditions:periodic"),
        "{text}"
    );

    // A run SWIFT says is not periodic is an open box, unless --periodic asks.
    let closed = dir.path().join("closed_0000.hdf5");
    write_swift(&f.scene, &closed, Some("0"), L);
    let (got, _) = common::aarbf_field(&snapshot_args(&closed, &f.queries, &[]), "cpu", &f.out);
    assert!(worst(&got, &open).0 <= 1e-12);
    let (got, _) = common::aarbf_field(
        &snapshot_args(&closed, &f.queries, &["--periodic"]),
        "cpu",
        &f.out,
    );
    assert!(worst(&got, &periodic).0 <= 1e-12);

    // A GADGET-style file with no flag: BoxSize makes it periodic.
    let gadget = dir.path().join("gadget_000.hdf5");
    write_swift(&f.scene, &gadget, None, L);
    let (got, log) = common::aarbf_field(&snapshot_args(&gadget, &f.queries, &[]), "cpu", &f.out);
    assert!(log.contains("GADGET-family"), "{log}");
    assert!(worst(&got, &periodic).0 <= 1e-12);

    // A header whose box the particles lie well outside is not the data's box: the field is
    // not wrapped, and the warning says so and how to force it.
    let small = dir.path().join("small_0000.hdf5");
    write_swift(&f.scene, &small, Some("1"), [2.0, 2.9, 4.3]);
    let (got, log) = common::aarbf_field(&snapshot_args(&small, &f.queries, &[]), "cpu", &f.out);
    assert!(
        log.contains("well outside it: the field is not wrapped") && log.contains("--periodic"),
        "{log}"
    );
    assert!(worst(&got, &open).0 <= 1e-12);

    // A header box of side 0 with --periodic: the error names it.
    let flat = dir.path().join("flat_0000.hdf5");
    write_swift(&f.scene, &flat, Some("1"), [3.7, 0.0, 4.3]);
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .arg("field")
        .args(snapshot_args(&flat, &f.queries, &["--periodic"]))
        .args(["--force", "--out"])
        .arg(&f.out)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && e.contains("positive finite") && e.contains("BoxSize"),
        "{e}"
    );
}

/// `aarbf slice` of a periodic box: the pixels either side of a face (the image's first and
/// last columns, one pixel apart across the face) match, and the edges are as bright as the
/// middle; the open box's slice fades at its faces, which this test must see.
#[test]
fn a_slice_of_a_periodic_box_has_no_seam() {
    let f = fixture();
    let slice = |extra: &[&str]| {
        let out = f.out.with_extension("png");
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .arg("slice")
            .arg("--data")
            .arg(&f.data)
            .args([
                "--attribute",
                "s",
                "--radius",
                "0.3",
                "--axis",
                "y",
                "--width",
                "370",
            ])
            .args(["--no-legend", "--force", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        image::open(&out).unwrap().to_luma8()
    };
    let column = |image: &image::GrayImage, x: u32| -> Vec<f64> {
        (0..image.height())
            .map(|y| f64::from(image.get_pixel(x, y).0[0]))
            .collect()
    };
    let seam = |image: &image::GrayImage| {
        let (a, b) = (column(image, 0), column(image, image.width() - 1));
        a.iter().zip(&b).map(|(a, b)| (a - b).abs()).sum::<f64>() / a.len() as f64
    };
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    let periodic = slice(&["--periodic", BOX]);
    // The box's x side over the width: the slice spans the box, not the data's bounds.
    assert_eq!(periodic.dimensions(), (370, 430));
    let open = slice(&[]);
    let (s_periodic, s_open) = (seam(&periodic), seam(&open));
    assert!(
        s_periodic < 3.0 && s_open > 4.0 * s_periodic,
        "mean difference across the x faces: periodic {s_periodic:.2}, open {s_open:.2}"
    );
    let (edge, middle) = (mean(column(&periodic, 0)), mean(column(&periodic, 185)));
    assert!(edge > 0.8 * middle, "edge {edge:.1}, middle {middle:.1}");
    let open_edge = mean(column(&open, 0));
    assert!(
        open_edge < 0.8 * edge,
        "open edge {open_edge:.1} vs {edge:.1}"
    );
}
