//! The shader table: every shader file the GPU backends run, one [`Shader`] each, in
//! [`SHADERS`], which `build.rs` writes while it validates and compiles them. Nothing here is
//! listed by hand: a file's name, language and backend come from where it lies
//! (`shaders_wgsl/*.wgsl` and `shaders_glsl/wgpu/*.comp` run on wgpu, `shaders_glsl/vulkan/*` on
//! ash), its entry points, workgroup sizes and bindings are reflected from the compiled module
//! (naga's for WGSL and the wgpu GLSL, the SPIR-V glslc writes for the ash stages, ray-tracing
//! ones included), and its twin is `backend/shaders/cpu/<name>.rs` unless the file's own
//! `// twin:` line says otherwise. The `on_wgpu` and `on_ash` modules name every entry point
//! as an [`Entry`] constant, so a backend asks for a pipeline by a name the compiler checks.
//!
//! A stage is one name: its shader file (`<name>.wgsl`, `<name>.comp`, ...), its table entry
//! and its CPU twin `cpu/<name>.rs`. A stage the two backends both run has one file for each
//! ([`Shader::also`]): GLSL for both where the code is the shared GLSL and only the bindings
//! differ, WGSL on wgpu and GLSL on ash where the stage needs atomics, which naga's GLSL front
//! end lacks, or goes with one that does ([`Twice`]).

/// The language a shader is written in (and so how it is compiled).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Language {
    /// WGSL, for wgpu (`shaders_wgsl/`).
    Wgsl,
    /// A GLSL compute kernel: through naga's GLSL front end on wgpu (`shaders_glsl/wgpu/`),
    /// through glslc on ash (`shaders_glsl/vulkan/*.comp`).
    GlslCompute,
    /// A GLSL ray-tracing stage, through glslc (`shaders_glsl/vulkan/*.{rgen,rint,rahit,rmiss}`).
    GlslRayTracing,
}

/// The backend that runs a shader file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GpuBackend {
    /// `wgpu_lbvh`: the source is compiled at run time (naga).
    Wgpu,
    /// `ash_rt`: SPIR-V compiled by glslc at build time.
    Ash,
}

/// The pipeline stage of an entry point.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StageKind {
    /// A compute kernel.
    Compute,
    /// A ray-generation shader.
    RayGeneration,
    /// An intersection shader (the particles' or clusters' sphere test).
    Intersection,
    /// An any-hit shader.
    AnyHit,
    /// A closest-hit shader.
    ClosestHit,
    /// A miss shader.
    Miss,
}

/// What a binding holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BindingKind {
    /// A uniform buffer.
    Uniform,
    /// A storage buffer.
    Storage {
        /// Whether the entry point only reads it.
        read_only: bool,
    },
    /// A sampled texture.
    Texture,
    /// A sampler.
    Sampler,
    /// A ray-tracing acceleration structure.
    AccelerationStructure,
}

/// One resource an entry point uses (bindings it declares but never uses are left out).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Binding {
    /// Its bind group (wgpu) or descriptor set (ash).
    pub group: u32,
    /// Its binding number within the group.
    pub binding: u32,
    /// What it holds.
    pub kind: BindingKind,
}

/// One entry point of a shader file.
#[derive(Debug)]
pub struct EntryPoint {
    /// Its name in the module (`main` for a GLSL file of one entry point; for a Vulkan GLSL
    /// file of several, the `ENTRY_<name>` block it is compiled from).
    pub name: &'static str,
    /// Its pipeline stage.
    pub stage: StageKind,
    /// Threads per workgroup (compute); `[0; 3]` for a ray-tracing stage.
    pub workgroup_size: [u32; 3],
    /// Its bindings, by group then binding. A wgpu kernel's are those of its one-part layout
    /// (`SPLIT_PARTS` = 1), which the four-part layout extends by the parts past the first.
    pub bindings: &'static [Binding],
    /// Whether it declares specialisation constants (`shader_constants::SPEC_CONSTANTS`).
    pub specialised: bool,
    /// The SPIR-V glslc compiled it to (ash; empty for wgpu, which compiles the source).
    pub spirv: &'static [u8],
}

impl EntryPoint {
    /// Threads per workgroup, all axes together.
    pub fn threads(&self) -> u32 {
        self.workgroup_size.iter().product()
    }
}

