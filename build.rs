//! Shader build: every GPU kernel is checked at build time, so a shader error is a build error.
//!
//! - `shaders_glsl/wgpu/*.comp` (GLSL compute kernels the wgpu backend runs through naga's GLSL
//!   front end) and `shaders_wgsl/*.wgsl`: includes resolved, parsed and validated by naga.
//! - `shaders_glsl/vulkan/*.{rgen,rint,rahit,rmiss,rchit,comp}` (the ash backend's ray-tracing
//!   pipeline and compute kernels): compiled to SPIR-V with `glslc` into OUT_DIR (no SPIR-V is
//!   committed). `cargo xtask setup` installs glslc.

use std::path::{Path, PathBuf};
use std::process::Command;

include!("src/backend/shaders/include.rs");

/// The constants Rust and the shaders share: the library's own definitions, so the kernels
/// validated here are given the text the library gives them.
#[path = "src/values/shader_constants.rs"]
#[allow(dead_code)]
mod shader_constants;

fn shared(name: &str) -> Option<String> {
    if name == "generated/constants.glsl" {
        return Some(shader_constants::glsl());
    }
    if name == "generated/hilbert_step.glsl" {
        return Some(shader_constants::hilbert_glsl());
    }
    std::fs::read_to_string(Path::new("shaders_glsl").join(name)).ok()
}

fn files(dir: &str, extensions: &[&str]) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    out.retain(|p| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| extensions.contains(&e))
    });
    out.sort();
    out
}

/// The entry points of a Vulkan GLSL file: one `main` (None) unless it has `#ifdef ENTRY_<name>`
/// blocks, each a `main` of its own, compiled with `ENTRY_<name>` defined (GLSL has one entry
/// point a module, so a stage with several passes, as its WGSL twin has, is written thus).
fn glsl_entry_points(source: &str) -> Vec<Option<String>> {
    let named: Vec<Option<String>> = source
        .lines()
        .filter_map(|l| l.trim().strip_prefix("#ifdef ENTRY_"))
        .map(|e| Some(e.trim().to_owned()))
        .collect();
    if named.is_empty() { vec![None] } else { named }
}

fn fail(message: String) -> ! {
    eprintln!("{message}");
    println!(
        "cargo::error={}",
        message.lines().next().unwrap_or("shader error")
    );
    std::process::exit(1);
}

/// Validates `module` (the `SPLIT_PARTS` = `parts` variant of `path`), and holds its one-part
/// variant to WebGPU's storage-buffer limit.
fn validate(module: &naga::Module, path: &Path, source: &str, parts: u32) {
    let mut validator = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    );
    if let Err(e) = validator.validate(module) {
        fail(format!(
            "{}: naga validation failed:\n{}",
            path.display(),
            e.emit_to_string(source)
        ));
    }
    if parts == 1 {
        check_storage_buffers(module, path);
    }
}

/// WebGPU's default `maxStorageBuffersPerShaderStage`, which the one-part layout keeps to.
const WEBGPU_STORAGE_BUFFERS: usize = 8;

/// Fails the build when the one-part variant of a kernel declares more storage buffers than
/// [`WEBGPU_STORAGE_BUFFERS`] (the module's count bounds each entry point's).
fn check_storage_buffers(module: &naga::Module, path: &Path) {
    let count = module
        .global_variables
        .iter()
        .filter(|(_, v)| matches!(v.space, naga::AddressSpace::Storage { .. }))
        .count();
    if count > WEBGPU_STORAGE_BUFFERS {
        fail(format!(
            "{}: the one-part variant declares {count} storage buffers, more than the \
             {WEBGPU_STORAGE_BUFFERS} WebGPU guarantees per stage",
            path.display()
        ));
    }
}

