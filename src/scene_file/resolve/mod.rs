//! Data and field options shared by the commands and the viewer, merged with a scene file
//! (flags win), and resolved into an open series and its field: where the data comes from
//! (`source`), the attributes the field asks for (`attributes`), the series opened with them
//! (`open`), and the settings taken from the data (`field_settings`, `radius`).

mod args;
mod attributes;
mod field_settings;
mod first_step;
mod open;
mod radius;
mod sections;
mod source;

use std::path::PathBuf;

use anyhow::{Context, bail};

pub use args::{DataArgs, FieldOptions, ViewFlags};
pub use first_step::{
    FirstStep, FirstStepFacts, median_of_positive, positive, smoothing_length_in,
};
pub use radius::{RADIUS_PER_SMOOTHING_LENGTH, RADIUS_PER_SPACING, default_radius};
pub use sections::scene_sections;

use super::{DataSection, FieldSection, RangeSpec, SceneFile};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::io::{Format, ReadOptions, StepRef};
use crate::scene::{StepsScan, TimeSeries};

/// Data and field settings after merging flags over the scene file.
pub struct Resolved {
    /// The scene file (or an empty one), for the sections a command reads itself.
    pub scene: SceneFile,
    /// The time series opened from the data.
    pub series: TimeSeries,
    /// The step to show, counted from 0.
    pub step: usize,
    /// The field: attribute, ranges, radius, maps, kernel.
    pub field: FieldSettings,
    /// The BVH's particles per cluster K, as asked or chosen from the data.
    pub cluster: ClusterSize,
    /// Where the data came from, and how it was spelled, for writing a scene file back.
    pub data_path: PathBuf,
    /// The format asked for; `None`: from the path's extension.
    pub format: Option<Format>,
    /// What was read of files that hold a choice (an HDF5 snapshot's particle type).
    pub read: ReadOptions,
    /// The colour map as asked (a preset's name or a file); `None`: the default.
    pub colormap: Option<String>,
    /// How long opening the series took, and the steps it decoded: the rest of resolving is
    /// the settings taken from the data (the cluster size, ranges), which `bench playback`
    /// reports apart.
    pub opened_in: std::time::Duration,
    /// Steps decoded while opening the series.
    pub decoded_at_open: usize,
    /// How the attribute's range was chosen: a per-step range is chosen again for each step
    /// shown ([`Resolved::range_for_step`]).
    pub range: RangeSpec,
    /// The periodic box the field wraps at ([`super::periodic::choose`]), if any.
    pub periodic: Option<crate::field::PeriodicBox>,
}

impl Resolved {
    /// The domain an image or grid of the field covers: the periodic box where there is one,
    /// else the series' bounds.
    pub fn domain(&self) -> crate::values::Bounds {
        self.periodic
            .map_or_else(|| self.series.bounds(), |b| b.bounds())
    }

    /// The data and field sections of a scene file that reproduces these settings.
    pub fn scene_sections(&self) -> (DataSection, FieldSection) {
        scene_sections(
            &self.data_path,
            self.format,
            self.read,
            self.step,
            &self.field,
            self.cluster,
            self.colormap.as_deref(),
            self.periodic,
        )
    }
}

impl Resolved {
    /// Sets the field's range for step `step` where the range is per step (`--attribute-range
    /// step` or `robust-step`); other ranges are the series' and stay.
    pub fn range_for_step(&mut self, step: usize) -> anyhow::Result<()> {
        if self.range.per_step() {
            self.field.attribute_range = self
                .range
                .resolve(&self.series, self.field.attribute.as_deref(), step)?
                .0;
        }
        Ok(())
    }

    /// The series-wide range of the field's attribute.
    pub fn series_range(&self) -> Option<(f64, f64)> {
        let name = self.field.attribute.as_deref()?;
        let a = self.series.attribute(name)?;
        Some((a.min, a.max))
    }
}

