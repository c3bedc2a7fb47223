//! `cargo xtask <command>`: set-up, tests and the demo, on a fresh Debian 12 machine too.
//!
//! - `setup`: make the machine ready. When no Vulkan device with ray-tracing pipelines is
//!   visible, install the Vulkan loader and Mesa lavapipe >= 25 from bookworm-backports; always
//!   make sure the GLSL compiler and Vulkan tools the build and tests use are present.
//!   Idempotent: it prints each step and skips what is already there.
//! - `test`: setup, then the whole test suite (optimised, with debug assertions).
//! - `demo`: setup, then render the built-in demo scene to `demo.png`.
//! - `bench NAME [args]`: setup, then `cargo bench --bench NAME -- args`.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{Context, Result, bail};

/// The Cargo profile tests and the demo build with (release speed, debug assertions on).
const PROFILE: &str = "checked";
const BACKPORTS_FILE: &str = "/etc/apt/sources.list.d/bookworm-backports.sources";
const MIN_MESA_MAJOR: u32 = 25;
/// Debian packages the build and tests need besides the driver.
const TOOL_PACKAGES: [&str; 4] = [
    "libvulkan1",
    "vulkan-tools",
    "vulkan-validationlayers",
    "glslc",
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("setup") => setup().map(|_| ()),
        Some("test") => test(&args[1..]),
        Some("demo") => demo(),
        Some("bench") if args.len() > 1 => bench(&args[1], &args[2..]),
        _ => {
            eprintln!(
                "usage: cargo xtask <setup | test [cargo test args] | demo | bench NAME [args]>\n\n  \
                 setup  install the Vulkan driver (lavapipe) and tools if missing\n  \
                 test   setup, then run every test\n  \
                 demo   setup, then render the demo scene to demo.png\n  \
                 bench  run benches/NAME.rs (results belong in docs/benchmarks.md)"
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
    let devices = ray_tracing_devices();
    let mesa = package_version("mesa-vulkan-drivers");
    let lavapipe_ok = mesa.as_deref().is_some_and(|v| major(v) >= MIN_MESA_MAJOR);
    let missing_tools: Vec<&str> = TOOL_PACKAGES
        .iter()
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
    setup()?;
    run(cargo()
        .args(["test", "--workspace", "--profile", PROFILE])
        .args(extra))
}

fn bench(name: &str, extra: &[String]) -> Result<()> {
    setup()?;
    run(cargo().args(["bench", "--bench", name, "--"]).args(extra))
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
