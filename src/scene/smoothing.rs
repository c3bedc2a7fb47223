//! Smoothing lengths from neighbours, for data that has none (N-body particles, point clouds):
//! h_i is the distance from particle i to its K-th nearest neighbour, as yt and sarracen
//! compute it, in parallel over a k-d tree. Each step's lengths are cached beside its file
//! (`.aarbf-smoothing/`), keyed by the file's size and modification time, so a series is
//! measured once.

use std::num::NonZero;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::UNIX_EPOCH;

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::io::{self, AttributeSelection, DataError, Part, StepPart, StepRef};
use crate::values::Attribute;

/// The folder, beside the data, the lengths are cached in.
pub const CACHE_DIR: &str = ".aarbf-smoothing";

/// The length given where no neighbour is at a distance (a single particle, or all particles
/// at one point): the data has no length scale, so one unit.
pub const NO_SCALE: f64 = 1.0;

/// `--smoothing knn:K`: h from the K-th nearest neighbour. Scene files spell it as the flag
/// does (`smoothing = "knn:32"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Smoothing {
    /// K: the neighbour whose distance is h (the 1st is the nearest other particle).
    pub neighbours: usize,
}

impl Smoothing {
    /// K when `--smoothing knn` gives none.
    pub const DEFAULT_NEIGHBOURS: usize = 32;

    /// The attribute the lengths are given as (usable as `--radius-attribute`): `h_knn32`,
    /// named with K so that the series index never mixes lengths of different K.
    pub fn attribute(self) -> String {
        format!("h_knn{}", self.neighbours)
    }

    /// The smoothing whose lengths an attribute of this name holds ([`Self::attribute`]'s
    /// inverse), so a scene file that uses them says how to make them again.
    pub fn of_attribute(name: &str) -> Option<Smoothing> {
        let neighbours = name.strip_prefix("h_knn")?.parse().ok()?;
        (neighbours > 0).then_some(Smoothing { neighbours })
    }
}

impl TryFrom<String> for Smoothing {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<Smoothing> for String {
    fn from(s: Smoothing) -> String {
        format!("knn:{}", s.neighbours)
    }
}

impl FromStr for Smoothing {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("smoothing '{s}': expected knn or knn:K with K a whole number >= 1");
        let rest = s.trim().strip_prefix("knn").ok_or_else(bad)?;
        let neighbours = match rest.strip_prefix(':') {
            None if rest.is_empty() => Smoothing::DEFAULT_NEIGHBOURS,
            Some(k) => k.parse().map_err(|_| bad())?,
            None => return Err(bad()),
        };
        if neighbours == 0 {
            return Err(bad());
        }
        Ok(Smoothing { neighbours })
    }
}

/// h_i = the distance from particle i to its K-th nearest other particle (K clipped to the
/// particles there are). Where that distance is 0 (K or more copies of one position), the
/// smallest positive h of the step; where there is none, [`NO_SCALE`]. Every h is finite and
/// positive.
pub fn knn_lengths(positions: &[DVec3], neighbours: usize) -> Vec<f64> {
    let n = positions.len();
    if n == 0 {
        return Vec::new();
    }
    let k = neighbours.min(n - 1);
    let mut h: Vec<f64> = if k == 0 {
        vec![0.0; n]
    } else {
        let points: Vec<[f64; 3]> = positions.iter().map(|p| p.to_array()).collect();
        let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points);
        // The particle itself is among its nearest (at distance 0): one more is asked for.
        let asked = NonZero::new(k + 1).expect("k + 1 >= 1");
        points
            .par_iter()
            .map(|q| {
                let found = tree.nearest_n::<SquaredEuclidean>(q, asked);
                found.last().map_or(0.0, |n| n.distance.sqrt())
            })
            .collect()
    };
    let floor = least_positive_or(&h, NO_SCALE);
    for v in &mut h {
        if !(*v > 0.0 && v.is_finite()) {
            *v = floor;
        }
    }
    h
}

/// The least positive finite length of `h`, or `none` where it has none: the length a
/// length of 0 takes.
pub fn least_positive_or(h: &[f64], none: f64) -> f64 {
    let least = h
        .iter()
        .copied()
        .filter(|&v| v > 0.0 && v.is_finite())
        .fold(f64::INFINITY, f64::min);
    if least.is_finite() { least } else { none }
}

/// Where step `step`'s lengths for K neighbours are cached.
fn cache_path(step: &StepRef, neighbours: usize) -> Option<PathBuf> {
    let dir = step.path.parent()?;
    let name = step.path.file_name()?.to_string_lossy();
    let read = &step.read;
    let physical = if read.physical { ".physical" } else { "" };
    Some(dir.join(CACHE_DIR).join(format!(
        "{name}.{}.{}{physical}.k{neighbours}.f64",
        step.name, read.particle_type
    )))
}

