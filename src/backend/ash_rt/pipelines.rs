//! The descriptor layout, the ray-tracing pipeline (one per specialisation variant, compiled
//! once per process and cached in the [`Context`]), its shader binding table, and the compute
//! pipelines.
//!
//! Shaders (`shaders_glsl/vulkan/`, compiled by build.rs with glslc; the shader table's
//! [`on_ash`] names each, and the descriptor-set layout is the union of their reflected
//! bindings, [`set_bindings`]):
//! - `render.rgen`: the shared integrator (`shared/integrators.glsl`) per pixel, adding the
//!   frame into the accumulation buffer; `query.rgen`: the field at points from a buffer.
//!   Both define `field_query(x)` (`vulkan/field_query.glsl`): one ray from x along (1, 1, 1)
//!   with tmin = tmax = 0.
//! - `particle.rint`: tests each particle of the hit box (one box per cluster of
//!   `CLUSTER_SIZE` particles) and reports (d², r, t) for each that contains the point;
//!   `particle.rahit`: adds the particle's RBF term into the payload and ignores the hit, so
//!   traversal goes on; `empty.rmiss`.
//! - `blas_boxes.comp`: the AABB of each cluster from positions, radius map and global radius.
//! - `hilbert_keys.comp`, `radix_sort.comp` (entry points count, scan, scatter), `gather.comp`
//!   (gather_words, gather_vec4s): preparing a step (`prepare.rs`).
//! - `lbvh_query.comp`, `lbvh_render.comp`: the same queries and integrators with the shared
//!   LBVH stack traversal (`shared/lbvh.glsl`) in place of the RT pipeline, for the
//!   same-device hardware-versus-software comparison (the paper's Fig. 10a).
//!
//! - `splat.rgen`, `splat.rint`, `splat.rahit`: Knoll et al.'s splatter (the Table 3
//!   baseline), its own pipeline ([`RtProgram::Splat`]), made only when a scene splats;
//!   `lbvh_splat.comp` its LBVH twin.
//! - `owned.rgen` over the field's `particle.*`: a brick's share of a distributed frame, its own
//!   pipeline ([`RtProgram::Owned`]), made only when a brick renders; `lbvh_owned.comp` its
//!   LBVH twin.
//!
//! Shader groups of the field pipeline: 0 render raygen, 1 query raygen, 2 miss, 3 the
//! procedural hit group (intersection + any-hit); of the splat pipeline: 0 raygen, 1 miss, 2
//! the hit group; of the owned pipeline likewise.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::{Context, Layouts, RtProgram, device_error, vk_error};
use super::resources::Buffer;
use crate::backend::BackendError;
use crate::backend::shaders::table::{BindingKind, GpuBackend, StageKind};
use crate::backend::shaders::{Entry, SHADERS, SpecConstants, on_ash};
use crate::values::shader_constants::SPEC_CONSTANTS;

/// The names of the descriptor bindings (set 0) the backend writes, as
/// `shaders_glsl/vulkan/bindings.glsl` declares them; the layout itself is [`set_bindings`],
/// reflected from the shaders. Bindings 2, 3 and 9 (particles, radius attributes, boxes) are
/// gone: those arrays grow with the step and are reached by device address (`Push`), so no
/// binding limit applies.
pub mod binding {
    /// The TLAS.
    pub const TLAS: u32 = 0;
    /// The frame's parameters (`Params`: frame, field and voxel uniforms).
    pub const PARAMS: u32 = 1;
    /// The maps' baked tables.
    pub const TABLES: u32 = 4;
    /// The blue-noise mask.
    pub const STBN: u32 = 5;
    /// A query launch's points.
    pub const QUERY_POINTS: u32 = 7;
    /// A query launch's results.
    pub const QUERY_RESULTS: u32 = 8;
    /// The LBVH's nodes (the traversal without RT hardware).
    pub const LBVH_NODES: u32 = 10;
    /// The LBVH's boxes.
    pub const LBVH_BOXES: u32 = 11;
}

