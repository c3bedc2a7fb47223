//! The particle file formats: their names on the command line and in scene files, and the
//! extensions that tell them apart.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The particle file formats we read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// The AA-RBF sample code's header + binary step files (x, y, z, attribute as f32).
    Particles,
    /// VTK XML poly data / unstructured grid (`.vtp`, `.vtu`, also `.vts`).
    VtkXml,
    /// Legacy VTK (`.vtk`).
    Vtk,
    /// Comma-separated values with a header row.
    Csv,
    /// Stanford PLY, ascii or binary, vertex element.
    Ply,
    /// Knoll et al.'s raw f32 x, y, z, w records.
    Raw,
    /// NumPy `.npy`, an N x (3 + k) array.
    Npy,
    /// HDF5 snapshots of SWIFT, GADGET-2/3/4, AREPO and GIZMO (`.hdf5`, `.h5`), one file or
    /// several per step.
    Hdf5,
}

impl Format {
    /// Every format, in the order messages list them.
    pub const ALL: [Format; 8] = [
        Format::Particles,
        Format::VtkXml,
        Format::Vtk,
        Format::Csv,
        Format::Ply,
        Format::Raw,
        Format::Npy,
        Format::Hdf5,
    ];

    /// The format a file's extension names, if any.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "particles" => Format::Particles,
            "vtp" | "vtu" | "vts" => Format::VtkXml,
            "vtk" => Format::Vtk,
            "csv" => Format::Csv,
            "ply" => Format::Ply,
            "raw" => Format::Raw,
            "npy" => Format::Npy,
            "hdf5" | "h5" => Format::Hdf5,
            _ => return None,
        })
    }

    /// The extension a file of this format is written with (and a temporary copy is read with).
    pub fn extension(self) -> &'static str {
        match self {
            Format::VtkXml => "vtp",
            other => other.name(),
        }
    }

    /// The format's name as `--format` takes it and messages print it (`particles`, `vtk-xml`,
    /// `vtk`, `csv`, `ply`, `raw`, `npy`, `hdf5`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Particles => "particles",
            Format::VtkXml => "vtk-xml",
            Format::Vtk => "vtk",
            Format::Csv => "csv",
            Format::Ply => "ply",
            Format::Raw => "raw",
            Format::Npy => "npy",
            Format::Hdf5 => "hdf5",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let lower = s.to_ascii_lowercase();
        Format::ALL
            .into_iter()
            .find(|f| f.name() == lower)
            .or(match lower.as_str() {
                "vtp" | "vtu" | "xml" => Some(Format::VtkXml),
                "h5" => Some(Format::Hdf5),
                _ => None,
            })
            .ok_or_else(|| {
                let names: Vec<_> = Format::ALL.iter().map(|f| f.name()).collect();
                format!("unknown format '{s}'; known: {}", names.join(", "))
            })
    }
}
