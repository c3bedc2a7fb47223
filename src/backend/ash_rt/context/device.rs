//! Choosing and opening the device: what each device lacks for the ray-tracing path, the best
//! (or the i-th) of those that lack nothing, the logical device with exactly the features the
//! backend uses, and the limits it lays its work out by.

use std::ffi::{CStr, c_char};

use ash::{khr, vk};

use super::ContextError;

/// The device extensions the backend needs, all of which it enables.
pub const REQUIRED_EXTENSIONS: [&CStr; 3] = [
    khr::acceleration_structure::NAME,
    khr::ray_tracing_pipeline::NAME,
    khr::deferred_host_operations::NAME,
];

/// Which of the devices with ray-tracing pipelines a context opens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum DeviceChoice {
    /// A discrete GPU before an integrated one, before a virtual one, before a CPU's; among
    /// several of the best kind, the one for this process's node-local rank
    /// ([`crate::backend::device_for_rank`]).
    Best,
    /// The i-th such device in the loader's order.
    Index(usize),
}

/// Device properties the backend lays its work out by.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// The device's name.
    pub name: String,
    /// A CPU implementation (lavapipe): correct, but slower than the CPU backend.
    pub software: bool,
    /// The driver's own description of itself (`driverInfo`; empty if none).
    pub driver: String,
    /// The Vulkan version it supports (`apiVersion`, packed).
    pub api_version: u32,
    /// Bytes of a shader group handle (`shaderGroupHandleSize`).
    pub handle_size: u32,
    /// Alignment of a record in a shader binding table (`shaderGroupHandleAlignment`).
    pub handle_alignment: u32,
    /// Alignment of a shader binding table region's start (`shaderGroupBaseAlignment`).
    pub base_alignment: u32,
    /// The largest stride of a shader binding table region (`maxShaderGroupStride`).
    pub max_group_stride: u32,
    /// The most rays one trace launch may generate (`maxRayDispatchInvocationCount`).
    pub max_dispatch_invocations: u32,
    /// Alignment of an acceleration structure's scratch address
    /// (`minAccelerationStructureScratchOffsetAlignment`).
    pub scratch_alignment: u64,
    /// The most primitives (boxes) a BLAS may hold (`maxPrimitiveCount`).
    pub max_primitive_count: u64,
    /// The largest range of a storage-buffer binding, bytes (`maxStorageBufferRange`).
    pub max_storage_buffer_range: u64,
    /// The largest single allocation (maxMemoryAllocationSize): what bounds the particle and
    /// box buffers, which shaders reach by device address rather than through a binding.
    pub max_allocation: u64,
    /// The size of the largest device-local memory heap: what an out-of-memory error names.
    pub device_local_heap: u64,
    /// The most workgroups of a compute dispatch per axis (`maxComputeWorkGroupCount`).
    pub max_workgroup_count: [u32; 3],
    /// Nanoseconds per timestamp tick; `None` when the queue has no timestamps.
    pub timestamp_period: Option<f64>,
    /// The bits of a timestamp the queue writes, as a mask (`timestampValidBits`).
    pub timestamp_mask: u64,
}

/// Why no device qualifies, per device.
fn missing_features(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
) -> Result<Vec<String>, vk::Result> {
    let mut missing = Vec::new();
    // SAFETY: pd comes from this instance.
    let extensions = unsafe { instance.enumerate_device_extension_properties(pd)? };
    let has = |name: &CStr| {
        extensions
            .iter()
            .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
    };
    for name in REQUIRED_EXTENSIONS {
        if !has(name) {
            missing.push(format!("extension {}", name.to_string_lossy()));
        }
    }
    // SAFETY: as above.
    let props = unsafe { instance.get_physical_device_properties(pd) };
    if props.api_version < vk::API_VERSION_1_2 {
        missing.push(format!(
            "Vulkan 1.2 (the device offers {}.{})",
            vk::api_version_major(props.api_version),
            vk::api_version_minor(props.api_version)
        ));
        return Ok(missing);
    }
    if !missing.is_empty() {
        return Ok(missing);
    }
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut accel = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
    let mut rt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
    let mut features = vk::PhysicalDeviceFeatures2::default()
        .push_next(&mut v12)
        .push_next(&mut accel)
        .push_next(&mut rt);
    // SAFETY: the chain holds valid structs that outlive the call.
    unsafe { instance.get_physical_device_features2(pd, &mut features) };
    if v12.buffer_device_address == vk::FALSE {
        missing.push("feature bufferDeviceAddress".into());
    }
    if accel.acceleration_structure == vk::FALSE {
        missing.push("feature accelerationStructure".into());
    }
    if rt.ray_tracing_pipeline == vk::FALSE {
        missing.push("feature rayTracingPipeline".into());
    }
    Ok(missing)
}

fn device_name(props: &vk::PhysicalDeviceProperties) -> String {
    props
        .device_name_as_c_str()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "unnamed device".into())
}

