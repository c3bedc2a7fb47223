//! Renders to a target error or within a time budget (`--target-error`, `--time-budget`) over
//! the ranks: every rank runs the single process's controller ([`render_chunks_to_target`]),
//! and each chunk of frames it asks for is a distributed render of the brick the ranks
//! prepared once ([`render_frames_on`]). Rank 0 composites the chunk and sends every rank its
//! image and its clock, so that every rank's controller sees the same images and the same
//! times and makes the same decisions, and so asks for the same next chunk: no rank waits in
//! a collective the others skip.
//!
//! The converged reference (`--reference`) runs the single process's search the same way
//! ([`converged_reference_on`]), on a brick the ranks prepared in f64 on the CPU.

use std::time::{Duration, Instant};

use super::DistError;
use super::comm::{Comm, CommExt};
use super::render::{DistScene, PreparedBrick, render_frames_on};
use crate::backend::Backend;
use crate::render::converged::{
    ParticlesDigest, Reference, ReferenceCache, ReferenceOptions, cache_key, reference_settings,
    search_reference,
};
use crate::render::target::{ChunkRenderer, Target, Targeted, render_chunks_to_target};
use crate::render::{FrameBasis, RenderError, RenderSettings, Resolved};
use crate::values::{FrameParams, Image};

/// The ranks' [`ChunkRenderer`]: this rank's part of each chunk, on the brick it prepared.
pub struct RankChunks<'a> {
    comm: &'a dyn Comm,
    backend: &'a mut dyn Backend,
    brick: &'a PreparedBrick,
    scene: &'a DistScene<'a>,
    basis: FrameBasis<'a>,
    started: Instant,
    /// Rank 0's time at the end of the last chunk: the clock every rank's controller reads.
    agreed: Duration,
}

/// [`render_chunks_to_target`] over the ranks: `settings` rendered from `brick` (which
/// `backend` holds) until `target` is met; every rank returns the same result. Collective.
pub fn render_to_target_on(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    brick: &PreparedBrick,
    scene: &DistScene<'_>,
    basis: FrameBasis<'_>,
    settings: &RenderSettings,
    target: &Target,
) -> Result<Targeted, RenderError> {
    let mut chunks = RankChunks::new(comm, backend, brick, scene, basis);
    render_chunks_to_target(&mut chunks, settings, target)
}

/// The converged reference of `settings` over the ranks ([`search_reference`], the single
/// process's search, on chunks rendered from `brick`: prepared in f64 on the CPU backend
/// `backend` holds); `part` digests this rank's part of the step as read. The digests join to
/// the whole step's, so the reference is cached under the key one process gives it, and
/// either finds the other's. Rank 0 reads and writes the cache and tells the others whether it
/// found the reference. Rank 0 returns the reference, the others `None`. Collective.
#[allow(clippy::too_many_arguments)]
pub fn converged_reference_on(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    brick: &PreparedBrick,
    scene: &DistScene<'_>,
    basis: FrameBasis<'_>,
    settings: &RenderSettings,
    options: &ReferenceOptions,
    part: ParticlesDigest,
) -> Result<Option<Reference>, RenderError> {
    options.check()?;
    let ranks = |e: DistError| RenderError::Ranks(Box::new(e));
    let base = reference_settings(settings);
    let digest = comm
        .all_gather_of(&[part.records, part.sum])
        .map_err(|e| ranks(e.into()))?
        .iter()
        .map(|p| ParticlesDigest {
            records: p[0],
            sum: p[1],
        })
        .fold(ParticlesDigest::default(), ParticlesDigest::joined);
    let cache = ReferenceCache::new(
        options,
        cache_key(&basis.frame_params(&base, 0)?, digest, scene.field, options),
    );
    let root = comm.rank() == 0;
    let found = if root { cache.load() } else { None };
    let agreed = comm
        .all_gather_of(&[u8::from(found.is_some())])
        .map_err(|e| ranks(e.into()))?;
    if agreed.first().and_then(|f| f.first()) == Some(&1) {
        if root {
            tracing::info!("reference from the cache");
        }
        return Ok(found);
    }
    let mut chunks = RankChunks::new(comm, backend, brick, scene, basis);
    let reference = search_reference(&mut chunks, &base, options, root)?;
    Ok(root.then(|| {
        cache.store(&reference);
        reference
    }))
}

impl<'a> RankChunks<'a> {
    /// The chunks of frames `basis` makes, rendered from `brick` (which `backend` holds); its
    /// clock starts now.
    pub fn new(
        comm: &'a dyn Comm,
        backend: &'a mut dyn Backend,
        brick: &'a PreparedBrick,
        scene: &'a DistScene<'a>,
        basis: FrameBasis<'a>,
    ) -> RankChunks<'a> {
        RankChunks {
            comm,
            backend,
            brick,
            scene,
            basis,
            started: Instant::now(),
            agreed: Duration::ZERO,
        }
    }
}

impl ChunkRenderer for RankChunks<'_> {
    fn resolve(&self, settings: &RenderSettings) -> Result<Resolved, RenderError> {
        self.basis.resolve(settings)
    }

    fn render_frames(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
        half_lattice: bool,
    ) -> Result<Image, RenderError> {
        let frames: Vec<FrameParams> = (first..first.saturating_add(count))
            .map(|f| {
                let params = self.basis.frame_params(settings, f)?;
                Ok(if half_lattice {
                    params.on_half_lattice()
                } else {
                    params
                })
            })
            .collect::<Result<_, RenderError>>()?;
        if frames.is_empty() {
            return Err(RenderError::Settings(format!(
                "a chunk of no frames (from frame {first})"
            )));
        }
        let ranks = |e: DistError| RenderError::Ranks(Box::new(e));
        let (image, _) = render_frames_on(self.comm, self.backend, self.brick, self.scene, &frames)
            .map_err(ranks)?;
        // Rank 0's image and clock to every rank: its elapsed nanoseconds, then the pixels.
        let mine: Vec<u8> = match image {
            Some(image) => {
                let image = image.image();
                let mut bytes = (self.started.elapsed().as_nanos() as u64)
                    .to_le_bytes()
                    .to_vec();
                bytes.extend_from_slice(bytemuck::cast_slice(&image.pixels));
                bytes
            }
            None => Vec::new(),
        };
        let all = self.comm.all_gather_v(&mine).map_err(|e| ranks(e.into()))?;
        let root = all.part(0);
        let (width, height) = (frames[0].width, frames[0].height);
        let pixels = (width as usize) * (height as usize);
        if root.len() != 8 + 16 * pixels {
            return Err(ranks(DistError::Malformed(format!(
                "rank 0 sent {} bytes for a {width}x{height} chunk",
                root.len()
            ))));
        }
        let (clock, pixel_bytes) = root.split_at(8);
        self.agreed = Duration::from_nanos(u64::from_le_bytes(clock.try_into().expect("8 bytes")));
        Ok(Image {
            width,
            height,
            pixels: pixel_bytes
                .chunks_exact(16)
                .map(bytemuck::pod_read_unaligned::<[f32; 4]>)
                .collect(),
        })
    }

    fn elapsed(&self) -> Duration {
        self.agreed
    }
}
