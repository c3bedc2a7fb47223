//! A time series of steps, loaded lazily from disk and cached up to a size bound.

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::index::{FileStamp, SeriesIndex, StepStats};
use crate::io::{self, AttributeSelection, DataError, Format, StepRef};
use crate::progress;
use crate::values::{Bounds, Step};

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

/// A time series of particle steps. Opening learns the series' bounds, counts and attribute
/// ranges (from the index beside the data, or by reading each step once); later reads come
/// from a bounded cache or from disk.
pub struct TimeSeries {
    source: Source,
    steps: Vec<StepInfo>,
    attributes: Vec<AttributeInfo>,
    bounds: Bounds,
    cache: Mutex<StepCache>,
    /// Signalled when a step being read (`StepCache::loading`) arrives.
    loaded: Condvar,
    /// Steps decoded from their files so far (opening, and reads the cache missed).
    decoded: AtomicUsize,
}

impl TimeSeries {
    /// Opens the series at `path` (a file, a directory or a glob).
    ///
    /// The series' bounds, counts and attribute ranges come from the index beside the data
    /// ([`super::index`]) for every step file it knows unchanged; the other steps are read
    /// (in parallel, each kept in the cache while it fits) and the index updated, so the next
    /// open reads nothing. Either way the values are the same, bit for bit.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<TimeSeries, DataError> {
        let refs = io::list_steps(path, options.format)?;
        let mut index = SeriesIndex::load(&refs);
        let cache = Mutex::new(StepCache::new(options.cache_bytes));
        let decoded = AtomicUsize::new(0);
        // Reads one step for its statistics, keeping it in the cache.
        let scan = |i: usize, selection: &AttributeSelection| {
            let r = &refs[i];
            let stamp = FileStamp::of(&r.path);
            let step = io::read_step(r, selection)?;
            decoded.fetch_add(1, Ordering::Relaxed);
            let stats = StepStats::of(&step, selection);
            cache.lock().unwrap().insert(i, Arc::new(step));
            Ok::<_, DataError>((stats, stamp))
        };
        let Some(first) = refs.first() else {
            // A `.particles` header that names no steps.
            return Ok(TimeSeries::assemble(
                Source::Files {
                    steps: refs,
                    selection: options.attributes.clone(),
                },
                Vec::new(),
                Vec::new(),
                StepCache::new(0),
            ));
        };
        // Every later step must carry the first step's attributes.
        let first_stats = match index.get(first, &options.attributes) {
            Some(stats) => stats,
            None => {
                let (stats, stamp) = scan(0, &options.attributes)?;
                index.insert(first, stamp, &stats);
                stats
            }
        };
        let selection = AttributeSelection::Only(
            first_stats
                .attributes
                .iter()
                .map(|a| a.name.clone())
                .collect(),
        );
        let known: Vec<Option<StepStats>> =
            refs[1..].iter().map(|r| index.get(r, &selection)).collect();
        let missing = known.iter().filter(|k| k.is_none()).count();
        let bar = progress::bar(missing as u64, "scanning steps");
        let scanned: Vec<(usize, StepStats, Option<FileStamp>)> = known
            .par_iter()
            .enumerate()
            .filter(|(_, k)| k.is_none())
            .map(|(k, _)| {
                let (stats, stamp) = scan(k + 1, &selection)?;
                bar.inc(1);
                Ok((k + 1, stats, stamp))
            })
            .collect::<Result<_, DataError>>()?;
        bar.finish_and_clear();
        let mut stats: Vec<Option<StepStats>> =
            std::iter::once(Some(first_stats)).chain(known).collect();
        for (i, s, stamp) in scanned {
            index.insert(&refs[i], stamp, &s);
            stats[i] = Some(s);
        }
        index.save();
        let stats: Vec<StepStats> = stats
            .into_iter()
            .map(|s| s.expect("every step known or scanned"))
            .collect();
        let infos = refs
            .iter()
            .zip(&stats)
            .map(|(r, s)| StepInfo {
                name: r.name.clone(),
                count: s.count,
                bounds: s.bounds,
                bytes: s.bytes,
            })
            .collect();
        let ranges = series_ranges(&stats);
        let mut series = TimeSeries::assemble(
            Source::Files {
                steps: refs,
                selection,
            },
            infos,
            ranges,
            cache.into_inner().unwrap(),
        );
        series.decoded = decoded;
        Ok(series)
    }

    /// A series held in memory (generated data, tests). Steps may be empty.
    pub fn from_steps(steps: Vec<Step>) -> TimeSeries {
        let stats: Vec<StepStats> = steps
            .iter()
            .map(|s| StepStats::of(s, &AttributeSelection::All))
            .collect();
        let infos = steps
            .iter()
            .zip(&stats)
            .map(|(step, s)| StepInfo {
                name: step.name.clone(),
                count: s.count,
                bounds: s.bounds,
                bytes: s.bytes,
            })
            .collect();
        let ranges = series_ranges(&stats);
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
            loaded: Condvar::new(),
            decoded: AtomicUsize::new(0),
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
                // A step another thread (the prefetcher) is reading is waited for, not read twice.
                let mut cache = self.cache.lock().unwrap();
                loop {
                    if let Some(s) = cache.get(index) {
                        return Ok(s);
                    }
                    if cache.loading.insert(index) {
                        break;
                    }
                    cache = self.loaded.wait(cache).unwrap();
                }
                drop(cache);
                let started = Instant::now();
                let read = io::read_step(&steps[index], selection).map(Arc::new);
                let mut cache = self.cache.lock().unwrap();
                cache.loading.remove(&index);
                if let Ok(step) = &read {
                    self.decoded.fetch_add(1, Ordering::Relaxed);
                    cache.read_times.insert(index, started.elapsed());
                    cache.insert(index, step.clone());
                }
                self.loaded.notify_all();
                read
            }
        }
    }

    /// How long the last read of step `index` from its file took (reading and decoding, on
    /// whichever thread read it), if it was read from a file.
    pub fn read_time(&self, index: usize) -> Option<Duration> {
        self.cache.lock().unwrap().read_times.get(&index).copied()
    }

    /// The file step `index` is read from (`None` for a series held in memory).
    pub fn step_file(&self, index: usize) -> Option<&Path> {
        match &self.source {
            Source::Files { steps, .. } => steps.get(index).map(|r| r.path.as_path()),
            Source::Memory(_) => None,
        }
    }

    /// Whether step `index` is held in memory now (a step read from memory always is).
    pub fn is_cached(&self, index: usize) -> bool {
        match &self.source {
            Source::Memory(_) => true,
            Source::Files { .. } => self.cache.lock().unwrap().contains(index),
        }
    }

    /// Drops every cached step (steps in use elsewhere live on until they are dropped there).
    pub fn clear_cache(&self) {
        let mut cache = self.cache.lock().unwrap();
        cache.entries.clear();
        cache.bytes = 0;
    }

    /// Marks the cached steps among `indices` as just used, in this order: the cache drops
    /// the least recently used first, so these stay while older steps go.
    pub fn touch(&self, indices: &[usize]) {
        let mut cache = self.cache.lock().unwrap();
        for &i in indices {
            cache.get(i);
        }
    }

    /// The most bytes of steps the cache keeps.
    pub fn cache_limit(&self) -> usize {
        self.cache.lock().unwrap().limit
    }

    /// Steps decoded from files so far, by the open and by reads the cache missed.
    pub fn steps_decoded(&self) -> usize {
        self.decoded.load(Ordering::Relaxed)
    }

    /// Bytes of steps held in the cache now.
    pub fn cached_bytes(&self) -> usize {
        self.cache.lock().unwrap().bytes
    }
}

