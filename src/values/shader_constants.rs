//! The constants Rust and the shaders share, each defined once, here.
//!
//! The shaders never spell these numbers: they include `generated/constants.glsl` or
//! `generated/constants.wgsl`, which [`glsl`] and [`wgsl`] write from the definitions below.
//! `build.rs` compiles this very file (`#[path]`, so it uses nothing of the crate) to validate
//! the kernels with that text, and the library's include resolver serves the same text at run
//! time, so a constant cannot differ between Rust and a shader.

/// Samples per baked 1D map (`values::tables`, `shaders_glsl/shared/maps.glsl`).
pub const TABLE_SIZE: usize = 256;
/// Where each map's table starts in the map-table buffer (floats): density, radius, optical
/// density, then the colour map as interleaved linear RGB (3 x `TABLE_SIZE`).
pub const TABLE_DENSITY: usize = 0;
/// The radius map's table.
pub const TABLE_RADIUS: usize = TABLE_SIZE;
/// The optical-density map's table.
pub const TABLE_OPTICAL: usize = 2 * TABLE_SIZE;
/// The colour map's table (3 x `TABLE_SIZE` floats).
pub const TABLE_COLOUR: usize = 3 * TABLE_SIZE;
/// Floats in the map-table buffer.
pub const TABLE_FLOATS: usize = 6 * TABLE_SIZE;

/// The shipped blue-noise mask's size (`assets/stbn_128x128x64.bin`), which the shaders index.
pub const STBN_WIDTH: u32 = 128;
/// The blue-noise mask's rows.
pub const STBN_HEIGHT: u32 = 128;
/// The blue-noise mask's slices in time.
pub const STBN_DEPTH: u32 = 64;
/// Toroidal offsets of the blue-noise mask per random dimension, so a pixel's different
/// decisions read different (decorrelated) mask values.
pub const NOISE_OFFSETS: [[u32; 2]; 3] = [[0, 0], [61, 29], [23, 97]];

/// Cluster boxes are padded by `max(|p|, r) · BOX_PAD` (4 ulp of an f32 coordinate), so the
/// f32 box holds every point the f32 sphere test accepts, and, with double-single positions,
/// every f32-rounded query point whose exact position lies in the exact sphere (the rounding of
/// the point, of the particle's hi part and of the box's own arithmetic add up to 7 · 2^-24 of
/// `max(|p|, r)` at most; `accel::clusters::cluster_box`).
pub const BOX_PAD: f32 = 4.0 * f32::EPSILON;

/// Below this, Phi counts as "no density": the sample has no colour (never NaN).
pub const PHI_EPSILON: f64 = 1e-30;

/// LBVH child pointers: the leaf flag (the low 31 bits are the cluster index).
pub const LBVH_LEAF: u32 = 0x8000_0000;
/// No node: a missing root, a root's parent, a cluster left out of the tree.
pub const LBVH_NONE: u32 = u32::MAX;
/// `leaf_parents` of the only leaf of a one-leaf tree (it is in the tree, with no parent).
pub const LBVH_ROOT_LEAF: u32 = 0xFFFF_FFFE;
/// The word a bound holds before the bottom-up pass writes it (a NaN no bound can be).
pub const LBVH_SENTINEL: u32 = u32::MAX;
/// The key of an empty cluster: above every Morton key (those use 30 bits).
pub const LBVH_EMPTY_KEY: u32 = u32::MAX;
/// Cells per axis of the Morton grid (10 bits).
pub const MORTON_CELLS: u32 = 1024;
/// Entries of the traversal stack: at least the deepest possible tree's depth (30 key bits +
/// 32 index bits = 62), so it cannot overflow.
pub const LBVH_STACK_SIZE: u32 = 64;
/// The most hits a GPU splatter's slab buffer holds (`--splat-k`; Knoll et al. used 31, the RBF
/// paper's port 15): the buffer lives in a ray payload or a kernel's private arrays.
pub const SPLAT_K_MAX: u32 = 64;

