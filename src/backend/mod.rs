//! The one interface the CLI, viewer and studies render and query through, and its
//! implementations: `cpu` (rayon + BVH, the reference), later `wgpu` (LBVH compute) and `ash`
//! (Vulkan ray-tracing pipeline).
//!
//! A backend holds one step's particles and its acceleration structure. The caller
//! ([`crate::render::RenderSession`]) decides what a change costs: a new step or attribute
//! means [`Backend::upload`] + [`Backend::build`]; a new radius (global radius, radius map or
//! radius attribute) means [`Backend::refit`]; anything else only restarts accumulation.

pub mod ash_rt;
pub mod brick;
pub mod cpu;
pub mod gpu_data;
pub mod precision;
pub mod shaders;
pub mod voxel;
pub mod wgpu_lbvh;

use std::fmt;
use std::time::Duration;

use glam::DVec3;

use crate::accel::ClusterSize;
use crate::field::{FieldError, FieldSettings};
use crate::values::{Bounds, FrameParams, HalfOpenBox, Image, Step};

pub use brick::{BrickShare, DepthRays, LightMap, LightPrefix};
pub use precision::{Precision, Representation, parse_precision};

/// Which backend.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    Hash,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// The best available: ash on a GPU with ray tracing, else wgpu on a GPU, else cpu
    /// (software devices such as lavapipe are skipped: the CPU backend is faster there).
    #[default]
    Auto,
    /// CPU: rayon over tiles, the particles in a grid of cells; the f64 reference, or f32 where
    /// the scene allows.
    Cpu,
    /// wgpu compute: a GPU-built LBVH (Karras 2012) with stack traversal; any GPU (or lavapipe).
    Wgpu,
    /// Vulkan ray-tracing pipeline (ash): hardware range queries over an AABB BLAS.
    Ash,
}

impl fmt::Display for BackendKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BackendKind::Auto => "auto",
            BackendKind::Cpu => "cpu",
            BackendKind::Wgpu => "wgpu",
            BackendKind::Ash => "ash",
        })
    }
}

/// Creates a backend (`Auto` picks the best one this machine has).
pub fn create(kind: BackendKind) -> Result<Box<dyn Backend>, BackendError> {
    match kind {
        BackendKind::Ash => Ok(Box::new(ash_rt::AshBackend::new()?)),
        BackendKind::Auto => Ok(auto()),
        BackendKind::Wgpu => Ok(Box::new(wgpu_lbvh::WgpuBackend::new()?)),
        BackendKind::Cpu => Ok(Box::new(cpu::CpuBackend::new())),
    }
}

/// The best backend here: ash on a GPU with ray tracing, else wgpu on a GPU, else the CPU
/// backend. A software device (lavapipe) is never "best": on the same cores the CPU backend is
/// faster (docs/benchmarks.md); ask for `--backend ash|wgpu` to use one anyway.
fn auto() -> Box<dyn Backend> {
    // Opening a GPU backend opens a device and builds its kernels, which on a software device
    // (lavapipe, llvmpipe) loads its compiler: 140 MB a process on lavapipe, kept after the
    // backend is dropped. Where every adapter is a CPU, the CPU backend is chosen without
    // opening one.
    let adapters = wgpu_lbvh::adapters_to_choose_from();
    if adapters
        .iter()
        .all(|a| a.info.device_type == wgpu::DeviceType::Cpu)
    {
        let names: Vec<&str> = adapters.iter().map(|a| a.info.name.as_str()).collect();
        tracing::info!(
            "auto: no GPU adapter ({}): the cpu backend",
            if names.is_empty() {
                "none found".to_owned()
            } else {
                format!("only software ones: {}", names.join(", "))
            }
        );
        return Box::new(cpu::CpuBackend::new());
    }
    match ash_rt::AshBackend::new() {
        Ok(b) if !b.capabilities().software => return Box::new(b),
        Ok(b) => tracing::info!(
            "auto: skipping ash on a software device ({})",
            b.capabilities().device
        ),
        Err(e) => tracing::info!("auto: ash unavailable ({e})"),
    }
    match wgpu_lbvh::WgpuBackend::new() {
        Ok(b) if !b.capabilities().software => return Box::new(b),
        Ok(b) => tracing::info!(
            "auto: skipping wgpu on a software device ({})",
            b.capabilities().device
        ),
        Err(e) => tracing::info!("auto: wgpu unavailable ({e})"),
    }
    Box::new(cpu::CpuBackend::new())
}

