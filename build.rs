//! Shader build: every GPU kernel is checked at build time, so a shader error is a build error.
//!
//! - `shaders_glsl/wgpu/*.comp` (GLSL compute kernels the wgpu backend runs through naga's GLSL
//!   front end) and `shaders_wgsl/*.wgsl`: includes resolved, parsed and validated by naga.
//! - `shaders_glsl/vulkan/*.{rgen,rint,rahit,rmiss,rchit,comp}` (the ash backend's ray-tracing
//!   pipeline and compute kernels): compiled to SPIR-V with `glslc` into OUT_DIR (no SPIR-V is
//!   committed). `cargo xtask setup` installs glslc.
//!
//! While at it, it writes the shader table (`OUT_DIR/shader_table.rs`, included by
//! `src/backend/shaders/table.rs`): every file, its entry points, workgroup sizes and bindings
//! as naga (WGSL, wgpu GLSL) or the SPIR-V (ash) has them, and its twin. Nothing lists a
//! shader by hand: adding a stage is writing its shader and its CPU twin.

use std::path::{Path, PathBuf};
use std::process::Command;

include!("src/backend/shaders/include.rs");

/// The constants Rust and the shaders share: the library's own definitions, so the kernels
/// validated here are given the text the library gives them.
#[path = "src/values/shader_constants.rs"]
#[allow(
    dead_code,
    unreachable_pub,
    missing_docs,
    reason = "the library's module, compiled here for its text: what it exports is the library's"
)]
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
fn validate(
    module: &naga::Module,
    path: &Path,
    source: &str,
    parts: u32,
) -> naga::valid::ModuleInfo {
    let mut validator = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    );
    let info = validator.validate(module).unwrap_or_else(|e| {
        fail(format!(
            "{}: naga validation failed:\n{}",
            path.display(),
            e.emit_to_string(source)
        ))
    });
    if parts == 1 {
        check_storage_buffers(module, path);
    }
    info
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
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let mut table = Vec::new();

    // Every wgpu kernel in both storage layouts (SPLIT_PARTS = 1 and 4; see
    // shaders_glsl/wgpu/split.glsl). The one-part layout must stay within WebGPU's default of
    // 8 storage buffers per stage, so the backend runs on any adapter for steps that fit.
    for path in files("shaders_glsl/wgpu", &["comp"]) {
        let text = read(&path);
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
            let info = validate(&module, &path, &source, parts);
            if parts == 1 {
                let entries = reflect_naga(&module, &info, &path);
                table.push(Row::new(&path, &text, "GlslCompute", "Wgpu", entries));
            }
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
        let text = read(&path);
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
            let info = validate(&module, &path, &source, parts);
            if parts == 1 {
                let entries = reflect_naga(&module, &info, &path);
                table.push(Row::new(&path, &text, "Wgsl", "Wgpu", entries));
            }
        }
    }

    let vulkan = files(
        "shaders_glsl/vulkan",
        &["rgen", "rint", "rahit", "rmiss", "rchit", "comp"],
    );
    let glslc = std::env::var("GLSLC").unwrap_or_else(|_| "glslc".into());
    if !vulkan.is_empty() && Command::new(&glslc).arg("--version").output().is_err() {
        fail(format!(
            "the GLSL compiler '{glslc}' was not found: run `cargo xtask setup` (it installs Debian's \
             glslc), install glslc from the Vulkan SDK, or point GLSLC at one"
        ));
    }
    for path in vulkan {
        let text = read(&path);
        let source = resolve_includes(&text, &shared, ShaderLanguage::Glsl)
            .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let resolved = out_dir.join(format!("{name}.glsl"));
        std::fs::write(&resolved, &source).unwrap();
        let stage = path.extension().unwrap().to_string_lossy().into_owned();
        let mut entries = Vec::new();
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
                .arg(out_dir.join(&spirv))
                .output()
                .unwrap_or_else(|e| fail(format!("cannot run {glslc}: {e}")));
            if !output.status.success() {
                fail(format!(
                    "{}{}: glslc failed:\n{}",
                    path.display(),
                    entry
                        .as_ref()
                        .map(|e| format!(" (entry point {e})"))
                        .unwrap_or_default(),
                    String::from_utf8_lossy(&output.stderr)
                ));
            }
            let bytes = std::fs::read(out_dir.join(&spirv)).unwrap();
            let mut reflected = reflect_spirv(&bytes).unwrap_or_else(|e| {
                fail(format!("{}: reflecting its SPIR-V: {e}", path.display()))
            });
            reflected.name = entry.unwrap_or(reflected.name);
            reflected.spirv = Some(spirv);
            entries.push(reflected);
        }
        let language = match stage.as_str() {
            "comp" => "GlslCompute",
            _ => "GlslRayTracing",
        };
        table.push(Row::new(&path, &text, language, "Ash", entries));
    }
    write_table(&table, &out_dir.join("shader_table.rs"));
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())))
}

