//! GPU-side definitions shared by the GPU backends: the shader sources (GLSL under
//! `shaders_glsl/`, WGSL under `shaders_wgsl/`) with their includes resolved, and the
//! `#[repr(C)]` twins of the structs in `shaders_glsl/shared/params.glsl`.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use crate::values::FrameParams;
use crate::values::shader_constants::{
    self, COLOUR_DENSITY, COLOUR_POST, COLOUR_PRE, INTEGRATOR_DELTA, INTEGRATOR_EA,
    INTEGRATOR_MARCHING, INTEGRATOR_SS_REFERENCE, NOISE_STBN, NOISE_WHITE, SPEC_CONSTANTS,
    TABLE_COLOUR, TABLE_DENSITY, TABLE_FLOATS, TABLE_OPTICAL, TABLE_RADIUS, TABLE_SIZE, spec,
};
use crate::values::{ColourMode, Integrator, NoiseKind};

pub mod cpu;

include!("include.rs");

/// The shared GLSL files, by the name kernels include them with.
pub const SHARED_GLSL: &[(&str, &str)] = &[
    (
        "shared/params.glsl",
        include_str!("../../../shaders_glsl/shared/params.glsl"),
    ),
    (
        "shared/maps.glsl",
        include_str!("../../../shaders_glsl/shared/maps.glsl"),
    ),
    (
        "shared/noise.glsl",
        include_str!("../../../shaders_glsl/shared/noise.glsl"),
    ),
    (
        "shared/rbf.glsl",
        include_str!("../../../shaders_glsl/shared/rbf.glsl"),
    ),
    (
        "shared/shade.glsl",
        include_str!("../../../shaders_glsl/shared/shade.glsl"),
    ),
    (
        "shared/integrators.glsl",
        include_str!("../../../shaders_glsl/shared/integrators.glsl"),
    ),
    (
        "shared/splat.glsl",
        include_str!("../../../shaders_glsl/shared/splat.glsl"),
    ),
    (
        "shared/splat_pixel.glsl",
        include_str!("../../../shaders_glsl/shared/splat_pixel.glsl"),
    ),
    (
        "shared/voxel_sample.glsl",
        include_str!("../../../shaders_glsl/shared/voxel_sample.glsl"),
    ),
    (
        "shared/cluster_box.glsl",
        include_str!("../../../shaders_glsl/shared/cluster_box.glsl"),
    ),
    (
        "shared/lbvh.glsl",
        include_str!("../../../shaders_glsl/shared/lbvh.glsl"),
    ),
    (
        "shared/lbvh_splat.glsl",
        include_str!("../../../shaders_glsl/shared/lbvh_splat.glsl"),
    ),
    (
        "wgpu/split.glsl",
        include_str!("../../../shaders_glsl/wgpu/split.glsl"),
    ),
    (
        "wgpu/split_tree.glsl",
        include_str!("../../../shaders_glsl/wgpu/split_tree.glsl"),
    ),
];

/// The shared WGSL files of the LBVH build and step-preparation passes, by the name passes include them with.
pub const SHARED_WGSL: &[(&str, &str)] = &[
    (
        "shared/tree_params.wgsl",
        include_str!("../../../shaders_wgsl/shared/tree_params.wgsl"),
    ),
    (
        "shared/invocation.wgsl",
        include_str!("../../../shaders_wgsl/shared/invocation.wgsl"),
    ),
    (
        "shared/split_boxes.wgsl",
        include_str!("../../../shaders_wgsl/shared/split_boxes.wgsl"),
    ),
    (
        "shared/prepare_params.wgsl",
        include_str!("../../../shaders_wgsl/shared/prepare_params.wgsl"),
    ),
];

/// The text of an included file: a shared shader file, or the generated constants.
fn shared_file(name: &str, language: ShaderLanguage) -> Option<String> {
    let (generated, text, files) = match language {
        ShaderLanguage::Glsl => (
            "generated/constants.glsl",
            shader_constants::glsl as fn() -> String,
            SHARED_GLSL,
        ),
        ShaderLanguage::Wgsl => (
            "generated/constants.wgsl",
            shader_constants::wgsl as fn() -> String,
            SHARED_WGSL,
        ),
    };
    if name == generated {
        return Some(text());
    }
    files
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| (*s).to_owned())
}

