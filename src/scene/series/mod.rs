//! A time series of steps, loaded lazily from disk and cached up to a size bound.

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::index::{AttributeStats, FileStamp, SeriesIndex, StepStats};
use super::smoothing::{self, NeighbourLengths, Smoothing, WholeStep};
use crate::io::{self, AttributeSelection, DataError, Format, ReadOptions, StepRef};
use crate::progress;
use crate::values::{Bounds, Step};

mod cache;
mod scan;
#[cfg(test)]
mod tests;

use cache::StepCache;
use scan::{scan, series_ranges};

/// How to open a series.
#[derive(Clone, Debug)]
pub struct OpenOptions {
    /// Force a format instead of detecting it from file extensions.
    pub format: Option<Format>,
    /// What to read from files that hold a choice (HDF5 snapshots' particle types).
    pub read: ReadOptions,
    /// Smoothing lengths from neighbours, given as the attribute [`Smoothing::attribute`]
    /// where the selection keeps it.
    pub smoothing: Option<Smoothing>,
    /// The attributes to keep (everything else is not held in memory).
    pub attributes: AttributeSelection,
    /// The most bytes of loaded steps kept in memory; older steps are dropped first.
    pub cache_bytes: usize,
    /// Return as soon as the files are listed and the first step is known, scanning the rest
    /// on a background thread (the viewer; the series-wide values are provisional until the
    /// scan ends). Otherwise `open` waits for the scan, so the values are final and an
    /// unreadable step is `open`'s error (batch commands, whose frames must not depend on
    /// when they started).
    pub background_scan: bool,
    /// Scan every step whatever the index says (and rewrite it).
    pub rescan: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            format: None,
            read: ReadOptions::default(),
            smoothing: None,
            attributes: AttributeSelection::All,
            cache_bytes: 2 << 30,
            background_scan: false,
            rescan: false,
        }
    }
}

/// The statistics of steps of a series ([`StepStats`]) gathered without this process reading
/// each step whole: by a distributed render's ranks, each reading its part of each step
/// (`crate::dist::step_stats`). They must be the statistics a read of the whole step gives
/// ([`StepStats::of`]), bit for bit.
pub trait StepsScan {
    /// The statistics of `steps[i]` for each `i` of `which`, in that order, read with
    /// `selection` (and the smoothing lengths from neighbours `smoothing` computes, where
    /// selected). Collective: every rank calls it with the same arguments.
    fn stats(
        &self,
        steps: &[StepRef],
        which: &[usize],
        selection: &AttributeSelection,
        smoothing: Option<Smoothing>,
    ) -> Result<Vec<StepStats>, DataError>;

    /// Whether this process writes what the scan found into the series' index (one rank of a
    /// job does: the others would write the same bytes).
    fn writes_index(&self) -> bool {
        true
    }
}

/// The one step's statistics a scan of one step returned.
fn one(found: Vec<StepStats>, step: &StepRef) -> Result<StepStats, DataError> {
    let n = found.len();
    found.into_iter().next().filter(|_| n == 1).ok_or_else(|| {
        DataError::new(
            &step.path,
            None,
            io::Problem::Malformed(format!(
                "the ranks' scan returned the statistics of {n} steps for 1"
            )),
        )
    })
}

/// Reads a step from its file, with the smoothing lengths from neighbours where `smoothing`
/// asks for them and `selection` keeps them.
fn read_file_step(
    step: &StepRef,
    selection: &AttributeSelection,
    smoothing: Option<Smoothing>,
) -> Result<Step, DataError> {
    smoothing::read_part(step, selection, smoothing, io::Part::WHOLE, &WholeStep).map(|r| r.step)
}

