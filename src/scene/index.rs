//! The series index: what scanning a step file taught us (its particle count, bounds and each
//! attribute's range and mean), kept in a small sidecar file beside the data so the next open
//! of the series reads no step at all.
//!
//! One index per directory, `.aarbf-index.json`, with an entry per step file keyed by its path
//! relative to that directory. An entry is used only while the file has the size and
//! modification time it had when scanned, and only for the attributes it holds; anything else
//! is scanned again and the index rewritten (atomically). An index that cannot be read or
//! written is ignored: the series opens the same, only without the speed-up.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use serde::{Deserialize, Serialize};

use crate::io::{AttributeSelection, Format, ReadOptions, StepRef};
use crate::values::exact::exact_sum;
use crate::values::{Bounds, Step, value_range};

/// The index's file name, in the directory of the series' first step.
pub const INDEX_FILE: &str = ".aarbf-index.json";

/// Bumped whenever a reader's output or a statistic's definition changes, so an index written
/// by another version is never trusted.
const VERSION: u32 = 3;

/// What a scan of one step learns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepStats {
    /// Particles after the reader dropped those with NaN/Inf values.
    pub count: usize,
    /// Bounds of the particles' positions.
    pub bounds: Bounds,
    /// Bytes the step occupies in memory as read (positions and the attributes read).
    pub bytes: usize,
    /// Every attribute of the step as read.
    pub attributes: Vec<AttributeStats>,
    /// Whether `attributes` are all the file holds (a read of every attribute), not only a
    /// selection.
    pub all_attributes: bool,
}

/// One attribute's range, robust range and mean over one step (or, merged, over a series:
/// `AttributeInfo`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttributeStats {
    /// The attribute's name as the file spells it.
    pub name: String,
    /// The least value.
    pub min: f64,
    /// The largest value.
    pub max: f64,
    /// The 1st and 99th percentiles ([`robust_range`]).
    pub p01: f64,
    /// The 99th percentile.
    pub p99: f64,
    /// The mean value: the exactly rounded sum over the count ([`exact_sum`]), so that it is
    /// the same however the values were split between readers.
    pub mean: f64,
    /// Values the mean is over.
    pub count: usize,
}

/// The ranks, from 0 in sorted order, of the 1st and 99th percentiles of `n` values (nearest
/// rank: floor(0.01 (n - 1)) and ceil(0.99 (n - 1))); `None` for none. A distributed scan takes
/// the same ranks over the ranks' parts (`crate::dist::step_stats`).
pub fn robust_ranks(n: usize) -> Option<(usize, usize)> {
    let last = n.checked_sub(1)?;
    Some((last / 100, (99 * last).div_ceil(100)))
}

/// The 1st and 99th percentiles of `values` (nearest rank: the values at ranks
/// [`robust_ranks`] in sorted order), the range a colour map spans
/// without a few outliers washing the rest into one colour. `None` for no values.
pub fn robust_range(values: &[f64]) -> Option<(f64, f64)> {
    let (lo, hi) = robust_ranks(values.len())?;
    let mut v = values.to_vec();
    let (_, &mut low, above) = v.select_nth_unstable_by(lo, f64::total_cmp);
    let high = if hi == lo {
        low
    } else {
        // The high rank lies in the part above the low one.
        let k = hi - lo - 1;
        *above.select_nth_unstable_by(k, f64::total_cmp).1
    };
    Some((low, high))
}

impl StepStats {
    /// The statistics of `step`, read with `selection` (which says whether it holds every attribute
    /// of its file).
    pub fn of(step: &Step, selection: &AttributeSelection) -> StepStats {
        StepStats {
            count: step.len(),
            bounds: step.bounds(),
            bytes: step.bytes(),
            attributes: step
                .attributes
                .iter()
                .filter_map(|a| {
                    let (min, max) = value_range(&a.values)?;
                    let (p01, p99) = robust_range(&a.values)?;
                    Some(AttributeStats {
                        name: a.name.clone(),
                        min,
                        max,
                        p01,
                        p99,
                        mean: exact_sum(&a.values) / a.values.len() as f64,
                        count: a.values.len(),
                    })
                })
                .collect(),
            all_attributes: *selection == AttributeSelection::All,
        }
    }

    /// Whether these statistics answer a read with `selection`: the same attributes, as the
    /// reader would keep them (in the selection's order).
    fn serves(&self, selection: &AttributeSelection) -> Option<StepStats> {
        match selection {
            AttributeSelection::All => self.all_attributes.then(|| self.clone()),
            AttributeSelection::Only(names) => {
                let attributes = names
                    .iter()
                    .map(|n| self.attributes.iter().find(|a| &a.name == n).cloned())
                    .collect::<Option<Vec<_>>>()?;
                // Bytes as the reader would hold them: positions and the selected attributes.
                let bytes = self.count * (24 + 8 * attributes.len());
                Some(StepStats {
                    attributes,
                    bytes,
                    all_attributes: false,
                    ..self.clone()
                })
            }
        }
    }
}

/// Identifies one version of a file: its size and modification time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
struct Stamp {
    size: u64,
    modified_s: u64,
    modified_ns: u32,
}