/// WGSL `source` with its `#include "shared/..."` lines replaced by the shared files (and
/// `generated/constants.wgsl` by [`shader_constants::wgsl`]), for `SPLIT_PARTS` =
/// `split_parts` (see [`select_split_parts`]).
pub fn wgsl_with_includes(source: &str, split_parts: u32) -> String {
    let resolved = resolve_includes(
        source,
        &|name| shared_file(name, ShaderLanguage::Wgsl),
        ShaderLanguage::Wgsl,
    )
    .expect("build.rs validated every include");
    select_split_parts(&resolved, split_parts).expect("build.rs validated every variant")
}

/// `source` with its `#include "shared/..."` lines replaced by the shared files (and
/// `generated/constants.glsl` by [`shader_constants::glsl`]).
pub fn glsl_with_includes(source: &str) -> String {
    resolve_includes(
        source,
        &|name| shared_file(name, ShaderLanguage::Glsl),
        ShaderLanguage::Glsl,
    )
    .expect("build.rs validated every include")
}

/// `params.glsl`'s `Frame`, in local coordinates (data coordinates minus `origin`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuFrame {
    pub eye: [f32; 4],
    pub forward: [f32; 4],
    pub right: [f32; 4],
    pub up: [f32; 4],
    pub box_min: [f32; 4],
    pub box_max: [f32; 4],
    pub light: [f32; 4],
    pub background: [f32; 4],
    pub shading: [f32; 4],
    pub image: [u32; 4],
}

fn v4(v: DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

impl GpuFrame {
    /// The frame constants, with positions made relative to `origin` in f64 before rounding.
    pub fn new(p: &FrameParams, origin: DVec3) -> GpuFrame {
        GpuFrame {
            eye: v4(p.camera.eye - origin, 0.0),
            forward: v4(p.camera.forward, 0.0),
            right: v4(p.camera.right, 0.0),
            up: v4(p.camera.up, 0.0),
            box_min: v4(p.box_min - origin, p.dt),
            box_max: v4(p.box_max - origin, p.opacity_threshold),
            light: v4(p.light_dir, p.light_intensity),
            background: [
                p.background[0] as f32,
                p.background[1] as f32,
                p.background[2] as f32,
                p.ambient as f32,
            ],
            shading: [
                p.phi_ref as f32,
                p.density_scale as f32,
                p.majorant as f32,
                0.0,
            ],
            image: [p.width, p.height, p.frame, p.seed],
        }
    }
}

/// `params.glsl`'s `Voxels` (and `shaders_wgsl/voxel_splat.wgsl`'s): the voxel baseline's
/// grid, and the range one splat pass covers.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuVoxels {
    pub origin: [f32; 4],
    pub origin_lo: [f32; 4],
    pub cell: [f32; 4],
    pub dims: [u32; 4],
    pub range: [u32; 4],
    pub channels: [u32; 4],
}

impl GpuVoxels {
    /// The grid of `geometry` in local coordinates (data coordinates minus `origin`, in f64
    /// before rounding; the first centre also as a double-single pair), with rows of
    /// `row_cells` cells in the splat's buffer, each cell receiving the sums `colour` needs.
    pub fn new(
        geometry: &crate::backend::voxel::VoxelGeometry,
        origin: DVec3,
        row_cells: u32,
        colour: ColourMode,
    ) -> GpuVoxels {
        // Phi, and a scalar (post-classification) or RGB (pre-) Theta numerator.
        let channels = match colour {
            ColourMode::Density => 1,
            ColourMode::Post => 2,
            ColourMode::Pre => 4,
        };
        let first = geometry.first_centre() - origin;
        let hi = first.as_vec3().as_dvec3();
        let d = geometry.dims;
        GpuVoxels {
            origin: v4(first, 0.0),
            origin_lo: v4(first - hi, 0.0),
            cell: v4(geometry.cell(), 0.0),
            dims: [d[0] as u32, d[1] as u32, d[2] as u32, row_cells],
            range: [0; 4],
            channels: [channels, 0, 0, 0],
        }
    }
}

