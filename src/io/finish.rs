//! What every reader's output goes through before it is a [`Step`]: lengths checked, the
//! selected attributes kept in the order asked for, particles with a non-finite value dropped
//! (with a warning that counts them), empty steps refused.

use glam::DVec3;

use super::{At, AttributeSelection, DataError, Problem, all_finite};
use crate::values::{Attribute, Step};

/// What a reader hands over: positions and named columns, not yet checked.
pub struct Columns {
    /// Particle positions in data coordinates, as the file holds them (not yet checked finite).
    pub positions: Vec<DVec3>,
    /// The selected attributes (a reader decodes only what the selection keeps).
    pub attributes: Vec<Attribute>,
    /// The names of the attributes the file holds that were not decoded (for errors that
    /// say what there is to choose from).
    pub skipped: Vec<String>,
    /// The reader found every position and attribute value finite as it decoded them (false:
    /// it did not check, or found one that is not; [`finish_step`] then checks).
    pub finite: bool,
}

/// Checks and cleans a reader's output: equal lengths, the selected attributes present (and
/// only those kept), particles with a non-finite position or selected attribute dropped with a
/// warning that counts them, and no empty step.
pub fn finish_step(
    at: At<'_>,
    name: &str,
    columns: Columns,
    selection: &AttributeSelection,
) -> Result<Step, DataError> {
    finish(at, name, columns, selection, false)
}

/// [`finish_step`]'s checks and cleaning; `part`: the columns are one rank's part of a step
/// ([`super::read_step_part`]), which may be empty or have every particle dropped.
pub(super) fn finish(
    at: At<'_>,
    name: &str,
    columns: Columns,
    selection: &AttributeSelection,
    part: bool,
) -> Result<Step, DataError> {
    let Columns {
        positions,
        mut attributes,
        skipped,
        finite,
    } = columns;
    let n = positions.len();
    for a in &attributes {
        if a.values.len() != n {
            return Err(at.malformed(format!(
                "attribute '{}' has {} values for {} particles",
                a.name,
                a.values.len(),
                n
            )));
        }
    }
    if let AttributeSelection::Only(wanted) = selection {
        for w in wanted {
            if !attributes.iter().any(|a| &a.name == w) {
                return Err(at.err(Problem::MissingAttribute {
                    name: w.clone(),
                    available: available_list(&attributes, &skipped),
                    names: attributes
                        .iter()
                        .map(|a| a.name.clone())
                        .chain(skipped.iter().cloned())
                        .collect(),
                }));
            }
        }
        attributes.retain(|a| wanted.contains(&a.name));
        attributes.sort_by_key(|a| wanted.iter().position(|w| *w == a.name));
    }
    if n == 0 && !part {
        return Err(at.err(Problem::EmptyStep(String::new())));
    }

    // Simulation output is almost always finite: one parallel pass says so (or the reader
    // did, as it decoded), and only data with a non-finite value pays for the per-particle
    // bookkeeping of `drop_non_finite`.
    let (positions, attributes) = if finite
        || (all_finite(bytemuck::cast_slice(&positions))
            && attributes.iter().all(|a| all_finite(&a.values)))
    {
        (positions, attributes)
    } else {
        drop_non_finite(at, positions, attributes, part)?
    };
    Ok(Step {
        name: name.to_owned(),
        positions,
        attributes,
    })
}

/// The particles whose position and attributes are all finite, with a warning that counts
/// the others and why they went; an error where none is left (of a whole step: a rank's part
/// may be left empty).
fn drop_non_finite(
    at: At<'_>,
    positions: Vec<DVec3>,
    attributes: Vec<Attribute>,
    part: bool,
) -> Result<(Vec<DVec3>, Vec<Attribute>), DataError> {
    let n = positions.len();
    let mut keep = vec![true; n];
    let mut bad_positions = 0usize;
    for (k, p) in keep.iter_mut().zip(&positions) {
        if !p.is_finite() {
            *k = false;
            bad_positions += 1;
        }
    }
    let mut bad_attributes = Vec::new();
    for a in &attributes {
        let mut count = 0usize;
        for (k, v) in keep.iter_mut().zip(&a.values) {
            if !v.is_finite() {
                count += usize::from(*k);
                *k = false;
            }
        }
        if count > 0 {
            bad_attributes.push(format!("{count} with NaN/Inf '{}'", a.name));
        }
    }
    let dropped = n - keep.iter().filter(|k| **k).count();
    if dropped == 0 {
        return Ok((positions, attributes));
    }
    let mut why = Vec::new();
    if bad_positions > 0 {
        why.push(format!("{bad_positions} with NaN/Inf positions"));
    }
    why.extend(bad_attributes);
    let why = why.join(", ");
    if dropped == n && !part {
        return Err(at.err(Problem::EmptyStep(format!(
            ": all {n} particles were dropped ({why})"
        ))));
    }
    tracing::warn!(
        "{}: dropped {dropped} of {n} particles ({why})",
        at.location()
    );
    let positions = filter(&positions, &keep);
    let attributes = attributes
        .into_iter()
        .map(|a| Attribute {
            values: filter(&a.values, &keep),
            name: a.name,
        })
        .collect();
    Ok((positions, attributes))
}

fn filter<T: Copy>(values: &[T], keep: &[bool]) -> Vec<T> {
    values
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(v, _)| *v)
        .collect()
}

fn available_list(attributes: &[Attribute], skipped: &[String]) -> String {
    let mut names: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
    names.extend(skipped.iter().map(String::as_str));
    if names.is_empty() {
        "no attributes".into()
    } else {
        names
            .iter()
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}
