//! The Vulkan instance and device the ash backend runs on: created once per process and shared
//! by every [`super::AshBackend`] (lavapipe JIT-compiles each pipeline on first use, so the
//! compiled pipelines are shared too).
//!
//! The device must offer exactly what the ray-tracing path needs, and nothing else is enabled:
//! the extensions `VK_KHR_acceleration_structure`, `VK_KHR_ray_tracing_pipeline` and
//! `VK_KHR_deferred_host_operations` (a dependency of the first), and the features
//! `bufferDeviceAddress` (Vulkan 1.2), `accelerationStructure` and `rayTracingPipeline`. A
//! device that lacks one is passed over, and when no device qualifies the error names what each
//! one lacks.
//!
//! Validation: the Khronos validation layer is enabled when it is installed and either the
//! build has debug assertions (debug builds, the `checked` test profile) or
//! `AARBF_VK_VALIDATION=1`; `AARBF_VK_VALIDATION=0` turns it off. Its warnings and errors are
//! logged and collected in a process-wide list ([`validation_messages`]) that the tests
//! require to be empty.

use std::collections::HashMap;
use std::ffi::{CStr, c_char, c_void};
use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use ash::{ext, khr, vk};
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use gpu_allocator::{AllocationSizes, AllocatorDebugSettings};

use crate::backend::BackendError;
use crate::backend::shaders::Entry;
use crate::backend::shaders::SpecConstants;

pub(crate) const NAME: &str = "ash";

/// A device error in the backend's own words.
pub(crate) fn device_error(what: &str, e: impl fmt::Display) -> BackendError {
    BackendError::Device {
        backend: NAME,
        message: format!("{what}: {e}"),
    }
}

/// A `vk::Result` as a [`BackendError`], with out-of-memory and device loss spelled out.
pub(crate) fn vk_error(what: &str, e: vk::Result) -> BackendError {
    let detail = match e {
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY => {
            "out of device memory (try fewer particles or a smaller image)".to_owned()
        }
        vk::Result::ERROR_OUT_OF_HOST_MEMORY => "out of host memory".to_owned(),
        vk::Result::ERROR_DEVICE_LOST => {
            "the Vulkan device was lost (driver reset or crash); restart the program".to_owned()
        }
        other => format!("{other}"),
    };
    device_error(what, detail)
}

/// The device extensions the backend needs, all of which it enables.
pub const REQUIRED_EXTENSIONS: [&CStr; 3] = [
    khr::acceleration_structure::NAME,
    khr::ray_tracing_pipeline::NAME,
    khr::deferred_host_operations::NAME,
];

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

static MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Every validation warning and error reported in this process so far.
pub fn validation_messages() -> Vec<String> {
    MESSAGES.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes a valid callback-data struct whose strings live for the call.
    let message = unsafe {
        data.as_ref()
            .and_then(|d| d.message_as_c_str())
            .map(|m| m.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) {
        tracing::error!("Vulkan validation ({kind:?}, {severity:?}): {message}");
        MESSAGES
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(format!("{severity:?} {kind:?}: {message}"));
    } else {
        tracing::trace!("Vulkan ({kind:?}): {message}");
    }
    vk::FALSE
}

/// Device properties the backend lays its work out by.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    pub name: String,
    /// A CPU implementation (lavapipe): correct, but slower than the CPU backend.
    pub software: bool,
    pub driver: String,
    pub api_version: u32,
    pub handle_size: u32,
    pub handle_alignment: u32,
    pub base_alignment: u32,
    pub max_group_stride: u32,
    pub max_dispatch_invocations: u32,
    pub scratch_alignment: u64,
    pub max_primitive_count: u64,
    pub max_storage_buffer_range: u64,
    /// The largest single allocation (maxMemoryAllocationSize): what bounds the particle and
    /// box buffers, which shaders reach by device address rather than through a binding.
    pub max_allocation: u64,
    /// The size of the largest device-local memory heap: what an out-of-memory error names.
    pub device_local_heap: u64,
    pub max_workgroup_count: [u32; 3],
    /// Nanoseconds per timestamp tick; `None` when the queue has no timestamps.
    pub timestamp_period: Option<f64>,
    pub timestamp_mask: u64,
}

/// Why the context could not be created (kept, so a process probes once).
#[derive(Clone, Debug)]
enum ContextError {
    Unavailable(String),
    Device(String),
    /// [`DeviceChoice::Index`] past the last device with ray-tracing pipelines.
    NoSuchDevice {
        index: usize,
        count: usize,
    },
}