/// The series-wide range and mean of each attribute, merged from the steps' statistics in
/// step order (so the same statistics, scanned or from the index, give the same values).
fn series_ranges(steps: &[StepStats]) -> Vec<AttributeInfo> {
    let mut ranges: Vec<AttributeInfo> = Vec::new();
    for step in steps {
        for a in &step.attributes {
            match ranges.iter_mut().find(|r| r.name == a.name) {
                Some(r) => {
                    r.min = r.min.min(a.min);
                    r.max = r.max.max(a.max);
                    let total = r.count + a.count;
                    r.mean = (r.mean * r.count as f64 + a.mean * a.count as f64) / total as f64;
                    r.count = total;
                }
                None => ranges.push(AttributeInfo {
                    name: a.name.clone(),
                    min: a.min,
                    max: a.max,
                    mean: a.mean,
                    count: a.count,
                }),
            }
        }
    }
    ranges
}

/// Least-recently-used steps, bounded in bytes. The step last inserted is always kept, even
/// when it alone exceeds the bound, so a caller never loads the same step twice in a row.
struct StepCache {
    limit: usize,
    bytes: usize,
    entries: VecDeque<(usize, Arc<Step>)>,
    /// Steps some thread is reading now.
    loading: HashSet<usize>,
    read_times: HashMap<usize, Duration>,
}

impl StepCache {
    fn new(limit: usize) -> StepCache {
        StepCache {
            limit,
            bytes: 0,
            entries: VecDeque::new(),
            loading: HashSet::new(),
            read_times: HashMap::new(),
        }
    }

    fn get(&mut self, index: usize) -> Option<Arc<Step>> {
        let pos = self.entries.iter().position(|(i, _)| *i == index)?;
        let entry = self.entries.remove(pos)?;
        let step = entry.1.clone();
        self.entries.push_back(entry);
        Some(step)
    }

    fn contains(&self, index: usize) -> bool {
        self.entries.iter().any(|(i, _)| *i == index)
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
