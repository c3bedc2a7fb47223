//! A time series of steps, loaded lazily from disk and cached up to a size bound.

use std::collections::VecDeque;
use std::path::Path;
use std::sync::{Arc, Mutex};

use crate::io::{self, AttributeSelection, DataError, Format, StepRef};
use crate::progress;
use crate::values::{Bounds, Step, value_range};

/// How to open a series.
#[derive(Clone, Debug)]
pub struct OpenOptions {
    /// Force a format instead of detecting it from file extensions.
    pub format: Option<Format>,
    /// The attributes to keep (everything else is not held in memory).
    pub attributes: AttributeSelection,
    /// The most bytes of loaded steps kept in memory; older steps are dropped first.
    pub cache_bytes: usize,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            format: None,
            attributes: AttributeSelection::All,
            cache_bytes: 2 << 30,
        }
    }
}

/// What is known about one step without holding it.
#[derive(Clone, Debug, PartialEq)]
pub struct StepInfo {
    pub name: String,
    pub count: usize,
    pub bounds: Bounds,
    pub bytes: usize,
}

/// An attribute's range and mean over the whole series (every particle of every step).
#[derive(Clone, Debug, PartialEq)]
pub struct AttributeInfo {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    /// Values the mean is over.
    pub count: usize,
}

enum Source {
    Files {
        steps: Vec<StepRef>,
        selection: AttributeSelection,
    },
    Memory(Vec<Arc<Step>>),
}

/// A time series of particle steps. Opening scans every step once for the series' bounds,
/// counts and attribute ranges; later reads come from a bounded cache or from disk.
pub struct TimeSeries {
    source: Source,
    steps: Vec<StepInfo>,
    attributes: Vec<AttributeInfo>,
    bounds: Bounds,
    cache: Mutex<StepCache>,
}

impl TimeSeries {
    /// Opens the series at `path` (a file, a directory or a glob).
    pub fn open(path: &Path, options: &OpenOptions) -> Result<TimeSeries, DataError> {
        let refs = io::list_steps(path, options.format)?;
        let mut cache = StepCache::new(options.cache_bytes);
        let mut selection = options.attributes.clone();
        let mut infos = Vec::with_capacity(refs.len());
        let mut ranges: Vec<AttributeInfo> = Vec::new();
        let bar = progress::bar(refs.len() as u64, "scanning steps");
        for (i, r) in refs.iter().enumerate() {
            let step = io::read_step(r, &selection)?;
            if i == 0 {
                // Every later step must carry the first step's attributes.
                selection = AttributeSelection::Only(
                    step.attributes.iter().map(|a| a.name.clone()).collect(),
                );
            }
            merge_ranges(&mut ranges, &step);
            infos.push(info_of(&step));
            cache.insert(i, Arc::new(step));
            bar.inc(1);
        }
        bar.finish_and_clear();
        Ok(TimeSeries::assemble(
            Source::Files {
                steps: refs,
                selection,
            },
            infos,
            ranges,
            cache,
        ))
    }

    /// A series held in memory (generated data, tests). Steps may be empty.
    pub fn from_steps(steps: Vec<Step>) -> TimeSeries {
        let mut ranges = Vec::new();
        let mut infos = Vec::with_capacity(steps.len());
        for s in &steps {
            merge_ranges(&mut ranges, s);
            infos.push(info_of(s));
        }
        let steps = steps.into_iter().map(Arc::new).collect();
        TimeSeries::assemble(Source::Memory(steps), infos, ranges, StepCache::new(0))
    }

    fn assemble(
        source: Source,
        steps: Vec<StepInfo>,
        attributes: Vec<AttributeInfo>,
        cache: StepCache,
    ) -> TimeSeries {
        let bounds = steps.iter().fold(Bounds::EMPTY, |b, s| b.union(s.bounds));
        TimeSeries {
            source,
            steps,
            attributes,
            bounds,
            cache: Mutex::new(cache),
        }
    }

