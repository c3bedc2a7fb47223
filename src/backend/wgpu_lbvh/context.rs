//! The wgpu device every wgpu backend in a process shares (pipelines are compiled once; on
//! lavapipe each compilation is a slow JIT run), its compiled kernels, and error capture:
//! every device operation runs inside error scopes, so a validation error, an out-of-memory
//! or a lost device becomes a [`BackendError`], never a panic.

use std::borrow::Cow;
use std::cell::Cell;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::backend::BackendError;
use crate::backend::shaders::table::{GpuBackend, Language};
use crate::backend::shaders::{Entry, Shader, glsl_with_includes, wgsl_with_includes};
use crate::values::shader_constants::SPEC_CONSTANTS;

pub(crate) fn device_error(message: impl Into<String>) -> BackendError {
    BackendError::Device {
        backend: "wgpu",
        message: message.into(),
    }
}

thread_local! {
    static BUFFERS_MADE: Cell<u64> = const { Cell::new(0) };
}

/// Buffers this thread has made through [`GpuContext::create_buffer`], which makes every buffer
/// of this backend: tests check that stepping through a reserved series makes none (per
/// thread, so tests running beside each other on the shared device do not count each other's).
pub fn buffers_made() -> u64 {
    BUFFERS_MADE.with(Cell::get)
}

/// The specialisation-constant values of a GLSL kernel variant (params.glsl's seven, in
/// constant_id order), or none.
pub(super) type Variant = Option<[u32; SPEC_CONSTANTS.len()]>;

/// Parts an array may be split into ([`super::util::SplitBuffer`]); the kernels' [`Layout::Split`] variant
/// (`SPLIT_PARTS` = 4 in `shaders_glsl/wgpu/split.glsl`, `shaders_wgsl/shared/split_boxes.wgsl`,
/// `shaders_wgsl/lbvh_{hierarchy,fit}.wgsl`) binds this many buffers per array.
pub(super) const PARTS: u64 = 4;

/// How a kernel binds the arrays that can outgrow one storage binding
/// (`shaders_glsl/wgpu/split.glsl`): each as one buffer, or in [`PARTS`] parts (`Layout::of` picks).
/// The two are separate shader modules (`SPLIT_PARTS` = 1 or 4), so the whole variant binds
/// one buffer per array and carries no part selection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layout {
    Whole,
    Split,
}

impl Layout {
    fn split_parts(self) -> u32 {
        match self {
            Layout::Whole => 1,
            Layout::Split => PARTS as u32,
        }
    }
}

/// A wgpu adapter, as `aarbf info --devices` lists it.
#[derive(Clone, Debug)]
pub struct AdapterSummary {
    /// Its name, vendor, device type, driver and backend.
    pub info: wgpu::AdapterInfo,
    /// The optional features it offers.
    pub features: wgpu::Features,
    /// Its limits.
    pub limits: wgpu::Limits,
}

/// Every adapter wgpu finds, on every backend it was built with.
pub fn adapters() -> Vec<AdapterSummary> {
    listed(&instance())
}

/// Every adapter `instance` finds.
fn listed(instance: &wgpu::Instance) -> Vec<AdapterSummary> {
    pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
        .into_iter()
        .map(|a| AdapterSummary {
            info: a.get_info(),
            features: a.features(),
            limits: a.limits(),
        })
        .collect()
}

/// The adapters a wgpu backend chooses among ([`GpuContext::new`]'s order): Vulkan, Metal or
/// DX12 ones, or every backend's where those have none or `WGPU_BACKEND` chooses. Listing GL
/// only then keeps its driver unloaded (and its EGL errors unsaid on a machine without a
/// display) where Vulkan answers.
pub fn adapters_to_choose_from() -> Vec<AdapterSummary> {
    let chosen = std::env::var_os("WGPU_BACKEND").is_some();
    for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::all()] {
        let instance = instance_for((!chosen).then_some(backends));
        let found = listed(&instance);
        if !found.is_empty() || chosen {
            return found;
        }
    }
    Vec::new()
}

fn instance() -> wgpu::Instance {
    instance_for(None)
}

