//! SPH-normalised kernels (`--kernel sph-*`) as a user runs them, on data written as SPH codes
//! write it (CSV with 17 digits; an HDF5 snapshot h5py wrote), on every backend: a single
//! particle against hand-derived values, a uniform lattice reproducing its density, the
//! backends agreeing, and bad input refused with a message that names it.

use crate::common;

use std::f64::consts::PI;
use std::ffi::OsString;
use std::path::Path;

use common::{aarbf_field, write_numpy};

const KERNELS: [&str; 4] = [
    "sph-cubic",
    "sph-quintic",
    "sph-wendland-c2",
    "sph-wendland-c4",
];
const BACKENDS: [&str; 3] = ["cpu", "wgpu", "ash"];

/// A kernel's support in h and `W(d, h) h³` at q = d/h, derived by hand from the published
/// forms (Monaghan 1992; Dehnen & Aly 2012 with H = 2h; Price 2012's normalisations), written
/// here apart from the crate's definition.
fn by_hand(kernel: &str, q: f64) -> (f64, f64) {
    let p = |x: f64| x.max(0.0);
    match kernel {
        "sph-cubic" => (2.0, (0.25 * p(2.0 - q).powi(3) - p(1.0 - q).powi(3)) / PI),
        "sph-quintic" => (
            3.0,
            (p(3.0 - q).powi(5) - 6.0 * p(2.0 - q).powi(5) + 15.0 * p(1.0 - q).powi(5))
                / (120.0 * PI),
        ),
        "sph-wendland-c2" => (
            2.0,
            21.0 / (16.0 * PI) * p(1.0 - q / 2.0).powi(4) * (1.0 + 2.0 * q),
        ),
        "sph-wendland-c4" => (
            2.0,
            495.0 / (256.0 * PI) * p(1.0 - q / 2.0).powi(6) * (1.0 + 3.0 * q + 35.0 / 12.0 * q * q),
        ),
        _ => unreachable!(),
    }
}

fn args(v: &[&str]) -> Vec<OsString> {
    v.iter().map(OsString::from).collect()
}

fn queries(dir: &Path, name: &str, points: &[[f64; 3]]) -> OsString {
    let path = dir.join(name);
    let flat: Vec<f64> = points.iter().flatten().copied().collect();
    write_numpy(&path, points.len(), 3, &flat);
    path.into_os_string()
}

/// One particle, off the origin, with its own h, mass and density: Phi at its centre, at h,
/// just inside and just outside its support is `m/ρ W(q) / h³` as derived by hand (relative
/// 1e-12 on the CPU, which computes in f64; the GPUs within 1e-5 of the peak), and 0 beyond.
#[test]
fn a_single_particle_gives_the_hand_derived_values() {
    let dir = tempfile::tempdir().unwrap();
    let (c, h, m, rho) = ([1.2345678901234567, -0.5, 2.5], 0.3, 0.7, 2.0);
    let data = dir.path().join("one.csv");
    std::fs::write(
        &data,
        format!(
            "x,y,z,h,mass,density,s\n{:.17e},{:.17e},{:.17e},{h:.17e},{m:.17e},{rho:.17e},5.0\n",
            c[0], c[1], c[2]
        ),
    )
    .unwrap();
    for kernel in KERNELS {
        let (support, _) = by_hand(kernel, 0.0);
        let unit = [1.0, 2.0, -2.0].map(|v: f64| v / 3.0);
        let at = |q: f64| [0, 1, 2].map(|a| c[a] + unit[a] * q * h);
        let qs = [0.0, 1.0, 0.999 * support, 1.001 * support];
        let points: Vec<[f64; 3]> = qs.iter().map(|&q| at(q)).collect();
        let query = queries(dir.path(), &format!("{kernel}.npy"), &points);
        let peak = m / rho * by_hand(kernel, 0.0).1 / h.powi(3);
        for backend in BACKENDS {
            let mut a = args(&["--data"]);
            a.push(data.clone().into_os_string());
            a.extend(args(&["--kernel", kernel, "--attribute", "s", "--queries"]));
            a.push(query.clone());
            let out = dir.path().join(format!("{kernel}-{backend}.npy"));
            let (got, log) = aarbf_field(&a, backend, &out);
            for (&q, [phi, theta]) in qs.iter().zip(&got) {
                let want = m / rho * by_hand(kernel, q).1 / h.powi(3);
                let tolerance = if backend == "cpu" {
                    1e-12 * want.max(1e-300)
                } else {
                    1e-5 * peak
                };
                assert!(
                    (phi - want).abs() <= tolerance,
                    "{kernel} {backend} q {q}: Phi {phi:e}, by hand {want:e}\n{log}"
                );
                if want > 0.0 {
                    assert!(
                        (theta - 5.0).abs() < 1e-5,
                        "{kernel} {backend}: Theta {theta}"
                    );
                }
            }
            assert_eq!(got[3][0], 0.0, "{kernel} {backend}: beyond the support");
        }
    }
}