/// A compute queue family of `pd` (ray tracing runs on compute-capable queues), preferring one
/// with timestamps.
fn compute_family(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Option<u32> {
    // SAFETY: pd comes from this instance.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    families
        .iter()
        .enumerate()
        .filter(|(_, f)| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
        .max_by_key(|(_, f)| {
            (
                f.timestamp_valid_bits > 0,
                f.queue_flags.contains(vk::QueueFlags::GRAPHICS),
            )
        })
        .map(|(i, _)| i as u32)
}

/// How [`DeviceChoice::Best`] ranks a device type (higher first).
fn rank(device_type: vk::PhysicalDeviceType) -> u32 {
    match device_type {
        vk::PhysicalDeviceType::DISCRETE_GPU => 4,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 3,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 1,
        _ => 0,
    }
}

/// The device `choice` names among those with everything the backend needs, and its queue
/// family; when there is none, an error that says what each device lacks.
pub(super) fn choose(
    instance: &ash::Instance,
    choice: DeviceChoice,
) -> Result<(vk::PhysicalDevice, u32), ContextError> {
    // SAFETY: plain queries.
    let devices = unsafe { instance.enumerate_physical_devices() }
        .map_err(|e| ContextError::failed("listing Vulkan devices", e))?;
    if devices.is_empty() {
        return Err(ContextError::Unavailable(
            "no Vulkan device found; run `cargo xtask setup` (it installs Mesa lavapipe when no GPU driver is present)"
                .into(),
        ));
    }
    let mut reasons = Vec::new();
    let mut best: Option<(u32, vk::PhysicalDevice, u32)> = None;
    let mut qualifying = 0;
    // Every qualifying device, for Best's choice among the best kind.
    let mut candidates: Vec<(u32, vk::PhysicalDevice, u32)> = Vec::new();
    for &pd in &devices {
        // SAFETY: pd comes from this instance.
        let props = unsafe { instance.get_physical_device_properties(pd) };
        let name = device_name(&props);
        let missing = missing_features(instance, pd)
            .map_err(|e| ContextError::failed("querying device extensions", e))?;
        if !missing.is_empty() {
            reasons.push(format!("{name}: missing {}", missing.join(", ")));
            continue;
        }
        let Some(family) = compute_family(instance, pd) else {
            reasons.push(format!("{name}: no compute queue"));
            continue;
        };
        let rank = rank(props.device_type);
        if choice == DeviceChoice::Index(qualifying) {
            best = Some((rank, pd, family));
        }
        candidates.push((rank, pd, family));
        qualifying += 1;
    }
    if choice == DeviceChoice::Best
        && let Some(top) = candidates.iter().map(|c| c.0).max()
    {
        let of_best_kind: Vec<_> = candidates.iter().filter(|c| c.0 == top).collect();
        let i =
            crate::backend::device_for_rank(of_best_kind.len(), crate::backend::node_local_rank());
        best = Some(*of_best_kind[i]);
    }
    if let DeviceChoice::Index(index) = choice
        && best.is_none()
        && qualifying > 0
    {
        return Err(ContextError::NoSuchDevice {
            index,
            count: qualifying,
        });
    }
    let Some((_, physical, queue_family)) = best else {
        return Err(ContextError::Unavailable(format!(
            "no Vulkan device supports ray-tracing pipelines ({}); on a machine without a GPU, `cargo xtask setup` installs Mesa lavapipe >= 25",
            reasons.join("; ")
        )));
    };
    Ok((physical, queue_family))
}

/// The logical device on `physical`, with one queue of `queue_family` and exactly the
/// extensions and features the backend uses.
pub(super) fn create(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    queue_family: u32,
) -> Result<ash::Device, ContextError> {
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true);
    let mut accel_features =
        vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
    let mut rt_features =
        vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default().ray_tracing_pipeline(true);
    let priorities = [1.0f32];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    let device_extensions: Vec<*const c_char> =
        REQUIRED_EXTENSIONS.iter().map(|n| n.as_ptr()).collect();
    let device_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_info)
        .enabled_extension_names(&device_extensions)
        .push_next(&mut v12)
        .push_next(&mut accel_features)
        .push_next(&mut rt_features);
    // SAFETY: a valid create info whose pointers outlive the call.
    unsafe { instance.create_device(physical, &device_info, None) }
        .map_err(|e| ContextError::failed("creating the Vulkan device", e))
}

impl DeviceInfo {
    /// The properties and limits of `pd`, whose queue family `family` the context uses.
    pub(super) fn query(
        instance: &ash::Instance,
        pd: vk::PhysicalDevice,
        family: u32,
    ) -> DeviceInfo {
        let mut rt = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
        let mut accel = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut props = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut rt)
            .push_next(&mut accel)
            .push_next(&mut driver)
            .push_next(&mut maintenance3);
        // SAFETY: valid chain, pd from this instance.
        unsafe { instance.get_physical_device_properties2(pd, &mut props) };
        let p = props.properties;
        // SAFETY: as above.
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        let bits = families[family as usize].timestamp_valid_bits;
        // SAFETY: as above.
        let memory = unsafe { instance.get_physical_device_memory_properties(pd) };
        let device_local_heap = memory.memory_heaps[..memory.memory_heap_count as usize]
            .iter()
            .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
            .map(|h| h.size)
            .max()
            .unwrap_or(0);
        let driver_name = driver
            .driver_info_as_c_str()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        DeviceInfo {
            name: device_name(&p),
            software: p.device_type == vk::PhysicalDeviceType::CPU,
            driver: driver_name,
            api_version: p.api_version,
            handle_size: rt.shader_group_handle_size,
            handle_alignment: rt.shader_group_handle_alignment,
            base_alignment: rt.shader_group_base_alignment,
            max_group_stride: rt.max_shader_group_stride,
            max_dispatch_invocations: rt.max_ray_dispatch_invocation_count,
            scratch_alignment: u64::from(accel.min_acceleration_structure_scratch_offset_alignment),
            max_primitive_count: accel.max_primitive_count,
            max_storage_buffer_range: u64::from(p.limits.max_storage_buffer_range),
            max_allocation: maintenance3.max_memory_allocation_size,
            device_local_heap,
            max_workgroup_count: p.limits.max_compute_work_group_count,
            timestamp_period: (bits > 0).then_some(f64::from(p.limits.timestamp_period)),
            timestamp_mask: if bits >= 64 {
                u64::MAX
            } else {
                (1u64 << bits) - 1
            },
        }
    }
}
