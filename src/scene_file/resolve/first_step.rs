//! What resolving's defaults need of the series' first step beyond its index: the names of the
//! attributes its file holds (an image's colour, an SPH kernel's arrays found by name) and the
//! median of its smoothing length (the default radius). One process reads the step whole for
//! them; a distributed render's ranks find the same from their parts ([`super::DataReads`]).

use std::sync::Arc;

use crate::values::Step;

/// Names smoothing-length arrays go by in SPH codes' output (compared ignoring case).
pub(super) const SMOOTHING_LENGTH_NAMES: [&str; 6] = [
    "h",
    "hsml",
    "smoothinglength",
    "smoothinglengths",
    "smoothing_length",
    "smoothing_lengths",
];

/// The series' first step as the defaults see it.
#[derive(Clone, Debug)]
pub enum FirstStep {
    /// The step with every attribute its file holds, read whole in this process.
    Whole(Arc<Step>),
    /// What the ranks found from their parts of it.
    FromParts(FirstStepFacts),
}

/// What the ranks of a distributed render find of the first step from their parts.
#[derive(Clone, Debug, PartialEq)]
pub struct FirstStepFacts {
    /// The names of the attributes its file holds, in the file's order.
    pub names: Vec<String>,
    /// Its smoothing length ([`smoothing_length_in`]) and the median of that attribute's
    /// positive values ([`median_of_positive`]; `None` where it has none).
    pub smoothing_length: Option<(String, Option<f64>)>,
}

impl FirstStep {
    /// The names of the attributes the step's file holds.
    pub fn names(&self) -> Vec<String> {
        match self {
            FirstStep::Whole(step) => step
                .attribute_names()
                .iter()
                .map(|n| n.to_string())
                .collect(),
            FirstStep::FromParts(facts) => facts.names.clone(),
        }
    }

    /// The step's smoothing length, by name, with the median of its positive values.
    pub fn smoothing_length(&self) -> Option<(String, Option<f64>)> {
        match self {
            FirstStep::Whole(step) => {
                let names = self.names();
                let name = smoothing_length_in(&names)?;
                let values = &step.attribute(name)?.values;
                Some((name.to_owned(), median_of_positive(values)))
            }
            FirstStep::FromParts(facts) => facts.smoothing_length.clone(),
        }
    }
}

/// The first of `names` that SPH codes give a smoothing length (compared ignoring case).
pub fn smoothing_length_in(names: &[String]) -> Option<&str> {
    names
        .iter()
        .find(|n| SMOOTHING_LENGTH_NAMES.contains(&n.to_ascii_lowercase().as_str()))
        .map(String::as_str)
}

/// The values the median of a smoothing length is taken over: positive and finite.
pub fn positive(values: &[f64]) -> Vec<f64> {
    values
        .iter()
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect()
}

/// The median of `values`' positive values: the one at rank `n / 2` in sorted order (`None`
/// for none). A distributed render's ranks find the same rank over their parts.
pub fn median_of_positive(values: &[f64]) -> Option<f64> {
    let mut positive = positive(values);
    if positive.is_empty() {
        return None;
    }
    let middle = positive.len() / 2;
    let (_, &mut median, _) = positive.select_nth_unstable_by(middle, f64::total_cmp);
    Some(median)
}