/// What is known about one step without holding it.
#[derive(Clone, Debug, PartialEq)]
pub struct StepInfo {
    /// A name for messages: the file name, or the step name in a `.particles` header.
    pub name: String,
    /// Particles in the step (0 until scanned).
    pub count: usize,
    /// Bounds of its positions (empty until scanned).
    pub bounds: Bounds,
    /// Bytes it occupies in memory (its file's size until scanned).
    pub bytes: usize,
    /// Whether count, bounds and bytes come from the step's data (from the index or a scan);
    /// a step not scanned yet has count 0, empty bounds and its file's size as `bytes`.
    pub scanned: bool,
    /// Each attribute's range, robust range and mean in this step (none until scanned): a
    /// per-step colour range needs no read of the step.
    pub attributes: Vec<AttributeStats>,
}

impl StepInfo {
    fn of(step: &StepRef, stats: Option<&StepStats>) -> StepInfo {
        match stats {
            Some(s) => StepInfo {
                name: step.name.clone(),
                count: s.count,
                bounds: s.bounds,
                bytes: s.bytes,
                scanned: true,
                attributes: s.attributes.clone(),
            },
            None => StepInfo {
                name: step.name.clone(),
                count: 0,
                bounds: Bounds::EMPTY,
                bytes: std::fs::metadata(&step.path).map_or(0, |m| m.len() as usize),
                scanned: false,
                attributes: Vec::new(),
            },
        }
    }
}

/// An attribute's range and mean over the whole series (every particle of every step): its
/// steps' statistics merged. The robust range is from the lowest step's 1st percentile to the
/// highest step's 99th, so outliers in any step are left out while every step's bulk is
/// inside.
pub type AttributeInfo = AttributeStats;

enum Source {
    Files {
        steps: Vec<StepRef>,
        selection: AttributeSelection,
        smoothing: Option<Smoothing>,
    },
    Memory(Vec<Arc<Step>>),
}

/// The series-wide values (bounds, counts, attribute ranges) as far as the steps scanned so far
/// tell them. While a scan is running they are *provisional*: a frame rendered from them says
/// so, and keeps them (they are printed and written into a saved scene) rather than changing
/// when the scan finishes.
#[derive(Clone, Debug, PartialEq)]
pub struct SeriesValues {
    /// Per step; a step not scanned yet has `scanned: false`, count 0, empty bounds and its
    /// file's size as `bytes`.
    pub steps: Vec<StepInfo>,
    /// Each attribute's statistics merged over the scanned steps.
    pub attributes: Vec<AttributeInfo>,
    /// Bounds over the scanned steps.
    pub bounds: Bounds,
    /// Steps whose statistics are known.
    pub scanned: usize,
    /// Why the scan stopped, if a step could not be read.
    pub error: Option<String>,
}

impl SeriesValues {
    fn of(steps: Vec<StepInfo>, stats: &[Option<StepStats>]) -> SeriesValues {
        let known: Vec<&StepStats> = stats.iter().flatten().collect();
        SeriesValues {
            bounds: known.iter().fold(Bounds::EMPTY, |b, s| b.union(s.bounds)),
            attributes: series_ranges(known.iter().copied()),
            scanned: known.len(),
            steps,
            error: None,
        }
    }

    /// Whether some steps are not scanned yet (or could not be), so that the values may
    /// still change.
    pub fn is_provisional(&self) -> bool {
        self.scanned < self.steps.len()
    }

    /// The statistics of the attribute called `name`, if the series has it.
    pub fn attribute(&self, name: &str) -> Option<&AttributeInfo> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// The largest particle count of any scanned step.
    pub fn max_count(&self) -> usize {
        self.steps.iter().map(|s| s.count).max().unwrap_or(0)
    }
}

