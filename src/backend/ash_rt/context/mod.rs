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
//!
//! Files: `instance` (the instance, the validation layer and its messenger), `device` (which
//! device, the device itself and its limits), and here the context made of them.

use std::collections::HashMap;
use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use ash::{khr, vk};
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use gpu_allocator::{AllocationSizes, AllocatorDebugSettings};

use crate::backend::BackendError;
use crate::backend::shaders::Entry;
use crate::backend::shaders::SpecConstants;

mod device;
mod instance;

use device::DeviceChoice;
pub use device::{DeviceInfo, REQUIRED_EXTENSIONS};
pub use instance::validation_messages;
use instance::{InstanceGuard, Messenger, validation_usable, validation_wanted};

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

impl ContextError {
    /// A Vulkan call that failed, in the context's words.
    fn failed(what: &str, e: vk::Result) -> ContextError {
        ContextError::Device(format!("{what}: {e}"))
    }
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
    /// Set 0's descriptor-set layout, reflected from the shaders.
    pub set: vk::DescriptorSetLayout,
    /// The pipeline layout of the ray-tracing and compute pipelines: set 0 and the `Push`
    /// constants.
    pub pipeline: vk::PipelineLayout,
    /// The pipeline layout of the kernels that prepare a step: `PreparePush` constants only.
    pub prepare: vk::PipelineLayout,
}

/// What a ray-tracing pipeline runs (its stages: `RtProgram::stages` in `pipelines.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RtProgram {
    /// The RBF field: frames and point queries (`render.rgen`, `query.rgen`, `particle.*`).
    Field,
    /// Knoll et al.'s splatter (`splat.*`).
    Splat,
    /// A brick's share of a distributed frame (`owned.rgen` over the field's `particle.*`),
    /// made only when a brick renders.
    Owned,
}

/// The instance, device, queue, allocator and compiled pipelines.
pub struct Context {
    _entry: ash::Entry,
    instance: ash::Instance,
    debug: Option<Messenger>,
    /// The physical device chosen.
    pub physical: vk::PhysicalDevice,
    /// The logical device.
    pub device: ash::Device,
    /// `VK_KHR_acceleration_structure`'s functions.
    pub accel: khr::acceleration_structure::Device,
    /// `VK_KHR_ray_tracing_pipeline`'s functions.
    pub rt: khr::ray_tracing_pipeline::Device,
    /// The family of the queue every submission goes to.
    pub queue_family: u32,
    queue: Mutex<vk::Queue>,
    allocator: Mutex<Option<Allocator>>,
    /// The device's properties and limits.
    pub info: DeviceInfo,
    /// Whether the Khronos validation layer runs (`AARBF_VK_VALIDATION`, else debug builds).
    pub validation: bool,
    /// The layouts every pipeline uses.
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

impl Context {
    fn new(validation: bool, choice: DeviceChoice) -> Result<Context, ContextError> {
        // SAFETY: loading the system's Vulkan loader; nothing else runs its code concurrently.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| {
            ContextError::Unavailable(format!(
                "no Vulkan loader (libvulkan.so.1) could be loaded ({e}); run `cargo xtask setup`"
            ))
        })?;
        let validation = validation_usable(&entry, validation);
        // From here on, a failure must destroy what was made: the guard does it.
        let guard = InstanceGuard::create(&entry, validation)?;
        let instance = guard.instance();
        let (physical, queue_family) = device::choose(instance, choice)?;
        let device = device::create(instance, physical, queue_family)?;
        // SAFETY: family and index 0 were requested at creation.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let accel = khr::acceleration_structure::Device::new(instance, &device);
        let rt = khr::ray_tracing_pipeline::Device::new(instance, &device);
        let info = DeviceInfo::query(instance, physical, queue_family);
        let (allocator, layouts) = match allocator_and_layouts(instance, &device, physical) {
            Ok(made) => made,
            Err(e) => {
                // SAFETY: nothing made from the device survives.
                unsafe { device.destroy_device(None) };
                return Err(e);
            }
        };
        tracing::info!(
            "ash backend: {} ({}), validation {}",
            info.name,
            info.driver,
            if validation { "on" } else { "off" }
        );
        let (instance, debug) = guard.release();
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

/// The memory allocator and the pipeline layouts of a new device. On failure neither is left,
/// and the caller destroys the device.
fn allocator_and_layouts(
    instance: &ash::Instance,
    device: &ash::Device,
    physical: vk::PhysicalDevice,
) -> Result<(Allocator, Layouts), ContextError> {
    let allocator = Allocator::new(&AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device: physical,
        debug_settings: AllocatorDebugSettings::default(),
        buffer_device_address: true,
        allocation_sizes: AllocationSizes::default(),
    })
    .map_err(|e| ContextError::Device(format!("creating the memory allocator: {e}")))?;
    let layouts = Layouts::new(device)
        .map_err(|e| ContextError::Device(format!("creating pipeline layouts: {e}")))?;
    Ok((allocator, layouts))
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
