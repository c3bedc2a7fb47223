//! The series opened with the attributes the field uses; a name the data spells in the other
//! number or case (SWIFT's `Temperatures` for `Temperature`) is taken as the data's, said in
//! the log.

use std::path::Path;

use anyhow::Context;

use super::args::DataArgs;
use super::attributes::Wanted;
use super::source::{Source, names_of};
use crate::io::AttributeSelection;
use crate::scene::{OpenOptions, StepsScan, TimeSeries};

/// A series held whole in memory: every attribute is there; checks the ones `wanted` asks for,
/// a name in the other number or case being the data's, as for a file.
pub(super) fn check_in_memory(
    series: TimeSeries,
    path: &Path,
    wanted: &mut Wanted,
) -> anyhow::Result<TimeSeries> {
    let (mass_attribute, density_attribute) = wanted.mass_and_density_attributes();
    if let Some(first) = series.first_step_in_full()? {
        let names = names_of(Some(&first));
        for a in [&mut wanted.attribute, &mut wanted.radius_attribute] {
            let Some(name) = a.clone() else { continue };
            if first.attribute(&name).is_some() {
                continue;
            }
            let found =
                crate::scene_file::names::other_spelling(&name, &names).with_context(|| {
                    format!(
                        "{}: no attribute '{name}'; the particles have: {}",
                        path.display(),
                        names.join(", ")
                    )
                })?;
            tracing::info!(
                "attribute '{name}': the data has no attribute of that name, but has \
                 '{found}': using '{found}'"
            );
            *a = Some(found);
        }
        for name in mass_attribute.iter().chain(density_attribute.iter()) {
            anyhow::ensure!(
                first.attribute(name).is_some(),
                "{}: no attribute '{name}'; the particles have: {}",
                path.display(),
                names.join(", ")
            );
        }
    }
    Ok(series)
}

/// Opens the series at `source`'s path reading the attributes `wanted` asks for (the first
/// step checked for them); `asked_step` is the step the command will show, for the message.
pub(super) fn from_files(
    source: &Source,
    wanted: &mut Wanted,
    data: &DataArgs,
    asked_step: usize,
    scan: Option<&dyn StepsScan>,
) -> anyhow::Result<TimeSeries> {
    let (mass_attribute, density_attribute) = wanted.mass_and_density_attributes();
    let open = |attribute: &Option<String>, radius_attribute: &Option<String>| {
        let options = OpenOptions {
            format: source.format,
            read: source.read,
            smoothing: wanted.smoothing,
            attributes: AttributeSelection::Only(
                attribute
                    .iter()
                    .chain(radius_attribute.iter())
                    .chain(mass_attribute.iter())
                    .chain(density_attribute.iter())
                    .cloned()
                    .collect(),
            ),
            cache_bytes: data.cache_mib << 20,
            // A batch frame uses the final series values, never provisional ones.
            background_scan: false,
            rescan: data.rescan,
        };
        match scan {
            Some(scan) => TimeSeries::open_scanned_by(&source.path, &options, scan),
            None => TimeSeries::open(&source.path, &options),
        }
    };
    let (mut attribute, mut radius_attribute) =
        (wanted.attribute.clone(), wanted.radius_attribute.clone());
    let mut opened = open(&attribute, &radius_attribute);
    // At most the two names asked for are spelled otherwise.
    for _ in 0..2 {
        let Err(crate::io::DataError {
            problem: crate::io::Problem::MissingAttribute { name, names, .. },
            ..
        }) = &opened
        else {
            break;
        };
        let Some(found) = crate::scene_file::names::other_spelling(name, names) else {
            break;
        };
        let name = name.clone();
        tracing::info!(
            "attribute '{name}': the data has no attribute of that name, but has '{found}': \
             using '{found}'"
        );
        for a in [&mut attribute, &mut radius_attribute] {
            if a.as_deref() == Some(name.as_str()) {
                *a = Some(found.clone());
            }
        }
        opened = open(&attribute, &radius_attribute);
    }
    let series = opened.map_err(|e| {
        // The series' first step is checked when it opens, whichever step was asked for: say
        // so, or the message seems to be about the wrong step.
        let missing = matches!(e.problem, crate::io::Problem::MissingAttribute { .. });
        if missing && asked_step != 0 {
            anyhow::Error::new(e).context(format!(
                "the attributes asked for must be in every step of the series, and its first \
                 step lacks one (step {asked_step} was asked for)"
            ))
        } else {
            e.into()
        }
    })?;
    (wanted.attribute, wanted.radius_attribute) = (attribute, radius_attribute);
    Ok(series)
}