/// This process's index among the processes of its job on its node, as the launcher says it
/// (Open MPI, MPICH and Intel MPI, Slurm); `None` outside such a job. A GPU backend opens the
/// device [`device_for_rank`] picks by it, so the ranks of a node spread over its GPUs.
pub fn node_local_rank() -> Option<usize> {
    [
        "OMPI_COMM_WORLD_LOCAL_RANK",
        "MPI_LOCALRANKID",
        "SLURM_LOCALID",
    ]
    .iter()
    .find_map(|name| std::env::var(name).ok()?.trim().parse().ok())
}

/// Which of `count` equally good devices a process opens: its node-local rank modulo the
/// count (a node's ranks spread over its GPUs; with one GPU they all share it), the first
/// outside a job.
pub fn device_for_rank(count: usize, node_local_rank: Option<usize>) -> usize {
    node_local_rank.map_or(0, |r| r % count.max(1))
}

/// What a backend is and can do.
#[derive(Clone, Debug, PartialEq)]
pub struct Capabilities {
    /// The backend's short name (`cpu`, `wgpu`, `ash`), as the command line spells it.
    pub name: &'static str,
    /// The device it runs on, in words.
    pub device: String,
    /// Whether range queries run on ray-tracing hardware (or a driver's RT pipeline).
    pub hardware_rt: bool,
    /// Whether the device is a CPU implementation of the GPU API (Mesa lavapipe): it runs
    /// everything correctly, but more slowly than the CPU backend on the same cores.
    pub software: bool,
    /// The most particles one step may hold, if limited.
    pub max_particles: Option<usize>,
    /// Whether [`Backend::query_grid`] scatters the uploaded particles onto the grid, so that
    /// a grid needs no [`Backend::build`] first (the CPU backend).
    pub scatters_grids: bool,
    /// How the backend's frame times ([`Timings::frame`]) are taken (on the GPU backends also
    /// their builds, refits and queries).
    pub frame_timer: FrameTimer,
}

/// How a backend times its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameTimer {
    /// Timestamps the device writes before and after the frame's work.
    DeviceTimestamps,
    /// The host's clock from submission to completion (a GPU without timestamp queries).
    SubmitToCompletion,
    /// The host's clock around the work (the CPU backend).
    WallClock,
}

/// Time spent in each stage, for the last time each ran.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// CPU work on a new step: the check and the conversion into what the device copies
    /// (`gpu_data`), and where a backend sorts on the CPU (ash; the CPU backend, for which it
    /// is the whole upload) the Hilbert sort and gather too. Only CPU work: waits for the
    /// device are in `upload` and `device_prepare`.
    pub prepare: Duration,
    /// Moving the step to the device (excluding `prepare`): buffers, the copy.
    pub upload: Duration,
    /// Preparing the step on the device after the copy (wgpu: Hilbert keys, sort, gather).
    pub device_prepare: Duration,
    /// The last [`Backend::build`] of the acceleration structure.
    pub build: Duration,
    /// The last [`Backend::refit`].
    pub refit: Duration,
    /// The last frame ([`Backend::render`] and its kin), taken as [`Capabilities::frame_timer`]
    /// says.
    pub frame: Duration,
    /// The last [`Backend::query`].
    pub query: Duration,
    /// The last [`Backend::voxelize`]: the splat into the grid, on the device where the
    /// backend has one (its march is timed as a frame).
    pub voxelize: Duration,
}

