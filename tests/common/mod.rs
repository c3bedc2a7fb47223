//! What the test files share: the GPU backends a test runs over (`gpu`); requiring a device
//! (a GPU test fails without one, never passes without running); capturing the validation
//! messages of wgpu, of the Vulkan layers it routes through `log` and of the ash backend's
//! messenger, so a test can fail on any of them; and, for the precision tests, NumPy files as
//! NumPy writes them and exact distances for their f64 oracles.

#![allow(dead_code)] // each test file uses its own part

mod gpu;
#[allow(unused_imports)] // a binary of its own (ash_validation) shares this file
pub(crate) use gpu::{Gpu, GpuBackend, on_every_gpu, wgpu_context};

/// What a GPU test needs: the device (or backend) `result` holds. Without one the test fails,
/// saying how to get one: a test that did not run must never read as passed.
pub(crate) fn require<T, E: std::fmt::Display>(what: &str, result: Result<T, E>) -> T {
    result.unwrap_or_else(|e| {
        panic!(
            "{what} is unavailable: {e}\nGPU tests fail rather than pass without running: \
             `cargo xtask setup` installs a Vulkan driver with ray tracing (Mesa lavapipe) \
             where the machine has none, and `cargo xtask test` runs the suite after it"
        )
    })
}

/// Validation-layer messages (wgpu-hal logs them as warnings or errors) seen in this process.
static DRIVER_MESSAGES: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

struct DriverMessages;

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for DriverMessages {
    fn on_event(&self, event: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        let meta = event.metadata();
        if *meta.level() > tracing::Level::WARN {
            return;
        }
        struct Text(String);
        impl tracing::field::Visit for Text {
            fn record_debug(&mut self, f: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                self.0.push_str(&format!("{}={v:?} ", f.name()));
            }
        }
        let mut text = Text(format!("{}: ", meta.target()));
        event.record(&mut text);
        // Probing for an OpenGL adapter through EGL on a machine without a display (as
        // `GpuContext::on_every_adapter` does for the traversal study) logs that EGL could not
        // start: an adapter missing, not a message about anything a test did.
        if text.0.contains("wgpu_hal::gles::egl") && text.0.contains("'eglInitialize'") {
            return;
        }
        // wgpu's `log` records arrive with target "log" and their own in `log.target`.
        if meta.target().starts_with("wgpu") || text.0.contains("log.target=\"wgpu") {
            DRIVER_MESSAGES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(text.0);
        }
    }
}

/// Starts capturing wgpu's messages (and the `log` records of wgpu-hal, through tracing-log);
/// call before the first device is created. Idempotent.
pub(crate) fn capture_driver_messages() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let _ = tracing_subscriber::registry()
        .with(DriverMessages)
        .try_init();
}

/// Fails if the validation layers (on in builds with debug assertions, when installed) or
/// wgpu reported anything so far in this process: through wgpu, or to the ash backend's
/// messenger.
pub(crate) fn assert_no_driver_messages() {
    let m = DRIVER_MESSAGES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    assert!(m.is_empty(), "validation / driver messages: {m:#?}");
    let m = aarbf::backend::ash_rt::validation_messages();
    assert!(
        m.is_empty(),
        "{} Vulkan validation message(s):\n{}",
        m.len(),
        m.join("\n")
    );
}

/// A float64 array as `numpy.save` writes it: magic, version 1.0, a header dict padded with
/// spaces to a multiple of 64 bytes and ended by a newline, then the row-major data.
pub(crate) fn write_numpy(path: &std::path::Path, rows: usize, cols: usize, data: &[f64]) {
    let mut header =
        format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat(total.next_multiple_of(64) - total));
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

/// x - c exactly, as the pair (s, e) with s + e = x - c (Knuth's two-sum).
pub(crate) fn two_diff(x: f64, c: f64) -> (f64, f64) {
    let s = x - c;
    let bb = s - x;
    let e = (x - (s - bb)) + (-c - bb);
    (s, e)
}

/// |x - c|² to f64's relative precision, however large x and c are.
pub(crate) fn exact_d2(x: glam::DVec3, c: glam::DVec3) -> f64 {
    [(x.x, c.x), (x.y, c.y), (x.z, c.z)]
        .iter()
        .map(|&(a, b)| {
            let (s, e) = two_diff(a, b);
            s * s + 2.0 * s * e
        })
        .sum()
}