/// The descriptor type of a binding of the shader table.
fn descriptor_type(kind: BindingKind) -> vk::DescriptorType {
    match kind {
        BindingKind::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
        BindingKind::Storage { .. } => vk::DescriptorType::STORAGE_BUFFER,
        BindingKind::Texture => vk::DescriptorType::SAMPLED_IMAGE,
        BindingKind::Sampler => vk::DescriptorType::SAMPLER,
        BindingKind::AccelerationStructure => vk::DescriptorType::ACCELERATION_STRUCTURE_KHR,
    }
}

/// The shader stage flag of a stage kind.
fn stage_flags(stage: StageKind) -> vk::ShaderStageFlags {
    match stage {
        StageKind::Compute => vk::ShaderStageFlags::COMPUTE,
        StageKind::RayGeneration => vk::ShaderStageFlags::RAYGEN_KHR,
        StageKind::Intersection => vk::ShaderStageFlags::INTERSECTION_KHR,
        StageKind::AnyHit => vk::ShaderStageFlags::ANY_HIT_KHR,
        StageKind::ClosestHit => vk::ShaderStageFlags::CLOSEST_HIT_KHR,
        StageKind::Miss => vk::ShaderStageFlags::MISS_KHR,
    }
}

/// The one descriptor set every ash pipeline binds (set 0): each binding any ash stage uses,
/// as the shader table reflects it from the SPIR-V, with its descriptor type and the stages
/// that use it, by binding.
pub fn set_bindings() -> Vec<(u32, vk::DescriptorType, vk::ShaderStageFlags)> {
    let mut out: Vec<(u32, vk::DescriptorType, vk::ShaderStageFlags)> = Vec::new();
    for shader in SHADERS.iter().filter(|s| s.backend == GpuBackend::Ash) {
        for entry in shader.entry_points {
            for b in entry.bindings {
                let (ty, stage) = (descriptor_type(b.kind), stage_flags(entry.stage));
                match out.iter_mut().find(|(n, ..)| *n == b.binding) {
                    Some((_, t, s)) => {
                        assert_eq!(*t, ty, "binding {} differs in {}", b.binding, shader.file);
                        *s |= stage;
                    }
                    None => out.push((b.binding, ty, stage)),
                }
            }
        }
    }
    out.sort_by_key(|b| b.0);
    out
}

/// The push constants of every kernel (`Push` in bindings.glsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Push {
    /// Items to process (queries, boxes).
    pub count: u32,
    /// Row width of a 2D launch over a 1D array.
    pub width: u32,
    /// 1: the frame replaces the accumulation instead of adding to it.
    pub first_frame: u32,
    /// 1: a query launch whose points carry lo parts (double-single positions).
    pub query_lo: u32,
    /// Device addresses of the step's particles, radius attributes and BLAS input boxes, of
    /// the frame's accumulation and of the particles' lo parts (filled in by the backend when
    /// it records a dispatch; 0 for what the step does not have).
    pub particle_address: u64,
    /// The radius attributes' device address (0 without them).
    pub radius_address: u64,
    /// The BLAS input boxes' device address.
    pub boxes_address: u64,
    /// The frame's accumulation's device address.
    pub accum_address: u64,
    /// The particles' lo parts' device address (0 without double-single positions).
    pub particle_lo_address: u64,
    /// The voxel baseline's grid (0 before a voxelisation).
    pub voxel_address: u64,
    /// A brick kernel's brick, output and inputs (`lbvh_owned.comp`; 0 for every other launch).
    pub owned_address: u64,
}

/// The push constants of the kernels that prepare a step (`PreparePush` in
/// `shaders_glsl/vulkan/prepare.glsl`): the Hilbert grid, counts, and each pass's arrays by
/// device address.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PreparePush {
    /// The Hilbert grid's origin: a cell is `(p - grid_lo) * grid_scale`.
    pub grid_lo: [f32; 4],
    /// The Hilbert grid's cells per unit length.
    pub grid_scale: [f32; 4],
    /// Elements to process (particles, keys).
    pub count: u32,
    /// The sort pass's digit, as a bit shift.
    pub shift: u32,
    /// The sort's tiles of `SORT_TILE` keys.
    pub tiles: u32,
    /// Row width of a 2D launch over a 1D array.
    pub width: u32,
    /// Each pass's arrays by device address, in the order its kernel's comment gives.
    pub arrays: [u64; 5],
}