/// Memory held for the current step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryReport {
    /// Particle data (positions, attributes, radii).
    pub particle_bytes: usize,
    /// The acceleration structure (boxes, tree).
    pub structure_bytes: usize,
    /// The accumulation image.
    pub image_bytes: usize,
    /// What preparing a step on the device keeps between steps: staging memory, the step's
    /// arrays in its own order and the sort's buffers (0 where the CPU prepares).
    pub preparation_bytes: usize,
    /// The voxel baseline's grid and what splatting it keeps (slab and staging buffers on
    /// wgpu); 0 before a [`Backend::voxelize`].
    pub voxel_bytes: usize,
}

/// One step as a backend receives it.
pub struct StepInput<'a> {
    /// Shared with the series' cache: a backend keeps the step by reference, never a copy.
    pub step: &'a std::sync::Arc<Step>,
    /// The field the particles define: attribute, radius, maps, kernel.
    pub field: &'a FieldSettings,
    /// Particles per cluster box K.
    pub cluster: ClusterSize,
    /// The series' bounds (Hilbert grid, local coordinates).
    pub series_bounds: Bounds,
    /// The attribute's range over the series.
    pub series_range: Option<(f64, f64)>,
    /// How precisely a backend holds positions: f32 or double-single on the GPU backends, f32
    /// (the fast kernel) or f64 (the reference) on the CPU backend.
    pub precision: Precision,
}

/// Points per [`Backend::query`] call in [`query_in_hilbert_order`] (each call may be a GPU
/// submission and readback).
pub const QUERY_BATCH: usize = 1 << 18;

/// Phi and the Theta numerator at `points`, in their order, queried in Hilbert order
/// (neighbouring queries share tree nodes: faster on every backend) in batches of
/// [`QUERY_BATCH`]; `progress` is told how many points each batch held.
pub fn query_in_hilbert_order<B: Backend + ?Sized>(
    backend: &mut B,
    points: &[DVec3],
    mut progress: impl FnMut(usize),
) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
    let order = crate::accel::hilbert_order(points, Bounds::of_points(points));
    let mut out = vec![(0.0, [0.0; 3]); points.len()];
    for indices in order.chunks(QUERY_BATCH) {
        let batch: Vec<DVec3> = indices.iter().map(|&i| points[i as usize]).collect();
        for (&i, sums) in indices.iter().zip(backend.query(&batch)?) {
            out[i as usize] = sums;
        }
        progress(indices.len());
    }
    Ok(out)
}