/// What the series and its background scan share.
struct Shared {
    source: Source,
    values: RwLock<SeriesValues>,
    /// Signalled when the scan finishes.
    scan_finished: Condvar,
    scan_running: Mutex<bool>,
    cancel: AtomicBool,
    cache: Mutex<StepCache>,
    /// Signalled when a step being read (`StepCache::loading`) arrives.
    loaded: Condvar,
    /// Steps decoded from their files so far (opening, the scan, and reads the cache missed).
    decoded: AtomicUsize,
    /// The scan's error, for the first caller of `wait_for_scan` (later ones get its text).
    scan_error: Mutex<Option<DataError>>,
    /// Each step's time, once asked for ([`TimeSeries::times`]).
    times: std::sync::OnceLock<Option<Vec<f64>>>,
    /// Ranks' parts kept by [`TimeSeries::step_part_kept`] until [`TimeSeries::clear_cache`].
    kept_parts: Mutex<HashMap<(usize, io::Part), Arc<Step>>>,
}

/// A time series of particle steps. Opening lists the step files and reads at most the first
/// step; the series-wide bounds, counts and attribute ranges come from the index beside the
/// data ([`super::index`]) for every file it knows unchanged, and the other steps are scanned
/// on a background thread, which updates the index so the next open scans nothing. Later
/// reads come from a bounded cache or from disk.
pub struct TimeSeries {
    shared: Arc<Shared>,
    len: usize,
    scanner: Option<std::thread::JoinHandle<()>>,
}