impl Layouts {
    /// The layouts, their set-0 bindings reflected from the shader table.
    pub fn new(device: &ash::Device) -> Result<Layouts, vk::Result> {
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = set_bindings()
            .into_iter()
            .map(|(binding, ty, stages)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(stages)
            })
            .collect();
        // SAFETY: valid create infos; destroyed in `destroy`.
        unsafe {
            let set = device.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )?;
            let sets = [set];
            let push = [vk::PushConstantRange::default()
                .stage_flags(vk::ShaderStageFlags::ALL)
                .size(std::mem::size_of::<Push>() as u32)];
            let pipeline = device
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&sets)
                        .push_constant_ranges(&push),
                    None,
                )
                .inspect_err(|_| device.destroy_descriptor_set_layout(set, None))?;
            let prepare_push = [vk::PushConstantRange::default()
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
                .size(std::mem::size_of::<PreparePush>() as u32)];
            let prepare = device
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&prepare_push),
                    None,
                )
                .inspect_err(|_| {
                    device.destroy_pipeline_layout(pipeline, None);
                    device.destroy_descriptor_set_layout(set, None);
                })?;
            Ok(Layouts {
                set,
                pipeline,
                prepare,
            })
        }
    }

    /// # Safety
    /// No pipeline or set made with these layouts may be in use.
    pub unsafe fn destroy(&self, device: &ash::Device) {
        // SAFETY: per the contract.
        unsafe {
            device.destroy_pipeline_layout(self.pipeline, None);
            device.destroy_pipeline_layout(self.prepare, None);
            device.destroy_descriptor_set_layout(self.set, None);
        }
    }
}

/// Whether a compute kernel prepares a step: it binds no descriptor (every array by address,
/// `PreparePush`) and reads no specialisation constant, so it uses the push-only layout.
fn prepares(kernel: Entry) -> bool {
    kernel.point().bindings.is_empty()
}

/// Shader modules destroyed when dropped.
struct Modules<'a> {
    device: &'a ash::Device,
    modules: Vec<vk::ShaderModule>,
}

impl Modules<'_> {
    fn load(&mut self, entry: Entry) -> Result<vk::ShaderModule, BackendError> {
        debug_assert_eq!(entry.shader().backend, GpuBackend::Ash, "{entry}");
        let spirv = entry.point().spirv;
        let words = ash::util::read_spv(&mut Cursor::new(spirv))
            .map_err(|e| device_error("reading SPIR-V", e))?;
        // SAFETY: valid SPIR-V produced by glslc at build time.
        let m = unsafe {
            self.device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
        }
        .map_err(|e| vk_error("creating a shader module", e))?;
        self.modules.push(m);
        Ok(m)
    }
}

impl Drop for Modules<'_> {
    fn drop(&mut self) {
        for &m in &self.modules {
            // SAFETY: modules may be destroyed once the pipelines using them exist.
            unsafe { self.device.destroy_shader_module(m, None) };
        }
    }
}

const SPEC_ENTRIES: [vk::SpecializationMapEntry; SPEC_CONSTANTS.len()] = {
    let mut e = [vk::SpecializationMapEntry {
        constant_id: 0,
        offset: 0,
        size: 4,
    }; SPEC_CONSTANTS.len()];
    let mut i = 0;
    while i < SPEC_CONSTANTS.len() {
        e[i].constant_id = i as u32;
        e[i].offset = 4 * i as u32;
        i += 1;
    }
    e
};

