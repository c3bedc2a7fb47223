//! Which files of a folder (or glob) are one time series.
//!
//! Simulation codes write more than their steps into an output folder: boundary or wall
//! particles (`boundary.vtp` beside PySPH's `fluid_00000.vtp …`), initial conditions, restart
//! snapshots, other species. Files are grouped by their name with the step number taken out
//! (`fluid_00037.vtp` → `fluid_*.vtp`); the group with the most steps is the series, ties going
//! to the group holding more bytes (more particles). Files with no number in their name form a
//! series only when no file has one, as a folder of `early.csv`, `late.csv` does.
//!
//! A snapshot split over several HDF5 files (`snap_012.0.hdf5`, `snap_012.1.hdf5`, ...) is one
//! step: its snapshot number, not its file number, is the step number.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use super::Format;

/// Files of one name pattern, in one format.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StemGroup {
    /// The file name with its step number as `*` (`fluid_*.vtp`), or the name itself when it
    /// has no number: a glob that selects this group alone within its folder.
    pub pattern: String,
    /// The files' format.
    pub format: Format,
    /// The group's files.
    pub files: Vec<PathBuf>,
    /// The files' total size in bytes (of two groups with as many steps, the larger is the series).
    pub bytes: u64,
}

impl StemGroup {
    fn numbered(&self) -> bool {
        self.pattern.contains('*')
    }

    /// `--data` that selects this group alone.
    pub fn data_argument(&self) -> String {
        let dir = self.files[0].parent().unwrap_or(Path::new(""));
        dir.join(&self.pattern).to_string_lossy().into_owned()
    }
}

/// The name with its last run of digits as `*`, if it has one: the step number is the last
/// number in a name (`run2_step_0040.vtp`), and padding widths may differ between steps.
pub fn name_pattern(name: &str) -> String {
    let bytes = name.as_bytes();
    let Some(end) = bytes.iter().rposition(u8::is_ascii_digit) else {
        return name.to_owned();
    };
    let start = bytes[..end]
        .iter()
        .rposition(|c| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    format!("{}*{}", &name[..start], &name[end + 1..])
}

/// A part of a multi-file HDF5 snapshot: `<prefix>.<file number>.<hdf5|h5>` where the prefix
/// ends in the snapshot number (`snap_012.3.hdf5` is file 3 of `snap_012`).
pub fn multi_file_part(name: &str) -> Option<(&str, u64, &str)> {
    let (rest, ext) = name.rsplit_once('.')?;
    if !matches!(ext.to_ascii_lowercase().as_str(), "hdf5" | "h5") {
        return None;
    }
    let (prefix, number) = rest.rsplit_once('.')?;
    if number.is_empty() || !number.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    if !prefix.as_bytes().last()?.is_ascii_digit() {
        return None;
    }
    Some((prefix, number.parse().ok()?, ext))
}

/// Keeps one file of each multi-file snapshot in `files`, the one with the lowest file number
/// (the reader finds the others from its header), and returns the kept files' step names
/// (the snapshot's name without the file number).
pub fn multi_file_sets(files: &mut Vec<(PathBuf, Format)>) -> HashMap<PathBuf, String> {
    let mut lowest: HashMap<(PathBuf, String, String), (u64, PathBuf)> = HashMap::new();
    for (path, format) in files.iter() {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        let Some((prefix, number, ext)) = name
            .as_deref()
            .filter(|_| *format == Format::Hdf5)
            .and_then(multi_file_part)
        else {
            continue;
        };
        let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let key = (dir, prefix.to_owned(), ext.to_owned());
        let entry = lowest.entry(key).or_insert((number, path.clone()));
        if number < entry.0 {
            *entry = (number, path.clone());
        }
    }
    let names: HashMap<PathBuf, String> = lowest
        .into_iter()
        .map(|((_, prefix, _), (_, path))| (path, prefix))
        .collect();
    files.retain(|(path, format)| {
        let part = path
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|_| *format == Format::Hdf5)
            .and_then(multi_file_part)
            .is_some();
        !part || names.contains_key(path)
    });
    names
}

/// The pattern of a file's name: for a multi-file snapshot's file, the snapshot number as `*`
/// (`snap_012.0.hdf5` → `snap_*.0.hdf5`), else [`name_pattern`] of the name before an
/// extension with a digit in it (`.hdf5`, `.h5`: never the step number).
fn step_pattern(name: &str, format: Format) -> String {
    if let Some((prefix, number, ext)) = multi_file_part(name).filter(|_| format == Format::Hdf5) {
        return format!("{}.{number}.{ext}", name_pattern(prefix));
    }
    match name.rsplit_once('.') {
        Some((stem, ext)) if ext.bytes().any(|c| c.is_ascii_digit()) => {
            format!("{}.{ext}", name_pattern(stem))
        }
        _ => name_pattern(name),
    }
}

