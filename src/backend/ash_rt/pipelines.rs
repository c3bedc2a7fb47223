//! The descriptor layout, the ray-tracing pipeline (one per specialisation variant, compiled
//! once per process and cached in the [`Context`]), its shader binding table, and the compute
//! pipelines.
//!
//! Shaders (`shaders_glsl/vulkan/`, compiled by build.rs with glslc):
//! - `render.rgen`: the shared integrator (`shared/integrators.glsl`) per pixel, adding the
//!   frame into the accumulation buffer; `query.rgen`: the field at points from a buffer.
//!   Both define `field_query(x)` (`vulkan/field_query.glsl`): one ray from x along (1, 1, 1)
//!   with tmin = tmax = 0.
//! - `particle.rint`: tests each particle of the hit box (one box per cluster of
//!   `CLUSTER_SIZE` particles) and reports (d², r, t) for each that contains the point;
//!   `particle.rahit`: adds the particle's RBF term into the payload and ignores the hit, so
//!   traversal goes on; `empty.rmiss`.
//! - `blas_boxes.comp`: the AABB of each cluster from positions, radius map and global radius.
//! - `lbvh_query.comp`, `lbvh_render.comp`: the same queries and integrators with the shared
//!   LBVH stack traversal (`shared/lbvh.glsl`) in place of the RT pipeline, for the
//!   same-device hardware-versus-software comparison (the paper's Fig. 10a).
//!
//! - `splat.rgen`, `splat.rint`, `splat.rahit`: Knoll et al.'s splatter (the Table 3
//!   baseline), its own pipeline ([`RtProgram::Splat`]), made only when a scene splats;
//!   `lbvh_splat.comp` its LBVH twin.
//!
//! Shader groups of the field pipeline: 0 render raygen, 1 query raygen, 2 miss, 3 the
//! procedural hit group (intersection + any-hit); of the splat pipeline: 0 raygen, 1 miss, 2
//! the hit group.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::{Context, device_error, vk_error};
use super::resources::Buffer;
use crate::backend::BackendError;
use crate::backend::shaders::SpecConstants;
use crate::values::shader_constants::SPEC_CONSTANTS;

macro_rules! spirv {
    ($name:literal) => {
        include_bytes!(concat!(env!("OUT_DIR"), "/", $name, ".spv"))
    };
}

const RAYGEN: &[u8] = spirv!("render.rgen");
const QUERY: &[u8] = spirv!("query.rgen");
const MISS: &[u8] = spirv!("empty.rmiss");
const INTERSECTION: &[u8] = spirv!("particle.rint");
const ANY_HIT: &[u8] = spirv!("particle.rahit");
const SPLAT_RAYGEN: &[u8] = spirv!("splat.rgen");
const SPLAT_INTERSECTION: &[u8] = spirv!("splat.rint");
const SPLAT_ANY_HIT: &[u8] = spirv!("splat.rahit");
const LBVH_SPLAT: &[u8] = spirv!("lbvh_splat.comp");
const BOXES: &[u8] = spirv!("blas_boxes.comp");
const LBVH_QUERY: &[u8] = spirv!("lbvh_query.comp");
const LBVH_RENDER: &[u8] = spirv!("lbvh_render.comp");
const HILBERT_KEYS: &[u8] = spirv!("hilbert_keys.comp");
const SORT_COUNT: &[u8] = spirv!("radix_sort.comp.count");
const SORT_SCAN: &[u8] = spirv!("radix_sort.comp.scan");
const SORT_SCATTER: &[u8] = spirv!("radix_sort.comp.scatter");
const GATHER_WORDS: &[u8] = spirv!("gather.comp.gather_words");
const GATHER_VEC4S: &[u8] = spirv!("gather.comp.gather_vec4s");
const VOXEL_SPLAT: &[u8] = spirv!("voxel_splat.comp");
const VOXEL_RENDER: &[u8] = spirv!("voxel_render.comp");