    pub fn len(&self) -> usize {
        self.steps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    pub fn steps(&self) -> &[StepInfo] {
        &self.steps
    }

    pub fn attributes(&self) -> &[AttributeInfo] {
        &self.attributes
    }

    /// Every attribute the data holds, including those this series did not select (for
    /// errors that tell the user what to choose from): read from the first step's file.
    pub fn attributes_in_data(&self) -> Result<Vec<String>, DataError> {
        let names = |step: &Step| {
            step.attribute_names()
                .iter()
                .map(|n| n.to_string())
                .collect()
        };
        match &self.source {
            Source::Files { steps, .. } => match steps.first() {
                Some(r) => Ok(names(&io::read_step(r, &AttributeSelection::All)?)),
                None => Ok(Vec::new()),
            },
            Source::Memory(steps) => Ok(steps.first().map(|s| names(s)).unwrap_or_default()),
        }
    }

    pub fn attribute(&self, name: &str) -> Option<&AttributeInfo> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// Bounds over all steps.
    pub fn bounds(&self) -> Bounds {
        self.bounds
    }

    /// The largest particle count of any step (what GPU buffers are sized for).
    pub fn max_count(&self) -> usize {
        self.steps.iter().map(|s| s.count).max().unwrap_or(0)
    }

    /// Step `index`, from the cache or from disk.
    pub fn step(&self, index: usize) -> Result<Arc<Step>, DataError> {
        if index >= self.steps.len() {
            return Err(DataError::new(
                "<series>",
                None,
                io::Problem::Malformed(format!(
                    "step {index} does not exist; the series has {} steps (0..{})",
                    self.steps.len(),
                    self.steps.len().saturating_sub(1)
                )),
            ));
        }
        match &self.source {
            Source::Memory(steps) => Ok(steps[index].clone()),
            Source::Files { steps, selection } => {
                if let Some(s) = self.cache.lock().unwrap().get(index) {
                    return Ok(s);
                }
                let step = Arc::new(io::read_step(&steps[index], selection)?);
                self.cache.lock().unwrap().insert(index, step.clone());
                Ok(step)
            }
        }
    }

    /// Bytes of steps held in the cache now.
    pub fn cached_bytes(&self) -> usize {
        self.cache.lock().unwrap().bytes
    }
}

fn info_of(step: &Step) -> StepInfo {
    StepInfo {
        name: step.name.clone(),
        count: step.len(),
        bounds: step.bounds(),
        bytes: step.bytes(),
    }
}

fn merge_ranges(ranges: &mut Vec<AttributeInfo>, step: &Step) {
    for a in &step.attributes {
        let Some((lo, hi)) = value_range(&a.values) else {
            continue;
        };
        let (n, mean) = (
            a.values.len(),
            a.values.iter().sum::<f64>() / a.values.len() as f64,
        );
        match ranges.iter_mut().find(|r| r.name == a.name) {
            Some(r) => {
                r.min = r.min.min(lo);
                r.max = r.max.max(hi);
                let total = r.count + n;
                r.mean = (r.mean * r.count as f64 + mean * n as f64) / total as f64;
                r.count = total;
            }
            None => ranges.push(AttributeInfo {
                name: a.name.clone(),
                min: lo,
                max: hi,
                mean,
                count: n,
            }),
        }
    }
}

/// Least-recently-used steps, bounded in bytes. The step last inserted is always kept, even
/// when it alone exceeds the bound, so a caller never loads the same step twice in a row.
struct StepCache {
    limit: usize,
    bytes: usize,
    entries: VecDeque<(usize, Arc<Step>)>,
}

impl StepCache {
    fn new(limit: usize) -> StepCache {
        StepCache {
            limit,
            bytes: 0,
            entries: VecDeque::new(),
        }
    }

    fn get(&mut self, index: usize) -> Option<Arc<Step>> {
        let pos = self.entries.iter().position(|(i, _)| *i == index)?;
        let entry = self.entries.remove(pos)?;
        let step = entry.1.clone();
        self.entries.push_back(entry);
        Some(step)
    }

    fn insert(&mut self, index: usize, step: Arc<Step>) {
        if self.limit == 0 {
            return;
        }
        self.bytes += step.bytes();
        self.entries.push_back((index, step));
        while self.bytes > self.limit && self.entries.len() > 1 {
            let (_, old) = self.entries.pop_front().unwrap();
            self.bytes -= old.bytes();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::values::Attribute;
    use glam::DVec3;

    fn step(n: usize, v: f64) -> Arc<Step> {
        Arc::new(Step {
            name: format!("s{n}"),
            positions: vec![DVec3::splat(v); n],
            attributes: vec![Attribute {
                name: "a".into(),
                values: vec![v; n],
            }],
        })
    }

    #[test]
    fn cache_keeps_within_its_bound_and_drops_the_oldest() {
        let one = step(10, 1.0).bytes();
        let mut cache = StepCache::new(2 * one);
        cache.insert(0, step(10, 0.0));
        cache.insert(1, step(10, 1.0));
        assert!(cache.get(0).is_some()); // 0 is now the most recent
        cache.insert(2, step(10, 2.0));
        assert_eq!(cache.bytes, 2 * one);
        assert!(
            cache.get(1).is_none(),
            "the least recently used step goes first"
        );
        assert!(cache.get(0).is_some() && cache.get(2).is_some());
        // A step larger than the bound is still held alone.
        cache.insert(3, step(100, 3.0));
        assert_eq!(cache.entries.len(), 1);
    }

    #[test]
    fn memory_series_reports_bounds_counts_and_ranges() {
        let s = TimeSeries::from_steps(vec![(*step(3, -1.0)).clone(), (*step(5, 2.0)).clone()]);
        assert_eq!(s.len(), 2);
        assert_eq!(s.max_count(), 5);
        assert_eq!(s.bounds().min, DVec3::splat(-1.0));
        assert_eq!(s.bounds().max, DVec3::splat(2.0));
        let a = s.attribute("a").unwrap();
        assert_eq!((a.min, a.max), (-1.0, 2.0));
        assert_eq!((a.mean, a.count), ((-3.0 + 5.0 * 2.0) / 8.0, 8));
        assert!(s.step(2).is_err());
    }
}