/// The CPU twin of a stage: what its results are compared against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Twin {
    /// `src/backend/shaders/cpu/<name>.rs`.
    Cpu,
    /// Code elsewhere in the crate that computes the same (its path), as the shader's
    /// `// twin: <path>: <why>` line says.
    Elsewhere {
        /// The twin's path, relative to the crate root.
        path: &'static str,
        /// Why it lives there.
        why: &'static str,
    },
    /// None by nature, as the shader's `// twin: none: <why>` line says.
    None {
        /// Why it has none.
        why: &'static str,
    },
}

/// Why a stage is written twice, once per backend ([`Shader::also`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Twice {
    /// GLSL for both: the code is the shared GLSL (`shaders_glsl/shared/`); each file declares
    /// its backend's bindings (wgpu's bind group, ash's descriptor set and device addresses).
    Bindings,
    /// WGSL on wgpu and GLSL on ash, because of the atomics: the radix sort and the voxel
    /// splat need them, which naga's GLSL front end (and so the shared GLSL) does not have, and
    /// the Hilbert keys and gather are the sort's companions in the same WGSL preparation
    /// (`shared/prepare_params.wgsl`, split arrays). On ash the same stages reach their arrays
    /// by device address (no binding limit). Whether naga's WGSL → SPIR-V could serve ash
    /// instead: `docs/notes/2026-12-07-shader-table.md`.
    WgslAndGlsl,
}

/// One shader file.
#[derive(Debug)]
pub struct Shader {
    /// The stage's name: the file's stem, and its twin's file stem.
    pub name: &'static str,
    /// The file, relative to the crate root.
    pub file: &'static str,
    /// The language it is written in.
    pub language: Language,
    /// The backend that runs it.
    pub backend: GpuBackend,
    /// The file's text (includes unresolved).
    pub source: &'static str,
    /// Its entry points, in the order they appear.
    pub entry_points: &'static [EntryPoint],
    /// What its results are compared against.
    pub twin: Twin,
    /// The same stage for the other backend, and why it is written twice.
    pub also: Option<(&'static str, Twice)>,
}

/// One entry point of one shader file of [`SHADERS`]: what a backend makes a pipeline of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Entry {
    shader: u16,
    entry: u16,
}

impl Entry {
    /// The shader file it is in.
    pub fn shader(self) -> &'static Shader {
        &SHADERS[usize::from(self.shader)]
    }

    /// The entry point itself.
    pub fn point(self) -> &'static EntryPoint {
        &self.shader().entry_points[usize::from(self.entry)]
    }
}

impl std::fmt::Display for Entry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.shader().entry_points.len() {
            1 => write!(f, "{}", self.shader().file),
            _ => write!(f, "{}:{}", self.shader().file, self.point().name),
        }
    }
}

/// The files `#include` can name, by that name: `shared/*.glsl` and `wgpu/*.glsl` under
/// `shaders_glsl/` (GLSL), `shared/*.wgsl` under `shaders_wgsl/` (WGSL). The Vulkan includes
/// are resolved at build time only.
pub fn include_file(name: &str, language: super::ShaderLanguage) -> Option<&'static str> {
    let files = match language {
        super::ShaderLanguage::Glsl => GLSL_INCLUDES,
        super::ShaderLanguage::Wgsl => WGSL_INCLUDES,
    };
    files.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