/// Resolves the data and the field as [`resolve`] does, for a command that makes an image:
/// without an attribute (flag or scene file), the image is coloured by the data's first
/// attribute, which is said with the others (`--color-by-density` colours by density).
pub fn resolve_for_images(data: &DataArgs, options: &FieldOptions) -> anyhow::Result<Resolved> {
    resolve_with_reads(data, options, true, &InOneProcess)
}

/// Resolves the data and the field: flags over the scene file, the series opened with the
/// attributes the field uses, and the automatic values of the data (radius, cluster size,
/// range) chosen and said. Without an attribute the field carries none (density only).
pub fn resolve(data: &DataArgs, options: &FieldOptions) -> anyhow::Result<Resolved> {
    resolve_with_reads(data, options, false, &InOneProcess)
}

/// Resolves as [`resolve`] (or, with `first_attribute_by_default`, [`resolve_for_images`])
/// does, what the data says beyond the flags and the series' index learned as `reads` says: a
/// distributed render's ranks learn it from their parts of each step.
pub fn resolve_with_reads(
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
    reads: &dyn DataReads,
) -> anyhow::Result<Resolved> {
    let scene = match &data.scene {
        Some(path) => SceneFile::load(path)?,
        None => SceneFile::default(),
    };
    resolve_from(
        scene,
        None,
        data,
        options,
        first_attribute_by_default,
        reads,
    )
}

/// How resolving learns from the data what neither the flags nor the series' index say: this
/// process reading the steps it needs whole ([`InOneProcess`]), or a distributed render's ranks
/// each reading its part of them (`cli::render::dist`), which find the same values.
pub trait DataReads {
    /// Who scans the steps the series' index does not know when the series opens (`None`:
    /// this process, reading each step whole).
    fn steps_scan(&self) -> Option<&dyn StepsScan>;

    /// The mean overlap that chooses the cluster size over the series' first step and the
    /// field ([`crate::render::auto::mean_overlap`]'s number).
    fn mean_overlap(&self, series: &TimeSeries, field: &FieldSettings) -> anyhow::Result<f64>;

    /// The series' first step, `first`, as the defaults see it ([`FirstStep`]), with every
    /// attribute its file holds.
    fn first_step(&self, first: &StepRef) -> anyhow::Result<FirstStep>;

    /// The opened series' first step as the defaults see it, with every attribute its file
    /// holds (and the smoothing lengths the series computes): by default from its file as
    /// [`DataReads::first_step`] reads it.
    fn first_step_of(&self, series: &TimeSeries) -> anyhow::Result<Option<FirstStep>> {
        match series.step_ref(0) {
            Some(first) => Ok(Some(self.first_step(first)?)),
            None => Ok(series.first_step_in_full()?.map(FirstStep::Whole)),
        }
    }

    /// The particles' spacing in the series' first step, as the default radius measures it
    /// ([`crate::accel::spacing::median_nearest_distance`]).
    fn first_step_spacing(&self, series: &TimeSeries) -> anyhow::Result<Option<f64>>;
}

/// One process reads what it needs, whole.
pub struct InOneProcess;

impl DataReads for InOneProcess {
    fn steps_scan(&self) -> Option<&dyn StepsScan> {
        None
    }

    fn first_step(&self, first: &StepRef) -> anyhow::Result<FirstStep> {
        Ok(FirstStep::Whole(std::sync::Arc::new(crate::io::read_step(
            first,
            &crate::io::AttributeSelection::All,
        )?)))
    }

    fn first_step_of(&self, series: &TimeSeries) -> anyhow::Result<Option<FirstStep>> {
        Ok(series.first_step_in_full()?.map(FirstStep::Whole))
    }

    fn first_step_spacing(&self, series: &TimeSeries) -> anyhow::Result<Option<f64>> {
        Ok(crate::accel::spacing::median_nearest_distance(
            &series.step(0)?.positions,
        ))
    }

    fn mean_overlap(&self, series: &TimeSeries, field: &FieldSettings) -> anyhow::Result<f64> {
        Ok(crate::render::auto::mean_overlap(series, field)?)
    }
}