/// The flags of every wgpu instance the program makes (the backend's and the viewer
/// window's). Validation layers follow the build (on with debug assertions, as in the tests)
/// unless WGPU_VALIDATION says otherwise. Shader debug information stays off unless
/// WGPU_DEBUG=1: with it naga tags WGSL modules with a SPIR-V source language (WGSL, 10) that
/// Debian's validation layers (1.3.239) reject as invalid SPIR-V, a false alarm that would
/// hide real messages.
pub fn instance_flags() -> wgpu::InstanceFlags {
    (wgpu::InstanceFlags::from_build_config() - wgpu::InstanceFlags::DEBUG).with_env()
}

/// An instance over `backends` (None: `WGPU_BACKEND`, else all), with [`instance_flags`].
fn instance_for(backends: Option<wgpu::Backends>) -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.flags = instance_flags();
    if let Some(b) = backends {
        desc.backends = b;
    }
    wgpu::Instance::new(desc)
}

/// A device, its queue and compiled kernels.
pub struct GpuContext {
    /// The adapter the device was requested from.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue, which every submission goes to.
    pub queue: wgpu::Queue,
    /// The adapter's name, vendor, device type, driver and backend.
    pub info: wgpu::AdapterInfo,
    /// The limits the device was created with.
    pub limits: wgpu::Limits,
    /// Timestamp queries, where the adapter has them inside command encoders.
    pub timestamps: Option<Timestamps>,
    /// The device's memory is the host's (a CPU or integrated adapter that lets storage
    /// buffers be mapped): a step is written straight into the buffers the kernels read,
    /// without a staging copy.
    pub unified_memory: bool,
    lost: Arc<Mutex<Option<String>>>,
    /// By shader file (`Shader::file`) and layout.
    modules: Mutex<HashMap<(&'static str, Layout), Arc<wgpu::ShaderModule>>>,
    pipelines: Mutex<HashMap<(Entry, Variant, Layout), Arc<wgpu::ComputePipeline>>>,
}

/// A pair of timestamp queries and the buffers their values come back through, for timing one
/// submission at a time (the lock: the context is shared between threads).
pub struct Timestamps {
    pub queries: wgpu::QuerySet,
    pub resolved: wgpu::Buffer,
    pub readback: wgpu::Buffer,
    /// Nanoseconds per timestamp tick.
    pub period: f32,
    pub lock: Mutex<()>,
}

impl Timestamps {
    fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Timestamps {
        let buffer = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        Timestamps {
            queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("frame timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolved: buffer(
                "resolved timestamps",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer(
                "timestamp readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            period: queue.get_timestamp_period(),
            lock: Mutex::new(()),
        }
    }
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.info.name)
            .field("backend", &self.info.backend)
            .finish()
    }
}

impl GpuContext {
    /// The process-wide device (created on first use; an error, such as no adapter, is kept).
    pub fn shared() -> Result<Arc<GpuContext>, BackendError> {
        static SHARED: OnceLock<Result<Arc<GpuContext>, String>> = OnceLock::new();
        SHARED
            .get_or_init(|| GpuContext::create().map(Arc::new))
            .clone()
            .map_err(|e| BackendError::Unavailable("wgpu", e))
    }

    /// A new device on the best adapter (`WGPU_ADAPTER_NAME` / `WGPU_BACKEND` narrow it),
    /// with every limit the adapter offers.
    pub fn create() -> Result<GpuContext, String> {
        GpuContext::create_with(None)
    }

    /// A new device on the best adapter holding to `limits` (tests: WebGPU's defaults stand in
    /// for a small GPU, on any adapter that offers at least those).
    pub fn with_limits(limits: wgpu::Limits) -> Result<GpuContext, String> {
        GpuContext::create_with(Some(limits))
    }

