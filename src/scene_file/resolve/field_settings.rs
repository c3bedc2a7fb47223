//! The field's settings taken from the flags over the scene file, and the automatic values of
//! the data (radius, colour range, cluster size) chosen and said in the log.

use super::DataReads;
use super::args::FieldOptions;
use super::attributes::Wanted;
use super::first_step::FirstStep;
use super::radius::default_radius;
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::scene::TimeSeries;
use crate::scene::maps::{ColorMap, DensityMap, PiecewiseLinear, RadiusMap};
use crate::scene_file::{FieldSection, MapSpec, RadiusSpec, RangeSpec};

/// The radius and density maps: a flag's spelling over the scene file's entry, else the
/// identity.
pub(super) fn maps(
    options: &FieldOptions,
    file: &FieldSection,
) -> anyhow::Result<(RadiusMap, DensityMap)> {
    let map = |flag: &Option<String>,
               file: &Option<MapSpec>|
     -> anyhow::Result<Option<PiecewiseLinear>> {
        Ok(match (flag, file) {
            (Some(text), _) => Some(text.parse()?),
            (None, Some(spec)) => Some(spec.to_map()?),
            (None, None) => None,
        })
    };
    let radius_map = map(&options.radius_map, &file.radius_map)?
        .map(RadiusMap::new)
        .transpose()?
        .unwrap_or_default();
    let density_map = map(&options.density_map, &file.density_map)?
        .map(DensityMap::new)
        .transpose()?
        .unwrap_or_default();
    Ok((radius_map, density_map))
}

/// The colour map a preset's name or a ParaView file spells (the default without one).
pub(super) fn color_map(spec: Option<&str>) -> anyhow::Result<ColorMap> {
    Ok(match spec {
        Some(spec) => ColorMap::from_name_or_file(spec)?,
        None => ColorMap::default(),
    })
}

/// The first step in full, read from the series only where a message or a default needs what
/// the series did not select: the data's attributes when the field carries none, a smoothing
/// length for the default radius.
pub(super) fn first_step_if_needed(
    first: Option<FirstStep>,
    series: &TimeSeries,
    reads: &dyn DataReads,
    wanted: &Wanted,
    radius_spec: Option<RadiusSpec>,
) -> anyhow::Result<Option<FirstStep>> {
    Ok(match first {
        Some(step) => Some(step),
        None if wanted.attribute.is_none()
            || (radius_spec.is_none() && wanted.radius_attribute.is_none()) =>
        {
            reads.first_step_of(series)?
        }
        None => None,
    })
}

/// Says that a field without an attribute is coloured by density, with the attributes the
/// data offers instead.
pub(super) fn say_colour_by_density(first: Option<&FirstStep>) {
    let names_in_data = first.map(FirstStep::names).unwrap_or_default();
    tracing::info!(
        "colour: by density (no --attribute given); the data's attributes: {} (--attribute \
         NAME colours by one)",
        if names_in_data.is_empty() {
            "none".to_owned()
        } else {
            names_in_data.join(", ")
        }
    );
}

/// The global radius: the one asked for, else the data's default, said in the log.
pub(super) fn radius(
    series: &TimeSeries,
    wanted: &Wanted,
    radius_spec: Option<RadiusSpec>,
    first: Option<&FirstStep>,
    reads: &dyn DataReads,
) -> anyhow::Result<f64> {
    Ok(match radius_spec {
        Some(spec) => spec.resolve(series.bounds().diagonal()),
        None => {
            let (radius, how) = default_radius(
                series,
                wanted.radius_attribute.as_deref(),
                first,
                wanted.kernel,
                reads,
            )?;
            tracing::info!("radius: {how}");
            radius
        }
    })
}

/// The attribute's range as `range` chooses it for step `step`, said in the log.
pub(super) fn attribute_range(
    series: &TimeSeries,
    attribute: Option<&str>,
    range: RangeSpec,
    step: usize,
) -> anyhow::Result<Option<(f64, f64)>> {
    let (attribute_range, range_is) = range.resolve(series, attribute, step)?;
    if let Some(name) = attribute {
        let (lo, hi) = attribute_range
            .or_else(|| series.attribute(name).map(|a| (a.min, a.max)))
            .unwrap_or((0.0, 0.0));
        let over = if range.per_step() {
            format!("{range_is}, each step its own (step {step}: [{lo}, {hi}])")
        } else {
            format!("[{lo}, {hi}], {range_is}")
        };
        tracing::info!(
            "colour: '{name}' over {over} (--attribute-range LO,HI, series, robust, step or \
             robust-step)"
        );
    }
    Ok(attribute_range)
}

/// The cluster size asked for, else the one for how much the particles overlap (by `overlap`),
/// said.
pub(super) fn cluster_size(
    asked: Option<ClusterSize>,
    series: &TimeSeries,
    field: &FieldSettings,
    reads: &dyn super::DataReads,
) -> anyhow::Result<ClusterSize> {
    Ok(match asked {
        Some(k) => k,
        None => {
            let overlap = reads.mean_overlap(series, field)?;
            let k = ClusterSize::for_overlap(overlap);
            tracing::info!(
                "cluster size K = {k} ({overlap:.1} particles reach a particle centre on average; --cluster sets it)"
            );
            k
        }
    })
}

/// Every backend uses a map through its table; says so where that changes it visibly.
pub(super) fn say_rounded_maps(field: &FieldSettings) {
    for (what, map) in [
        ("radius map", &field.radius_map.0),
        ("density map", &field.density_map.0),
    ] {
        let e = map.table_error();
        if e > 1e-3 * map.max_value().abs().max(1e-300) {
            tracing::info!(
                "{what}: control points between the {}-sample table's points are rounded onto them; \
                 the map as used differs from them by up to {e:.2e} (points on multiples of 1/{} \
                 are exact)",
                crate::values::tables::TABLE_SIZE,
                crate::values::tables::TABLE_SIZE - 1
            );
        }
    }
}