impl RtProgram {
    /// Its stages: the raygens, then the miss, intersection and any-hit stages.
    fn stages(self) -> (&'static [Entry], [Entry; 3]) {
        let miss = on_ash::EMPTY_RMISS;
        match self {
            RtProgram::Field => (
                &[on_ash::RENDER_RGEN, on_ash::QUERY_RGEN],
                [miss, on_ash::PARTICLE_RINT, on_ash::PARTICLE_RAHIT],
            ),
            RtProgram::Splat => (
                &[on_ash::SPLAT_RGEN],
                [miss, on_ash::SPLAT_RINT, on_ash::SPLAT_RAHIT],
            ),
            RtProgram::Owned => (
                &[on_ash::OWNED_RGEN],
                [miss, on_ash::PARTICLE_RINT, on_ash::PARTICLE_RAHIT],
            ),
        }
    }

    /// Ray-generation groups (first in the pipeline's groups; a miss and a hit group follow).
    pub fn raygens(self) -> u32 {
        match self {
            RtProgram::Field => 2,
            RtProgram::Splat | RtProgram::Owned => 1,
        }
    }
}

/// The ray-tracing pipeline of `program` for `spec`, compiled on first use in this process.
pub fn rt_pipeline(
    ctx: &Context,
    spec: SpecConstants,
    program: RtProgram,
) -> Result<vk::Pipeline, BackendError> {
    // The lock is held while compiling, so two threads never compile the same variant.
    let mut cache = ctx.rt_pipelines.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(&p) = cache.get(&(spec, program)) {
        return Ok(p);
    }
    let started = std::time::Instant::now();
    let device = &ctx.device;
    let mut modules = Modules {
        device,
        modules: Vec::new(),
    };
    let values = spec.values();
    let data: &[u8] = bytemuck::cast_slice(&values);
    let spec_info = vk::SpecializationInfo::default()
        .map_entries(&SPEC_ENTRIES)
        .data(data);
    let (raygens, [miss, intersection, any_hit]) = program.stages();
    let mut stages = Vec::new();
    for &entry in raygens.iter().chain(&[miss, intersection, any_hit]) {
        // Every SPIR-V module glslc writes has one entry point, `main`.
        stages.push(
            vk::PipelineShaderStageCreateInfo::default()
                .stage(stage_flags(entry.point().stage))
                .module(modules.load(entry)?)
                .name(c"main")
                .specialization_info(&spec_info),
        );
    }
    let general = |i: u32| {
        vk::RayTracingShaderGroupCreateInfoKHR::default()
            .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
            .general_shader(i)
            .closest_hit_shader(vk::SHADER_UNUSED_KHR)
            .any_hit_shader(vk::SHADER_UNUSED_KHR)
            .intersection_shader(vk::SHADER_UNUSED_KHR)
    };
    // Raygens, then the miss shader (stage n), then the hit group (stages n + 1, n + 2).
    let n = program.raygens();
    let mut groups: Vec<_> = (0..=n).map(general).collect();
    groups.push(
        vk::RayTracingShaderGroupCreateInfoKHR::default()
            .ty(vk::RayTracingShaderGroupTypeKHR::PROCEDURAL_HIT_GROUP)
            .general_shader(vk::SHADER_UNUSED_KHR)
            .closest_hit_shader(vk::SHADER_UNUSED_KHR)
            .any_hit_shader(n + 2)
            .intersection_shader(n + 1),
    );
    let info = [vk::RayTracingPipelineCreateInfoKHR::default()
        .stages(&stages)
        .groups(&groups)
        .max_pipeline_ray_recursion_depth(1)
        .layout(ctx.layouts.pipeline)];
    // SAFETY: valid create info; modules outlive the call.
    let pipeline = unsafe {
        ctx.rt.create_ray_tracing_pipelines(
            vk::DeferredOperationKHR::null(),
            vk::PipelineCache::null(),
            &info,
            None,
        )
    }
    .map_err(|(_, e)| vk_error("creating the ray-tracing pipeline", e))?[0];
    tracing::debug!(
        "ash: ray-tracing pipeline {program:?} {spec:?} created in {:.2} s",
        started.elapsed().as_secs_f64()
    );
    cache.insert((spec, program), pipeline);
    Ok(pipeline)
}