const MAGIC: &[u8; 8] = b"AARBFKN1";

/// The file's size and modification time, which a cached entry must match.
fn stamp(path: &Path) -> Option<[u8; 20]> {
    let m = std::fs::metadata(path).ok()?;
    let t = m.modified().ok()?.duration_since(UNIX_EPOCH).ok()?;
    let mut out = [0u8; 20];
    out[..8].copy_from_slice(&m.len().to_le_bytes());
    out[8..16].copy_from_slice(&t.as_secs().to_le_bytes());
    out[16..].copy_from_slice(&t.subsec_nanos().to_le_bytes());
    Some(out)
}

fn load(path: &Path, stamp: &[u8; 20], count: usize) -> Option<Vec<f64>> {
    let bytes = std::fs::read(path).ok()?;
    let header = 8 + 20 + 8;
    if bytes.len() != header + 8 * count
        || &bytes[..8] != MAGIC
        || &bytes[8..28] != stamp
        || u64::from_le_bytes(bytes[28..36].try_into().ok()?) != count as u64
    {
        return None;
    }
    Some(
        bytes[header..]
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect(),
    )
}

fn save(path: &Path, stamp: &[u8; 20], h: &[f64]) -> std::io::Result<()> {
    let mut bytes = Vec::with_capacity(36 + 8 * h.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(stamp);
    bytes.extend_from_slice(&(h.len() as u64).to_le_bytes());
    bytes.extend(h.iter().flat_map(|v| v.to_le_bytes()));
    std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))?;
    crate::io::output::write_atomically(path, true, |tmp| std::fs::write(tmp, &bytes))
        .map_err(std::io::Error::other)
}

/// The lengths of `step` (read from `positions`), from the cache beside its file where it
/// holds them for the file as it is, else computed and cached (a cache that cannot be
/// written is skipped).
pub fn lengths_for(step: &StepRef, positions: &[DVec3], neighbours: usize) -> Vec<f64> {
    let stamp = stamp(&step.path);
    let path = cache_path(step, neighbours);
    if let (Some(stamp), Some(path)) = (&stamp, &path)
        && let Some(h) = load(path, stamp, positions.len())
    {
        return h;
    }
    let h = knn_lengths(positions, neighbours);
    if let (Some(stamp), Some(path)) = (stamp, path)
        && let Err(e) = save(&path, &stamp, &h)
    {
        tracing::debug!("{}: smoothing lengths not cached ({e})", path.display());
    }
    h
}

/// How the smoothing lengths of the particles this process read are found: by this process
/// alone where it holds the whole step ([`WholeStep`]), or by every rank together where each
/// holds a part of it (`crate::dist::knn`), since a part's neighbours lie in other parts.
pub trait NeighbourLengths {
    /// The lengths for `neighbours` (K) of `positions`, this process's `part` of `step` (its
    /// particles after the reader's checks): the whole step's lengths of those particles.
    fn lengths(
        &self,
        step: &StepRef,
        part: Part,
        positions: &[DVec3],
        neighbours: usize,
    ) -> Result<Vec<f64>, DataError>;
}

/// One process holding the whole step: [`lengths_for`], cached beside the file.
pub struct WholeStep;

impl NeighbourLengths for WholeStep {
    fn lengths(
        &self,
        step: &StepRef,
        part: Part,
        positions: &[DVec3],
        neighbours: usize,
    ) -> Result<Vec<f64>, DataError> {
        if !part.is_whole() {
            return Err(DataError::new(
                &step.path,
                Some(&step.name),
                io::Problem::Malformed(format!(
                    "smoothing lengths of part {} of {} need the other parts' particles",
                    part.rank + 1,
                    part.ranks
                )),
            ));
        }
        Ok(lengths_for(step, positions, neighbours))
    }
}

/// Reads `part` of `step` with `selection`, and where `smoothing` is given and selected, the
/// smoothing lengths from neighbours as the attribute [`Smoothing::attribute`] (in the
/// selection's order), found by `lengths`.
pub fn read_part(
    step: &StepRef,
    selection: &AttributeSelection,
    smoothing: Option<Smoothing>,
    part: Part,
    lengths: &dyn NeighbourLengths,
) -> Result<StepPart, DataError> {
    let Some(smoothing) = smoothing.filter(|s| selection.keeps(&s.attribute())) else {
        return io::read_step_part(step, selection, part);
    };
    let name = smoothing.attribute();
    let from_file = match selection {
        AttributeSelection::All => AttributeSelection::All,
        AttributeSelection::Only(names) => {
            AttributeSelection::Only(names.iter().filter(|n| **n != name).cloned().collect())
        }
    };
    let mut read = io::read_step_part(step, &from_file, part)?;
    let values = lengths.lengths(step, part, &read.step.positions, smoothing.neighbours)?;
    read.step.attributes.push(Attribute { name, values });
    if let AttributeSelection::Only(names) = selection {
        read.step
            .attributes
            .sort_by_key(|a| names.iter().position(|n| *n == a.name));
    }
    Ok(read)
}

