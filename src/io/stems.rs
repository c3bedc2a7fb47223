//! Which files of a folder (or glob) are one time series.
//!
//! Simulation codes write more than their steps into an output folder: boundary or wall
//! particles (`boundary.vtp` beside PySPH's `fluid_00000.vtp …`), initial conditions, restart
//! snapshots, other species. Files are grouped by their name with the step number taken out
//! (`fluid_00037.vtp` → `fluid_*.vtp`); the group with the most steps is the series, ties going
//! to the group holding more bytes (more particles). Files with no number in their name form a
//! series only when no file has one, as a folder of `early.csv`, `late.csv` does.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::Format;

/// Files of one name pattern, in one format.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StemGroup {
    /// The file name with its step number as `*` (`fluid_*.vtp`), or the name itself when it
    /// has no number: a glob that selects this group alone within its folder.
    pub pattern: String,
    pub format: Format,
    pub files: Vec<PathBuf>,
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
        let pattern = name_pattern(&name);
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