/// Descriptor bindings (set 0); `shaders_glsl/vulkan/bindings.glsl` declares the same.
/// Bindings 2, 3 and 9 (particles, radius attributes, boxes) are gone: those arrays grow with
/// the step and are reached by device address (`Push`), so no binding limit applies.
pub mod binding {
    pub const TLAS: u32 = 0;
    pub const PARAMS: u32 = 1;
    pub const TABLES: u32 = 4;
    pub const STBN: u32 = 5;
    pub const QUERY_POINTS: u32 = 7;
    pub const QUERY_RESULTS: u32 = 8;
    pub const LBVH_NODES: u32 = 10;
    pub const LBVH_BOXES: u32 = 11;
    /// Storage buffers: every binding but the TLAS and the uniform block.
    pub const STORAGE: [u32; 6] = [
        TABLES,
        STBN,
        QUERY_POINTS,
        QUERY_RESULTS,
        LBVH_NODES,
        LBVH_BOXES,
    ];
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
    pub radius_address: u64,
    pub boxes_address: u64,
    pub accum_address: u64,
    pub particle_lo_address: u64,
    /// The voxel baseline's grid (0 before a voxelisation).
    pub voxel_address: u64,
}

/// The push constants of the kernels that prepare a step (`PreparePush` in
/// `shaders_glsl/vulkan/prepare.glsl`): the Hilbert grid, counts, and each pass's arrays by
/// device address.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PreparePush {
    pub grid_lo: [f32; 4],
    pub grid_scale: [f32; 4],
    pub count: u32,
    pub shift: u32,
    pub tiles: u32,
    pub width: u32,
    pub arrays: [u64; 5],
}

/// The descriptor-set layout and pipeline layout every pipeline uses, and the layout of the
/// kernels that prepare a step (push constants only: they reach every array by address).
pub struct Layouts {
    pub set: vk::DescriptorSetLayout,
    pub pipeline: vk::PipelineLayout,
    pub prepare: vk::PipelineLayout,
}

impl Layouts {
    pub fn new(device: &ash::Device) -> Result<Layouts, vk::Result> {
        let mut bindings = vec![
            vk::DescriptorSetLayoutBinding::default()
                .binding(binding::TLAS)
                .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::RAYGEN_KHR),
            vk::DescriptorSetLayoutBinding::default()
                .binding(binding::PARAMS)
                .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::ALL),
        ];
        for b in binding::STORAGE {
            bindings.push(
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::ALL),
            );
        }
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

/// The compute kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ComputeKind {
    /// One AABB per cluster (`blas_boxes.comp`).
    Boxes,
    /// Field queries by LBVH traversal (`lbvh_query.comp`).
    LbvhQuery,
    /// One frame by LBVH traversal (`lbvh_render.comp`).
    LbvhRender,
    /// One splatted frame by LBVH traversal (`lbvh_splat.comp`).
    LbvhSplat,
    /// The voxel baseline: the particles added to the grid (`voxel_splat.comp`), and one
    /// frame over the grid (`voxel_render.comp`).
    VoxelSplat,
    VoxelRender,
    /// Preparing a step (`PreparePush`): Hilbert keys, the radix sort's three passes, and the
    /// gathers of words and of vec4s.
    HilbertKeys,
    SortCount,
    SortScan,
    SortScatter,
    GatherWords,
    GatherVec4s,
}

impl ComputeKind {
    /// Whether the kernel prepares a step (the push-only layout, no specialisation).
    fn prepares(self) -> bool {
        !matches!(
            self,
            ComputeKind::Boxes
                | ComputeKind::LbvhQuery
                | ComputeKind::LbvhRender
                | ComputeKind::LbvhSplat
                | ComputeKind::VoxelSplat
                | ComputeKind::VoxelRender
        )
    }
}

/// Shader modules destroyed when dropped.
struct Modules<'a> {
    device: &'a ash::Device,
    modules: Vec<vk::ShaderModule>,
}

impl Modules<'_> {
    fn load(&mut self, spirv: &[u8]) -> Result<vk::ShaderModule, BackendError> {
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

/// What a ray-tracing pipeline runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RtProgram {
    /// The RBF field: frames and point queries (`render.rgen`, `query.rgen`, `particle.*`).
    Field,
    /// Knoll et al.'s splatter (`splat.*`).
    Splat,
}