impl Stamp {
    fn of(path: &Path) -> Option<Stamp> {
        let m = std::fs::metadata(path).ok()?;
        let t = m.modified().ok()?.duration_since(UNIX_EPOCH).ok()?;
        Some(Stamp {
            size: m.len(),
            modified_s: t.as_secs(),
            modified_ns: t.subsec_nanos(),
        })
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Entry {
    format: Format,
    /// The step's name (a `.particles` header names its steps).
    name: String,
    /// What was read of a file that holds a choice (an HDF5 snapshot's particle type).
    #[serde(default)]
    read: ReadOptions,
    stamp: Stamp,
    stats: StepStats,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct IndexFile {
    version: u32,
    entries: BTreeMap<String, Entry>,
}

/// The index of the directory a series lives in, as read at open.
pub struct SeriesIndex {
    path: PathBuf,
    dir: PathBuf,
    file: IndexFile,
    changed: bool,
}

impl SeriesIndex {
    /// The index beside `steps` (an empty one when there is none, or it cannot be read).
    pub fn load(steps: &[StepRef]) -> SeriesIndex {
        let dir = steps
            .first()
            .and_then(|s| s.path.parent())
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf();
        let path = dir.join(INDEX_FILE);
        let file = match std::fs::read(&path) {
            Ok(bytes) => match serde_json::from_slice::<IndexFile>(&bytes) {
                Ok(f) if f.version == VERSION => f,
                Ok(f) => {
                    tracing::debug!(
                        "{}: index version {} (this build writes {VERSION}); rebuilding",
                        path.display(),
                        f.version
                    );
                    IndexFile::default()
                }
                Err(e) => {
                    tracing::debug!("{}: unreadable index ({e}); rebuilding", path.display());
                    IndexFile::default()
                }
            },
            Err(_) => IndexFile::default(),
        };
        SeriesIndex {
            path,
            dir,
            file,
            changed: false,
        }
    }

    /// Drops every entry, so every step is scanned again (and the index rewritten).
    pub fn forget(&mut self) {
        self.file.entries.clear();
        self.changed = true;
    }

    fn key(&self, step: &StepRef) -> String {
        let p = step.path.strip_prefix(&self.dir).unwrap_or(&step.path);
        p.to_string_lossy().into_owned()
    }

    /// The statistics of `step` read with `selection`, if the index holds them for the file
    /// as it is now.
    pub fn get(&self, step: &StepRef, selection: &AttributeSelection) -> Option<StepStats> {
        let entry = self.file.entries.get(&self.key(step))?;
        if entry.format != step.format || entry.name != step.name || entry.read != step.read {
            return None;
        }
        if Stamp::of(&step.path)? != entry.stamp {
            return None;
        }
        entry.stats.serves(selection)
    }

    /// Records what a scan of `step` learned. `stamp_before` is the file's stamp taken before
    /// it was read: a file that changed while it was read is not recorded.
    pub fn insert(&mut self, step: &StepRef, stamp_before: Option<FileStamp>, stats: &StepStats) {
        let Some(FileStamp(stamp)) = stamp_before else {
            return;
        };
        if Stamp::of(&step.path) != Some(stamp) {
            return;
        }
        let key = self.key(step);
        // A read of a selection adds to what an earlier read of other attributes learned.
        let mut stats = stats.clone();
        if let Some(old) = self.file.entries.get(&key)
            && old.stamp == stamp
            && old.read == step.read
            && !stats.all_attributes
        {
            for a in &old.stats.attributes {
                if !stats.attributes.iter().any(|b| b.name == a.name) {
                    stats.attributes.push(a.clone());
                }
            }
            stats.all_attributes = old.stats.all_attributes;
        }
        self.file.entries.insert(
            key,
            Entry {
                format: step.format,
                name: step.name.clone(),
                read: step.read,
                stamp,
                stats,
            },
        );
        self.changed = true;
    }

    /// Writes the index back if a scan added to it, atomically; entries of files that no
    /// longer exist are dropped. A failure is reported at debug level and otherwise ignored.
    pub fn save(mut self) {
        if !self.changed {
            return;
        }
        let dir = self.dir.clone();
        self.file.version = VERSION;
        self.file.entries.retain(|k, _| dir.join(k).exists());
        let written = serde_json::to_vec(&self.file)
            .map_err(std::io::Error::other)
            .and_then(|bytes| {
                crate::io::output::write_atomically(&self.path, true, |p| std::fs::write(p, &bytes))
                    .map_err(std::io::Error::other)
            });
        if let Err(e) = written {
            tracing::debug!(
                "{}: index not written ({e}); the next open scans again",
                self.path.display()
            );
        }
    }
}

/// A file's stamp, taken before reading it (see [`SeriesIndex::insert`]).
#[derive(Clone, Copy, Debug)]
pub struct FileStamp(Stamp);

impl FileStamp {
    /// The stamp (size and modification time) of the file at `path`; `None` where it cannot be
    /// read.
    pub fn of(path: &Path) -> Option<FileStamp> {
        Stamp::of(path).map(FileStamp)
    }
}

#[cfg(test)]
mod tests {
    use super::robust_range;

    #[test]
    fn robust_range_takes_the_nearest_ranks_and_leaves_outliers_out() {
        assert_eq!(robust_range(&[]), None);
        assert_eq!(robust_range(&[7.5]), Some((7.5, 7.5)));
        assert_eq!(robust_range(&[2.0, -1.0]), Some((-1.0, 2.0)));
        // 1001 values 0..=1000 shuffled, with two wild outliers replacing 0 and 1000.
        let mut v: Vec<f64> = (0..=1000).map(|i| ((i * 389) % 1001) as f64).collect();
        for x in &mut v {
            if *x == 0.0 {
                *x = -1e30;
            } else if *x == 1000.0 {
                *x = 1e30;
            }
        }
        assert_eq!(robust_range(&v), Some((10.0, 990.0)));
        // Against a full sort on an awkward size.
        let w: Vec<f64> = (0..1237)
            .map(|i| ((i * 7919) % 1237) as f64 * 0.5 - 17.0)
            .collect();
        let mut sorted = w.clone();
        sorted.sort_by(f64::total_cmp);
        let last = w.len() - 1;
        assert_eq!(
            robust_range(&w),
            Some((sorted[last / 100], sorted[(99 * last).div_ceil(100)]))
        );
    }
}
