//! The measurement behind `docs/notes/2026-12-07-shader-table.md`: could naga's WGSL → SPIR-V
//! serve the ash backend's step preparation, so that the stages written twice (WGSL for wgpu,
//! GLSL for ash: radix sort, Hilbert keys, gather) had one source? The wgpu backend's WGSL,
//! compiled by naga and run here through ash with descriptor-set layouts made from the shader
//! table's reflected bindings, against the ash backend's glslc-compiled GLSL on the same
//! buffers and the CPU twin. Ignored in the suite (it measures rather than guards); run it
//! with `cargo test --profile checked --lib naga_spirv -- --ignored --nocapture`.

use std::sync::Arc;
use std::time::Instant;

use ash::vk;
use gpu_allocator::MemoryLocation;
use wgpu::naga;

use super::context::{self, Context, validation_messages};
use super::pipelines::{PreparePush, prepare_pipeline};
use super::resources::{Buffer, Commands, barrier};
use crate::backend::shaders::cpu::radix_sort::sort_pairs;
use crate::backend::shaders::table::BindingKind;
use crate::backend::shaders::{Entry, on_ash, on_wgpu, wgsl_with_includes};
use crate::values::shader_constants::SORT_TILE;

/// How naga bounds-checks: as wgpu-hal compiles for a device without robustBufferAccess2
/// (`Restrict`, loops bounded), or as glslc's code does (unchecked).
#[derive(Clone, Copy, Debug)]
enum Checks {
    AsWgpu,
    Unchecked,
}

/// `entry`'s WGSL (one-part layout) as naga's SPIR-V 1.5, for `entry`'s entry point.
fn naga_spirv(entry: Entry, checks: Checks) -> Vec<u32> {
    let source = wgsl_with_includes(entry.shader().source, 1);
    let module = naga::front::wgsl::parse_str(&source).expect("build.rs validated it");
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .expect("build.rs validated it");
    let policy = match checks {
        Checks::AsWgpu => naga::proc::BoundsCheckPolicy::Restrict,
        Checks::Unchecked => naga::proc::BoundsCheckPolicy::Unchecked,
    };
    let options = naga::back::spv::Options {
        lang_version: (1, 5),
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: policy,
            buffer: policy,
            image_load: policy,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        // The wgpu backend asks for no zeroing (zero_initialize_workgroup_memory: false).
        zero_initialize_workgroup_memory: naga::back::spv::ZeroInitializeWorkgroupMemoryMode::None,
        force_loop_bounding: matches!(checks, Checks::AsWgpu),
        ..Default::default()
    };
    let pipeline = naga::back::spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: entry.point().name.into(),
    };
    naga::back::spv::write_vec(&module, &info, &options, Some(&pipeline)).expect("naga writes it")
}

/// A descriptor-set layout of `entries`' reflected bindings (the union), and a pipeline
/// layout over it.
fn layouts(ctx: &Context, entries: &[Entry]) -> (vk::DescriptorSetLayout, vk::PipelineLayout) {
    let mut bindings: Vec<vk::DescriptorSetLayoutBinding> = Vec::new();
    for e in entries {
        for b in e.point().bindings {
            if bindings.iter().any(|x| x.binding == b.binding) {
                continue;
            }
            let ty = match b.kind {
                BindingKind::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
                BindingKind::Storage { .. } => vk::DescriptorType::STORAGE_BUFFER,
                other => panic!("{e}: {other:?}"),
            };
            bindings.push(
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b.binding)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE),
            );
        }
    }
    // SAFETY: valid create infos; destroyed by the caller.
    unsafe {
        let set = ctx
            .device
            .create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                None,
            )
            .unwrap();
        let sets = [set];
        let layout = ctx
            .device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&sets),
                None,
            )
            .unwrap();
        (set, layout)
    }
}

/// A compute pipeline of `words` (entry point `name`) over `layout`, and the seconds its
/// creation took (lavapipe compiles it then).
fn pipeline(
    ctx: &Context,
    words: &[u32],
    name: &str,
    layout: vk::PipelineLayout,
) -> (vk::Pipeline, f64) {
    let name = std::ffi::CString::new(name).unwrap();
    let started = Instant::now();
    // SAFETY: valid SPIR-V (naga validated the module) and create infos.
    unsafe {
        let module = ctx
            .device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
            .unwrap();
        let info = [vk::ComputePipelineCreateInfo::default()
            .stage(
                vk::PipelineShaderStageCreateInfo::default()
                    .stage(vk::ShaderStageFlags::COMPUTE)
                    .module(module)
                    .name(&name),
            )
            .layout(layout)];
        let p = ctx
            .device
            .create_compute_pipelines(vk::PipelineCache::null(), &info, None)
            .map_err(|(_, e)| e)
            .unwrap()[0];
        ctx.device.destroy_shader_module(module, None);
        (p, started.elapsed().as_secs_f64())
    }
}