/// The light map's lattice jitter per texel is white noise of this seed (dimension 0, frame
/// 0), so that a map is the same for every frame under one light: it is computed once and
/// kept (`backend::cpu::owned`, `shared/integrators.glsl`'s `owned_depth_ray`).
pub const LIGHT_MAP_SEED: u32 = 0x4C49_4748;

/// What a brick kernel computes (`params.glsl`'s `Brick.task.x`): a brick's share of a frame
/// (`Backend::render_owned`), or its optical depth along primary rays (stochastic marching's,
/// or emission–absorption's occluding rays) or light map rays (`Backend::owned_depth`).
pub const OWNED_TASK_RENDER: u32 = 0;
/// See [`OWNED_TASK_RENDER`].
pub const OWNED_TASK_PRIMARY_DEPTH: u32 = 1;
/// See [`OWNED_TASK_RENDER`].
pub const OWNED_TASK_LIGHT_DEPTH: u32 = 2;
/// See [`OWNED_TASK_RENDER`].
pub const OWNED_TASK_OCCLUDING_DEPTH: u32 = 3;

/// Keys per radix-sort tile (`shaders_wgsl/radix_sort.wgsl`) and digits per pass.
pub const SORT_TILE: u32 = 4096;
/// Values of one radix-sort digit (4 bits a pass).
pub const SORT_RADIX: u32 = 16;

/// Bits per axis of the Hilbert keys particles are sorted by (`accel::hilbert`, and on the
/// device `shaders_wgsl/hilbert_keys.wgsl`).
pub const HILBERT_BITS: u32 = 21;

/// The Hilbert curve as a state machine over the 24 orientations a sub-cube's curve can
/// have: `HILBERT_STEP[8 s + o]` for orientation `s` and octant `o` (x·4 + y·2 + z, one bit of
/// each coordinate) is `digit | next << 3`, the octant's 3-bit place along the curve and the
/// orientation of the curve inside it. It is Skilling's curve exactly (the tests derive this
/// table from his transform and compare keys at every depth): one lookup per level replaces his
/// twenty-odd exchanges.
pub const HILBERT_STEP: [u8; 192] = [
    8, 17, 27, 2, 39, 46, 52, 5, 56, 71, 73, 86, 91, 20, 10, 13, 48, 1, 103, 110, 115, 18, 12, 21,
    126, 129, 29, 26, 79, 80, 140, 3, 148, 43, 37, 34, 127, 128, 78, 81, 156, 45, 35, 42, 31, 6,
    160, 105, 72, 87, 139, 4, 57, 70, 50, 53, 0, 171, 111, 76, 49, 58, 102, 61, 180, 143, 83, 184,
    69, 54, 66, 97, 16, 123, 9, 74, 47, 60, 38, 77, 132, 95, 85, 14, 67, 144, 82, 33, 142, 55, 185,
    96, 93, 116, 90, 11, 188, 107, 175, 176, 101, 98, 62, 65, 164, 109, 119, 22, 99, 106, 152, 41,
    174, 177, 63, 64, 117, 114, 92, 19, 30, 125, 161, 122, 7, 172, 104, 75, 130, 25, 133, 166, 179,
    136, 84, 191, 94, 15, 141, 28, 145, 32, 138, 51, 146, 155, 149, 36, 137, 24, 190, 167, 154,
    157, 147, 44, 169, 182, 120, 135, 162, 165, 121, 134, 187, 108, 168, 183, 118, 173, 23, 124,
    153, 170, 40, 59, 178, 113, 131, 88, 181, 158, 68, 151, 186, 163, 89, 112, 189, 100, 150, 159,
];

