//! A rendering session: one backend, one series, the current step and settings. It decides
//! what each change costs (rebuild, refit, map update or only a restart of accumulation), so
//! the CLI, the viewer and the studies all drive a backend the same way.

use std::sync::Arc;

use glam::DVec3;

use super::auto::AutoValues;
use super::cycles::CycleWeights;
use super::error::RenderError;
use super::settings::RenderSettings;
use crate::accel::ClusterSize;
use crate::backend::{Backend, BackendError, Precision, StepInput};
use crate::field::{Classification, FieldSettings, PeriodicBox};
use crate::scene::{Camera, TimeSeries};
use crate::values::tables::table_max;
use crate::values::{Bounds, ColourMode, FrameParams, Image};

/// What the backend holds now.
#[derive(Clone, PartialEq)]
struct Loaded {
    step: usize,
    field: FieldSettings,
    cluster: ClusterSize,
    precision: Precision,
}

/// What making the backend hold a step and field took: the cheapest work that does it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepChange {
    /// Already held.
    None,
    /// Only the density or colour maps changed: tables uploaded again.
    Maps,
    /// Radii changed: the structure refit (topology kept).
    Refit,
    /// A new step or particle data: uploaded and built.
    Build,
}

/// The automatic values of a frame as they were resolved: what a user did not set, and what
/// a saved scene records so the frame can be reproduced exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resolved {
    /// The density that maps to 1 for colour and extinction.
    pub phi_ref: f64,
    /// The ray-marching step, data units.
    pub step_size: f64,
    /// Extinction per unit optical density (per data unit).
    pub density_scale: f64,
    /// The march box's margin around the series' bounds (twice the largest radius).
    pub margin: f64,
}

/// The default march never takes more samples than this across the data's box.
pub const DEFAULT_SAMPLES_PER_RAY: f64 = 4096.0;
/// No march takes more samples than this across the data's box (bounded work per pixel).
pub const MAX_SAMPLES_PER_RAY: f64 = 100_000.0;

/// A backend driven through one series: it holds the step and field loaded, the automatic values,
/// and the frames accumulated since the last change.
pub struct RenderSession {
    backend: Box<dyn Backend>,
    /// How GPU backends hold positions (`Precision::RENDER` unless set).
    precision: Precision,
    /// The domain: the series' bounds, or the periodic box.
    bounds: Bounds,
    series_bounds: Bounds,
    /// The box whose faces wrap, if any: each step is uploaded with its periodic images.
    periodic: Option<PeriodicBox>,
    max_count: usize,
    loaded: Option<Loaded>,
    /// The automatic values of the series under the loaded field ([`AutoValues`]).
    auto: Option<(FieldSettings, AutoValues)>,
    frames: u32,
    /// How the accumulation's whole mask cycles and its incomplete one combine into its image
    /// (`None`: the plain mean).
    cycles: Option<CycleWeights>,
    last_frame_key: Option<(RenderSettings, Loaded)>,
    warned_coarse_step: std::sync::atomic::AtomicBool,
}