impl RtProgram {
    /// Ray-generation groups (first in the pipeline's groups; a miss and a hit group follow).
    pub fn raygens(self) -> u32 {
        match self {
            RtProgram::Field => 2,
            RtProgram::Splat => 1,
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
    let stage = |flags, module| {
        vk::PipelineShaderStageCreateInfo::default()
            .stage(flags)
            .module(module)
            .name(c"main")
            .specialization_info(&spec_info)
    };
    let (raygens, intersection, any_hit): (&[&[u8]], _, _) = match program {
        RtProgram::Field => (&[RAYGEN, QUERY], INTERSECTION, ANY_HIT),
        RtProgram::Splat => (&[SPLAT_RAYGEN], SPLAT_INTERSECTION, SPLAT_ANY_HIT),
    };
    let mut stages = Vec::new();
    for &code in raygens {
        stages.push(stage(vk::ShaderStageFlags::RAYGEN_KHR, modules.load(code)?));
    }
    stages.push(stage(vk::ShaderStageFlags::MISS_KHR, modules.load(MISS)?));
    stages.push(stage(
        vk::ShaderStageFlags::INTERSECTION_KHR,
        modules.load(intersection)?,
    ));
    stages.push(stage(
        vk::ShaderStageFlags::ANY_HIT_KHR,
        modules.load(any_hit)?,
    ));
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

/// The compute pipeline `kind` for `spec` (only the constants the kernel reads matter).
pub fn compute_pipeline(
    ctx: &Context,
    kind: ComputeKind,
    spec: SpecConstants,
) -> Result<vk::Pipeline, BackendError> {
    let key_spec = match kind {
        ComputeKind::Boxes => SpecConstants {
            integrator: 0,
            colour_mode: 0,
            noise_kind: 0,
            density_map_varies: 0,
            ..spec
        },
        ComputeKind::LbvhQuery => SpecConstants {
            integrator: 0,
            noise_kind: 0,
            ..spec
        },
        ComputeKind::VoxelSplat => SpecConstants {
            integrator: 0,
            noise_kind: 0,
            cluster_size: 0,
            rt_hit_per_particle: 0,
            compensated_sum: 0,
            ..spec
        },
        // The march reads no particle.
        ComputeKind::VoxelRender => SpecConstants {
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
        ComputeKind::LbvhRender | ComputeKind::LbvhSplat => spec,
        // Their code reads no specialisation constant: one pipeline each.
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
    let code = match kind {
        ComputeKind::Boxes => BOXES,
        ComputeKind::LbvhQuery => LBVH_QUERY,
        ComputeKind::LbvhRender => LBVH_RENDER,
        ComputeKind::LbvhSplat => LBVH_SPLAT,
        ComputeKind::VoxelSplat => VOXEL_SPLAT,
        ComputeKind::VoxelRender => VOXEL_RENDER,
        ComputeKind::HilbertKeys => HILBERT_KEYS,
        ComputeKind::SortCount => SORT_COUNT,
        ComputeKind::SortScan => SORT_SCAN,
        ComputeKind::SortScatter => SORT_SCATTER,
        ComputeKind::GatherWords => GATHER_WORDS,
        ComputeKind::GatherVec4s => GATHER_VEC4S,
    };
    let values = key_spec.values();
    let spec_info = vk::SpecializationInfo::default()
        .map_entries(&SPEC_ENTRIES)
        .data(bytemuck::cast_slice(&values));
    let stage = vk::PipelineShaderStageCreateInfo::default()
        .stage(vk::ShaderStageFlags::COMPUTE)
        .module(modules.load(code)?)
        .name(c"main")
        .specialization_info(&spec_info);
    let info = [vk::ComputePipelineCreateInfo::default()
        .stage(stage)
        .layout(if kind.prepares() {
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
pub fn prepare_pipeline(ctx: &Context, kind: ComputeKind) -> Result<vk::Pipeline, BackendError> {
    debug_assert!(kind.prepares());
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
    pub raygens: Vec<vk::StridedDeviceAddressRegionKHR>,
    pub miss: vk::StridedDeviceAddressRegionKHR,
    pub hit: vk::StridedDeviceAddressRegionKHR,
}

impl BindingTable {
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
