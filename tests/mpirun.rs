//! `mpirun -np N aarbf render` with a build that has the `mpi` feature (`cargo xtask test` runs
//! these last, building it): the ranks as MPI processes render the very image the same number
//! of ranks as threads (`--ranks N`) renders, bit for bit, and so the single-rank image within
//! the distributed tolerances (tests/distributed.rs); only rank 0 writes; a rank that dies ends
//! the job with a failure within 30 s.
#![cfg(feature = "mpi")]

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;
use std::time::{Duration, Instant};

/// `mpirun -np ranks aarbf args`, as root where the tests run as root, more ranks than cores,
/// shared memory between the ranks.
fn mpirun(ranks: usize, args: &[String]) -> Command {
    let mut cmd = Command::new("mpirun");
    cmd.args(["--oversubscribe", "--mca", "btl", "self,vader", "-np"])
        .arg(ranks.to_string())
        .arg(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        // Containers often forbid the cross-process memory attach Open MPI tries first.
        .env("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
        .env("AARBF_LOG", "info");
    cmd
}

fn pixels(path: &Path) -> Vec<f32> {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgba32f()
        .into_raw()
}

#[test]
fn mpi_processes_render_the_image_of_as_many_threads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let single_path = d.join("single.exr");
    let single = common::aarbf_logged(
        &common::dam_break_render_args(&header, &single_path, (64, 48), 2)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(
        single.status.success(),
        "{}",
        String::from_utf8_lossy(&single.stderr)
    );
    let single = pixels(&single_path);
    assert!(single.iter().any(|&v| v > 0.05), "the fluid shows");
    for ranks in 1..=4 {
        let threads_path = d.join(format!("threads-{ranks}.exr"));
        let mut args = common::dam_break_render_args(&header, &threads_path, (64, 48), 2);
        args.extend(["--ranks".into(), ranks.to_string()]);
        let threads = common::aarbf_logged(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(
            threads.status.success(),
            "{}",
            String::from_utf8_lossy(&threads.stderr)
        );

        let mpi_dir = d.join(format!("mpi-{ranks}"));
        std::fs::create_dir(&mpi_dir).unwrap();
        let mpi_path = mpi_dir.join("image.exr");
        let out = mpirun(
            ranks,
            &common::dam_break_render_args(&header, &mpi_path, (64, 48), 2),
        )
        .output()
        .expect("mpirun runs (cargo xtask setup --mpi installs Open MPI)");
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "mpirun -np {ranks}:\n{log}");
        for rank in 0..ranks {
            assert!(
                log.contains(&format!("rank {rank} of {ranks} MPI processes")),
                "rank {rank} of {ranks} did not say it ran:\n{log}"
            );
        }
        assert!(
            log.contains(&format!("rank {}: read", ranks - 1)) && log.contains("owned once each"),
            "rank 0 logs every rank's report:\n{log}"
        );
        // Rank 0 alone writes, and no temporary file is left behind.
        let written: Vec<PathBuf> = std::fs::read_dir(&mpi_dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(written, vec![mpi_path.clone()], "-np {ranks}");

        let mpi = pixels(&mpi_path);
        let threads = pixels(&threads_path);
        assert_eq!(mpi.len(), threads.len());
        let differing = mpi
            .iter()
            .zip(&threads)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differing, 0,
            "-np {ranks}: {differing} values differ from --ranks {ranks}"
        );
        let diff = mpi
            .iter()
            .zip(&single)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        // The default early termination is on: each brick stops at its threshold.
        assert!(
            diff <= 0.01,
            "-np {ranks} differs from the single-rank image by {diff}"
        );
    }
}

/// A SWIFT snapshot as h5py writes it (tests/data/h5py_swift: gas and dark matter, f64
/// coordinates, a periodic box in its header), rendered as a user would, with no data flags:
/// the periodic box renders under mpirun what the same ranks as threads render, bit for bit.
#[test]
fn an_hdf5_snapshot_renders_under_mpirun_as_with_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = common::swift_snapshot_copy(d);
    let args = |out: &Path| common::swift_render_args(&data, out);
    // The header's box is periodic: each rank wraps its particles and exchanges their images.
    let out = mpirun(2, &args(&d.join("mpi.exr"))).output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    assert!(log.contains("periodic box"), "{log}");
    let mut threads = args(&d.join("threads.exr"));
    threads.extend(["--ranks", "2"].map(String::from));
    let out = common::aarbf_logged(&threads.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (mpi, threads) = (pixels(&d.join("mpi.exr")), pixels(&d.join("threads.exr")));
    assert!(mpi.iter().any(|&v| v > 0.01), "the gas shows");
    assert!(
        mpi.iter()
            .zip(&threads)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "mpirun -np 2 differs from --ranks 2"
    );
}

/// Single scattering under mpirun: stochastic marching and delta tracking with shadows across
/// bricks by the light map render what the same ranks as threads render, bit for bit (the
/// scans and the light map are the same collectives over MPI).
#[test]
fn single_scattering_renders_under_mpirun_as_with_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    for integrator in ["marching", "delta"] {
        let args = |out: &Path| {
            let mut a = common::dam_break_render_args(&header, out, (64, 48), 2);
            a.extend(["--integrator", integrator].map(String::from));
            a
        };
        let mpi_path = d.join(format!("mpi-{integrator}.exr"));
        let out = mpirun(3, &args(&mpi_path)).output().unwrap();
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{integrator}:\n{log}");
        assert!(log.contains("light map"), "{log}");
        let threads_path = d.join(format!("threads-{integrator}.exr"));
        let mut threads = args(&threads_path);
        threads.extend(["--ranks", "3"].map(String::from));
        let out = common::aarbf_logged(&threads.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let (mpi, threads) = (pixels(&mpi_path), pixels(&threads_path));
        assert!(
            mpi.iter().any(|&v| v > 0.01),
            "{integrator}: the fluid shows"
        );
        assert!(
            mpi.iter()
                .zip(&threads)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{integrator}: mpirun -np 3 differs from --ranks 3"
        );
    }
}

/// The processes `root` started, and theirs.
fn descendants(root: u32) -> Vec<u32> {
    let mut parents: Vec<(u32, u32)> = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid ...: the command may hold spaces and parentheses.
        let Some(after) = stat.rfind(')').map(|i| &stat[i + 1..]) else {
            continue;
        };
        if let Some(ppid) = after.split_whitespace().nth(1).and_then(|p| p.parse().ok()) {
            parents.push((pid, ppid));
        }
    }
    let mut found = vec![root];
    let mut i = 0;
    while i < found.len() {
        let parent = found[i];
        found.extend(parents.iter().filter(|p| p.1 == parent).map(|p| p.0));
        i += 1;
    }
    found.remove(0);
    found
}

/// The MPI rank a process of the job is, from its environment.
fn rank_of(pid: u32) -> Option<usize> {
    let environ = std::fs::read(format!("/proc/{pid}/environ")).ok()?;
    environ
        .split(|&b| b == 0)
        .find_map(|var| var.strip_prefix(b"OMPI_COMM_WORLD_RANK="))
        .and_then(|v| std::str::from_utf8(v).ok()?.parse().ok())
}

#[test]
fn a_rank_that_dies_ends_the_job_with_a_failure() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let out_path = d.join("never.exr");
    // Long enough (several seconds a rank) that rank 1 is killed mid-render.
    let mut job = mpirun(
        3,
        &common::dam_break_render_args(&header, &out_path, (512, 512), 64),
    )
    .stdout(std::process::Stdio::null())
    .stderr(std::process::Stdio::piped())
    .spawn()
    .expect("mpirun starts");
    let started = Instant::now();
    let victim = loop {
        let ranks: Vec<(u32, usize)> = descendants(job.id())
            .into_iter()
            .filter_map(|pid| Some((pid, rank_of(pid)?)))
            .collect();
        if let Some(&(pid, _)) = ranks.iter().find(|r| r.1 == 1) {
            break pid;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "rank 1 never started"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    // Past MPI's start-up, into the render.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        job.try_wait().unwrap().is_none(),
        "the job ended before the fault: make its render longer"
    );
    let killed = Command::new("kill")
        .args(["-KILL", &victim.to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let killed_at = Instant::now();
    let status = loop {
        if let Some(status) = job.try_wait().unwrap() {
            break status;
        }
        if killed_at.elapsed() > Duration::from_secs(30) {
            let _ = job.kill();
            panic!("the job still ran 30 s after rank 1 died");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut log = String::new();
    std::io::Read::read_to_string(job.stderr.as_mut().unwrap(), &mut log).unwrap();
    assert!(
        !status.success(),
        "the job succeeded without rank 1:\n{log}"
    );
    assert!(!out_path.exists(), "an image was written without rank 1");
    eprintln!(
        "the job ended {:.1} s after rank 1 died ({status})",
        killed_at.elapsed().as_secs_f64()
    );
}

common::on_every_gpu!(gpu_processes_render_the_image_of_as_many_gpu_threads);

/// `mpirun -np 2 aarbf render --backend <gpu>`: each process renders its brick on its own
/// device (the first adapter; on a machine of one GPU, that one), and the image is the one two
/// ranks as threads sharing one device render (measured: bit for bit, see the message).
fn gpu_processes_render_the_image_of_as_many_gpu_threads(gpu: common::Gpu) {
    gpu.require();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let args = |path: &Path| {
        let mut args = common::dam_break_render_args(&header, path, (48, 40), 2);
        let at = args.iter().position(|a| a == "--backend").unwrap();
        args[at + 1] = gpu.to_string();
        let at = args.iter().position(|a| a == "--precision").unwrap();
        args[at + 1] = "f32".into();
        args.extend(["--integrator".into(), "marching".into()]);
        args
    };
    let threads_path = d.join("threads.exr");
    let mut threads_args = args(&threads_path);
    threads_args.extend(["--ranks".into(), "2".into()]);
    let threads =
        common::aarbf_logged(&threads_args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        threads.status.success(),
        "{}",
        String::from_utf8_lossy(&threads.stderr)
    );
    let mpi_dir = d.join("mpi");
    std::fs::create_dir(&mpi_dir).unwrap();
    let mpi_path = mpi_dir.join("image.exr");
    let out = mpirun(2, &args(&mpi_path))
        .output()
        .expect("mpirun runs (cargo xtask setup --mpi installs Open MPI)");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "mpirun -np 2:\n{log}");
    assert!(log.contains(&format!("{gpu} backend")), "{log}");
    let (a, b) = (pixels(&threads_path), pixels(&mpi_path));
    let diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    eprintln!("{gpu}: mpirun -np 2 against --ranks 2: max difference {diff:e}");
    assert!(a.iter().any(|&v| v > 0.05), "the fluid shows");
    assert_eq!(a, b, "max difference {diff:e}");
}

/// A SWIFT-like series of CSV steps (%.17g, steps of 500 to 511 rows) with no index beside it
/// and no flags but the image's: the MPI processes scan it and find its defaults (colour,
/// radius from the median smoothing length, cluster size) each from its parts, as the same
/// ranks as threads do, and render their image bit for bit; rank 0 alone writes the index.
#[test]
fn a_new_series_is_scanned_from_the_processes_parts() {
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs/swift_like");
    let copy = |dir: &Path| {
        for n in 0..4 {
            let name = format!("output_{n:04}.csv");
            std::fs::copy(runs.join(&name), dir.join(&name)).unwrap();
        }
        dir.join("output_*.csv")
    };
    let args = |data: &Path, out: &Path| -> Vec<String> {
        let mut a: Vec<String> = ["render", "--width", "64", "--height", "48", "--spp", "1"]
            .map(String::from)
            .to_vec();
        a.extend(["--data".into(), data.display().to_string()]);
        a.extend(["--out".into(), out.display().to_string()]);
        a
    };
    let (mpi_dir, threads_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mpi_out = mpi_dir.path().join("mpi.exr");
    let out = mpirun(3, &args(&copy(mpi_dir.path()), &mpi_out))
        .output()
        .unwrap();
    let mpi_log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{mpi_log}");
    assert!(
        mpi_log.contains("steps the series' index lacks, each rank its part of each"),
        "{mpi_log}"
    );
    let threads_out = threads_dir.path().join("threads.exr");
    let mut threads = args(&copy(threads_dir.path()), &threads_out);
    threads.extend(["--ranks", "3"].map(String::from));
    let out = common::aarbf_logged(&threads.iter().map(String::as_str).collect::<Vec<_>>());
    let threads_log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{threads_log}");
    let line = |log: &str, start: &str| {
        log.lines()
            .find_map(|l| l.split_once(start).map(|(_, rest)| rest.to_owned()))
            .unwrap_or_else(|| panic!("no '{start}' in {log}"))
    };
    for start in ["radius: ", "colour: ", "cluster size K = "] {
        assert_eq!(line(&mpi_log, start), line(&threads_log, start), "{start}");
    }
    let (mpi, threads) = (pixels(&mpi_out), pixels(&threads_out));
    assert!(mpi.iter().any(|&v| v > 0.01), "the gas shows");
    assert!(
        mpi.iter()
            .zip(&threads)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "mpirun -np 3 differs from --ranks 3"
    );
    // The index, written once (no other rank's temporary file left), serves a later open.
    let mut written: Vec<String> = std::fs::read_dir(mpi_dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with("output_"))
        .collect();
    written.sort();
    assert_eq!(written, [".aarbf-index.json", "mpi.exr"]);
    // Without AARBF_LOG, rank 0 alone says what every process resolved.
    let again = mpi_dir.path().join("again.exr");
    let out = mpirun(3, &args(&mpi_dir.path().join("output_*.csv"), &again))
        .env_remove("AARBF_LOG")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    assert_eq!(log.matches("radius: ").count(), 1, "{log}");
    assert_eq!(pixels(&again), mpi, "the same image from the index");
}

/// `--smoothing knn:16` on a GADGET-like NumPy series with no index or cache beside it: the MPI
/// processes find the lengths together from their parts, render the image of the same ranks
/// as threads bit for bit, and cache the same lengths.
#[test]
fn neighbour_smoothing_lengths_are_found_by_the_processes_together() {
    let runs = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs/gadget_like");
    let copy = |dir: &Path| {
        for n in 0..3 {
            let name = format!("snapshot_{n:03}.npy");
            std::fs::copy(runs.join(&name), dir.join(&name)).unwrap();
        }
        dir.join("snapshot_*.npy")
    };
    let args = |data: &Path, out: &Path| -> Vec<String> {
        let mut a: Vec<String> = [
            "render",
            "--width",
            "64",
            "--height",
            "48",
            "--spp",
            "1",
            "--smoothing",
            "knn:16",
        ]
        .map(String::from)
        .to_vec();
        a.extend(["--data".into(), data.display().to_string()]);
        a.extend(["--out".into(), out.display().to_string()]);
        a
    };
    let (mpi_dir, threads_dir) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mpi_out = mpi_dir.path().join("mpi.exr");
    let out = mpirun(3, &args(&copy(mpi_dir.path()), &mpi_out))
        .output()
        .unwrap();
    let mpi_log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{mpi_log}");
    // The steps scanned from the ranks' parts, their lengths with them.
    assert!(
        mpi_log.contains("steps the series' index lacks, each rank its part of each"),
        "{mpi_log}"
    );
    let threads_out = threads_dir.path().join("threads.exr");
    let mut threads = args(&copy(threads_dir.path()), &threads_out);
    threads.extend(["--ranks", "3"].map(String::from));
    let out = common::aarbf_logged(&threads.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (mpi, threads) = (pixels(&mpi_out), pixels(&threads_out));
    assert!(mpi.iter().any(|&v| v > 0.01), "the particles show");
    assert!(
        mpi.iter()
            .zip(&threads)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "mpirun -np 3 differs from --ranks 3"
    );
    let mpi_cache = common::cached_lengths(mpi_dir.path());
    assert_eq!(
        mpi_cache.len(),
        3,
        "one cache file a step, no partial file left"
    );
    assert_eq!(mpi_cache, common::cached_lengths(threads_dir.path()));
}

/// `mpirun -np 2 aarbf render --target-error`: every process runs the controller on the images
/// rank 0 composites and sends it, so they ask for the same chunks and none waits in a
/// collective the other skipped; rank 0 says the estimate once and writes an image within
/// twice the target of `--ranks 2`'s (the chunk sizes follow measured times, so the two may
/// differ in samples).
#[test]
fn mpi_processes_render_to_a_target_error_together() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let target = 0.002;
    let args = |out: &Path| -> Vec<String> {
        let mut a = common::dam_break_render_args(&header, out, (48, 36), 1);
        a.extend(
            [
                "--integrator",
                "marching",
                "--target-error",
                &target.to_string(),
            ]
            .map(String::from),
        );
        a
    };
    let mpi_out = d.join("mpi.exr");
    let started = Instant::now();
    let out = mpirun(2, &args(&mpi_out)).output().unwrap();
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{log}");
    assert!(started.elapsed() < Duration::from_secs(120), "{log}");
    assert_eq!(log.matches("estimated error").count(), 1, "{log}");
    assert!(log.contains("met") && !log.contains("NOT met"), "{log}");
    let threads_out = d.join("threads.exr");
    let mut threads = args(&threads_out);
    threads.extend(["--ranks", "2"].map(String::from));
    let out = common::aarbf_logged(&threads.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (pixels(&mpi_out), pixels(&threads_out));
    let (sum, n) = a
        .chunks_exact(4)
        .zip(b.chunks_exact(4))
        .flat_map(|(p, q)| (0..3).map(move |c| f64::from(p[c] - q[c]).powi(2)))
        .fold((0.0, 0usize), |(s, n), e| (s + e, n + 1));
    let rmse = (sum / n as f64).sqrt();
    assert!(
        rmse <= 2.0 * target,
        "RMSE {rmse} between mpirun and --ranks 2"
    );
}

/// `mpirun -np 3 aarbf render --reference`: the processes run the single process's search on
/// the images rank 0 composites, as three ranks as threads do, to the same image bit for bit;
/// rank 0 alone caches it, and a later job finds it there.
#[test]
fn mpi_processes_converge_the_reference_of_as_many_threads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let args = |out: &Path| -> Vec<String> {
        let mut a = common::dam_break_render_args(&header, out, (40, 30), 1);
        a.extend(["--reference", "--reference-tolerance", "0.004"].map(String::from));
        a
    };
    let mpi_out = d.join("mpi.exr");
    let out = mpirun(3, &args(&mpi_out))
        .env("XDG_CACHE_HOME", d.join("mpi-cache"))
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{log}");
    assert_eq!(log.matches("reference of step").count(), 1, "{log}");
    assert!(log.contains(", converged)"), "{log}");
    let cached: Vec<_> = std::fs::read_dir(d.join("mpi-cache/aarbf/references"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(cached.len(), 1, "one cache file: {cached:?}");

    let threads_out = d.join("threads.exr");
    let mut threads = args(&threads_out);
    threads.extend(["--ranks", "3"].map(String::from));
    let out = Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(&threads)
        .env("XDG_CACHE_HOME", d.join("threads-cache"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(pixels(&mpi_out), pixels(&threads_out));

    let again = d.join("again.exr");
    let out = mpirun(3, &args(&again))
        .env("XDG_CACHE_HOME", d.join("mpi-cache"))
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{log}");
    assert!(log.contains("reference from the cache"), "{log}");
    assert_eq!(pixels(&again), pixels(&mpi_out));
}
