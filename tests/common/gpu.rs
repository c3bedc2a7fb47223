//! The GPU backends a test runs over. A check every GPU backend must pass is written once, as
//! `fn NAME(gpu: Gpu)`, and `on_every_gpu!(NAME)` makes it one test per backend, `NAME::ash`
//! and `NAME::wgpu` (as wgpu's and vello's test harnesses do): a failure names its backend, and
//! `-- ::ash` runs one backend's share. A backend without its device fails its tests.

use std::ops::{Deref, DerefMut};
use std::sync::Arc;

use aarbf::accel::HilbertQuantizer;
use aarbf::backend::ash_rt::{self, AshBackend, Traversal};
use aarbf::backend::gpu_data::SortedParticles;
use aarbf::backend::wgpu_lbvh::{self, GpuContext, WgpuBackend};
use aarbf::backend::{Backend, BackendKind};

/// One test per GPU backend running the body `fn NAME(gpu: Gpu)` beside it.
#[allow(unused_macros)] // a binary of its own (ash_validation) shares this file
macro_rules! on_every_gpu {
    ($($test:ident),+ $(,)?) => {$(
        mod $test {
            #[test]
            fn ash() {
                super::$test($crate::common::Gpu::Ash)
            }

            #[test]
            fn wgpu() {
                super::$test($crate::common::Gpu::Wgpu)
            }
        }
    )+};
}
#[allow(unused_imports)] // a binary of its own (ash_validation) shares this file
pub(crate) use on_every_gpu;

/// A GPU backend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Gpu {
    /// Vulkan ray tracing (`backend::ash_rt`).
    Ash,
    /// A software LBVH in compute shaders (`backend::wgpu_lbvh`).
    Wgpu,
}

impl std::fmt::Display for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.kind())
    }
}

/// The wgpu backends' device, shared by every test of the process.
pub(crate) fn wgpu_context() -> Arc<GpuContext> {
    super::capture_driver_messages();
    super::require("a wgpu adapter", GpuContext::shared())
}

impl Gpu {
    pub(crate) fn kind(self) -> BackendKind {
        match self {
            Gpu::Ash => BackendKind::Ash,
            Gpu::Wgpu => BackendKind::Wgpu,
        }
    }

    /// Fails the test unless this backend's device is there.
    pub(crate) fn require(self) {
        self.backend();
    }

    /// A backend on this backend's shared device; the test fails without one.
    pub(crate) fn backend(self) -> GpuBackend {
        super::capture_driver_messages();
        match self {
            Gpu::Ash => GpuBackend::Ash(Box::new(super::require(
                "a Vulkan device with ray-tracing pipelines",
                AshBackend::new(),
            ))),
            Gpu::Wgpu => GpuBackend::Wgpu(Box::new(WgpuBackend::with_context(wgpu_context()))),
        }
    }

    /// A backend for each way this backend traverses the particles, named: ash's RT pipeline
    /// and its LBVH compute kernel; wgpu's LBVH.
    pub(crate) fn traversals(self) -> Vec<(&'static str, GpuBackend)> {
        match self {
            Gpu::Ash => [
                ("rt pipeline", Traversal::RtPipeline),
                ("lbvh", Traversal::Lbvh),
            ]
            .into_iter()
            .map(|(name, traversal)| {
                let mut b = self.backend();
                if let GpuBackend::Ash(ash) = &mut b {
                    ash.set_traversal(traversal);
                }
                (name, b)
            })
            .collect(),
            Gpu::Wgpu => vec![("lbvh", self.backend())],
        }
    }

    /// Buffers this backend has made on this thread so far (each test runs on a thread of its
    /// own).
    pub(crate) fn buffers_made(self) -> u64 {
        match self {
            Gpu::Ash => ash_rt::resources::buffers_made(),
            Gpu::Wgpu => wgpu_lbvh::buffers_made(),
        }
    }
}

/// A GPU backend with the hooks the tests reach on either.
pub(crate) enum GpuBackend {
    Ash(Box<AshBackend>),
    Wgpu(Box<WgpuBackend>),
}

impl Deref for GpuBackend {
    type Target = dyn Backend;
    fn deref(&self) -> &(dyn Backend + 'static) {
        match self {
            GpuBackend::Ash(b) => &**b,
            GpuBackend::Wgpu(b) => &**b,
        }
    }
}

impl DerefMut for GpuBackend {
    fn deref_mut(&mut self) -> &mut (dyn Backend + 'static) {
        match self {
            GpuBackend::Ash(b) => &mut **b,
            GpuBackend::Wgpu(b) => &mut **b,
        }
    }
}

impl GpuBackend {
    pub(crate) fn boxed(self) -> Box<dyn Backend> {
        match self {
            GpuBackend::Ash(b) => b,
            GpuBackend::Wgpu(b) => b,
        }
    }

    /// The uploaded step's particles as the device prepared them, with their order.
    pub(crate) fn sorted_particles(&mut self) -> SortedParticles {
        match self {
            GpuBackend::Ash(b) => b.sorted_particles(),
            GpuBackend::Wgpu(b) => b.sorted_particles(),
        }
        .unwrap()
    }

    /// Fills the prepared particles and the preparation's buffers with 0xFF.
    pub(crate) fn poison_prepared(&mut self) {
        match self {
            GpuBackend::Ash(b) => b.poison_prepared(),
            GpuBackend::Wgpu(b) => b.poison_prepared(),
        }
        .unwrap()
    }

    /// The preparation's first stage on the device: the Hilbert keys of `points` (f32 local
    /// coordinates) with the identity permutation.
    pub(crate) fn hilbert_keys(
        &mut self,
        points: &[[f32; 4]],
        quantizer: &HilbertQuantizer,
    ) -> (Vec<u64>, Vec<u32>) {
        match self {
            GpuBackend::Ash(b) => b.prepare_hilbert_keys(points, quantizer),
            GpuBackend::Wgpu(b) => wgpu_lbvh::prepare::hilbert_keys(b.context(), points, quantizer),
        }
        .unwrap()
    }

    /// The device's radix sort of (key, index) pairs.
    pub(crate) fn sort_pairs(&mut self, keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
        match self {
            GpuBackend::Ash(b) => b.prepare_sort_pairs(keys),
            GpuBackend::Wgpu(b) => wgpu_lbvh::sort::sort_pairs(b.context(), keys),
        }
        .unwrap()
    }
}