/// The compute pipeline of `kind` (one of [`on_ash`]) for `spec` (only the constants the
/// kernel reads matter).
pub fn compute_pipeline(
    ctx: &Context,
    kind: Entry,
    spec: SpecConstants,
) -> Result<vk::Pipeline, BackendError> {
    let key_spec = match kind {
        on_ash::BLAS_BOXES => SpecConstants {
            integrator: 0,
            colour_mode: 0,
            noise_kind: 0,
            density_map_varies: 0,
            ..spec
        },
        on_ash::LBVH_QUERY => SpecConstants {
            integrator: 0,
            noise_kind: 0,
            ..spec
        },
        on_ash::VOXEL_SPLAT => SpecConstants {
            integrator: 0,
            noise_kind: 0,
            cluster_size: 0,
            rt_hit_per_particle: 0,
            compensated_sum: 0,
            ..spec
        },
        // The march reads no particle.
        on_ash::VOXEL_RENDER => SpecConstants {
            cluster_size: 0,
            radius_map_varies: 0,
            density_map_varies: 0,
            has_radius_attribute: 0,
            position_ds: 0,
            rt_hit_per_particle: 0,
            compensated_sum: 0,
            kernel: 0,
            ..spec
        },
        // Every constant (the frame kernels, and a new kernel until it is narrowed here).
        _ if kind.point().specialised => spec,
        // Their code reads no specialisation constant (the table reflects it): one pipeline
        // each.
        _ => UNSPECIALISED,
    };
    let mut cache = ctx
        .compute_pipelines
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(&p) = cache.get(&(kind, key_spec)) {
        return Ok(p);
    }
    let mut modules = Modules {
        device: &ctx.device,
        modules: Vec::new(),
    };
    let values = key_spec.values();
    let spec_info = vk::SpecializationInfo::default()
        .map_entries(&SPEC_ENTRIES)
        .data(bytemuck::cast_slice(&values));
    let stage = vk::PipelineShaderStageCreateInfo::default()
        .stage(vk::ShaderStageFlags::COMPUTE)
        .module(modules.load(kind)?)
        .name(c"main")
        .specialization_info(&spec_info);
    let info = [vk::ComputePipelineCreateInfo::default()
        .stage(stage)
        .layout(if prepares(kind) {
            ctx.layouts.prepare
        } else {
            ctx.layouts.pipeline
        })];
    // SAFETY: valid create info.
    let pipeline = unsafe {
        ctx.device
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
    }
    .map_err(|(_, e)| vk_error("creating a compute pipeline", e))?[0];
    cache.insert((kind, key_spec), pipeline);
    Ok(pipeline)
}

/// The pipeline of a kernel that prepares a step (no specialisation constant).
pub fn prepare_pipeline(ctx: &Context, kind: Entry) -> Result<vk::Pipeline, BackendError> {
    debug_assert!(prepares(kind));
    compute_pipeline(ctx, kind, UNSPECIALISED)
}

/// What the kernels that read no specialisation constant are keyed by.
const UNSPECIALISED: SpecConstants = SpecConstants {
    integrator: 0,
    colour_mode: 0,
    noise_kind: 0,
    cluster_size: 1,
    radius_map_varies: 0,
    density_map_varies: 0,
    has_radius_attribute: 0,
    position_ds: 0,
    rt_hit_per_particle: 0,
    compensated_sum: 0,
    kernel: 0,
};

fn align_up(x: u64, a: u64) -> u64 {
    x.div_ceil(a.max(1)) * a.max(1)
}

/// A shader binding table for one ray-tracing pipeline of `program`: its raygens (the field's:
/// render, then query), the miss shader and the hit group, each region starting at a multiple
/// of `shaderGroupBaseAlignment`, records `shaderGroupHandleAlignment`-aligned, and each raygen
/// region's size equal to its stride (as the specification requires).
pub struct BindingTable {
    _buffer: Buffer,
    /// The raygen regions, one per raygen of the program.
    pub raygens: Vec<vk::StridedDeviceAddressRegionKHR>,
    /// The miss shader's region.
    pub miss: vk::StridedDeviceAddressRegionKHR,
    /// The hit group's region.
    pub hit: vk::StridedDeviceAddressRegionKHR,
}