fn main() {
    println!("cargo::rerun-if-changed=shaders_glsl");
    println!("cargo::rerun-if-changed=shaders_wgsl");
    println!("cargo::rerun-if-changed=src/backend/shaders/include.rs");
    println!("cargo::rerun-if-changed=src/values/shader_constants.rs");

    // Every wgpu kernel in both storage layouts (SPLIT_PARTS = 1 and 4; see
    // shaders_glsl/wgpu/split.glsl). The one-part layout must stay within WebGPU's default of
    // 8 storage buffers per stage, so the backend runs on any adapter for steps that fit.
    for path in files("shaders_glsl/wgpu", &["comp"]) {
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let source = resolve_includes(&text, &shared, ShaderLanguage::Glsl)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        for parts in SPLIT_PARTS_VARIANTS {
            let mut frontend = naga::front::glsl::Frontend::default();
            let mut options = naga::front::glsl::Options::from(naga::ShaderStage::Compute);
            options
                .defines
                .insert("SPLIT_PARTS".into(), parts.to_string());
            let module = frontend.parse(&options, &source).unwrap_or_else(|e| {
                fail(format!(
                    "{} (SPLIT_PARTS = {parts}): GLSL parse failed:\n{}",
                    path.display(),
                    e.emit_to_string(&source)
                ))
            });
            validate(&module, &path, &source, parts);
        }
    }
    // WGSL has no includes either: `#include "shared/x.wgsl"` lines name files under
    // shaders_wgsl/shared/, resolved by the same code (src/backend/shaders/include.rs), and the
    // SPLIT_PARTS blocks are selected by it too.
    let shared_wgsl = |name: &str| {
        if name == "generated/constants.wgsl" {
            return Some(shader_constants::wgsl());
        }
        std::fs::read_to_string(Path::new("shaders_wgsl").join(name)).ok()
    };
    for path in files("shaders_wgsl", &["wgsl"]) {
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let resolved = resolve_includes(&text, &shared_wgsl, ShaderLanguage::Wgsl)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        for parts in SPLIT_PARTS_VARIANTS {
            let source = select_split_parts(&resolved, parts)
                .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
            let module = naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| {
                fail(format!(
                    "{} (SPLIT_PARTS = {parts}): WGSL parse failed:\n{}",
                    path.display(),
                    e.emit_to_string(&source)
                ))
            });
            validate(&module, &path, &source, parts);
        }
    }

    let vulkan = files(
        "shaders_glsl/vulkan",
        &["rgen", "rint", "rahit", "rmiss", "rchit", "comp"],
    );
    if vulkan.is_empty() {
        return;
    }
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let glslc = std::env::var("GLSLC").unwrap_or_else(|_| "glslc".into());
    if Command::new(&glslc).arg("--version").output().is_err() {
        fail(format!(
            "the GLSL compiler '{glslc}' was not found: run `cargo xtask setup` (it installs Debian's \
             glslc), install glslc from the Vulkan SDK, or point GLSLC at one"
        ));
    }
    for path in vulkan {
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let source = resolve_includes(&text, &shared, ShaderLanguage::Glsl)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let resolved = out_dir.join(format!("{name}.glsl"));
        std::fs::write(&resolved, &source).unwrap();
        let stage = path.extension().unwrap().to_string_lossy().into_owned();
        for entry in glsl_entry_points(&source) {
            let (define, spirv) = match &entry {
                None => (None, format!("{name}.spv")),
                Some(e) => (Some(format!("-DENTRY_{e}")), format!("{name}.{e}.spv")),
            };
            let output = Command::new(&glslc)
                .args([
                    "--target-env=vulkan1.2",
                    "-O",
                    &format!("-fshader-stage={stage}"),
                ])
                .args(define)
                .arg(&resolved)
                .arg("-o")
                .arg(out_dir.join(spirv))
                .output()
                .unwrap_or_else(|e| fail(format!("cannot run {glslc}: {e}")));
            if !output.status.success() {
                fail(format!(
                    "{}{}: glslc failed:\n{}",
                    path.display(),
                    entry
                        .map(|e| format!(" (entry point {e})"))
                        .unwrap_or_default(),
                    String::from_utf8_lossy(&output.stderr)
                ));
            }
        }
    }
}