fn addressed(ctx: &Arc<Context>, name: &str, bytes: u64) -> Buffer {
    Buffer::new(
        ctx,
        name,
        bytes,
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        MemoryLocation::GpuOnly,
    )
    .unwrap()
}

fn compute_barrier(ctx: &Context, cb: vk::CommandBuffer) {
    let access = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
    barrier(
        ctx,
        cb,
        (vk::PipelineStageFlags::COMPUTE_SHADER, access),
        (vk::PipelineStageFlags::COMPUTE_SHADER, access),
    );
}

/// The sort's buffers: keys and values, ping and pong, the histogram.
struct SortBuffers {
    keys: [Buffer; 2],
    values: [Buffer; 2],
    histogram: Buffer,
}

impl SortBuffers {
    fn new(ctx: &Arc<Context>, n: u32, tiles: u32) -> SortBuffers {
        let bytes = u64::from(n) * 4;
        SortBuffers {
            keys: [
                addressed(ctx, "keys", bytes),
                addressed(ctx, "keys tmp", bytes),
            ],
            values: [
                addressed(ctx, "values", bytes),
                addressed(ctx, "values tmp", bytes),
            ],
            histogram: addressed(ctx, "histogram", u64::from(16 * tiles) * 4),
        }
    }

    /// The device addresses of keys, values (ping, pong) and histogram.
    fn addresses(&self) -> ([u64; 2], [u64; 2], u64) {
        (
            [self.keys[0].address, self.keys[1].address],
            [self.values[0].address, self.values[1].address],
            self.histogram.address,
        )
    }
}

/// The sort's size: keys, and tiles of [`SORT_TILE`] keys.
#[derive(Clone, Copy)]
struct SortSize {
    n: u32,
    tiles: u32,
}

/// The uniform entries of the WGSL sort's 8 passes (count, shift, tiles, pad), `stride` bytes
/// apart.
fn sort_params(ctx: &Arc<Context>, size: SortSize, stride: u64) -> Buffer {
    let mut params = Buffer::new(
        ctx,
        "sort params",
        stride * 8,
        vk::BufferUsageFlags::UNIFORM_BUFFER,
        MemoryLocation::CpuToGpu,
    )
    .unwrap();
    for pass in 0..8u32 {
        params
            .write(
                u64::from(pass) * stride,
                bytemuck::cast_slice(&[size.n, 4 * pass, size.tiles, 0]),
            )
            .unwrap();
    }
    params
}

/// `n` pseudo-random keys (xorshift).
fn random_keys(n: u32) -> Vec<u32> {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 16) as u32
        })
        .collect()
}

/// Every prepare pass of the wgpu backend compiles (naga) and makes a pipeline here; the
/// ash backend's own sort passes (glslc) for comparison.
fn compile_the_prepare_passes(ctx: &Context) {
    for entry in [
        on_wgpu::RADIX_SORT_COUNT,
        on_wgpu::RADIX_SORT_SCAN,
        on_wgpu::RADIX_SORT_SCATTER,
        on_wgpu::HILBERT_KEYS,
        on_wgpu::GATHER_WORDS,
        on_wgpu::GATHER_VEC4S,
    ] {
        let words = naga_spirv(entry, Checks::AsWgpu);
        let (set, layout) = layouts(ctx, &[entry]);
        let (p, seconds) = pipeline(ctx, &words, entry.point().name, layout);
        eprintln!(
            "{entry}: {} SPIR-V words, pipeline in {seconds:.2} s",
            words.len()
        );
        // SAFETY: unused.
        unsafe {
            ctx.device.destroy_pipeline(p, None);
            ctx.device.destroy_pipeline_layout(layout, None);
            ctx.device.destroy_descriptor_set_layout(set, None);
        }
    }
    for glsl in [
        on_ash::RADIX_SORT_COUNT,
        on_ash::RADIX_SORT_SCAN,
        on_ash::RADIX_SORT_SCATTER,
    ] {
        let started = Instant::now();
        prepare_pipeline(ctx, glsl).unwrap();
        eprintln!(
            "{glsl}: glslc's SPIR-V, pipeline in {:.2} s",
            started.elapsed().as_secs_f64()
        );
    }
}