/// One entry point, as the table holds it.
struct EntryRow {
    name: String,
    /// A `StageKind` variant.
    stage: &'static str,
    workgroup_size: [u32; 3],
    /// (group, binding, a `BindingKind` expression), sorted.
    bindings: Vec<(u32, u32, String)>,
    specialised: bool,
    /// The SPIR-V file in OUT_DIR (ash).
    spirv: Option<String>,
}

/// One shader file, as the table holds it.
struct Row {
    name: String,
    file: String,
    language: &'static str,
    backend: &'static str,
    entries: Vec<EntryRow>,
    /// A `Twin` expression.
    twin: String,
}

impl Row {
    fn new(
        path: &Path,
        text: &str,
        language: &'static str,
        backend: &'static str,
        entries: Vec<EntryRow>,
    ) -> Row {
        let file = path.to_string_lossy().replace('\\', "/");
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        Row {
            twin: twin(&file, text),
            name,
            file,
            language,
            backend,
            entries,
        }
    }
}

/// The shader's twin: `Twin::Cpu` unless a line `// twin: <path>: <why>` or
/// `// twin: none: <why>` says otherwise.
fn twin(file: &str, text: &str) -> String {
    let Some(line) = text.lines().find_map(|l| l.trim().strip_prefix("// twin:")) else {
        return "Twin::Cpu".into();
    };
    let Some((what, why)) = line.trim().split_once(": ") else {
        fail(format!(
            "{file}: a twin line reads `// twin: <path or none>: <why>`, not `// twin:{line}`"
        ));
    };
    match what.trim() {
        "none" => format!("Twin::None {{ why: {:?} }}", why.trim()),
        path => {
            if !Path::new(path).exists() {
                fail(format!("{file}: its twin {path} does not exist"));
            }
            format!(
                "Twin::Elsewhere {{ path: {path:?}, why: {:?} }}",
                why.trim()
            )
        }
    }
}

/// The entry points of a module naga validated, each with the bindings it uses.
fn reflect_naga(
    module: &naga::Module,
    info: &naga::valid::ModuleInfo,
    path: &Path,
) -> Vec<EntryRow> {
    module
        .entry_points
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            if entry.stage != naga::ShaderStage::Compute {
                fail(format!(
                    "{}: entry point {} is not a compute stage",
                    path.display(),
                    entry.name
                ));
            }
            let uses = info.get_entry_point(i);
            let mut bindings: Vec<(u32, u32, String)> = module
                .global_variables
                .iter()
                .filter(|(handle, _)| !uses[*handle].is_empty())
                .filter_map(|(_, var)| {
                    let binding = var.binding.as_ref()?;
                    let kind = match var.space {
                        naga::AddressSpace::Uniform => "Uniform".to_owned(),
                        naga::AddressSpace::Storage { access } => format!(
                            "Storage {{ read_only: {} }}",
                            !access.contains(naga::StorageAccess::STORE)
                        ),
                        naga::AddressSpace::Handle => match module.types[var.ty].inner {
                            naga::TypeInner::Image { .. } => "Texture".to_owned(),
                            naga::TypeInner::Sampler { .. } => "Sampler".to_owned(),
                            naga::TypeInner::AccelerationStructure { .. } => {
                                "AccelerationStructure".to_owned()
                            }
                            ref other => fail(format!(
                                "{}: binding {} has a type the table does not know: {other:?}",
                                path.display(),
                                binding.binding
                            )),
                        },
                        other => fail(format!(
                            "{}: binding {} is in address space {other:?}",
                            path.display(),
                            binding.binding
                        )),
                    };
                    Some((binding.group, binding.binding, kind))
                })
                .collect();
            bindings.sort();
            EntryRow {
                name: entry.name.clone(),
                stage: "Compute",
                workgroup_size: entry.workgroup_size,
                bindings,
                specialised: !module.overrides.is_empty(),
                spirv: None,
            }
        })
        .collect()
}