/// `params.glsl`'s `Field`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuField {
    /// Global radius R, constant radius-map value, constant density-map value, and
    /// k = 4.5 / (R m)² (rounded once from f64) for the exponent where every particle has that
    /// radius (`rbf_exponent` in `rbf.glsl`).
    pub radius: [f32; 4],
    /// Particles, clusters; the wgpu backend's part lengths (`shaders_glsl/wgpu/split.glsl`;
    /// it sets them when it writes the uniform, the Vulkan kernels ignore them).
    pub counts: [u32; 4],
    /// Where an SPH kernel's volumes start in the radius-attribute buffer (floats), then
    /// unused.
    pub factors: [u32; 4],
}

/// The specialisation constants (`shader_constants::SPEC_CONSTANTS` names and numbers them).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SpecConstants {
    pub integrator: u32,
    pub colour_mode: u32,
    pub noise_kind: u32,
    pub cluster_size: u32,
    pub radius_map_varies: u32,
    pub density_map_varies: u32,
    pub has_radius_attribute: u32,
    pub position_ds: u32,
    pub rt_hit_per_particle: u32,
    pub compensated_sum: u32,
    pub kernel: u32,
}

impl SpecConstants {
    /// In constant_id order: Vulkan's specialisation map entries, and the keys naga 30 gives
    /// wgpu's pipeline-overridable constants ("0", "1", ...).
    pub fn values(&self) -> [u32; SPEC_CONSTANTS.len()] {
        let mut v = [0; SPEC_CONSTANTS.len()];
        v[spec::INTEGRATOR] = self.integrator;
        v[spec::COLOUR_MODE] = self.colour_mode;
        v[spec::NOISE_KIND] = self.noise_kind;
        v[spec::CLUSTER_SIZE] = self.cluster_size;
        v[spec::RADIUS_MAP_VARIES] = self.radius_map_varies;
        v[spec::DENSITY_MAP_VARIES] = self.density_map_varies;
        v[spec::HAS_RADIUS_ATTRIBUTE] = self.has_radius_attribute;
        v[spec::POSITION_DS] = self.position_ds;
        v[spec::RT_HIT_PER_PARTICLE] = self.rt_hit_per_particle;
        v[spec::COMPENSATED_SUM] = self.compensated_sum;
        v[spec::KERNEL] = self.kernel;
        v
    }

    pub fn integrator_id(i: Integrator) -> u32 {
        match i {
            Integrator::Ea => INTEGRATOR_EA,
            Integrator::Delta => INTEGRATOR_DELTA,
            Integrator::Marching => INTEGRATOR_MARCHING,
            Integrator::SsReference => INTEGRATOR_SS_REFERENCE,
        }
    }

    pub fn colour_id(c: ColourMode) -> u32 {
        match c {
            ColourMode::Post => COLOUR_POST,
            ColourMode::Pre => COLOUR_PRE,
            ColourMode::Density => COLOUR_DENSITY,
        }
    }

    pub fn noise_id(n: NoiseKind) -> u32 {
        match n {
            NoiseKind::Stbn => NOISE_STBN,
            NoiseKind::White => NOISE_WHITE,
        }
    }
}