impl RenderSession {
    /// A session over `series` on `backend`, nothing loaded yet, the backend's buffers reserved for
    /// the series' largest step.
    pub fn new(mut backend: Box<dyn Backend>, series: &TimeSeries) -> RenderSession {
        // Allocate once for the largest step, so stepping through time allocates nothing.
        backend.reserve(series.max_count());
        RenderSession {
            backend,
            precision: Precision::RENDER,
            bounds: series.bounds(),
            series_bounds: series.bounds(),
            periodic: None,
            max_count: series.max_count(),
            loaded: None,
            auto: None,
            frames: 0,
            cycles: None,
            last_frame_key: None,
            warned_coarse_step: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// How GPU backends hold positions from the next upload on (the next [`show`](Self::show)
    /// uploads the step again).
    pub fn set_precision(&mut self, precision: Precision) {
        self.precision = precision;
    }

    /// Wraps the field at the faces of `periodic` from the next [`show`](Self::show) on (which
    /// uploads the step again): each step goes to the backend with the periodic images of its
    /// particles near the faces ([`PeriodicBox::images`]), and the domain (the default camera,
    /// the march box) is the box itself. `None` restores the open domain.
    pub fn set_periodic(&mut self, periodic: Option<PeriodicBox>) {
        if self.periodic != periodic {
            self.periodic = periodic;
            self.bounds = periodic.map_or(self.series_bounds, |b| b.bounds());
            self.loaded = None;
        }
    }

    /// The backend it drives.
    pub fn backend(&self) -> &dyn Backend {
        self.backend.as_ref()
    }

    /// The backend it drives, to change it directly.
    pub fn backend_mut(&mut self) -> &mut dyn Backend {
        self.backend.as_mut()
    }

    /// Frames accumulated since the last change.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Frames accumulated of `settings` over what the backend holds: 0 if the accumulation is
    /// of anything else (the next [`accumulate`](Self::accumulate) restarts it).
    pub fn frames_of(&self, settings: &RenderSettings) -> u32 {
        match (&self.last_frame_key, &self.loaded) {
            (Some((s, l)), Some(loaded)) if s == settings && l == loaded => self.frames,
            _ => 0,
        }
    }

    /// Makes the backend hold step `step` under `field`, doing only the work the change needs,
    /// and says which work that was.
    pub fn show(
        &mut self,
        series: &TimeSeries,
        step: usize,
        field: &FieldSettings,
        cluster: ClusterSize,
    ) -> Result<StepChange, RenderError> {
        let want = Loaded {
            step,
            field: field.clone(),
            cluster,
            precision: self.precision,
        };
        let change = match &self.loaded {
            Some(have) if *have == want => return Ok(StepChange::None),
            Some(have)
                if have.step == step
                    && have.cluster == cluster
                    && have.precision == self.precision
                    && same_particles(&have.field, field)
                    // Under periodicity the radii decide which particles have images.
                    && (self.periodic.is_none() || same_radii(&have.field, field)) =>
            {
                if same_radii(&have.field, field) {
                    self.backend.update_maps(field)?;
                    StepChange::Maps
                } else {
                    self.backend.refit(field)?;
                    StepChange::Refit
                }
            }
            _ => {
                let data = series.step(step)?;
                let range = field
                    .attribute
                    .as_deref()
                    .and_then(|a| series.attribute(a))
                    .map(|a| (a.min, a.max));
                let images = match &self.periodic {
                    Some(b) => Some(periodic_images(b, &data, field, range)?),
                    None => None,
                };
                let (step_data, step_bounds) = match &images {
                    Some((images, bounds)) => (&images.step, *bounds),
                    None => (&data, self.bounds),
                };
                self.backend.upload(&StepInput {
                    step: step_data,
                    field,
                    cluster,
                    series_bounds: step_bounds,
                    series_range: range,
                    precision: self.precision,
                })?;
                self.backend.build()?;
                StepChange::Build
            }
        };
        self.loaded = Some(want);
        // Properties of the series and the field, never of the step: a new step keeps them.
        if self
            .auto
            .as_ref()
            .is_none_or(|(f, _)| !AutoValues::same_for(f, field))
        {
            self.auto = Some((field.clone(), AutoValues::of(series, field)?));
        }
        Ok(change)
    }

    /// The automatic values of the loaded field over the series.
    pub fn auto_values(&self) -> Option<AutoValues> {
        self.auto.as_ref().map(|(_, a)| *a)
    }

    /// What `settings` leaves automatic, resolved for the loaded field (the step size, the
    /// density scale and Phi_ref, from the series' automatic values unless set).
    pub fn resolve(&self, settings: &RenderSettings) -> Result<Resolved, RenderError> {
        let basis = self.basis()?;
        let resolved = basis.resolve(settings)?;
        let (r, dt) = (basis.auto.typical_radius.max(1e-30), resolved.step_size);
        if settings.step_size.is_none()
            && dt > r
            && !self
                .warned_coarse_step
                .swap(true, std::sync::atomic::Ordering::Relaxed)
        {
            tracing::warn!(
                "the particles' radius ({r:.3e}) is below the march step ({dt:.3e}, {DEFAULT_SAMPLES_PER_RAY} samples across the data): the image will miss particles; pass --step-size to march finer"
            );
        }
        Ok(resolved)
    }

    /// The frame constants for `settings`, frame number `frame`.
    pub fn frame_params(
        &self,
        settings: &RenderSettings,
        frame: u32,
    ) -> Result<FrameParams, RenderError> {
        self.resolve(settings)?;
        self.basis()?.frame_params(settings, frame)
    }

    /// What the frames of the loaded field follow from.
    fn basis(&self) -> Result<FrameBasis<'_>, RenderError> {
        let (Some(loaded), Some((_, auto))) = (&self.loaded, &self.auto) else {
            return Err(BackendError::NothingUploaded("session").into());
        };
        Ok(FrameBasis {
            bounds: self.bounds,
            max_count: self.max_count,
            periodic: self.periodic.is_some(),
            field: &loaded.field,
            auto: *auto,
        })
    }

    /// Renders `frames` more frames into the accumulation (restarted if anything changed since
    /// the last call) and returns the image.
    pub fn render(&mut self, settings: &RenderSettings, frames: u32) -> Result<Image, RenderError> {
        self.accumulate(settings, frames)?;
        self.image()
    }

    /// The image of the frames accumulated so far, read back from the backend: the one copy
    /// of the image a batch render makes, when it writes the image. It is their mean, except
    /// that past the first blue-noise mask cycle the incomplete cycle's frames are weighted by
    /// their measured noise, so that more frames never make a noisier image
    /// ([`super::cycles`]).
    pub fn image(&mut self) -> Result<Image, RenderError> {
        let mean = self.backend.image()?;
        Ok(match &self.cycles {
            Some(cycles) => cycles.image(self.frames, mean),
            None => mean,
        })
    }

    /// Renders `frames` more frames into the accumulation (restarted if anything changed since
    /// the last call), on the device: nothing is read back.
    pub fn accumulate(
        &mut self,
        settings: &RenderSettings,
        frames: u32,
    ) -> Result<(), RenderError> {
        let loaded = self
            .loaded
            .clone()
            .ok_or(BackendError::NothingUploaded("session"))?;
        let key = (settings.clone(), loaded);
        if self.last_frame_key.as_ref() != Some(&key) {
            self.backend.reset();
            self.frames = 0;
            self.cycles = CycleWeights::of(settings);
            self.last_frame_key = Some(key);
        }
        for _ in 0..frames {
            // The means the cycles' weights need, read back once each (a few per accumulation).
            if let Some(cycles) = &mut self.cycles
                && cycles.wants_mean_at(self.frames)
            {
                cycles.took_mean(self.frames, self.backend.image()?);
            }
            let params = self.frame_params(settings, self.frames)?;
            match (settings.splat_k, settings.voxel_grid) {
                (Some(k), _) => {
                    self.backend.render_splat(&params, k)?;
                }
                (None, Some(n)) => {
                    // The grid holds this accumulation's step, field and colour map.
                    if self.frames == 0 {
                        self.backend.voxelize(&params, n)?;
                    }
                    self.backend.render_voxels(&params)?;
                }
                (None, None) => self.backend.render(&params)?,
            }
            self.frames += 1;
        }
        Ok(())
    }
}

impl RenderSession {
    /// Frames `first..first + count` of `settings` as a fresh accumulation, read back: one
    /// chunk of a sequence. The frame numbers pick the noise, so the chunks of a sequence,
    /// averaged by their frames, are the sequence's image; targeted renders keep two
    /// independent sequences this way. The next [`accumulate`](Self::accumulate) restarts.
    pub fn render_frames(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
    ) -> Result<Image, RenderError> {
        self.render_chunk(settings, first, count, false)
    }