impl TimeSeries {
    /// Opens the series at `path` (a file, a directory or a glob), returning once the files
    /// are listed and the first step's attributes known (the first step read, unless the index
    /// knows it). Steps the index does not know are scanned in the background: until
    /// [`TimeSeries::wait_for_scan`] returns, [`TimeSeries::values`] are provisional. The final
    /// values are the same, bit for bit, however the statistics were gathered.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<TimeSeries, DataError> {
        TimeSeries::open_with(path, options, None)
    }

    /// Opens the series at `path` as [`TimeSeries::open`] does, the statistics of the steps
    /// the index does not know gathered by `scan` (a distributed render's ranks, each reading
    /// its part of each step: [`StepsScan`]) instead of this process reading them whole, before
    /// it returns. The series' values are the same, bit for bit, smoothing lengths from
    /// neighbours included. Every rank calls it, at the same point: the scan is collective.
    pub fn open_scanned_by(
        path: &Path,
        options: &OpenOptions,
        scan: &dyn StepsScan,
    ) -> Result<TimeSeries, DataError> {
        TimeSeries::open_with(path, options, Some(scan))
    }

    fn open_with(
        path: &Path,
        options: &OpenOptions,
        parts: Option<&dyn StepsScan>,
    ) -> Result<TimeSeries, DataError> {
        let refs = io::list_steps_reading(path, options.format, options.read)?;
        let mut index = SeriesIndex::load(&refs);
        if options.rescan {
            index.forget();
        }
        let mut cache = StepCache::new(options.cache_bytes);
        let mut decoded = 0;
        let Some(first) = refs.first() else {
            // A `.particles` header that names no steps.
            return Ok(TimeSeries::assemble(
                Source::Files {
                    steps: refs,
                    selection: options.attributes.clone(),
                    smoothing: options.smoothing,
                },
                Vec::new(),
                Vec::new(),
                StepCache::new(0),
            ));
        };
        // Every later step must carry the first step's attributes.
        let first_stats = match (index.get(first, &options.attributes), parts) {
            (Some(stats), _) => stats,
            (None, Some(parts)) => {
                let stamp = FileStamp::of(&first.path);
                let stats = one(
                    parts.stats(&refs, &[0], &options.attributes, options.smoothing)?,
                    first,
                )?;
                index.insert(first, stamp, &stats);
                stats
            }
            (None, None) => {
                let stamp = FileStamp::of(&first.path);
                let step = read_file_step(first, &options.attributes, options.smoothing)?;
                decoded += 1;
                let stats = StepStats::of(&step, &options.attributes);
                cache.insert(0, Arc::new(step));
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
        let mut stats: Vec<Option<StepStats>> = std::iter::once(Some(first_stats))
            .chain(refs[1..].iter().map(|r| index.get(r, &selection)))
            .collect();
        let mut missing: Vec<usize> = (0..stats.len()).filter(|&i| stats[i].is_none()).collect();
        if let Some(parts) = parts.filter(|_| !missing.is_empty()) {
            let stamps: Vec<_> = missing
                .iter()
                .map(|&i| FileStamp::of(&refs[i].path))
                .collect();
            let found = parts.stats(&refs, &missing, &selection, options.smoothing)?;
            if found.len() != missing.len() {
                return Err(DataError::new(
                    &refs[missing[0]].path,
                    None,
                    io::Problem::Malformed(format!(
                        "the ranks' scan returned the statistics of {} steps for {}",
                        found.len(),
                        missing.len()
                    )),
                ));
            }
            for ((&i, stamp), s) in missing.iter().zip(stamps).zip(found) {
                index.insert(&refs[i], stamp, &s);
                stats[i] = Some(s);
            }
            missing.clear();
        }
        let infos = refs
            .iter()
            .zip(&stats)
            .map(|(r, s)| StepInfo::of(r, s.as_ref()))
            .collect();
        let mut series = TimeSeries::assemble_with(
            Source::Files {
                steps: refs,
                selection,
                smoothing: options.smoothing,
            },
            SeriesValues::of(infos, &stats),
            cache,
        );
        series.shared.decoded.store(decoded, Ordering::Relaxed);
        if missing.is_empty() {
            if parts.is_none_or(|p| p.writes_index()) {
                index.save();
            }
        } else {
            *series.shared.scan_running.lock().unwrap() = true;
            let shared = series.shared.clone();
            series.scanner = Some(std::thread::spawn(move || {
                scan(&shared, stats, &missing, index);
            }));
            if !options.background_scan {
                series.wait_for_scan()?;
            }
        }
        Ok(series)
    }

    /// A series held in memory (generated data, tests). Steps may be empty.
    pub fn from_steps(steps: Vec<Step>) -> TimeSeries {
        TimeSeries::from_shared_steps(steps.into_iter().map(Arc::new).collect())
    }

    /// A series of steps held in memory and shared (the Python package's particles: the
    /// series takes no copy of them).
    pub fn from_shared_steps(steps: Vec<Arc<Step>>) -> TimeSeries {
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
                scanned: true,
                attributes: s.attributes.clone(),
            })
            .collect();
        let ranges = series_ranges(stats.iter());
        TimeSeries::assemble(Source::Memory(steps), infos, ranges, StepCache::new(0))
    }

    fn assemble(
        source: Source,
        steps: Vec<StepInfo>,
        attributes: Vec<AttributeInfo>,
        cache: StepCache,
    ) -> TimeSeries {
        let values = SeriesValues {
            bounds: steps.iter().fold(Bounds::EMPTY, |b, s| b.union(s.bounds)),
            scanned: steps.len(),
            steps,
            attributes,
            error: None,
        };
        TimeSeries::assemble_with(source, values, cache)
    }

    fn assemble_with(source: Source, values: SeriesValues, cache: StepCache) -> TimeSeries {
        let len = values.steps.len();
        TimeSeries {
            shared: Arc::new(Shared {
                source,
                values: RwLock::new(values),
                scan_finished: Condvar::new(),
                scan_running: Mutex::new(false),
                cancel: AtomicBool::new(false),
                cache: Mutex::new(cache),
                loaded: Condvar::new(),
                decoded: AtomicUsize::new(0),
                scan_error: Mutex::new(None),
                times: std::sync::OnceLock::new(),
                kept_parts: Mutex::new(HashMap::new()),
            }),
            len,
            scanner: None,
        }
    }

    /// How many steps the series has.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the series has no steps.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The series-wide values as known now (provisional while the scan runs).
    pub fn values(&self) -> SeriesValues {
        self.shared.values.read().unwrap().clone()
    }

    /// Waits for the background scan (showing its progress when it takes long), so the values
    /// are final; an unreadable step is the error.
    pub fn wait_for_scan(&self) -> Result<(), DataError> {
        let mut running = self.shared.scan_running.lock().unwrap();
        if *running {
            let values = self.values();
            let bar = progress::bar(values.steps.len() as u64, "scanning steps");
            while *running {
                bar.set_position(self.shared.values.read().unwrap().scanned as u64);
                running = self
                    .shared
                    .scan_finished
                    .wait_timeout(running, Duration::from_millis(100))
                    .unwrap()
                    .0;
            }
            bar.finish_and_clear();
        }
        drop(running);
        if let Some(e) = self.shared.scan_error.lock().unwrap().take() {
            return Err(e);
        }
        match &self.shared.values.read().unwrap().error {
            None => Ok(()),
            Some(e) => Err(DataError::new(
                "<series>",
                None,
                io::Problem::Malformed(e.clone()),
            )),
        }
    }

    /// Per-step information (see [`SeriesValues::steps`]).
    pub fn steps(&self) -> Vec<StepInfo> {
        self.shared.values.read().unwrap().steps.clone()
    }

    /// Each step's time, where the data records one for every step (a `.pvd`'s timesteps, HDF5
    /// snapshots' `Time`); read once, on the first call.
    pub fn times(&self) -> Option<&[f64]> {
        self.shared
            .times
            .get_or_init(|| match &self.shared.source {
                Source::Files { steps, .. } => steps.iter().map(io::step_time).collect(),
                Source::Memory(_) => None,
            })
            .as_deref()
    }

    /// The step whose time is nearest `time` (the earlier of two equally near), with the
    /// time it has; without times, the time is the step's index.
    pub fn step_at_time(&self, time: f64) -> Option<(usize, f64)> {
        let indices: Vec<f64>;
        let times = match self.times() {
            Some(t) => t,
            None => {
                indices = (0..self.len).map(|i| i as f64).collect();
                &indices
            }
        };
        times
            .iter()
            .copied()
            .enumerate()
            .min_by(|a, b| (a.1 - time).abs().total_cmp(&(b.1 - time).abs()))
    }

    /// One step's information.
    pub fn step_info(&self, index: usize) -> Option<StepInfo> {
        self.shared.values.read().unwrap().steps.get(index).cloned()
    }

    /// Each selected attribute's statistics over the steps scanned so far.
    pub fn attributes(&self) -> Vec<AttributeInfo> {
        self.shared.values.read().unwrap().attributes.clone()
    }

    /// Every attribute the data holds, including those this series did not select (for
    /// errors that tell the user what to choose from): read from the first step's file.
    pub fn attributes_in_data(&self) -> Result<Vec<String>, DataError> {
        Ok(self
            .first_step_in_full()?
            .map(|step| {
                step.attribute_names()
                    .iter()
                    .map(|n| n.to_string())
                    .collect()
            })
            .unwrap_or_default())
    }

    /// The first step with every attribute its file holds, including those this series did
    /// not select (read again from the file; not cached).
    pub fn first_step_in_full(&self) -> Result<Option<Arc<Step>>, DataError> {
        match &self.shared.source {
            Source::Files {
                steps, smoothing, ..
            } => steps
                .first()
                .map(|r| read_file_step(r, &AttributeSelection::All, *smoothing).map(Arc::new))
                .transpose(),
            Source::Memory(steps) => Ok(steps.first().cloned()),
        }
    }

    /// The statistics of the attribute called `name` over the steps scanned so far, if the series
    /// has it.
    pub fn attribute(&self, name: &str) -> Option<AttributeInfo> {
        self.shared.values.read().unwrap().attribute(name).cloned()
    }

    /// Bounds over all steps (the scanned ones while scanning).
    pub fn bounds(&self) -> Bounds {
        self.shared.values.read().unwrap().bounds
    }

    /// The largest particle count of any step (what GPU buffers are sized for).
    pub fn max_count(&self) -> usize {
        self.shared.values.read().unwrap().max_count()
    }

    /// Step `index`, from the cache or from disk.
    pub fn step(&self, index: usize) -> Result<Arc<Step>, DataError> {
        if index >= self.len {
            return Err(DataError::new(
                "<series>",
                None,
                io::Problem::Malformed(format!(
                    "step {index} does not exist; the series has {} steps (0..{})",
                    self.len,
                    self.len.saturating_sub(1)
                )),
            ));
        }
        match &self.shared.source {
            Source::Memory(steps) => Ok(steps[index].clone()),
            Source::Files {
                steps,
                selection,
                smoothing,
            } => {
                // A step another thread (the prefetcher) is reading is waited for, not read twice.
                let mut cache = self.shared.cache.lock().unwrap();
                loop {
                    if let Some(s) = cache.get(index) {
                        return Ok(s);
                    }
                    if cache.loading.insert(index) {
                        break;
                    }
                    cache = self.shared.loaded.wait(cache).unwrap();
                }
                drop(cache);
                let started = Instant::now();
                let read = read_file_step(&steps[index], selection, *smoothing).map(Arc::new);
                let mut cache = self.shared.cache.lock().unwrap();
                cache.loading.remove(&index);
                if let Ok(step) = &read {
                    self.shared.decoded.fetch_add(1, Ordering::Relaxed);
                    cache.read_times.insert(index, started.elapsed());
                    cache.insert(index, step.clone());
                }
                self.shared.loaded.notify_all();
                read
            }
        }
    }

    /// Rank `part.rank`'s part of step `index` ([`io::read_step_part`]): read from the file
    /// without the cache (it is one rank's, and the cache is for whole steps), or cut from a
    /// step held in memory. Where the series computes smoothing lengths from neighbours, a
    /// part's neighbours lie in other parts too: `lengths` finds them (every rank together,
    /// `crate::dist::knn`), so that the field is the single-rank field.
    pub fn step_part(
        &self,
        index: usize,
        part: io::Part,
        lengths: &dyn NeighbourLengths,
    ) -> Result<io::StepPart, DataError> {
        let whole_and_cut = |step: &Step| io::StepPart {
            step: io::slice_step(step, part),
            decoded: step.len(),
        };
        let (
            Some(step),
            Source::Files {
                selection,
                smoothing,
                ..
            },
        ) = (self.step_ref(index), &self.shared.source)
        else {
            return self.step(index).map(|s| whole_and_cut(&s));
        };
        let read = smoothing::read_part(step, selection, *smoothing, part, lengths)?;
        tracing::debug!(
            "{}: rank {} of {} decoded {} records, keeps {}",
            step.name,
            part.rank,
            part.ranks,
            read.decoded,
            read.step.len()
        );
        Ok(read)
    }

    /// [`Self::step_part`]'s step, read once and kept until [`Self::clear_cache`]: the
    /// automatic values a distributed render computes from the first step (its spacing, the
    /// mean overlap, Phi_ref) read each rank's part of it once. Every rank must clear at the
    /// same point, since the lengths from neighbours are found by all ranks together.
    pub fn step_part_kept(
        &self,
        index: usize,
        part: io::Part,
        lengths: &dyn NeighbourLengths,
    ) -> Result<Arc<Step>, DataError> {
        if let Some(kept) = self.shared.kept_parts.lock().unwrap().get(&(index, part)) {
            return Ok(kept.clone());
        }
        let read = Arc::new(self.step_part(index, part, lengths)?.step);
        self.shared
            .kept_parts
            .lock()
            .unwrap()
            .insert((index, part), read.clone());
        Ok(read)
    }

    /// Takes the part of step `index` that [`Self::step_part_kept`] kept for `part`, if any: the
    /// render of that step starts from it instead of reading it again, and owns it (so that it
    /// can drop it once its brick is made).
    pub fn take_kept_part(&self, index: usize, part: io::Part) -> Option<Step> {
        let kept = self
            .shared
            .kept_parts
            .lock()
            .unwrap()
            .remove(&(index, part))?;
        Some(Arc::try_unwrap(kept).unwrap_or_else(|shared| (*shared).clone()))
    }

    /// How long the last read of step `index` from its file took (reading and decoding, on
    /// whichever thread read it), if it was read from a file.
    pub fn read_time(&self, index: usize) -> Option<Duration> {
        self.shared
            .cache
            .lock()
            .unwrap()
            .read_times
            .get(&index)
            .copied()
    }

    /// The step file `index` refers to (`None` for a series held in memory).
    pub fn step_ref(&self, index: usize) -> Option<&StepRef> {
        match &self.shared.source {
            Source::Files { steps, .. } => steps.get(index),
            Source::Memory(_) => None,
        }
    }

    /// The file step `index` is read from (`None` for a series held in memory).
    pub fn step_file(&self, index: usize) -> Option<&Path> {
        match &self.shared.source {
            Source::Files { steps, .. } => steps.get(index).map(|r| r.path.as_path()),
            Source::Memory(_) => None,
        }
    }

    /// The simulation box step `index`'s file states (an HDF5 snapshot's `BoxSize` and
    /// periodicity; `None` for other formats and for a series held in memory).
    pub fn simulation_box(&self, index: usize) -> Result<Option<io::SimulationBox>, DataError> {
        match &self.shared.source {
            Source::Files { steps, .. } => match steps.get(index) {
                Some(step) => io::simulation_box(step),
                None => Ok(None),
            },
            Source::Memory(_) => Ok(None),
        }
    }

    /// Whether step `index` is held in memory now (a step read from memory always is).
    pub fn is_cached(&self, index: usize) -> bool {
        match &self.shared.source {
            Source::Memory(_) => true,
            Source::Files { .. } => self.shared.cache.lock().unwrap().contains(index),
        }
    }

    /// Drops every cached step (steps in use elsewhere live on until they are dropped there).
    pub fn clear_cache(&self) {
        self.clear_cache_but_parts_of(None);
    }

    /// Drops every cached step, but the ranks' parts of step `keep` where they were kept
    /// ([`Self::step_part_kept`]): the step a distributed render renders next takes them
    /// ([`Self::take_kept_part`]).
    pub fn clear_cache_but_parts_of(&self, keep: Option<usize>) {
        let mut cache = self.shared.cache.lock().unwrap();
        cache.entries.clear();
        cache.bytes = 0;
        self.shared
            .kept_parts
            .lock()
            .unwrap()
            .retain(|(index, _), _| Some(*index) == keep);
    }

    /// Marks the cached steps among `indices` as just used, in this order: the cache drops
    /// the least recently used first, so these stay while older steps go.
    pub fn touch(&self, indices: &[usize]) {
        let mut cache = self.shared.cache.lock().unwrap();
        for &i in indices {
            cache.get(i);
        }
    }

    /// The most bytes of steps the cache keeps.
    pub fn cache_limit(&self) -> usize {
        self.shared.cache.lock().unwrap().limit
    }

    /// Steps decoded from files so far, by the open and by reads the cache missed.
    pub fn steps_decoded(&self) -> usize {
        self.shared.decoded.load(Ordering::Relaxed)
    }

    /// Bytes of steps held in the cache now.
    pub fn cached_bytes(&self) -> usize {
        self.shared.cache.lock().unwrap().bytes
    }
}

impl Drop for TimeSeries {
    /// Stops the background scan (what it learned so far is written to the index).
    fn drop(&mut self) {
        self.shared.cancel.store(true, Ordering::Relaxed);
        if let Some(scanner) = self.scanner.take() {
            let _ = scanner.join();
        }
    }
}