/// Why a backend cannot do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The field settings do not fit the step.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// A call that needs a step before any upload; names the backend.
    #[error("{0}: no step uploaded yet")]
    NothingUploaded(&'static str),
    /// The device or its API failed, or refused what was asked.
    #[error("{backend}: {message}")]
    Device {
        /// The backend's name.
        backend: &'static str,
        /// What went wrong.
        message: String,
    },
    /// The backend (first) cannot run here, and why (second).
    #[error("the {0} backend is not available on this machine: {1}")]
    Unavailable(&'static str, String),
    /// [`Backend::render_voxels`] or [`Backend::voxel_grid`] before any [`Backend::voxelize`].
    #[error("{0}: no voxel grid yet (voxelize the step first)")]
    NoVoxelGrid(&'static str),
    /// The caller raised the abandon flag ([`Backend::set_abandon_flag`]) during the frame.
    #[error("the frame was abandoned for a newer one")]
    Abandoned,
    /// [`Backend::render_owned`] where it is not implemented yet.
    #[error("{backend}: {what} is not distributed yet")]
    NotDistributed {
        /// The backend's name.
        backend: &'static str,
        /// What it cannot render distributed.
        what: String,
    },
}

/// The GPU splatters' rule for `k`, the hits a slab's buffer holds (a ray payload or a
/// kernel's private array of [`crate::values::shader_constants::SPLAT_K_MAX`] entries).
pub(crate) fn check_gpu_splat_k(backend: &'static str, k: usize) -> Result<(), BackendError> {
    use crate::values::shader_constants::SPLAT_K_MAX;
    if k == 0 || k > SPLAT_K_MAX as usize {
        return Err(BackendError::Device {
            backend,
            message: format!(
                "{k} hits per slab: the GPU splatter's slab buffer holds 1..={SPLAT_K_MAX} hits"
            ),
        });
    }
    Ok(())
}

/// A rendering and query backend: holds one step of particles and its acceleration structure,
/// answers field queries and renders frames into a progressive accumulation.
pub trait Backend: Send {
    /// What the backend is and can do.
    fn capabilities(&self) -> &Capabilities;

    /// Makes room for steps of up to `max_particles` particles (a series' maximum count), so
    /// stepping through a series allocates nothing more. Optional: backends grow as needed.
    fn reserve(&mut self, _max_particles: usize) {}

    /// Takes a step's particles (sorted, with their attribute and radii) and keeps them.
    fn upload(&mut self, input: &StepInput<'_>) -> Result<(), BackendError>;

    /// Builds the acceleration structure over the uploaded step from scratch.
    fn build(&mut self) -> Result<(), BackendError>;

    /// Applies new field settings whose only change is the particles' radii (global radius,
    /// radius map or radius attribute), keeping the structure's topology.
    fn refit(&mut self, field: &FieldSettings) -> Result<(), BackendError>;

    /// Applies field settings that change neither particles nor radii (density map, colour
    /// map): no structure work.
    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError>;

    /// Phi and the Theta numerator at each point (see [`cpu::integrators::FieldSampler`]).
    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError>;

    /// Phi and the Theta numerator at every point of a regular grid, in the grid's order.
    /// By default a query per point (in Hilbert order, batched); the CPU backend scatters the
    /// particles onto the grid instead ([`crate::field::ReferenceField::eval_grid_sums`]).
    fn query_grid(
        &mut self,
        grid: &crate::field::RegularGrid,
    ) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        query_in_hilbert_order(self, &grid.points(), |_| {})
    }

    /// Renders one frame and adds it to the accumulation (restarted by `reset`, or when the
    /// frame's size differs from the accumulated one's).
    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError>;

    /// Renders one frame with Knoll et al.'s RT splatter, the paper's Table 3 baseline
    /// (`--method splat`: slabs of one march step, at most `k` hits each, sorted and
    /// composited front to back; `crate::field::splat` says what a hit is and how a full
    /// buffer loses hits), and adds it to the accumulation; returns what the slabs' buffers
    /// kept and lost where the backend counts them (the CPU does; the GPU kernels do not, to
    /// cost nothing beside the splatting). Emission–absorption only. GPU backends hold at
    /// most [`crate::values::shader_constants::SPLAT_K_MAX`] hits per slab.
    fn render_splat(
        &mut self,
        frame: &FrameParams,
        k: usize,
    ) -> Result<Option<crate::field::splat::SplatCounts>, BackendError>;

    /// A brick's share of one frame ([`BrickShare`]): for the pixels of `share.rect`,
    /// row-major, each `[r, g, b, T]` of the samples in `share.owned`, the premultiplied colour
    /// gathered from them and the transmittance through them, from transmittance 1 with no
    /// background (a rank's share of a distributed frame). The samples are the whole frame's
    /// lattice `t_enter + (k + jitter) dt`, from the entry into the frame's march box, with the
    /// whole frame's noise, so boxes that tile space split each pixel's samples between them,
    /// one box to each; composited in the order a ray meets the boxes they give the whole
    /// frame. Emission–absorption up to rounding. Single scattering with what the share says of
    /// the bricks before it: stochastic marching scatters in the brick where the depth in front
    /// plus its own passes the free-flight depth (the single rank's decision), delta tracking
    /// tracks the brick's own segment with the brick's numbers, and a shadow ray is marched to
    /// its brick's exit and adds the depth nearer the light ([`BrickShare::light`]); a pixel
    /// that scatters gives `[L, 0]`, one that does not `[0, 0, 0, 1]`. Nothing is accumulated.
    /// By default not implemented.
    fn render_owned(
        &mut self,
        _frame: &FrameParams,
        _share: &BrickShare<'_>,
    ) -> Result<Vec<[f64; 4]>, BackendError> {
        Err(BackendError::NotDistributed {
            backend: self.capabilities().name,
            what: "rendering a part of a frame (distributed renders run on the cpu backend)".into(),
        })
    }

    /// The optical depth `Σ sigma dt` of the samples in `owned` along each of `rays`, row-major
    /// over its rectangle: pass 1 of single scattering across bricks ([`DepthRays`]), summed
    /// over the bricks in front by an exclusive scan. By default not implemented.
    fn owned_depth(
        &mut self,
        _frame: &FrameParams,
        _owned: &HalfOpenBox,
        _rays: DepthRays<'_>,
    ) -> Result<Vec<f64>, BackendError> {
        Err(BackendError::NotDistributed {
            backend: self.capabilities().name,
            what: "the optical depth of a brick (distributed renders run on the cpu backend)"
                .into(),
        })
    }

    /// The voxel-grid baseline of the paper's Table 3 ([`voxel`]), its first half: splats the
    /// uploaded particles (no [`Backend::build`] needed) into a grid over the frame's march
    /// box, cubic cells with `n` along its longest side, each cell centre receiving Phi and
    /// the Theta numerator of every particle that reaches it (with the frame's colour map for
    /// pre-classification), and keeps the grid, replacing the last one. Timed in
    /// [`Timings::voxelize`]. The CPU backend scatters in f64 and rounds the sums to f32; the
    /// GPU backends add f32 contributions with atomics (the grid is the CPU's up to f32
    /// rounding and summation order). A grid the backend cannot hold is refused with an
    /// error naming the limit.
    fn voxelize(&mut self, frame: &FrameParams, n: usize) -> Result<(), BackendError>;

    /// The voxel baseline's second half: renders one frame of the frame's integrator over the
    /// last voxelised grid (trilinear between cell centres, [`voxel::VoxelGrid`]'s sampling
    /// rule) and adds it to the accumulation (restarted by `reset`, or when the frame's size
    /// differs), so [`Backend::image`] gives the mean. Timed as a frame.
    fn render_voxels(&mut self, frame: &FrameParams) -> Result<(), BackendError>;

    /// The last voxelised grid, read back (tests, exports).
    fn voxel_grid(&mut self) -> Result<voxel::VoxelGrid, BackendError>;

    /// Restarts progressive accumulation.
    fn reset(&mut self);

    /// A flag the caller raises to abandon the frame being rendered (a viewer whose view
    /// changed mid-frame); `None` renders every frame whole. A backend that renders a frame in
    /// pieces checks it between pieces and returns [`BackendError::Abandoned`] with the
    /// accumulation as it was before the frame; one that submits a frame whole (the GPU
    /// backends) finishes it.
    fn set_abandon_flag(&mut self, _flag: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>) {}

    /// The mean of the frames accumulated so far.
    fn image(&mut self) -> Result<Image, BackendError>;

    /// Time spent in each stage, the last time each ran.
    fn timings(&self) -> Timings;

    /// Memory held for the current step.
    fn memory(&self) -> MemoryReport;

    /// How the uploaded step's positions are held and its terms summed, with the error bound
    /// that follows (`None` before an upload).
    fn representation(&self) -> Option<Representation>;
}

#[cfg(test)]
mod tests {
    use super::device_for_rank;

    /// A node's ranks spread over its GPUs, round robin; one GPU serves them all; outside a
    /// job (or with no device counted) the first.
    #[test]
    fn ranks_of_a_node_spread_over_its_devices() {
        let on_four: Vec<usize> = (0..9).map(|r| device_for_rank(4, Some(r))).collect();
        assert_eq!(on_four, [0, 1, 2, 3, 0, 1, 2, 3, 0]);
        assert!((0..5).all(|r| device_for_rank(1, Some(r)) == 0));
        assert_eq!(device_for_rank(3, None), 0);
        assert_eq!(device_for_rank(0, Some(2)), 0);
    }
}