    /// [`render_frames`](Self::render_frames) on the image's half-resolution lattice
    /// ([`FrameParams::on_half_lattice`]): the rays of the full image's even pixels, at a
    /// quarter of the work. Its pixels estimate the full image's noise (`render::target`).
    pub fn render_frames_on_half_lattice(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
    ) -> Result<Image, RenderError> {
        self.render_chunk(settings, first, count, true)
    }

    fn render_chunk(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
        half_lattice: bool,
    ) -> Result<Image, RenderError> {
        if self.loaded.is_none() {
            return Err(BackendError::NothingUploaded("session").into());
        }
        self.backend.reset();
        self.frames = 0;
        self.cycles = None;
        self.last_frame_key = None;
        for frame in first..first.saturating_add(count) {
            let params = self.frame_params(settings, frame)?;
            let params = if half_lattice {
                params.on_half_lattice()
            } else {
                params
            };
            self.backend.render(&params)?;
        }
        self.image()
    }
}

/// What a frame's constants follow from besides the render settings: the domain, the series'
/// largest step, the field and the series' automatic values under it. A session makes one for
/// what its backend holds; a distributed render, whose ranks each hold a part of the step,
/// makes one from the series alone, so that every rank's frames are the single-rank frames.
#[derive(Clone, Copy, Debug)]
pub struct FrameBasis<'a> {
    /// The domain: the series' bounds, or the periodic box.
    pub bounds: Bounds,
    /// Particles in the series' largest step.
    pub max_count: usize,
    /// Whether the domain's faces wrap (the march box then has no margin).
    pub periodic: bool,
    /// The field the frames render.
    pub field: &'a FieldSettings,
    /// The series' automatic values under `field`.
    pub auto: AutoValues,
}