impl BindingTable {
    /// The table of `pipeline`, made for `program`: its handles read back and written into a new
    /// buffer.
    pub fn new(
        ctx: &Arc<Context>,
        pipeline: vk::Pipeline,
        program: RtProgram,
    ) -> Result<BindingTable, BackendError> {
        let info = &ctx.info;
        let handle = u64::from(info.handle_size);
        let stride = align_up(handle, u64::from(info.handle_alignment));
        if stride > u64::from(info.max_group_stride) {
            return Err(device_error(
                "shader binding table",
                format!(
                    "record stride {stride} exceeds the device's maximum {}",
                    info.max_group_stride
                ),
            ));
        }
        let slot = align_up(stride, u64::from(info.base_alignment));
        let raygens = program.raygens();
        let groups = raygens + 2;
        // SAFETY: the pipeline of `program` has that many groups.
        let handles = unsafe {
            ctx.rt.get_ray_tracing_shader_group_handles(
                pipeline,
                0,
                groups,
                (handle * u64::from(groups)) as usize,
            )
        }
        .map_err(|e| vk_error("reading shader group handles", e))?;
        let base = u64::from(info.base_alignment);
        // Room to align the start to the base alignment.
        let mut buffer = Buffer::new(
            ctx,
            "shader binding table",
            slot * u64::from(groups) + base,
            vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::CpuToGpu,
        )?;
        let start = align_up(buffer.address, base) - buffer.address;
        let mut bytes = vec![0u8; (slot * u64::from(groups)) as usize];
        for g in 0..groups as usize {
            let src = &handles[g * handle as usize..(g + 1) * handle as usize];
            bytes[g * slot as usize..g * slot as usize + handle as usize].copy_from_slice(src);
        }
        buffer.write(start, &bytes)?;
        let region = |g: u64| {
            vk::StridedDeviceAddressRegionKHR::default()
                .device_address(buffer.address + start + g * slot)
                .stride(stride)
                .size(stride)
        };
        Ok(BindingTable {
            raygens: (0..raygens).map(|g| region(u64::from(g))).collect(),
            miss: region(u64::from(raygens)),
            hit: region(u64::from(raygens) + 1),
            _buffer: buffer,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The descriptor set is what the stages use, as reflected: the bindings the backend
    /// writes by name, each of the type it writes, and nothing more.
    #[test]
    fn the_set_layout_is_the_reflected_bindings_the_backend_writes() {
        let set = set_bindings();
        let of = |b: u32| set.iter().find(|x| x.0 == b).map(|x| (x.1, x.2));
        assert_eq!(
            of(binding::TLAS),
            Some((
                vk::DescriptorType::ACCELERATION_STRUCTURE_KHR,
                vk::ShaderStageFlags::RAYGEN_KHR
            ))
        );
        let (ty, stages) = of(binding::PARAMS).unwrap();
        assert_eq!(ty, vk::DescriptorType::UNIFORM_BUFFER);
        assert!(
            stages.contains(vk::ShaderStageFlags::COMPUTE | vk::ShaderStageFlags::INTERSECTION_KHR)
        );
        let storage = [
            binding::TABLES,
            binding::STBN,
            binding::QUERY_POINTS,
            binding::QUERY_RESULTS,
            binding::LBVH_NODES,
            binding::LBVH_BOXES,
        ];
        for b in storage {
            assert_eq!(
                of(b).unwrap().0,
                vk::DescriptorType::STORAGE_BUFFER,
                "binding {b}"
            );
        }
        assert_eq!(set.len(), 2 + storage.len());
        // The prepare kernels bind nothing (the push-only layout); the others do.
        for kernel in [
            on_ash::HILBERT_KEYS,
            on_ash::RADIX_SORT_COUNT,
            on_ash::RADIX_SORT_SCAN,
            on_ash::RADIX_SORT_SCATTER,
            on_ash::GATHER_WORDS,
            on_ash::GATHER_VEC4S,
        ] {
            assert!(prepares(kernel), "{kernel}");
        }
        assert!(!prepares(on_ash::BLAS_BOXES) && !prepares(on_ash::LBVH_RENDER));
    }
}