    fn create_with(requested: Option<wgpu::Limits>) -> Result<GpuContext, String> {
        // Vulkan, Metal or DX12 first; GL only when none of them has an adapter (unless
        // WGPU_BACKEND chooses).
        let chosen = std::env::var_os("WGPU_BACKEND").is_some();
        let mut adapter = Err("no adapter".to_owned());
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::all()] {
            let instance = instance_for((!chosen).then_some(backends));
            adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
                &instance, None,
            ))
            .map_err(|e| format!("no wgpu adapter: {e}"))
            .map(|default| for_this_rank(&instance, default));
            if adapter.is_ok() || chosen {
                break;
            }
        }
        GpuContext::open(adapter?, requested)
    }

    /// A device on every adapter wgpu finds (on every backend it was built with: on this
    /// project's machines lavapipe through Vulkan and llvmpipe through GL), each opened or
    /// the reason it could not be, for studies that compare traversal across adapters.
    pub fn on_every_adapter() -> Vec<Result<GpuContext, String>> {
        let instance = instance();
        pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
            .into_iter()
            .map(|a| GpuContext::open(a, None))
            .collect()
    }

    fn open(adapter: wgpu::Adapter, requested: Option<wgpu::Limits>) -> Result<GpuContext, String> {
        let info = adapter.get_info();
        let limits = requested.unwrap_or_else(|| adapter.limits());
        // Frames are timed on the device where timestamps can be written between command
        // buffers (util::submit_and_time).
        let timestamp_features =
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        let timed = adapter.features().contains(timestamp_features);
        // Where device memory is host memory, a copy from staging memory is a CPU's memcpy
        // (lavapipe: on the same cores): storage buffers the host maps skip it. Not on a
        // discrete GPU, where mapped device memory is slow to read and the copy is a DMA.
        let unified_memory = matches!(
            info.device_type,
            wgpu::DeviceType::Cpu | wgpu::DeviceType::IntegratedGpu
        ) && adapter
            .features()
            .contains(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS);
        let mut required_features = wgpu::Features::empty();
        if timed {
            required_features |= timestamp_features;
        }
        if unified_memory {
            required_features |= wgpu::Features::MAPPABLE_PRIMARY_BUFFERS;
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("aarbf wgpu"),
            required_features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| format!("{}: cannot open a device: {e}", info.name))?;
        let lost = Arc::new(Mutex::new(None));
        let lost_in = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            tracing::error!("wgpu device lost ({reason:?}): {message}");
            *lost_in.lock().unwrap_or_else(|e| e.into_inner()) =
                Some(format!("device lost ({reason:?}): {message}"));
        });
        // Errors outside any scope (there should be none) are logged, never a panic.
        device.on_uncaptured_error(Arc::new(|e: wgpu::Error| {
            tracing::error!("wgpu: uncaptured error: {e}");
        }));
        tracing::info!(
            "wgpu: {} ({:?}, {:?}, {} {})",
            info.name,
            info.backend,
            info.device_type,
            info.driver,
            info.driver_info
        );
        let timestamps = timed.then(|| Timestamps::new(&device, &queue));
        Ok(GpuContext {
            adapter,
            device,
            queue,
            info,
            limits,
            timestamps,
            unified_memory,
            lost,
            modules: Mutex::new(HashMap::new()),
            pipelines: Mutex::new(HashMap::new()),
        })
    }

    /// Makes a buffer, counting it ([`buffers_made`]).
    pub fn create_buffer(&self, desc: &wgpu::BufferDescriptor<'_>) -> wgpu::Buffer {
        BUFFERS_MADE.with(|c| c.set(c.get() + 1));
        self.device.create_buffer(desc)
    }

    /// The adapter in words.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?}; {} {})",
            self.info.name,
            self.info.backend,
            self.info.device_type,
            self.info.driver,
            self.info.driver_info
        )
    }

    /// The largest storage-buffer binding, in bytes.
    pub fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// Runs `f` inside validation, out-of-memory and internal error scopes; any error (or a
    /// lost device) is returned as [`BackendError::Device`] naming `what`.
    pub fn scoped<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, BackendError> {
        self.check_lost()?;
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let memory = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let internal = self.device.push_error_scope(wgpu::ErrorFilter::Internal);
        let out = f();
        let errors = [
            pollster::block_on(internal.pop()),
            pollster::block_on(memory.pop()),
            pollster::block_on(validation.pop()),
        ];
        if let Some(e) = errors.into_iter().flatten().next() {
            return Err(device_error(format!("{what}: {e}")));
        }
        self.check_lost()?;
        Ok(out)
    }

    fn check_lost(&self) -> Result<(), BackendError> {
        match &*self.lost.lock().unwrap_or_else(|e| e.into_inner()) {
            Some(m) => Err(device_error(m.clone())),
            None => Ok(()),
        }
    }

    /// Waits until the device has finished everything submitted.
    pub fn wait(&self) -> Result<(), BackendError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| device_error(format!("waiting for the device: {e}")))?;
        self.check_lost()
    }

    fn module(
        &self,
        shader: &'static Shader,
        layout: Layout,
    ) -> Result<Arc<wgpu::ShaderModule>, BackendError> {
        let mut modules = self.modules.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(m) = modules.get(&(shader.file, layout)) {
            return Ok(m.clone());
        }
        let label = format!("{} {layout:?}", shader.file);
        let parts = layout.split_parts();
        let parts_text = parts.to_string();
        let defines = [("SPLIT_PARTS", parts_text.as_str())];
        let source = match shader.language {
            Language::GlslCompute => wgpu::ShaderSource::Glsl {
                shader: Cow::Owned(glsl_with_includes(shader.source)),
                stage: wgpu::naga::ShaderStage::Compute,
                defines: &defines,
            },
            Language::Wgsl => {
                wgpu::ShaderSource::Wgsl(Cow::Owned(wgsl_with_includes(shader.source, parts)))
            }
            Language::GlslRayTracing => {
                return Err(device_error(format!("{}: not a wgpu shader", shader.file)));
            }
        };
        let module = self.scoped(&format!("shader {label}"), || {
            self.device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some(&label),
                    source,
                })
        })?;
        let module = Arc::new(module);
        modules.insert((shader.file, layout), module.clone());
        Ok(module)
    }

    /// The pipeline of `kernel` (one of [`crate::backend::shaders::on_wgpu`], with
    /// specialisation constants `variant` where it has them) binding its splittable arrays as
    /// `layout` says, compiled on first use and cached for the process.
    pub fn pipeline(
        &self,
        kernel: Entry,
        variant: Variant,
        layout: Layout,
    ) -> Result<Arc<wgpu::ComputePipeline>, BackendError> {
        debug_assert_eq!(kernel.shader().backend, GpuBackend::Wgpu, "{kernel}");
        let variant = if kernel.point().specialised {
            variant
        } else {
            None
        };
        let key = (kernel, variant, layout);
        if let Some(p) = self
            .pipelines
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return Ok(p.clone());
        }
        let module = self.module(kernel.shader(), layout)?;
        // naga names an override by its constant_id when it has one: the keys are "0", "1", ...
        let keys: Vec<String> = (0..SPEC_CONSTANTS.len()).map(|i| i.to_string()).collect();
        let constants: Vec<(&str, f64)> = variant
            .map(|v| {
                keys.iter()
                    .zip(v)
                    .map(|(k, v)| (k.as_str(), f64::from(v)))
                    .collect()
            })
            .unwrap_or_default();
        let label = format!("{kernel} {variant:?} {layout:?}");
        let started = std::time::Instant::now();
        let pipeline = self.scoped(&format!("pipeline {label}"), || {
            self.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(&label),
                    layout: None,
                    module: &module,
                    entry_point: Some(kernel.point().name),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: &constants,
                        zero_initialize_workgroup_memory: false,
                    },
                    cache: None,
                })
        });
        let pipeline = pipeline.map_err(|e| match layout {
            // Most likely the layout's storage buffers are more than the adapter binds.
            Layout::Split => device_error(format!(
                "{e} (this step or image outgrows one storage binding, so each of its large \
                 arrays is bound in {} parts; {} allows {} storage buffers per shader stage: a \
                 larger cluster size or a smaller image keeps every array in one binding)",
                PARTS, self.info.name, self.limits.max_storage_buffers_per_shader_stage
            )),
            Layout::Whole => e,
        })?;
        tracing::debug!(
            "wgpu: compiled {label} in {:.2} s",
            started.elapsed().as_secs_f64()
        );
        let pipeline = Arc::new(pipeline);
        self.pipelines
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, pipeline.clone());
        Ok(pipeline)
    }
}

/// In a job of several processes a node (`crate::backend::node_local_rank`), the adapter of
/// this process's rank among those like `default` (its API and kind of device, in wgpu's
/// order): a node's ranks spread over its GPUs. `default` itself outside a job, where
/// `WGPU_ADAPTER_NAME` names one, or where it is the only one of its kind.
fn for_this_rank(instance: &wgpu::Instance, default: wgpu::Adapter) -> wgpu::Adapter {
    let Some(rank) = crate::backend::node_local_rank() else {
        return default;
    };
    if std::env::var_os("WGPU_ADAPTER_NAME").is_some() {
        return default;
    }
    let info = default.get_info();
    let mut alike: Vec<wgpu::Adapter> =
        pollster::block_on(instance.enumerate_adapters(info.backend.into()))
            .into_iter()
            .filter(|a| {
                let other = a.get_info();
                other.device_type == info.device_type
            })
            .collect();
    if alike.len() <= 1 {
        return default;
    }
    let index = crate::backend::device_for_rank(alike.len(), Some(rank));
    alike.swap_remove(index)
}