/// The map-table buffer of `maps.glsl`: density, radius, optical density, then the colour map
/// as interleaved linear RGB, at the `TABLE_*` offsets of `shader_constants`.
pub fn pack_map_tables(
    density: &[f32],
    radius: &[f32],
    optical: &[f32],
    colour: &[[f32; 3]],
) -> Vec<f32> {
    assert!(
        density.len() == TABLE_SIZE
            && radius.len() == TABLE_SIZE
            && optical.len() == TABLE_SIZE
            && colour.len() == TABLE_SIZE
    );
    let mut out = vec![0.0; TABLE_FLOATS];
    out[TABLE_DENSITY..TABLE_DENSITY + TABLE_SIZE].copy_from_slice(density);
    out[TABLE_RADIUS..TABLE_RADIUS + TABLE_SIZE].copy_from_slice(radius);
    out[TABLE_OPTICAL..TABLE_OPTICAL + TABLE_SIZE].copy_from_slice(optical);
    for (i, rgb) in colour.iter().enumerate() {
        out[TABLE_COLOUR + 3 * i..TABLE_COLOUR + 3 * i + 3].copy_from_slice(rgb);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_parts_blocks_select_their_variant_and_refuse_what_they_cannot_do() {
        let source = "a\n#if SPLIT_PARTS > 1\nsplit\n#else\nwhole\n#endif\nb\n#if SPLIT_PARTS > 1\nmore\n#endif\n";
        let lines = |parts| {
            select_split_parts(source, parts)
                .unwrap()
                .lines()
                .filter(|l| !l.is_empty())
                .collect::<Vec<_>>()
                .join(" ")
        };
        assert_eq!(lines(1), "a whole b");
        assert_eq!(lines(4), "a split b more");
        // Line numbers are kept for naga's error messages.
        assert_eq!(select_split_parts(source, 1).unwrap().lines().count(), 10);
        for (bad, why) in [
            (
                "#if SPLIT_PARTS > 1\n#if SPLIT_PARTS > 1\n#endif\n#endif\n",
                "line 2",
            ),
            ("#ifdef X\n#endif\n", "'#ifdef X' is not supported"),
            ("#else\n", "line 1"),
            ("#if SPLIT_PARTS > 1\nx\n", "without '#endif'"),
        ] {
            let e = select_split_parts(bad, 1).unwrap_err();
            assert!(e.contains(why), "{bad:?}: {e}");
        }
        // Both variants of every WGSL pass resolve (build.rs validates them with naga).
        for parts in SPLIT_PARTS_VARIANTS {
            let fit =
                wgsl_with_includes(include_str!("../../../shaders_wgsl/lbvh_fit.wgsl"), parts);
            assert_eq!(fit.contains("nodes3"), parts > 1);
        }
    }

    #[test]
    fn split_arrays_declare_every_part_and_select_it_in_the_accessor() {
        let glsl = split_array(
            " particles 10 vec4 readonly counts.z get:particle",
            ShaderLanguage::Glsl,
        )
        .unwrap();
        for k in 0..4 {
            assert!(glsl.contains(&format!(
                "binding = {}) readonly buffer Particles{k} {{ vec4 particles{k}[]; }};",
                10 + k
            )));
        }
        let one_part = select_split_parts(&glsl, 1).unwrap();
        assert!(one_part.contains("return particles0[i];") && !one_part.contains("particles1"));
        let four = select_split_parts(&glsl, 4).unwrap();
        assert_eq!(four.matches("i -= len;").count(), 3);
        assert!(four.contains("return particles3[i];"));
        let wgsl = split_array(
            " nodes 14 atomic<u32> read_write params.w exchange:swap store:put",
            ShaderLanguage::Wgsl,
        )
        .unwrap();
        assert!(wgsl.contains("fn swap(index: u32, value: u32) -> u32"));
        assert!(wgsl.contains("atomicStore(&nodes3[i], value);"));
        for (bad, why) in [
            (" x 1 vec4 readonly len", "no accessor"),
            (" x y vec4 readonly len get:f", "not a number"),
            (" x 1 vec4 readonly len frob:f", "no op 'frob'"),
            (" x 1", "expected NAME"),
        ] {
            let e = split_array(bad, ShaderLanguage::Glsl).unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn includes_resolve_once_and_name_missing_files() {
        let files = |name: &str| match name {
            "a" => Some("A\n#include \"b\"\n".to_owned()),
            "b" => Some("B\n".to_owned()),
            _ => None,
        };
        let out = resolve_includes(
            "#include \"a\"\n#include \"b\"\nmain",
            &files,
            ShaderLanguage::Glsl,
        )
        .unwrap();
        assert_eq!(out.matches("\nB\n").count(), 1);
        assert!(out.trim_end().ends_with("main"));
        let e = resolve_includes("#include \"zzz\"", &files, ShaderLanguage::Glsl).unwrap_err();
        assert!(e.contains("zzz"));
        assert_eq!(std::mem::size_of::<GpuFrame>(), 160);
        assert_eq!(std::mem::size_of::<GpuVoxels>(), 96);
    }
}
