//! ParaView's `.pvd` collections: an XML list of data set files, each with its time.
//!
//! ```xml
//! <VTKFile type="Collection" version="0.1">
//!   <Collection>
//!     <DataSet timestep="0.5" group="" part="0" file="run/fluid_0000.vtu"/>
//!   </Collection>
//! </VTKFile>
//! ```
//!
//! Each `DataSet` is a step, in the order of its `timestep` (the file's order among equal
//! times); a relative `file` is resolved against the `.pvd`'s folder. A collection of several
//! parts per time (ParaView's multi-block output) is refused: the parts would have to be
//! merged into one step.

use std::path::{Path, PathBuf};

use quick_xml::events::{BytesStart, Event};

use super::{At, DataError, Format, Problem, ReadOptions, StepRef};

/// One `DataSet` entry: its file as written, and its time (`None` without `timestep`).
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The `file` attribute as written (a relative path is resolved against the `.pvd`'s folder).
    pub file: String,
    /// The `timestep` attribute (`None` without one).
    pub time: Option<f64>,
    /// The `part` attribute (`None` without one); a collection with more than one part per time is
    /// refused.
    pub part: Option<String>,
}

/// The entries of a collection's text, in time order; an error says what is wrong in it.
pub fn parse(text: &[u8]) -> Result<Vec<Entry>, String> {
    let mut xml = quick_xml::Reader::from_reader(text);
    let mut buffer = Vec::new();
    let mut entries = Vec::new();
    let mut collection = false;
    loop {
        let event = xml
            .read_event_into(&mut buffer)
            .map_err(|e| format!("not well-formed XML at byte {}: {e}", xml.buffer_position()))?;
        match event {
            Event::Eof => break,
            Event::Start(e) | Event::Empty(e) => match e.name().as_ref() {
                b"VTKFile" => {
                    let kind = attribute(&e, b"type")?;
                    if kind.as_deref() != Some("Collection") {
                        return Err(format!(
                            "a VTKFile of type '{}', not a Collection",
                            kind.unwrap_or_default()
                        ));
                    }
                    collection = true;
                }
                b"DataSet" => entries.push(entry(&e)?),
                _ => {}
            },
            _ => {}
        }
        buffer.clear();
    }
    if !collection {
        return Err("no <VTKFile type=\"Collection\"> element".into());
    }
    if entries.is_empty() {
        return Err("the collection lists no DataSet".into());
    }
    let mut parts: Vec<&str> = entries.iter().filter_map(|e| e.part.as_deref()).collect();
    parts.sort_unstable();
    parts.dedup();
    if parts.len() > 1 {
        return Err(format!(
            "the collection has {} parts per time step (part=\"{}\", ...); multi-part \
             collections are not read: name one part's files instead",
            parts.len(),
            parts[1]
        ));
    }
    // Stable: equal times keep the file's order.
    entries.sort_by(|a, b| match (a.time, b.time) {
        (Some(a), Some(b)) => a.total_cmp(&b),
        _ => std::cmp::Ordering::Equal,
    });
    Ok(entries)
}

fn attribute(e: &BytesStart<'_>, key: &[u8]) -> Result<Option<String>, String> {
    for a in e.attributes() {
        let a = a.map_err(|err| format!("a malformed attribute: {err}"))?;
        if a.key.as_ref() == key {
            let value = a
                .unescape_value()
                .map_err(|err| format!("a malformed attribute value: {err}"))?;
            return Ok(Some(value.into_owned()));
        }
    }
    Ok(None)
}

fn entry(e: &BytesStart<'_>) -> Result<Entry, String> {
    let file = attribute(e, b"file")?.ok_or("a DataSet without a file attribute")?;
    if file.trim().is_empty() {
        return Err("a DataSet with an empty file attribute".into());
    }
    let time = match attribute(e, b"timestep")? {
        Some(t) => {
            let value: f64 = t
                .trim()
                .parse()
                .map_err(|_| format!("DataSet '{file}': timestep '{t}' is not a number"))?;
            if !value.is_finite() {
                return Err(format!("DataSet '{file}': timestep '{t}' is not finite"));
            }
            Some(value)
        }
        None => None,
    };
    Ok(Entry {
        file,
        time,
        part: attribute(e, b"part")?,
    })
}

/// The files and times of the collection at `path`, each file resolved against the
/// collection's folder and checked to exist.
pub fn read(path: &Path) -> Result<Vec<(PathBuf, Option<f64>)>, DataError> {
    let at = At::new(path, None);
    let text = std::fs::read(path).map_err(|e| at.io(e))?;
    let entries = parse(&text).map_err(|e| at.malformed(e))?;
    let dir = path.parent().unwrap_or(Path::new(""));
    entries
        .into_iter()
        .map(|e| {
            let file = dir.join(&e.file);
            if !file.is_file() {
                return Err(at.malformed(format!(
                    "the DataSet file '{}'{} does not exist ({})",
                    e.file,
                    e.time.map_or(String::new(), |t| format!(" (timestep {t})")),
                    file.display()
                )));
            }
            Ok((file, e.time))
        })
        .collect()
}

/// Whether `path` names a collection (by its extension).
pub fn is_collection(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pvd"))
}

/// The steps of the collection at `path`: each entry's file, its format from its extension
/// (or `format`), its time.
pub fn steps(
    path: &Path,
    format: Option<Format>,
    read_options: ReadOptions,
) -> Result<Vec<StepRef>, DataError> {
    let at = At::new(path, None);
    read(path)?
        .into_iter()
        .map(|(file, time)| {
            let format = format.or_else(|| Format::from_path(&file)).ok_or_else(|| {
                at.err(Problem::UnknownFormat(format!(
                    "cannot tell the format of the DataSet file {} from its extension; pass \
                     --format",
                    file.display()
                )))
            })?;
            Ok(StepRef {
                name: file
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                path: file,
                format,
                read: read_options,
                time,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_in_time_order_and_errors_in_words() {
        let text = br#"<?xml version="1.0"?>
<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">
  <Collection>
    <DataSet timestep="2.5" group="" part="0" file="b/step_1.vtu"/>
    <DataSet timestep="0" group="" part="0" file="a &amp; b.vtp"/>
  </Collection>
</VTKFile>"#;
        let entries = parse(text).unwrap();
        assert_eq!(entries[0].file, "a & b.vtp");
        assert_eq!(entries[0].time, Some(0.0));
        assert_eq!(entries[1].time, Some(2.5));
        let cases: [(&[u8], &str); 6] = [
            (b"<VTKFile type=\"PolyData\"/>", "not a Collection"),
            (b"<VTKFile type=\"Collection\"><Collection/></VTKFile>", "no DataSet"),
            (b"<Collection><DataSet file=\"x.vtu\"/></Collection>", "no <VTKFile"),
            (
                b"<VTKFile type=\"Collection\"><DataSet timestep=\"soon\" file=\"x.vtu\"/></VTKFile>",
                "timestep 'soon' is not a number",
            ),
            (b"<VTKFile type=\"Collection\"><DataSet timestep=\"1\"/></VTKFile>", "without a file"),
            (
                b"<VTKFile type=\"Collection\"><DataSet part=\"0\" file=\"a\"/><DataSet part=\"1\" file=\"b\"/></VTKFile>",
                "2 parts per time step",
            ),
        ];
        for (text, expected) in cases {
            let e = parse(text).unwrap_err();
            assert!(e.contains(expected), "{e}");
        }
    }
}