/// Which of the devices with ray-tracing pipelines a context opens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DeviceChoice {
    /// A discrete GPU before an integrated one, before a virtual one, before a CPU's.
    Best,
    /// The i-th such device in the loader's order.
    Index(usize),
}

impl From<ContextError> for BackendError {
    fn from(e: ContextError) -> BackendError {
        match e {
            ContextError::Unavailable(m) => BackendError::Unavailable(NAME, m),
            ContextError::Device(message) => BackendError::Device {
                backend: NAME,
                message,
            },
            ContextError::NoSuchDevice { index, count } => BackendError::Unavailable(
                NAME,
                format!(
                    "no Vulkan device {index} with ray-tracing pipelines (this machine has {count})"
                ),
            ),
        }
    }
}

/// The descriptor-set layout and pipeline layout every pipeline uses, and the layout of the
/// kernels that prepare a step (push constants only: they reach every array by
/// address). Made by `Layouts::new` in `pipelines.rs`.
pub struct Layouts {
    pub set: vk::DescriptorSetLayout,
    pub pipeline: vk::PipelineLayout,
    pub prepare: vk::PipelineLayout,
}

/// What a ray-tracing pipeline runs (its stages: `RtProgram::stages` in `pipelines.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RtProgram {
    /// The RBF field: frames and point queries (`render.rgen`, `query.rgen`, `particle.*`).
    Field,
    /// Knoll et al.'s splatter (`splat.*`).
    Splat,
}