/// The specialisation constants (Vulkan constant ids; wgpu's pipeline-overridable constants
/// "0", "1", ...), in id order: their names and what their values mean.
pub const SPEC_CONSTANTS: [(&str, &str); 11] = [
    ("INTEGRATOR", "0 EA, 1 delta, 2 marching, 3 SS reference"),
    ("COLOUR_MODE", "0 post, 1 pre, 2 density"),
    ("NOISE_KIND", "0 STBN, 1 white"),
    ("CLUSTER_SIZE", "particles per box: 1, 2, 4, 8, 16"),
    (
        "RADIUS_MAP_VARIES",
        "1: look the radius map up per particle",
    ),
    (
        "DENSITY_MAP_VARIES",
        "1: look the density map up per particle",
    ),
    ("HAS_RADIUS_ATTRIBUTE", "1: per-particle radius buffer"),
    (
        "POSITION_DS",
        "1: positions as double-single (f32 hi + lo) pairs",
    ),
    (
        "RT_HIT_PER_PARTICLE",
        "ray tracing: 0 one report per cluster with its sum, 1 one per particle (the paper's)",
    ),
    (
        "COMPENSATED_SUM",
        "1: a point's clusters' sums added compensated (Kahan; backend::precision)",
    ),
    (
        "KERNEL",
        "the kernel: 0 the paper's Gaussian RBF, 1.. the SPH kernels of KERNEL_SUPPORT",
    ),
];
/// Indices into [`SPEC_CONSTANTS`].
pub mod spec {
    /// `INTEGRATOR`: which integrator.
    pub const INTEGRATOR: usize = 0;
    /// `COLOUR_MODE`: what the colour map is applied to.
    pub const COLOUR_MODE: usize = 1;
    /// `NOISE_KIND`: blue or white noise.
    pub const NOISE_KIND: usize = 2;
    /// `CLUSTER_SIZE`: particles per cluster box.
    pub const CLUSTER_SIZE: usize = 3;
    /// `RADIUS_MAP_VARIES`: whether the radius map is looked up per particle.
    pub const RADIUS_MAP_VARIES: usize = 4;
    /// `DENSITY_MAP_VARIES`: whether the density map is looked up per particle.
    pub const DENSITY_MAP_VARIES: usize = 5;
    /// `HAS_RADIUS_ATTRIBUTE`: whether there is a per-particle radius buffer.
    pub const HAS_RADIUS_ATTRIBUTE: usize = 6;
    /// `POSITION_DS`: whether positions are double-single pairs.
    pub const POSITION_DS: usize = 7;
    /// `RT_HIT_PER_PARTICLE`: whether ray tracing reports one hit per particle.
    pub const RT_HIT_PER_PARTICLE: usize = 8;
    /// `COMPENSATED_SUM`: whether cluster sums are added compensated.
    pub const COMPENSATED_SUM: usize = 9;
    /// `KERNEL`: which kernel.
    pub const KERNEL: usize = 10;
}

/// Values of the `KERNEL` specialisation constant (`values::Kernel`, method.md §2 and
/// docs/formats.md): the paper's Gaussian RBF, then the SPH kernels in the convention of
/// Price (2012), Phantom and sarracen, where h is the smoothing length and the support is a
/// multiple of it.
pub const KERNEL_GAUSSIAN_RBF: u32 = 0;
/// The M4 cubic spline, support 2h.
pub const KERNEL_SPH_CUBIC: u32 = 1;
/// The M6 quintic spline, support 3h.
pub const KERNEL_SPH_QUINTIC: u32 = 2;
/// Wendland C2, support 2h.
pub const KERNEL_SPH_WENDLAND_C2: u32 = 3;
/// Wendland C4, support 2h.
pub const KERNEL_SPH_WENDLAND_C4: u32 = 4;
/// Each kernel's support in units of h (indexed by `KERNEL`; the Gaussian's radius is its own
/// unit).
pub const KERNEL_SUPPORT: [f64; 5] = [1.0, 2.0, 3.0, 2.0, 2.0];
/// Each SPH kernel's 3D normalisation σ: `W(d, h) = σ / h³ · f(d / h)` integrates to 1 with
/// `f` as `values::kernel` writes it (the Gaussian RBF is not normalised: 1).
pub const KERNEL_SIGMA: [f64; 5] = [
    1.0,
    1.0 / std::f64::consts::PI,
    1.0 / (120.0 * std::f64::consts::PI),
    21.0 / (16.0 * std::f64::consts::PI),
    495.0 / (256.0 * std::f64::consts::PI),
];