/// The one entry point of a SPIR-V module glslc wrote: its stage, workgroup size, the
/// descriptors it uses (those in its interface; SPIR-V 1.4 and later list every global there)
/// and whether it has specialisation constants. A few dozen lines of the SPIR-V
/// specification's instruction layout, rather than a reflection crate.
fn reflect_spirv(bytes: &[u8]) -> Result<EntryRow, String> {
    use std::collections::{HashMap, HashSet};
    if !bytes.len().is_multiple_of(4) || bytes.len() < 20 {
        return Err("not a whole number of words".into());
    }
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    if words[0] != 0x0723_0203 {
        return Err("no SPIR-V magic number".into());
    }
    let version = words[1];
    let mut entry: Option<(u32, u32, String, Vec<u32>)> = None;
    let mut local_size = [0u32; 3];
    let mut decorations: HashMap<(u32, u32), u32> = HashMap::new();
    let mut non_writable_members: HashMap<u32, usize> = HashMap::new();
    let mut struct_members: HashMap<u32, usize> = HashMap::new();
    let mut pointers: HashMap<u32, u32> = HashMap::new();
    let mut types: HashMap<u32, &'static str> = HashMap::new();
    let mut variables: Vec<(u32, u32, u32)> = Vec::new();
    let mut specialised = false;
    let mut at = 5;
    while at < words.len() {
        let (opcode, count) = (words[at] & 0xffff, (words[at] >> 16) as usize);
        if count == 0 || at + count > words.len() {
            return Err(format!("a malformed instruction at word {at}"));
        }
        let op = &words[at + 1..at + count];
        match opcode {
            // OpEntryPoint: model, id, name (a nul-terminated string), interface ids.
            15 => {
                let name_words = op[2..].iter().position(|w| w >> 24 == 0).unwrap_or(0) + 1;
                let name: Vec<u8> = op[2..2 + name_words]
                    .iter()
                    .flat_map(|w| w.to_le_bytes())
                    .take_while(|&b| b != 0)
                    .collect();
                if entry.is_some() {
                    return Err("more than one entry point".into());
                }
                entry = Some((
                    op[0],
                    op[1],
                    String::from_utf8_lossy(&name).into_owned(),
                    op[2 + name_words..].to_vec(),
                ));
            }
            // OpExecutionMode LocalSize.
            16 if op[1] == 17 => local_size = [op[2], op[3], op[4]],
            // OpDecorate: target, decoration (1 SpecId, 2 Block, 3 BufferBlock, 24
            // NonWritable, 33 Binding, 34 DescriptorSet), its operand.
            71 => {
                decorations.insert((op[0], op[1]), op.get(2).copied().unwrap_or(0));
                specialised |= op[1] == 1;
            }
            // OpMemberDecorate NonWritable.
            72 if op[2] == 24 => *non_writable_members.entry(op[0]).or_default() += 1,
            25 => _ = types.insert(op[0], "Texture"),
            26 => _ = types.insert(op[0], "Sampler"),
            5341 => _ = types.insert(op[0], "AccelerationStructure"),
            // OpTypeStruct: its members.
            30 => _ = struct_members.insert(op[0], op.len() - 1),
            // OpTypePointer: result, storage class, pointee.
            32 => _ = pointers.insert(op[0], op[2]),
            // OpVariable: type, result, storage class.
            59 => variables.push((op[0], op[1], op[2])),
            _ => {}
        }
        at += count;
    }
    let (model, _, name, interface) = entry.ok_or("no entry point")?;
    let stage = match model {
        5 => "Compute",
        5313 => "RayGeneration",
        5314 => "Intersection",
        5315 => "AnyHit",
        5316 => "ClosestHit",
        5317 => "Miss",
        other => return Err(format!("execution model {other}")),
    };
    let interface: HashSet<u32> = interface.into_iter().collect();
    let mut bindings = Vec::new();
    for (ty, id, class) in variables {
        let (Some(&set), Some(&binding)) = (decorations.get(&(id, 34)), decorations.get(&(id, 33)))
        else {
            continue;
        };
        if version >= 0x0001_0400 && !interface.contains(&id) {
            continue;
        }
        let pointee = pointers.get(&ty).copied().unwrap_or(0);
        let read_only = decorations.contains_key(&(id, 24))
            || struct_members
                .get(&pointee)
                .is_some_and(|&n| non_writable_members.get(&pointee) == Some(&n));
        let storage = format!("Storage {{ read_only: {read_only} }}");
        let kind = match class {
            // StorageBuffer, or Uniform with the old BufferBlock decoration.
            12 => storage,
            2 if decorations.contains_key(&(pointee, 3)) => storage,
            2 => "Uniform".to_owned(),
            // UniformConstant: an opaque handle.
            0 => types
                .get(&pointee)
                .ok_or_else(|| {
                    format!("binding {binding}: a handle of a type the table does not know")
                })?
                .to_string(),
            other => return Err(format!("binding {binding} in storage class {other}")),
        };
        bindings.push((set, binding, kind));
    }
    bindings.sort();
    Ok(EntryRow {
        name,
        stage,
        workgroup_size: if stage == "Compute" {
            local_size
        } else {
            [0; 3]
        },
        bindings,
        specialised,
        spirv: None,
    })
}

/// A Rust constant name: upper case.
fn constant(name: &str) -> String {
    name.to_ascii_uppercase().replace(['-', '.'], "_")
}