/// The bytes before a cache file's lengths: magic, the data file's stamp, the count.
const CACHE_HEADER: u64 = 8 + 20 + 8;

/// The cached lengths `range` of step `step`'s `count` lengths for `neighbours`, read alone
/// (a rank's share), where the cache holds them for the file as it is.
pub fn cached_part(
    step: &StepRef,
    neighbours: usize,
    count: usize,
    range: std::ops::Range<usize>,
) -> Option<Vec<f64>> {
    use std::io::{Read, Seek, SeekFrom};
    let stamp = stamp(&step.path)?;
    let mut file = std::fs::File::open(cache_path(step, neighbours)?).ok()?;
    let mut header = [0u8; CACHE_HEADER as usize];
    file.read_exact(&mut header).ok()?;
    if &header[..8] != MAGIC
        || header[8..28] != stamp
        || u64::from_le_bytes(header[28..36].try_into().ok()?) != count as u64
        || file.metadata().ok()?.len() != CACHE_HEADER + 8 * count as u64
        || range.end > count
    {
        return None;
    }
    file.seek(SeekFrom::Start(CACHE_HEADER + 8 * range.start as u64))
        .ok()?;
    let mut bytes = vec![0u8; 8 * range.len()];
    file.read_exact(&mut bytes).ok()?;
    Some(
        bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect(),
    )
}

/// A cache file written by several processes at once, each its share at its offset
/// ([`SharedCache::write_at`]), made the cache by one of them when all have written
/// ([`SharedCache::publish`]): until then it is a temporary file beside the cache.
pub struct SharedCache {
    /// The temporary file the shares are written into.
    pub partial: PathBuf,
    /// The cache file it becomes.
    pub path: PathBuf,
}

impl SharedCache {
    /// Creates the temporary file for step `step`'s `count` lengths for `neighbours`, with
    /// its header and size (by one process, which hands `partial` to the others).
    pub fn create(step: &StepRef, neighbours: usize, count: usize) -> std::io::Result<SharedCache> {
        let missing = || std::io::Error::other("the data file has no folder or stamp");
        let stamp = stamp(&step.path).ok_or_else(missing)?;
        let path = cache_path(step, neighbours).ok_or_else(missing)?;
        let dir = path.parent().ok_or_else(missing)?;
        std::fs::create_dir_all(dir)?;
        let (file, partial) = tempfile::Builder::new()
            .prefix(".aarbf-partial-")
            .tempfile_in(dir)?
            .keep()
            .map_err(|e| e.error)?;
        let mut header = Vec::with_capacity(CACHE_HEADER as usize);
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&stamp);
        header.extend_from_slice(&(count as u64).to_le_bytes());
        use std::io::Write;
        (&file).write_all(&header)?;
        file.set_len(CACHE_HEADER + 8 * count as u64)?;
        Ok(SharedCache { partial, path })
    }

    /// Writes lengths `start..start + h.len()` into the temporary file.
    pub fn write_at(partial: &Path, start: usize, h: &[f64]) -> std::io::Result<()> {
        use std::os::unix::fs::FileExt;
        let file = std::fs::OpenOptions::new().write(true).open(partial)?;
        let bytes: Vec<u8> = h.iter().flat_map(|v| v.to_le_bytes()).collect();
        file.write_all_at(&bytes, CACHE_HEADER + 8 * start as u64)
    }

    /// Makes the written file the cache (`complete`), or removes it.
    pub fn publish(self, complete: bool) -> std::io::Result<()> {
        if complete {
            std::fs::rename(&self.partial, &self.path)
        } else {
            std::fs::remove_file(&self.partial)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flag_spells_k() {
        assert_eq!("knn".parse(), Ok(Smoothing { neighbours: 32 }));
        assert_eq!("knn:7".parse(), Ok(Smoothing { neighbours: 7 }));
        for bad in ["knn:0", "knn:x", "knn7", "sph", "knn:-3"] {
            assert!(bad.parse::<Smoothing>().is_err(), "{bad}");
        }
    }
}