/// Values of the `INTEGRATOR`, `COLOUR_MODE` and `NOISE_KIND` specialisation constants.
pub const INTEGRATOR_EA: u32 = 0;
/// Single scattering by delta tracking.
pub const INTEGRATOR_DELTA: u32 = 1;
/// Single scattering by stochastic ray marching.
pub const INTEGRATOR_MARCHING: u32 = 2;
/// Single scattering by deterministic marching with a shadow ray per sample.
pub const INTEGRATOR_SS_REFERENCE: u32 = 3;
/// Colour-map the averaged attribute.
pub const COLOUR_POST: u32 = 0;
/// Average the colour-mapped particles.
pub const COLOUR_PRE: u32 = 1;
/// Colour by density only.
pub const COLOUR_DENSITY: u32 = 2;
/// Spatiotemporal blue noise.
pub const NOISE_STBN: u32 = 0;
/// White noise (a hash).
pub const NOISE_WHITE: u32 = 1;

/// The unsigned constants both languages get, with their names there.
fn unsigned() -> Vec<(&'static str, u64)> {
    vec![
        ("TABLE_SIZE", TABLE_SIZE as u64),
        ("TABLE_DENSITY", TABLE_DENSITY as u64),
        ("TABLE_RADIUS", TABLE_RADIUS as u64),
        ("TABLE_OPTICAL", TABLE_OPTICAL as u64),
        ("TABLE_COLOUR", TABLE_COLOUR as u64),
        ("STBN_WIDTH", STBN_WIDTH.into()),
        ("STBN_HEIGHT", STBN_HEIGHT.into()),
        ("STBN_DEPTH", STBN_DEPTH.into()),
        ("LBVH_LEAF", LBVH_LEAF.into()),
        ("LBVH_NONE", LBVH_NONE.into()),
        ("LBVH_ROOT_LEAF", LBVH_ROOT_LEAF.into()),
        ("LBVH_SENTINEL", LBVH_SENTINEL.into()),
        ("LBVH_EMPTY_KEY", LBVH_EMPTY_KEY.into()),
        ("MORTON_CELLS", MORTON_CELLS.into()),
        ("LBVH_STACK_SIZE", LBVH_STACK_SIZE.into()),
        ("SPLAT_K_MAX", SPLAT_K_MAX.into()),
        ("LIGHT_MAP_SEED", LIGHT_MAP_SEED.into()),
        ("OWNED_TASK_RENDER", OWNED_TASK_RENDER.into()),
        ("OWNED_TASK_PRIMARY_DEPTH", OWNED_TASK_PRIMARY_DEPTH.into()),
        ("OWNED_TASK_LIGHT_DEPTH", OWNED_TASK_LIGHT_DEPTH.into()),
        (
            "OWNED_TASK_OCCLUDING_DEPTH",
            OWNED_TASK_OCCLUDING_DEPTH.into(),
        ),
        ("SORT_TILE", SORT_TILE.into()),
        ("SORT_RADIX", SORT_RADIX.into()),
        ("HILBERT_BITS", HILBERT_BITS.into()),
        ("INTEGRATOR_EA", INTEGRATOR_EA.into()),
        ("INTEGRATOR_DELTA", INTEGRATOR_DELTA.into()),
        ("INTEGRATOR_MARCHING", INTEGRATOR_MARCHING.into()),
        ("INTEGRATOR_SS_REFERENCE", INTEGRATOR_SS_REFERENCE.into()),
        ("COLOUR_POST", COLOUR_POST.into()),
        ("COLOUR_PRE", COLOUR_PRE.into()),
        ("COLOUR_DENSITY", COLOUR_DENSITY.into()),
        ("NOISE_STBN", NOISE_STBN.into()),
        ("NOISE_WHITE", NOISE_WHITE.into()),
        ("KERNEL_GAUSSIAN_RBF", KERNEL_GAUSSIAN_RBF.into()),
        ("KERNEL_SPH_CUBIC", KERNEL_SPH_CUBIC.into()),
        ("KERNEL_SPH_QUINTIC", KERNEL_SPH_QUINTIC.into()),
        ("KERNEL_SPH_WENDLAND_C2", KERNEL_SPH_WENDLAND_C2.into()),
        ("KERNEL_SPH_WENDLAND_C4", KERNEL_SPH_WENDLAND_C4.into()),
    ]
}