/// Records the 8 passes of glslc's sort (`glsl`: count, scan, scatter), push constants and
/// device addresses as the backend's own passes have them.
fn record_glsl_sort(
    ctx: &Context,
    cb: vk::CommandBuffer,
    glsl: &[vk::Pipeline; 3],
    size: SortSize,
    (k, v, h): ([u64; 2], [u64; 2], u64),
) {
    for pass in 0..8usize {
        let (i, o) = (pass % 2, 1 - pass % 2);
        let push = PreparePush {
            count: size.n,
            shift: 4 * pass as u32,
            tiles: size.tiles,
            arrays: [k[i], v[i], k[o], v[o], h],
            ..PreparePush::default()
        };
        for (p, groups) in glsl.iter().zip([size.tiles, 1, size.tiles]) {
            // SAFETY: recording; the pipelines use the prepare layout.
            unsafe {
                ctx.device
                    .cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, *p);
                ctx.device.cmd_push_constants(
                    cb,
                    ctx.layouts.prepare,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    bytemuck::bytes_of(&push),
                );
                ctx.device.cmd_dispatch(cb, groups, 1, 1);
            }
            compute_barrier(ctx, cb);
        }
    }
}

/// A descriptor pool and one set per pass of the WGSL sort (its bind group as a descriptor
/// set over `b`, the pass's entry of `params` at `stride`).
fn sort_sets(
    ctx: &Context,
    set_layout: vk::DescriptorSetLayout,
    params: &Buffer,
    stride: u64,
    b: &SortBuffers,
) -> (vk::DescriptorPool, Vec<vk::DescriptorSet>) {
    let sizes = [
        vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::UNIFORM_BUFFER)
            .descriptor_count(8),
        vk::DescriptorPoolSize::default()
            .ty(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count(40),
    ];
    // SAFETY: valid create and allocate infos; destroyed by the caller.
    let (pool, sets) = unsafe {
        let pool = ctx
            .device
            .create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(8)
                    .pool_sizes(&sizes),
                None,
            )
            .unwrap();
        let layouts = [set_layout; 8];
        let sets = ctx
            .device
            .allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(pool)
                    .set_layouts(&layouts),
            )
            .unwrap();
        (pool, sets)
    };
    for (pass, &set) in sets.iter().enumerate() {
        let (i, o) = (pass % 2, 1 - pass % 2);
        let infos = [
            params.descriptor(),
            b.keys[i].descriptor(),
            b.values[i].descriptor(),
            b.keys[o].descriptor(),
            b.values[o].descriptor(),
            b.histogram.descriptor(),
        ];
        let param_info = [vk::DescriptorBufferInfo::default()
            .buffer(infos[0].buffer)
            .offset(pass as u64 * stride)
            .range(16)];
        let storage: Vec<[vk::DescriptorBufferInfo; 1]> = infos[1..].iter().map(|d| [*d]).collect();
        let mut writes = vec![
            vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::UNIFORM_BUFFER)
                .buffer_info(&param_info),
        ];
        for (k, info) in storage.iter().enumerate() {
            writes.push(
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(k as u32 + 1)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info),
            );
        }
        // SAFETY: the set is not in use.
        unsafe { ctx.device.update_descriptor_sets(&writes, &[]) };
    }
    (pool, sets)
}

/// Records the 8 passes of naga's sort (`made`: count, scan, scatter), one descriptor set a
/// pass.
fn record_naga_sort(
    ctx: &Context,
    cb: vk::CommandBuffer,
    made: &[(vk::Pipeline, f64)],
    layout: vk::PipelineLayout,
    sets: &[vk::DescriptorSet],
    size: SortSize,
) {
    for &set in sets {
        for (&(p, _), groups) in made.iter().zip([size.tiles, 1, size.tiles]) {
            // SAFETY: recording; the set matches the pipeline's layout.
            unsafe {
                ctx.device
                    .cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, p);
                ctx.device.cmd_bind_descriptor_sets(
                    cb,
                    vk::PipelineBindPoint::COMPUTE,
                    layout,
                    0,
                    &[set],
                    &[],
                );
                ctx.device.cmd_dispatch(cb, groups, 1, 1);
            }
            compute_barrier(ctx, cb);
        }
    }
}