/// Splits `files` into groups of one name pattern and format, and returns the series (the
/// numbered group with the most steps, then the most bytes) and the groups left out; with no
/// numbered file, `None`: every file together is the series.
pub fn choose_series(files: &[(PathBuf, Format)]) -> Option<(StemGroup, Vec<StemGroup>)> {
    let mut groups: BTreeMap<(String, &str), StemGroup> = BTreeMap::new();
    for (path, format) in files {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let pattern = step_pattern(&name, *format);
        let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
        let group = groups
            .entry((pattern.clone(), format.name()))
            .or_insert_with(|| StemGroup {
                pattern,
                format: *format,
                files: Vec::new(),
                bytes: 0,
            });
        group.files.push(path.clone());
        group.bytes += bytes;
    }
    if groups.len() < 2 || !groups.values().any(StemGroup::numbered) {
        return None;
    }
    let mut groups: Vec<StemGroup> = groups.into_values().collect();
    let best = groups
        .iter()
        .enumerate()
        .filter(|(_, g)| g.numbered())
        .max_by(|(_, a), (_, b)| {
            (a.files.len(), a.bytes)
                .cmp(&(b.files.len(), b.bytes))
                // Equal counts and sizes: the first pattern in name order, whatever the
                // order the folder listed its files in.
                .then_with(|| b.pattern.cmp(&a.pattern))
        })
        .map(|(i, _)| i)
        .expect("a numbered group exists");
    let chosen = groups.remove(best);
    Some((chosen, groups))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_number_is_the_last_number_in_the_name() {
        assert_eq!(name_pattern("fluid_00037.vtp"), "fluid_*.vtp");
        assert_eq!(name_pattern("boundary.vtp"), "boundary.vtp");
        assert_eq!(name_pattern("run2_step_0040.vtp"), "run2_step_*.vtp");
        assert_eq!(name_pattern("12.csv"), "*.csv");
        assert_eq!(name_pattern("snap_012.npy"), "snap_*.npy");
        assert_eq!(name_pattern("ply"), "ply");
        assert_eq!(
            step_pattern("snap_012.3.hdf5", Format::Hdf5),
            "snap_*.3.hdf5"
        );
        assert_eq!(step_pattern("snap_012.hdf5", Format::Hdf5), "snap_*.hdf5");
        assert_eq!(step_pattern("output.h5", Format::Hdf5), "output.h5");
        assert_eq!(step_pattern("out.3.hdf5", Format::Hdf5), "out.*.hdf5");
        assert_eq!(
            step_pattern("snap_012.3.csv", Format::Csv),
            "snap_012.*.csv"
        );
    }

    #[test]
    fn a_multi_file_snapshot_is_one_step_named_by_its_snapshot() {
        assert_eq!(
            multi_file_part("snap_012.10.hdf5"),
            Some(("snap_012", 10, "hdf5"))
        );
        assert_eq!(multi_file_part("snap_012.hdf5"), None);
        assert_eq!(multi_file_part("snap.1.hdf5"), None);
        assert_eq!(multi_file_part("snap_1.x.h5"), None);
        let mut files: Vec<(PathBuf, Format)> = [
            "d/snap_012.1.hdf5",
            "d/snap_012.0.hdf5",
            "d/snap_013.1.hdf5",
            "d/snap_013.2.hdf5",
            "d/other.hdf5",
        ]
        .iter()
        .map(|p| (PathBuf::from(p), Format::Hdf5))
        .collect();
        let names = multi_file_sets(&mut files);
        let kept: Vec<&str> = files.iter().map(|(p, _)| p.to_str().unwrap()).collect();
        assert_eq!(
            kept,
            ["d/snap_012.0.hdf5", "d/snap_013.1.hdf5", "d/other.hdf5"]
        );
        assert_eq!(names[Path::new("d/snap_012.0.hdf5")], "snap_012");
        assert_eq!(names[Path::new("d/snap_013.1.hdf5")], "snap_013");
        assert_eq!(names.len(), 2);
    }

    #[test]
    fn the_group_with_most_steps_wins_and_ties_go_to_more_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, bytes: usize| {
            let p = dir.path().join(name);
            std::fs::write(&p, vec![b'x'; bytes]).unwrap();
            (p, Format::Csv)
        };
        let files = vec![
            write("boundary.csv", 5000),
            write("solid_0.csv", 10),
            write("solid_10.csv", 10),
            write("fluid_0.csv", 20),
            write("fluid_10.csv", 20),
            write("restart_3.csv", 900),
        ];
        let (chosen, left) = choose_series(&files).unwrap();
        assert_eq!(chosen.pattern, "fluid_*.csv");
        assert_eq!(chosen.files.len(), 2);
        let mut left: Vec<_> = left.iter().map(|g| g.pattern.as_str()).collect();
        left.sort();
        assert_eq!(left, ["boundary.csv", "restart_*.csv", "solid_*.csv"]);
        assert!(
            chosen.data_argument().ends_with("fluid_*.csv"),
            "{}",
            chosen.data_argument()
        );
        // No numbered file: the folder is one series, as before.
        assert!(choose_series(&files[..1]).is_none());
        assert!(choose_series(&[files[0].clone(), write("other.csv", 3)]).is_none());
    }
}