/// The instance, device, queue, allocator and compiled pipelines.
pub struct Context {
    _entry: ash::Entry,
    instance: ash::Instance,
    debug: Option<(ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    pub physical: vk::PhysicalDevice,
    pub device: ash::Device,
    pub accel: khr::acceleration_structure::Device,
    pub rt: khr::ray_tracing_pipeline::Device,
    pub queue_family: u32,
    queue: Mutex<vk::Queue>,
    allocator: Mutex<Option<Allocator>>,
    pub info: DeviceInfo,
    pub validation: bool,
    pub layouts: Layouts,
    pub(crate) rt_pipelines: Mutex<HashMap<(SpecConstants, RtProgram), vk::Pipeline>>,
    pub(crate) compute_pipelines: Mutex<HashMap<(Entry, SpecConstants), vk::Pipeline>>,
}

static SHARED: OnceLock<Result<Arc<Context>, ContextError>> = OnceLock::new();

/// The process's Vulkan context, created on first use. An error (no loader, no device with ray
/// tracing) is remembered: later calls return it at once.
pub fn shared() -> Result<Arc<Context>, BackendError> {
    SHARED
        .get_or_init(|| Context::new(validation_wanted(), DeviceChoice::Best).map(Arc::new))
        .clone()
        .map_err(BackendError::from)
}

/// Whether contexts run the Khronos validation layer: `AARBF_VK_VALIDATION=0|1`, else in
/// builds with debug assertions.
fn validation_wanted() -> bool {
    match std::env::var("AARBF_VK_VALIDATION").as_deref() {
        Ok("0") => false,
        Ok("1") => true,
        _ => cfg!(debug_assertions),
    }
}

/// A context on every device with ray-tracing pipelines, in the loader's order (a study
/// compares them, as the paper's Fig. 10a compares vendors): each its own instance and device,
/// apart from the shared one. A device that fails to open is its entry's error; none at all is
/// one error saying why.
pub fn on_every_device() -> Vec<Result<Arc<Context>, BackendError>> {
    let validation = validation_wanted();
    let mut out = Vec::new();
    // No machine has 64 GPUs; the bound keeps a loader that fails before counting finite.
    for index in 0..64 {
        match Context::new(validation, DeviceChoice::Index(index)) {
            Ok(ctx) => out.push(Ok(Arc::new(ctx))),
            Err(ContextError::NoSuchDevice { .. }) => break,
            Err(e @ ContextError::Unavailable(_)) if index == 0 => {
                out.push(Err(e.into()));
                break;
            }
            Err(e) => out.push(Err(e.into())),
        }
    }
    out
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

impl Context {
    fn new(validation: bool, choice: DeviceChoice) -> Result<Context, ContextError> {
        let unavailable = |m: String| ContextError::Unavailable(m);
        let failed = |what: &str, e: vk::Result| ContextError::Device(format!("{what}: {e}"));
        // SAFETY: loading the system's Vulkan loader; nothing else runs its code concurrently.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| {
            unavailable(format!(
                "no Vulkan loader (libvulkan.so.1) could be loaded ({e}); run `cargo xtask setup`"
            ))
        })?;

        // SAFETY: plain queries of the loader.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }.unwrap_or_default();
        let have_layer = layers
            .iter()
            .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
        let instance_extensions =
            unsafe { entry.enumerate_instance_extension_properties(None) }.unwrap_or_default();
        let have_debug_utils = instance_extensions.iter().any(|e| {
            e.extension_name_as_c_str()
                .is_ok_and(|n| n == ext::debug_utils::NAME)
        });
        let validation = validation && have_layer && have_debug_utils;
        if !have_layer && cfg!(debug_assertions) {
            tracing::info!(
                "the Khronos validation layer is not installed (Debian: vulkan-validationlayers); running without it"
            );
        }

        let app = vk::ApplicationInfo::default()
            .application_name(c"aarbf")
            .engine_name(c"aarbf")
            .api_version(vk::API_VERSION_1_2);
        let layer_names: Vec<*const c_char> = if validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            Vec::new()
        };
        let extension_names: Vec<*const c_char> = if validation {
            vec![ext::debug_utils::NAME.as_ptr()]
        } else {
            Vec::new()
        };
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback));
        let mut create = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&extension_names);
        if validation {
            // Also reports on instance creation and destruction.
            create = create.push_next(&mut messenger_info);
        }
        // SAFETY: the create info and everything it points to outlive the call.
        let instance = unsafe { entry.create_instance(&create, None) }
            .map_err(|e| failed("creating the Vulkan instance", e))?;
        let debug = if validation {
            let loader = ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: a valid create info; the callback is a plain function.
            match unsafe { loader.create_debug_utils_messenger(&messenger_info, None) } {
                Ok(m) => Some((loader, m)),
                Err(e) => {
                    // SAFETY: nothing was created from the instance yet.
                    unsafe { instance.destroy_instance(None) };
                    return Err(failed("creating the validation messenger", e));
                }
            }
        } else {
            None
        };
        // From here on, a failure must destroy what was made: a guard does it.
        let mut guard = InstanceGuard {
            instance: Some(instance),
            debug,
        };
        let instance = guard.instance.as_ref().expect("set above");

        // SAFETY: plain queries.
        let devices = unsafe { instance.enumerate_physical_devices() }
            .map_err(|e| failed("listing Vulkan devices", e))?;
        if devices.is_empty() {
            return Err(unavailable(
                "no Vulkan device found; run `cargo xtask setup` (it installs Mesa lavapipe when no GPU driver is present)"
                    .into(),
            ));
        }
        let mut reasons = Vec::new();
        let mut best: Option<(u32, vk::PhysicalDevice, u32)> = None;
        let mut qualifying = 0;
        for &pd in &devices {
            // SAFETY: pd comes from this instance.
            let props = unsafe { instance.get_physical_device_properties(pd) };
            let name = device_name(&props);
            let missing = missing_features(instance, pd)
                .map_err(|e| failed("querying device extensions", e))?;
            if !missing.is_empty() {
                reasons.push(format!("{name}: missing {}", missing.join(", ")));
                continue;
            }
            // SAFETY: as above.
            let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
            // A compute queue (ray tracing runs on compute-capable queues), preferring one with
            // timestamps.
            let family = families
                .iter()
                .enumerate()
                .filter(|(_, f)| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .max_by_key(|(_, f)| {
                    (
                        f.timestamp_valid_bits > 0,
                        f.queue_flags.contains(vk::QueueFlags::GRAPHICS),
                    )
                })
                .map(|(i, _)| i as u32);
            let Some(family) = family else {
                reasons.push(format!("{name}: no compute queue"));
                continue;
            };
            let rank = match props.device_type {
                vk::PhysicalDeviceType::DISCRETE_GPU => 4,
                vk::PhysicalDeviceType::INTEGRATED_GPU => 3,
                vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
                vk::PhysicalDeviceType::CPU => 1,
                _ => 0,
            };
            let chosen = match choice {
                DeviceChoice::Best => best.is_none_or(|b| rank > b.0),
                DeviceChoice::Index(i) => qualifying == i,
            };
            if chosen {
                best = Some((rank, pd, family));
            }
            qualifying += 1;
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
            return Err(unavailable(format!(
                "no Vulkan device supports ray-tracing pipelines ({}); on a machine without a GPU, `cargo xtask setup` installs Mesa lavapipe >= 25",
                reasons.join("; ")
            )));
        };

        // Exactly the features the backend uses.
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true);
        let mut accel_features = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default()
            .acceleration_structure(true);
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
        let device = unsafe { instance.create_device(physical, &device_info, None) }
            .map_err(|e| failed("creating the Vulkan device", e))?;
        // SAFETY: family and index 0 were requested above.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let accel = khr::acceleration_structure::Device::new(instance, &device);
        let rt = khr::ray_tracing_pipeline::Device::new(instance, &device);

        let info = Self::device_info(instance, physical, queue_family);
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: physical,
            debug_settings: AllocatorDebugSettings::default(),
            buffer_device_address: true,
            allocation_sizes: AllocationSizes::default(),
        });
        let allocator = match allocator {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: nothing was created from the device yet.
                unsafe { device.destroy_device(None) };
                return Err(ContextError::Device(format!(
                    "creating the memory allocator: {e}"
                )));
            }
        };
        let layouts = match Layouts::new(&device) {
            Ok(l) => l,
            Err(e) => {
                drop(allocator);
                // SAFETY: as above.
                unsafe { device.destroy_device(None) };
                return Err(ContextError::Device(format!(
                    "creating pipeline layouts: {e}"
                )));
            }
        };
        tracing::info!(
            "ash backend: {} ({}), validation {}",
            info.name,
            info.driver,
            if validation { "on" } else { "off" }
        );
        let instance = guard.instance.take().expect("set above");
        let debug = guard.debug.take();
        Ok(Context {
            _entry: entry,
            instance,
            debug,
            physical,
            device,
            accel,
            rt,
            queue_family,
            queue: Mutex::new(queue),
            allocator: Mutex::new(Some(allocator)),
            info,
            validation,
            layouts,
            rt_pipelines: Mutex::new(HashMap::new()),
            compute_pipelines: Mutex::new(HashMap::new()),
        })
    }

    fn device_info(instance: &ash::Instance, pd: vk::PhysicalDevice, family: u32) -> DeviceInfo {
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

    /// The queue, locked for one submission (queues need external synchronisation).
    pub(crate) fn queue(&self) -> MutexGuard<'_, vk::Queue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The allocator, locked.
    pub(crate) fn allocator(&self) -> MutexGuard<'_, Option<Allocator>> {
        self.allocator.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The device in words.
    pub fn describe(&self) -> String {
        format!("{} ({})", self.info.name, self.info.driver)
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: every object made from the device is destroyed here or by its owner (backends
        // hold an Arc to this context, so they are gone); the device is idle after the wait.
        unsafe {
            let _ = self.device.device_wait_idle();
            for (_, p) in self
                .rt_pipelines
                .get_mut()
                .unwrap_or_else(|e| e.into_inner())
                .drain()
            {
                self.device.destroy_pipeline(p, None);
            }
            for (_, p) in self
                .compute_pipelines
                .get_mut()
                .unwrap_or_else(|e| e.into_inner())
                .drain()
            {
                self.device.destroy_pipeline(p, None);
            }
            self.layouts.destroy(&self.device);
            drop(
                self.allocator
                    .get_mut()
                    .unwrap_or_else(|e| e.into_inner())
                    .take(),
            );
            self.device.destroy_device(None);
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// Destroys the instance (and messenger) if context creation fails half way.
struct InstanceGuard {
    instance: Option<ash::Instance>,
    debug: Option<(ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
}

impl Drop for InstanceGuard {
    fn drop(&mut self) {
        // SAFETY: reached only when creation failed; nothing made from the instance survives.
        unsafe {
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            if let Some(i) = self.instance.take() {
                i.destroy_instance(None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every device with ray-tracing pipelines opens on its own (here lavapipe, so one), the
    /// best of them is among them, and an index past the last is refused with the count.
    #[test]
    fn a_context_opens_on_every_ray_tracing_device() {
        let every = on_every_device();
        assert!(!every.is_empty());
        let names: Vec<String> = every
            .iter()
            .map(|c| c.as_ref().expect("the device opens").describe())
            .collect();
        let best = shared().expect("a device").describe();
        assert!(names.contains(&best), "{best} not in {names:?}");
        match Context::new(false, DeviceChoice::Index(names.len())) {
            Err(ContextError::NoSuchDevice { index, count }) => {
                assert_eq!((index, count), (names.len(), names.len()));
                let e = BackendError::from(ContextError::NoSuchDevice { index, count });
                assert!(e.to_string().contains(&format!("has {count}")), "{e}");
            }
            Err(e) => panic!("{e:?}"),
            Ok(_) => panic!("a device past the last opened"),
        }
    }
}