#[test]
#[ignore = "a measurement (docs/notes/2026-12-07-shader-table.md), not a guard"]
fn naga_wgsl_spirv_runs_the_prepare_passes_on_ash() {
    let ctx = context::shared().expect("a Vulkan device");
    eprintln!("device: {}", ctx.describe());
    compile_the_prepare_passes(&ctx);

    // The sort itself: 8 passes over n keys, both ways, on the same buffers.
    let n: u32 = std::env::var("AARBF_NAGA_SORT_KEYS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1 << 20);
    let size = SortSize {
        n,
        tiles: n.div_ceil(SORT_TILE),
    };
    let keys = random_keys(n);
    let (expected_keys, expected_order) = sort_pairs(&keys);
    let bytes = u64::from(n) * 4;
    let mut b = SortBuffers::new(&ctx, n, size.tiles);
    // Per pass: count, shift, tiles, pad, at a 256-byte stride.
    let stride = 256u64;
    let params = sort_params(&ctx, size, stride);
    let commands = Commands::new(&ctx, 2).unwrap();
    let identity: Vec<u32> = (0..n).collect();
    let run = |b: &mut SortBuffers, record: &dyn Fn(vk::CommandBuffer)| {
        b.keys[0].write(0, bytemuck::cast_slice(&keys)).unwrap();
        b.values[0]
            .write(0, bytemuck::cast_slice(&identity))
            .unwrap();
        let cb = commands.begin().unwrap();
        commands.timestamp(0);
        record(cb);
        commands.timestamp(1);
        commands.submit_and_wait().unwrap();
        let seconds = commands.elapsed(0, 1).map_or(f64::NAN, |d| d.as_secs_f64());
        let got_keys: Vec<u32> = bytemuck::pod_collect_to_vec(&b.keys[0].read(bytes).unwrap());
        let got_order: Vec<u32> = bytemuck::pod_collect_to_vec(&b.values[0].read(bytes).unwrap());
        assert!(
            got_keys == expected_keys && got_order == expected_order,
            "not the twin's sort"
        );
        seconds
    };

    // glslc's SPIR-V: push constants and device addresses, the backend's own passes.
    let glsl = [
        on_ash::RADIX_SORT_COUNT,
        on_ash::RADIX_SORT_SCAN,
        on_ash::RADIX_SORT_SCATTER,
    ]
    .map(|e| prepare_pipeline(&ctx, e).unwrap());

    // naga's SPIR-V: the WGSL's bind group as a descriptor set, one set per pass.
    let wgsl = [
        on_wgpu::RADIX_SORT_COUNT,
        on_wgpu::RADIX_SORT_SCAN,
        on_wgpu::RADIX_SORT_SCATTER,
    ];
    let (set_layout, layout) = layouts(&ctx, &wgsl);
    let (pool, sets) = sort_sets(&ctx, set_layout, &params, stride, &b);
    let mut report = Vec::new();
    for checks in [Checks::AsWgpu, Checks::Unchecked] {
        let made: Vec<(vk::Pipeline, f64)> = wgsl
            .iter()
            .map(|&e| pipeline(&ctx, &naga_spirv(e, checks), e.point().name, layout))
            .collect();
        let record_wgsl = |cb| record_naga_sort(&ctx, cb, &made, layout, &sets, size);
        // Alternating, five of each; the medians.
        let (mut naga_times, mut glslc_times) = (Vec::new(), Vec::new());
        for _ in 0..5 {
            naga_times.push(run(&mut b, &record_wgsl));
            let a = b.addresses();
            glslc_times.push(run(&mut b, &|cb| {
                record_glsl_sort(&ctx, cb, &glsl, size, a)
            }));
        }
        let median = |t: &mut Vec<f64>| {
            t.sort_by(f64::total_cmp);
            t[t.len() / 2]
        };
        let compile: f64 = made.iter().map(|m| m.1).sum();
        report.push(format!(
            "{n} keys, naga ({checks:?}): {:.1} ms (pipelines {compile:.2} s); glslc: {:.1} ms",
            median(&mut naga_times) * 1e3,
            median(&mut glslc_times) * 1e3
        ));
        for (p, _) in made {
            // SAFETY: waited for.
            unsafe { ctx.device.destroy_pipeline(p, None) };
        }
    }
    // SAFETY: nothing in use.
    unsafe {
        ctx.device.destroy_descriptor_pool(pool, None);
        ctx.device.destroy_pipeline_layout(layout, None);
        ctx.device.destroy_descriptor_set_layout(set_layout, None);
    }
    eprintln!("{}", report.join("\n"));
    let messages = validation_messages();
    assert!(messages.is_empty(), "validation: {messages:?}");
}