const HEADER: &str = "// Generated from src/values/shader_constants.rs (the one definition of each constant);\n// not a file on disk: edit the Rust.\n";

/// The GLSL text of `generated/constants.glsl`: every constant, the specialisation-constant
/// declarations, and `noise_offset(dim)`.
pub fn glsl() -> String {
    let mut out = String::from(HEADER);
    for (name, value) in unsigned() {
        out.push_str(&format!("const uint {name} = {value}u;\n"));
    }
    out.push_str(&format!("const float PHI_EPSILON = {PHI_EPSILON:e};\n"));
    out.push_str(&format!("const float BOX_PAD = {BOX_PAD:e};\n"));
    for (id, (name, meaning)) in SPEC_CONSTANTS.iter().enumerate() {
        // CLUSTER_SIZE's default is 1 (a cluster is never empty); every other default is 0.
        let default = u32::from(id == spec::CLUSTER_SIZE);
        out.push_str(&format!(
            "layout(constant_id = {id}) const uint {name} = {default}u; // {meaning}\n"
        ));
    }
    out.push_str("uvec2 noise_offset(uint dim) {\n");
    for (dim, [x, y]) in NOISE_OFFSETS.iter().enumerate().skip(1) {
        out.push_str(&format!(
            "    if (dim == {dim}u) {{\n        return uvec2({x}u, {y}u);\n    }}\n"
        ));
    }
    let [x, y] = NOISE_OFFSETS[0];
    out.push_str(&format!("    return uvec2({x}u, {y}u);\n}}\n"));
    // The kernel's support in h and its σ · support³ (the normalisation over the radius,
    // `rbf.glsl`'s particle_weight), for the KERNEL in use.
    for (name, values) in [
        ("kernel_support", KERNEL_SUPPORT),
        (
            "kernel_radius_norm",
            std::array::from_fn(|k| KERNEL_SIGMA[k] * KERNEL_SUPPORT[k].powi(3)),
        ),
    ] {
        out.push_str(&format!("float {name}() {{\n"));
        for (k, v) in values.iter().enumerate().skip(1) {
            out.push_str(&format!(
                "    if (KERNEL == {k}u) {{\n        return {v:e};\n    }}\n"
            ));
        }
        out.push_str(&format!("    return {:e};\n}}\n", values[0]));
    }
    out
}

/// The GLSL text of `generated/hilbert_step.glsl`: the Hilbert state table, for the ash
/// backend's compute kernels (compiled by glslc in build.rs; kept out of
/// `generated/constants.glsl`, which naga's GLSL front end reads for every wgpu kernel).
pub fn hilbert_glsl() -> String {
    let table: Vec<String> = HILBERT_STEP.iter().map(|e| format!("{e}u")).collect();
    format!(
        "{HEADER}const uint HILBERT_STEP[{n}] = uint[{n}]({});\n",
        table.join(", "),
        n = HILBERT_STEP.len()
    )
}

/// The WGSL text of `generated/constants.wgsl`: every constant, and the Hilbert state table.
pub fn wgsl() -> String {
    let mut out = String::from(HEADER);
    for (name, value) in unsigned() {
        out.push_str(&format!("const {name}: u32 = {value}u;\n"));
    }
    let table: Vec<String> = HILBERT_STEP.iter().map(|e| format!("{e}u")).collect();
    out.push_str(&format!(
        "const HILBERT_STEP: array<u32, {}> = array<u32, {}>({});\n",
        HILBERT_STEP.len(),
        HILBERT_STEP.len(),
        table.join(", ")
    ));
    out
}