/// Writes the table (`src/backend/shaders/table.rs` declares its types).
fn write_table(rows: &[Row], out: &Path) {
    use std::fmt::Write;
    let mut text = String::from(
        "// Written by build.rs: the shader table (src/backend/shaders/table.rs).\n\n",
    );
    text.push_str("/// Every shader file the GPU backends run (`build.rs` writes this list).\npub static SHADERS: &[Shader] = &[\n");
    for row in rows {
        let also = rows
            .iter()
            .find(|o| o.name == row.name && o.backend != row.backend)
            .map(|o| {
                let twice = if (o.language == "Wgsl") != (row.language == "Wgsl") {
                    "WgslAndGlsl"
                } else {
                    "Bindings"
                };
                format!("Some(({:?}, Twice::{twice}))", o.file)
            })
            .unwrap_or_else(|| "None".into());
        let _ = writeln!(
            text,
            "    Shader {{\n        name: {:?},\n        file: {:?},\n        language: Language::{},\n        backend: GpuBackend::{},\n        source: include_str!(concat!(env!(\"CARGO_MANIFEST_DIR\"), \"/{}\")),\n        twin: {},\n        also: {also},\n        entry_points: &[",
            row.name, row.file, row.language, row.backend, row.file, row.twin
        );
        for e in &row.entries {
            let bindings: Vec<String> = e
                .bindings
                .iter()
                .map(|(g, b, k)| {
                    format!("Binding {{ group: {g}, binding: {b}, kind: BindingKind::{k} }}")
                })
                .collect();
            let spirv = match &e.spirv {
                Some(f) => format!("include_bytes!(concat!(env!(\"OUT_DIR\"), \"/{f}\"))"),
                None => "&[]".into(),
            };
            let _ = writeln!(
                text,
                "            EntryPoint {{\n                name: {:?},\n                stage: StageKind::{},\n                workgroup_size: {:?},\n                bindings: &[{}],\n                specialised: {},\n                spirv: {spirv},\n            }},",
                e.name,
                e.stage,
                e.workgroup_size,
                bindings.join(", "),
                e.specialised
            );
        }
        text.push_str("        ],\n    },\n");
    }
    text.push_str("];\n");
    // One constant per entry point, by backend.
    let mut names = std::collections::HashSet::new();
    for (module, backend) in [("on_wgpu", "Wgpu"), ("on_ash", "Ash")] {
        let _ = writeln!(
            text,
            "\n/// The {backend} backend's entry points, one constant each: the stage's name, then the \
             entry point's where the file has several, or the stage kind's for a ray-tracing stage.\npub mod {module} {{\n    use super::Entry;"
        );
        for (s, row) in rows
            .iter()
            .enumerate()
            .filter(|(_, r)| r.backend == backend)
        {
            for (e, entry) in row.entries.iter().enumerate() {
                let suffix = if row.language == "GlslRayTracing" {
                    Path::new(&row.file)
                        .extension()
                        .unwrap()
                        .to_string_lossy()
                        .into_owned()
                } else {
                    entry.name.clone()
                };
                let name = if row.entries.len() == 1 && row.language != "GlslRayTracing" {
                    constant(&row.name)
                } else if suffix.starts_with(&row.name) {
                    constant(&suffix)
                } else {
                    constant(&format!("{}_{suffix}", row.name))
                };
                if !names.insert((backend, name.clone())) {
                    fail(format!("{}: two entry points are named {name}", row.file));
                }
                let _ = writeln!(
                    text,
                    "    /// `{}`{}.\n    pub const {name}: Entry = Entry {{ shader: {s}, entry: {e} }};",
                    row.file,
                    if row.entries.len() > 1 {
                        format!(", entry point `{}`", entry.name)
                    } else {
                        String::new()
                    }
                );
            }
        }
        text.push_str("}\n");
    }
    // The files kernels include at run time, by the name they include them with.
    for (constant, language, dirs) in [
        (
            "GLSL_INCLUDES",
            "GLSL",
            &[
                ("shaders_glsl", "shared", "glsl"),
                ("shaders_glsl", "wgpu", "glsl"),
            ][..],
        ),
        (
            "WGSL_INCLUDES",
            "WGSL",
            &[("shaders_wgsl", "shared", "wgsl")][..],
        ),
    ] {
        let _ = writeln!(
            text,
            "\n/// The {language} files a wgpu kernel may include, by the name it includes them with.\npub static {constant}: &[(&str, &str)] = &["
        );
        for (root, dir, ext) in dirs {
            for path in files(&format!("{root}/{dir}"), &[ext]) {
                let file = path.file_name().unwrap().to_string_lossy();
                let _ = writeln!(
                    text,
                    "    (\"{dir}/{file}\", include_str!(concat!(env!(\"CARGO_MANIFEST_DIR\"), \"/{root}/{dir}/{file}\"))),"
                );
            }
        }
        text.push_str("];\n");
    }
    std::fs::write(out, text).unwrap_or_else(|e| fail(format!("{}: {e}", out.display())));
}