/// A uniform lattice (20 x 21 x 19 particles, spacing 0.037, off the origin; m = ρ0 Δ³, h = 2Δ,
/// as an SPH code's initial conditions) reproduces its density to 1e-3 away from its edges,
/// for every kernel on every backend: `--density 1` makes Phi the SPH density `Σ m W`; with the
/// data's densities Phi is `Σ m/ρ W`, 1; and the GPUs agree with the CPU's f64 to 1e-5.
#[test]
fn a_uniform_lattice_reproduces_its_density() {
    let dir = tempfile::tempdir().unwrap();
    let (d, rho0) = (0.037, 1000.0);
    let (m, h) = (rho0 * d * d * d, 2.0 * d);
    let o = [3.1, -2.7, 0.55];
    let mut csv = String::from("x,y,z,m,rho,h\n");
    for i in 0..20 {
        for j in 0..21 {
            for k in 0..19 {
                let p = [
                    o[0] + i as f64 * d,
                    o[1] + j as f64 * d,
                    o[2] + k as f64 * d,
                ];
                csv += &format!(
                    "{:.17e},{:.17e},{:.17e},{m:.17e},{rho0:.17e},{h:.17e}\n",
                    p[0], p[1], p[2]
                );
            }
        }
    }
    let data = dir.path().join("lattice.csv");
    std::fs::write(&data, csv).unwrap();
    // Points at least 3h (the quintic's support) inside every face.
    let mut rng = 12345u64;
    let mut uniform = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let points: Vec<[f64; 3]> = (0..37)
        .map(|_| {
            [
                o[0] + (6.0 + 7.0 * uniform()) * d,
                o[1] + (6.0 + 8.0 * uniform()) * d,
                o[2] + (6.0 + 6.0 * uniform()) * d,
            ]
        })
        .collect();
    let query = queries(dir.path(), "points.npy", &points);
    for kernel in KERNELS {
        for (density, want) in [("1", rho0), ("rho", 1.0)] {
            let mut cpu: Option<Vec<[f64; 2]>> = None;
            for backend in BACKENDS {
                let mut a = args(&["--data"]);
                a.push(data.clone().into_os_string());
                a.extend(args(&[
                    "--kernel",
                    kernel,
                    "--density",
                    density,
                    "--attribute",
                    "rho",
                    "--queries",
                ]));
                a.push(query.clone());
                let out = dir.path().join(format!("{kernel}-{density}-{backend}.npy"));
                let (got, log) = aarbf_field(&a, backend, &out);
                for [phi, _] in &got {
                    assert!(
                        (phi / want - 1.0).abs() < 1e-3,
                        "{kernel} --density {density} {backend}: Phi {phi}, not {want}\n{log}"
                    );
                }
                match &cpu {
                    None => cpu = Some(got),
                    Some(reference) => {
                        for (g, r) in got.iter().zip(reference) {
                            assert!(
                                (g[0] / r[0] - 1.0).abs() < 1e-5,
                                "{kernel} {backend}: {} against the CPU's {}",
                                g[0],
                                r[0]
                            );
                        }
                    }
                }
            }
        }
    }
}

/// What an SPH kernel needs and cannot find, or finds wrong, is said with the file's names and
/// the flag that gives it; the baselines that splat the paper's Gaussian refuse an SPH kernel.
#[test]
fn missing_or_bad_masses_and_densities_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let run = |csv: &str, extra: &[&str]| -> String {
        let data = dir.path().join("d.csv");
        std::fs::write(&data, csv).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .arg("render")
            .arg("--data")
            .arg(&data)
            .args([
                "--kernel",
                "sph-cubic",
                "--width",
                "16",
                "--height",
                "16",
                "--force",
            ])
            .args(extra)
            .arg("--out")
            .arg(dir.path().join("o.png"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{csv} {extra:?} was accepted");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = run("x,y,z,h,m\n0,0,0,0.5,1\n1,0,0,0.5,1\n", &[]);
    assert!(e.contains("no densities") && e.contains("h, m"), "{e}");
    assert!(e.contains("--density"), "{e}");
    let e = run("x,y,z,m,rho\n0,0,0,1,1\n1,0,0,1,1\n", &[]);
    assert!(
        e.contains("smoothing length") && e.contains("--smoothing knn:32"),
        "{e}"
    );
    let e = run(
        "x,y,z,h,m,rho\n0,0,0,0.5,1,1\n1,0,0,0.5,1,0\n0,1,0,0.5,1,2\n",
        &[],
    );
    assert!(
        e.contains("'rho'") && e.contains("holds 0 for particle 1") && e.contains("> 0"),
        "{e}"
    );
    let e = run(
        "x,y,z,h,m,rho\n0,0,0,0.5,1,1\n1,0,0,0.5,1,1\n",
        &["--method", "voxel"],
    );
    assert!(e.contains("--method rbf"), "{e}");
}

/// The acceptance command on an HDF5 snapshot h5py wrote (SWIFT's layout): the SPH kernel
/// finds SWIFT's smoothing lengths, masses and densities by their names and renders, on every
/// backend, the same picture to a few 8-bit steps.
#[test]
fn a_swift_snapshot_renders_with_an_sph_kernel() {
    let dir = tempfile::tempdir().unwrap();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/h5py_swift");
    let mut images = Vec::new();
    for backend in BACKENDS {
        let out = dir.path().join(format!("{backend}.png"));
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .arg("render")
            .arg("--data")
            .arg(&data)
            .args(["--particle-type", "gas", "--attribute", "Temperatures"])
            .args(["--kernel", "sph-cubic", "--width", "64", "--height", "48"])
            .args(["--no-legend", "--backend", backend, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let log = String::from_utf8_lossy(&run.stderr).into_owned();
        assert!(run.status.success(), "{backend}: {log}");
        assert!(log.contains("smoothing length 'SmoothingLengths'"), "{log}");
        assert!(log.contains("masses 'Masses'") && log.contains("densities 'Densities'"));
        let img = image::open(&out).unwrap().to_rgba8();
        assert!(
            img.pixels().any(|p| p.0[..3] != [0, 0, 0]),
            "{backend}: empty"
        );
        images.push(img);
    }
    for img in &images[1..] {
        let worst = img
            .pixels()
            .zip(images[0].pixels())
            .flat_map(|(a, b)| (0..3).map(move |c| (i16::from(a.0[c]) - i16::from(b.0[c])).abs()))
            .max()
            .unwrap();
        assert!(worst <= 4, "backends differ by {worst} 8-bit steps");
    }
}