/// Resolves as [`resolve`] (or, with `first_attribute_by_default`, [`resolve_for_images`])
/// does, with the scene file given as a value instead of `data.scene`'s path (the Python
/// package builds one from its arguments).
pub fn resolve_scene(
    scene: SceneFile,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    resolve_from(
        scene,
        None,
        data,
        options,
        first_attribute_by_default,
        &InOneProcess,
    )
}

/// Resolves the field over a series already in memory ([`TimeSeries::from_steps`]: arrays the
/// Python package was handed) exactly as [`resolve_scene`] does over data read from a path;
/// `name` stands for the data's path in messages and in `Resolved::data_path`.
pub fn resolve_in_memory(
    series: TimeSeries,
    name: &std::path::Path,
    scene: SceneFile,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    resolve_from(
        scene,
        Some((series, name.to_path_buf())),
        data,
        options,
        first_attribute_by_default,
        &InOneProcess,
    )
}

/// Resolves the data and the field, step by step, in the order their messages are said.
fn resolve_from(
    scene: SceneFile,
    memory: Option<(TimeSeries, PathBuf)>,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
    reads: &dyn DataReads,
) -> anyhow::Result<Resolved> {
    let mut source = source::Source::new(&scene, memory, data)?;
    let (mut wanted, first) = attributes::choose(
        &source,
        &scene,
        data,
        options,
        first_attribute_by_default,
        reads,
    )?;
    let opening = std::time::Instant::now();
    let mut step = data.step.or(scene.data.step).unwrap_or(0);
    let series = match source.memory.take() {
        Some(series) => open::check_in_memory(series, &source.path, &mut wanted)?,
        None => open::from_files(&source, &mut wanted, data, step, reads.steps_scan())?,
    };
    if let Some(time) = data.time {
        let (nearest, at) = series
            .step_at_time(time)
            .with_context(|| format!("--time {time}: the series has no steps"))?;
        tracing::info!("--time {time}: step {nearest} (time {at}), the nearest");
        step = nearest;
    }
    let opened_in = opening.elapsed();
    let decoded_at_open = series.steps_decoded();
    let (periodic_spec, no_periodic) =
        super::periodic::merge(data.periodic, data.no_periodic, scene.data.periodic);
    let periodic = super::periodic::choose(&series, periodic_spec, no_periodic)?;
    if step >= series.len() {
        bail!(
            "{}: step {step} does not exist; the series has {} steps (0..{})",
            source.path.display(),
            series.len(),
            series.len() - 1
        );
    }
    let (radius_map, density_map) = field_settings::maps(options, &scene.field)?;
    let colormap = options.colormap.clone().or(scene.field.colormap.clone());
    let color_map = field_settings::color_map(colormap.as_deref())?;
    let radius_spec = options.radius.or(scene.field.radius);
    let first = field_settings::first_step_if_needed(first, &series, reads, &wanted, radius_spec)?;
    if wanted.attribute.is_none() && !first_attribute_by_default {
        field_settings::say_colour_by_density(first.as_ref());
    }
    let radius = field_settings::radius(&series, &wanted, radius_spec, first.as_ref(), reads)?;
    let range = options
        .attribute_range
        .or(scene.data.attribute_range)
        .unwrap_or(RangeSpec::Series);
    let attribute_range =
        field_settings::attribute_range(&series, wanted.attribute.as_deref(), range, step)?;
    let field = FieldSettings {
        attribute: wanted.attribute,
        attribute_range,
        radius,
        radius_attribute: wanted.radius_attribute,
        radius_map,
        density_map,
        color_map,
        classification: options
            .classification
            .or(scene.field.classification)
            .unwrap_or_default(),
        kernel: wanted.kernel,
        mass: wanted.mass,
        density: wanted.density,
    };
    let cluster = field_settings::cluster_size(
        options.cluster.or(scene.field.cluster),
        &series,
        &field,
        reads,
    )?;
    field_settings::say_rounded_maps(&field);
    Ok(Resolved {
        format: source.format,
        read: source.read,
        scene,
        series,
        step,
        field,
        cluster,
        data_path: source.path,
        colormap,
        opened_in,
        decoded_at_open,
        range,
        periodic,
    })
}