include!(concat!(env!("OUT_DIR"), "/shader_table.rs"));

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;
    use std::path::Path;

    use super::*;

    fn root() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR"))
    }

    /// The stems of the twin files in `src/backend/shaders/cpu/`.
    fn twin_files() -> BTreeSet<String> {
        std::fs::read_dir(root().join("src/backend/shaders/cpu"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "rs"))
            .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            .filter(|stem| stem != "mod")
            .collect()
    }

    /// A stage is one name in three places: its shader file, its table entry and its twin
    /// `cpu/<name>.rs`. This fails for a shader without a twin (unless its `// twin:` line
    /// names one elsewhere or says why there is none) and for a twin without a shader (a
    /// twin of a shared include, `shaders_glsl/shared/<name>.glsl`, counts as one with).
    #[test]
    fn every_shader_has_a_twin_and_every_twin_a_shader() {
        let twins = twin_files();
        let declared =
            std::fs::read_to_string(root().join("src/backend/shaders/cpu/mod.rs")).unwrap();
        let mut problems = Vec::new();
        for shader in SHADERS {
            let file = twins.contains(shader.name);
            match shader.twin {
                Twin::Cpu if !file => problems.push(format!(
                    "{}: no twin: write src/backend/shaders/cpu/{}.rs, or say in the shader \
                     `// twin: <path>: <why>` or `// twin: none: <why>`",
                    shader.file, shader.name
                )),
                Twin::Elsewhere { path, .. } if !root().join(path).is_file() => {
                    problems.push(format!(
                        "{}: its twin line names {path}, which is not a file",
                        shader.file
                    ))
                }
                Twin::Elsewhere { .. } | Twin::None { .. } if file => problems.push(format!(
                    "{}: has src/backend/shaders/cpu/{}.rs, yet its twin line says otherwise",
                    shader.file, shader.name
                )),
                Twin::None { why } | Twin::Elsewhere { why, .. } if why.is_empty() => {
                    problems.push(format!("{}: its twin line gives no reason", shader.file))
                }
                _ => {}
            }
        }
        for twin in &twins {
            let stage = SHADERS
                .iter()
                .any(|s| s.name == twin && s.twin == Twin::Cpu);
            let include = root()
                .join(format!("shaders_glsl/shared/{twin}.glsl"))
                .is_file();
            if !stage && !include {
                problems.push(format!(
                    "src/backend/shaders/cpu/{twin}.rs: the twin of no shader (no stage, nor \
                     shaders_glsl/shared/{twin}.glsl, is named {twin})"
                ));
            }
            if !declared.contains(&format!("pub mod {twin};")) {
                problems.push(format!(
                    "src/backend/shaders/cpu/{twin}.rs: not declared (`pub mod {twin};` in cpu/mod.rs)"
                ));
            }
        }
        assert!(problems.is_empty(), "{}", problems.join("\n"));
    }

    /// The table holds what each backend needs: wgpu compiles the source, ash loads SPIR-V;
    /// compute stages have a workgroup; a stage written for both backends says why.
    #[test]
    fn entries_carry_what_their_backend_needs() {
        for shader in SHADERS {
            assert!(!shader.source.is_empty() && !shader.entry_points.is_empty());
            assert!(
                shader.file.ends_with(&format!(
                    "/{}.{}",
                    shader.name,
                    Path::new(shader.file)
                        .extension()
                        .unwrap()
                        .to_string_lossy()
                )),
                "{}",
                shader.file
            );
            for e in shader.entry_points {
                match shader.backend {
                    GpuBackend::Wgpu => assert!(e.spirv.is_empty(), "{}", shader.file),
                    GpuBackend::Ash => {
                        assert_eq!(&e.spirv[..4], &0x0723_0203u32.to_le_bytes());
                        assert!(e.bindings.iter().all(|b| b.group == 0), "{}", shader.file);
                    }
                }
                assert_eq!(
                    e.stage == StageKind::Compute,
                    shader.language != Language::GlslRayTracing
                );
                assert_eq!(
                    e.stage == StageKind::Compute,
                    e.threads() > 0,
                    "{}",
                    shader.file
                );
            }
            if let Some((other, twice)) = shader.also {
                let other = SHADERS.iter().find(|s| s.file == other).unwrap();
                assert_eq!(other.name, shader.name);
                assert_eq!(other.twin == Twin::Cpu, shader.twin == Twin::Cpu);
                assert_ne!(other.backend, shader.backend);
                assert_eq!(
                    twice == Twice::WgslAndGlsl,
                    (shader.language == Language::Wgsl) != (other.language == Language::Wgsl)
                );
            }
        }
        // The prepare stages and the voxel splat need atomics on wgpu (or sit with passes that
        // do), so they are WGSL there and GLSL on ash.
        for name in ["radix_sort", "hilbert_keys", "gather", "voxel_splat"] {
            let wgsl = SHADERS
                .iter()
                .find(|s| s.name == name && s.language == Language::Wgsl)
                .unwrap();
            assert!(matches!(wgsl.also, Some((_, Twice::WgslAndGlsl))), "{name}");
        }
        assert_eq!(on_wgpu::RADIX_SORT_SCAN.point().workgroup_size, [256, 1, 1]);
        assert_eq!(on_ash::RADIX_SORT_SCAN.point().workgroup_size, [256, 1, 1]);
        assert_eq!(on_wgpu::LBVH_RENDER.point().workgroup_size, [8, 8, 1]);
        assert!(on_wgpu::LBVH_RENDER.point().specialised);
        assert!(!on_wgpu::RADIX_SORT_COUNT.point().specialised);
        assert_eq!(
            on_ash::GATHER_VEC4S.to_string(),
            "shaders_glsl/vulkan/gather.comp:gather_vec4s"
        );
    }
}