/// `aarbf ARGS` as a user runs it (warnings logged), which must succeed and, with the
/// validation layers on (debug assertions, as in the `checked` profile, when the layers are
/// installed), report no validation message, through wgpu or the ash backend's messenger:
/// what it printed.
pub(crate) fn aarbf_ok(args: &[&str]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "aarbf {args:?} failed:\n{stderr}");
    assert!(
        !stderr.contains("VALIDATION")
            && !stderr.contains("Validation Error")
            && !stderr.contains("Vulkan validation"),
        "aarbf {args:?}: validation messages:\n{stderr}"
    );
    String::from_utf8(out.stdout).unwrap()
}

/// `aarbf field ARGS --backend BACKEND --force --out OUT` as a user runs it: (Phi, Theta) per
/// query from the output, and what it printed. A GPU backend that cannot start fails the test
/// as [`require`] does.
pub(crate) fn aarbf_field(
    args: &[std::ffi::OsString],
    backend: &str,
    out: &std::path::Path,
) -> (Vec<[f64; 2]>, String) {
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .arg("field")
        .args(args)
        .args(["--backend", backend, "--force", "--out"])
        .arg(out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    if !output.status.success() && backend != "cpu" {
        require::<(), _>(&format!("the {backend} backend"), Err(stderr.clone()));
    }
    assert!(
        output.status.success(),
        "aarbf field --backend {backend}: {stderr}"
    );
    let m = aarbf::io::npy::read_matrix(aarbf::io::At::new(out, None)).unwrap();
    assert_eq!(m.cols, 2);
    let got = (0..m.rows).map(|i| [m.row(i)[0], m.row(i)[1]]).collect();
    (got, stderr)
}

/// `aarbf ARGS` with the log at `info` (what the distributed tests read: each rank's report),
/// its exit status and output as they came.
pub(crate) fn aarbf_logged(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "info")
        .output()
        .expect("the binary runs")
}

/// A dam break of 4000 particles in 3 steps written by `aarbf generate` under `dir`; its
/// header's path.
pub(crate) fn generated_dam_break(dir: &std::path::Path) -> String {
    let out = aarbf_logged(&[
        "generate",
        "dambreak-demo",
        "--out",
        dir.join("db").to_str().unwrap(),
        "--count",
        "4000",
        "--steps",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap().trim().to_owned()
}

/// The arguments of `aarbf render` of that dam break's last step into `out` on the CPU in
/// f64 (the distributed tests compare these images).
pub(crate) fn dam_break_render_args(
    header: &str,
    out: &std::path::Path,
    size: (u32, u32),
    spp: u32,
) -> Vec<String> {
    [
        "render",
        "--data",
        header,
        "--step",
        "2",
        "--attribute",
        "attribute",
        "--radius",
        "2%",
        "--width",
        &size.0.to_string(),
        "--height",
        &size.1.to_string(),
        "--spp",
        &spp.to_string(),
        "--backend",
        "cpu",
        "--precision",
        "f64",
        "--up",
        "y",
        "--out",
        out.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec()
}

/// A copy under `dir` of the SWIFT snapshot h5py wrote (tests/data/h5py_swift: gas and dark
/// matter, f64 coordinates, a periodic box in its header): reading writes an index beside the
/// files, and the inputs stay untouched.
pub(crate) fn swift_snapshot_copy(dir: &std::path::Path) -> std::path::PathBuf {
    let data = dir.join("swift");
    std::fs::create_dir(&data).unwrap();
    let fixture = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/h5py_swift");
    for name in ["snap_0000.hdf5", "snap_0001.hdf5"] {
        std::fs::copy(fixture.join(name), data.join(name)).unwrap();
    }
    data
}

/// The largest difference of any channel of any pixel between two images of one size.
pub(crate) fn max_image_difference(a: &std::path::Path, b: &std::path::Path) -> f32 {
    let a = image::open(a).unwrap().to_rgba32f();
    let b = image::open(b).unwrap().to_rgba32f();
    assert_eq!(a.dimensions(), b.dimensions());
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

/// The arguments of `aarbf render` of that snapshot copy into `out` as a user gives them: no
/// data flags (the header's periodic box, the default particle type), 64 x 64, 2 spp.
pub(crate) fn swift_render_args(data: &std::path::Path, out: &std::path::Path) -> Vec<String> {
    [
        "render",
        "--data",
        data.to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "64",
        "--spp",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec()
}

/// The smoothing lengths cached beside the data in `dir` (`.aarbf-smoothing/`), each file's
/// name and the values after its header (magic, the data file's stamp, the count), by name.
pub(crate) fn cached_lengths(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> =
        std::fs::read_dir(dir.join(aarbf::scene::smoothing::CACHE_DIR))
            .unwrap()
            .map(|e| {
                let path = e.unwrap().path();
                let name = path.file_name().unwrap().to_string_lossy().into_owned();
                (name, std::fs::read(&path).unwrap()[36..].to_vec())
            })
            .collect();
    files.sort();
    files
}