impl FrameBasis<'_> {
    /// What `settings` leaves automatic, resolved (the step size, the density scale and
    /// Phi_ref, from the series' automatic values unless set).
    pub fn resolve(&self, settings: &RenderSettings) -> Result<Resolved, RenderError> {
        let auto = &self.auto;
        let r = auto.typical_radius.max(1e-30);
        let spacing = (self.bounds.extent().max(DVec3::splat(r)).element_product()
            / self.max_count.max(1) as f64)
            .cbrt();
        // Work per pixel stays bounded: at most MAX_SAMPLES_PER_RAY samples across the march
        // box. The default resolves the kernel (R / 3) and the particle spacing, but never
        // finer than the box's diagonal / DEFAULT_SAMPLES_PER_RAY.
        let box_diagonal = (self.bounds.extent() + 4.0 * auto.max_radius).length();
        let dt = settings.step_size.unwrap_or_else(|| {
            (r / 3.0)
                .min(0.5 * spacing)
                .max(box_diagonal / DEFAULT_SAMPLES_PER_RAY)
        });
        if !(dt.is_finite() && dt > 0.0) {
            return Err(RenderError::Settings(format!(
                "step size {dt} must be positive"
            )));
        }
        if box_diagonal / dt > MAX_SAMPLES_PER_RAY {
            return Err(RenderError::Settings(format!(
                "step size {dt} would take {:.0} samples across the data ({box_diagonal}); at most {MAX_SAMPLES_PER_RAY} are allowed",
                box_diagonal / dt
            )));
        }
        let phi_ref = settings.phi_ref.unwrap_or(auto.phi_ref);
        if !(phi_ref.is_finite() && phi_ref > 0.0) {
            return Err(RenderError::Settings(format!(
                "Phi_ref {phi_ref} must be positive"
            )));
        }
        Ok(Resolved {
            phi_ref,
            step_size: dt,
            density_scale: settings.optical.scale().unwrap_or(0.4 / r),
            // A periodic box is the whole domain: nothing outside it is drawn.
            margin: if self.periodic {
                0.0
            } else {
                2.0 * auto.max_radius
            },
        })
    }

    /// The frame constants for `settings`, frame number `frame`.
    pub fn frame_params(
        &self,
        settings: &RenderSettings,
        frame: u32,
    ) -> Result<FrameParams, RenderError> {
        let resolved = self.resolve(settings)?;
        settings.check().map_err(RenderError::Settings)?;
        let camera = settings
            .camera
            .unwrap_or_else(|| Camera::default_for(self.bounds));
        let grow = DVec3::splat(resolved.margin);
        let density_scale = resolved.density_scale;
        let optical_table = settings.optical.map().bake();
        let colour = if settings.colour_by_density || self.field.attribute.is_none() {
            ColourMode::Density
        } else if self.field.classification == Classification::Pre {
            ColourMode::Pre
        } else {
            ColourMode::Post
        };
        // A series without particles has inverted (infinite) bounds; its march box is a point,
        // which every ray misses, so the frame is background at no cost on any backend.
        let (box_min, box_max) = if self.bounds.is_empty() {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            (self.bounds.min - grow, self.bounds.max + grow)
        };
        Ok(FrameParams {
            width: settings.width,
            height: settings.height,
            frame,
            seed: settings.seed,
            camera: camera.frame(settings.width, settings.height)?,
            box_min,
            box_max,
            dt: resolved.step_size,
            opacity_threshold: settings.opacity_threshold,
            phi_ref: resolved.phi_ref,
            density_scale,
            majorant: density_scale * table_max(&optical_table),
            light_dir: {
                let (side, front) = settings.up_axis.horizontal();
                settings
                    .light
                    .direction_about(settings.up_axis.vector(), side, front)
            },
            light_intensity: settings.light.intensity,
            ambient: settings.light.ambient,
            background: settings.background,
            integrator: settings.integrator,
            noise: settings.noise,
            colour,
            optical_table: Arc::new(optical_table),
            colour_table: Arc::new(self.field.color_map.bake()),
        })
    }
}

/// `step` with its periodic images in `periodic`, and the bounds the images lie in (the box
/// grown by the largest reach), which fix the backend's Hilbert grid and local origin.
fn periodic_images(
    periodic: &PeriodicBox,
    step: &crate::values::Step,
    field: &FieldSettings,
    range: Option<(f64, f64)>,
) -> Result<(crate::field::periodic::Images, Bounds), RenderError> {
    let images = periodic
        .images(step, field, range)
        .map_err(BackendError::from)?;
    if images.wrapped > 0 {
        tracing::info!(
            "step '{}': {} particles outside the periodic box wrapped into it",
            step.name,
            images.wrapped
        );
    }
    tracing::debug!(
        "step '{}': {} periodic images of particles near the box's faces",
        step.name,
        images.step.len() - images.originals
    );
    let bounds = periodic.bounds().grown(images.largest_reach);
    Ok((images, bounds))
}

/// Whether two field settings give the same per-particle data (positions, attribute).
fn same_particles(a: &FieldSettings, b: &FieldSettings) -> bool {
    a.attribute == b.attribute
        && a.attribute_range == b.attribute_range
        && a.classification == b.classification
}

/// Whether two field settings give the same radii.
fn same_radii(a: &FieldSettings, b: &FieldSettings) -> bool {
    a.radius == b.radius && a.radius_map == b.radius_map && a.radius_attribute == b.radius_attribute
}
