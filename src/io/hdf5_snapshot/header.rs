//! A snapshot file's `/Header` (and SWIFT's `/Units` and `/Cosmology`, GADGET-4's, AREPO's
//! and GIZMO's `/Parameters`): particle counts, the number of files, box, time, units.

use ::hdf5::types::{FixedAscii, FixedUnicode, TypeDescriptor, VarLenAscii, VarLenUnicode};
use ::hdf5::{Attribute, File, Group, Location};

use crate::io::{At, DataError};

/// What a snapshot file's header says.
#[derive(Clone, Debug, Default)]
pub struct Header {
    /// The code that wrote the file, when the file names it (SWIFT, GIZMO).
    pub code: Option<String>,
    /// Whether SWIFT wrote the file (its `Code` names SWIFT): its comoving exponents and scale
    /// factor are then read from SWIFT's own attributes.
    pub swift: bool,
    /// Particles of each type in this file.
    pub num_this_file: Vec<u64>,
    /// Particles of each type in the whole snapshot (with `NumPart_Total_HighWord`).
    pub num_total: Vec<u64>,
    /// Files the snapshot is split over (`NumFilesPerSnapshot`; 1 when absent).
    pub num_files: u64,
    /// `BoxSize` on each axis (one value in the file: a cube), in the file's comoving length units;
    /// `None` when absent.
    pub box_size: Option<[f64; 3]>,
    /// Whether the run's box is periodic, and what in the file says so
    /// ([`periodicity`]).
    pub periodic: (bool, &'static str),
    /// `Time` as the header states it (a GADGET cosmological run stores its scale factor there);
    /// `None` when absent.
    pub time: Option<f64>,
    /// `Redshift` as the header states it; `None` when absent.
    pub redshift: Option<f64>,
    /// The scale factor of a cosmological run (`None` otherwise: comoving is physical).
    pub scale_factor: Option<f64>,
    /// Mass of each particle of a type whose particles share one (0: the masses are a dataset).
    pub mass_table: Vec<f64>,
    /// The units, as the file states them (name, value in cgs).
    pub units: Vec<(String, f64)>,
    /// The cosmological parameters the file states (name, value).
    pub cosmology: Vec<(String, String)>,
}

impl Header {
    /// Reads the header of the open snapshot `file` (with its units, cosmology and periodicity); an
    /// error when there is no `/Header` or it lacks `NumPart_ThisFile`.
    pub fn read(at: At<'_>, file: &File) -> Result<Header, DataError> {
        let group = file.group("Header").map_err(|_| {
            at.malformed(
                "no /Header group: not a SWIFT, GADGET, AREPO or GIZMO snapshot (other HDF5 \
                 layouts are not read)",
            )
        })?;
        let counts = |name: &str| -> Result<Vec<u64>, DataError> {
            attr_u64s(&group, name)
                .ok_or_else(|| at.malformed(format!("/Header has no attribute '{name}'")))
        };
        let num_this_file = counts("NumPart_ThisFile")?;
        let mut num_total = attr_u64s(&group, "NumPart_Total").unwrap_or_default();
        if let Some(high) = attr_u64s(&group, "NumPart_Total_HighWord") {
            for (total, high) in num_total.iter_mut().zip(high) {
                *total = total.saturating_add(high.saturating_mul(1 << 32));
            }
        }
        let code = attr_string(&group, "Code")
            .or_else(|| {
                file.group("Code")
                    .ok()
                    .and_then(|c| attr_string(&c, "Code"))
            })
            .or_else(|| attr_string(&group, "GIZMO_version").map(|v| format!("GIZMO {v}")));
        let swift = code.as_deref().is_some_and(|c| c.contains("SWIFT"));
        let cosmology_group = file.group("Cosmology").ok();
        let parameters = file.group("Parameters").ok();
        let time = attr_f64(&group, "Time");
        let redshift = attr_f64(&group, "Redshift");
        let scale_factor = if swift {
            let run = cosmology_group
                .as_ref()
                .and_then(|c| attr_f64(c, "Cosmological run"));
            (run == Some(1.0))
                .then(|| {
                    cosmology_group
                        .as_ref()
                        .and_then(|c| attr_f64(c, "Scale-factor"))
                        .or_else(|| attr_f64(&group, "Scale-factor"))
                })
                .flatten()
        } else {
            gadget_scale_factor(parameters.as_ref(), time, redshift)
        };
        let box_size = attr_f64s(&group, "BoxSize").and_then(|b| match b.as_slice() {
            [side] => Some([*side; 3]),
            [x, y, z] => Some([*x, *y, *z]),
            _ => None,
        });
        Ok(Header {
            periodic: periodicity(file, parameters.as_ref(), box_size),
            swift,
            num_total: if num_total.is_empty() {
                num_this_file.clone()
            } else {
                num_total
            },
            num_this_file,
            num_files: attr_u64s(&group, "NumFilesPerSnapshot")
                .and_then(|v| v.first().copied())
                .unwrap_or(1),
            box_size,
            time,
            redshift,
            scale_factor,
            mass_table: attr_f64s(&group, "MassTable").unwrap_or_default(),
            units: units(file, parameters.as_ref()),
            cosmology: cosmology(&group, cosmology_group.as_ref()),
            code,
        })
    }

    /// Particles of type `t` in this file.
    pub fn this_file(&self, t: usize) -> u64 {
        self.num_this_file.get(t).copied().unwrap_or(0)
    }

    /// The mass every particle of type `t` has, if the mass table gives one.
    pub fn table_mass(&self, t: usize) -> Option<f64> {
        self.mass_table.get(t).copied().filter(|m| *m > 0.0)
    }
}

/// Whether the run's box is periodic, and what says so:
/// - SWIFT: its run-time parameter `InitialConditions:periodic`, which it writes into
///   `/Parameters` (as text, "0" or "1");
/// - GADGET-4 and AREPO: the compile-time options they write as attributes of `/Config`:
///   `PERIODIC` (GADGET-4's switch) makes the box periodic, AREPO's `REFLECTIVE_X`, `_Y` or
///   `_Z` makes it not;
/// - otherwise (GADGET-2/3 and GIZMO write no flag): a positive `BoxSize` is a periodic box,
///   the GADGET family's default for the cosmological volumes such files hold.
pub(super) fn periodicity(
    file: &File,
    parameters: Option<&Group>,
    box_size: Option<[f64; 3]>,
) -> (bool, &'static str) {
    let flag = parameters.and_then(|p| {
        attr_f64(p, "InitialConditions:periodic").or_else(|| {
            attr_string(p, "InitialConditions:periodic").and_then(|t| t.trim().parse().ok())
        })
    });
    if let Some(flag) = flag {
        return (
            flag != 0.0,
            "/Parameters InitialConditions:periodic (SWIFT)",
        );
    }
    if let Ok(config) = file.group("Config") {
        let names = config.attr_names().unwrap_or_default();
        if names.iter().any(|n| n == "PERIODIC") {
            return (true, "/Config PERIODIC");
        }
        if names.iter().any(|n| n.starts_with("REFLECTIVE_")) {
            return (false, "/Config REFLECTIVE_* (reflective faces)");
        }
    }
    match box_size {
        Some(b) if b.iter().all(|s| *s > 0.0) => (
            true,
            "BoxSize in /Header, no flag saying otherwise (GADGET-family boxes are periodic)",
        ),
        _ => (false, "no positive BoxSize in /Header"),
    }
}

/// GADGET-style files store the scale factor as `Time` in cosmological runs; such a run is
/// recognised by `ComovingIntegrationOn` where `/Parameters` has it, else by
/// `Time = 1 / (1 + Redshift)`.
fn gadget_scale_factor(
    parameters: Option<&Group>,
    time: Option<f64>,
    redshift: Option<f64>,
) -> Option<f64> {
    let time = time?;
    let comoving = match parameters.and_then(|p| attr_f64(p, "ComovingIntegrationOn")) {
        Some(flag) => flag != 0.0,
        None => redshift.is_some_and(|z| ((1.0 + z) * time - 1.0).abs() < 1e-4),
    };
    (comoving && time > 0.0).then_some(time)
}

fn units(file: &File, parameters: Option<&Group>) -> Vec<(String, f64)> {
    // SWIFT: a group of its own; GADGET-4, AREPO, GIZMO: `Unit*` among the run's parameters.
    if let Ok(group) = file.group("Units") {
        return numeric_attributes(&group, |_| true);
    }
    parameters.map_or_else(Vec::new, |p| {
        numeric_attributes(p, |name| name.starts_with("Unit"))
    })
}

fn cosmology(header: &Group, cosmology: Option<&Group>) -> Vec<(String, String)> {
    if let Some(group) = cosmology {
        return numeric_attributes(group, |_| true)
            .into_iter()
            .map(|(n, v)| (n, format!("{v}")))
            .collect();
    }
    ["HubbleParam", "Omega0", "OmegaLambda", "OmegaBaryon"]
        .iter()
        .filter_map(|n| attr_f64(header, n).map(|v| ((*n).to_owned(), format!("{v}"))))
        .collect()
}

fn numeric_attributes(location: &Location, keep: impl Fn(&str) -> bool) -> Vec<(String, f64)> {
    location
        .attr_names()
        .unwrap_or_default()
        .into_iter()
        .filter(|n| keep(n))
        .filter_map(|n| attr_f64(location, &n).map(|v| (n, v)))
        .collect()
}

fn attribute(location: &Location, name: &str) -> Option<Attribute> {
    location.attr(name).ok()
}

/// A numeric attribute's values (scalar or array, any integer or float type) as f64.
pub(super) fn attr_f64s(location: &Location, name: &str) -> Option<Vec<f64>> {
    let a = attribute(location, name)?;
    if !matches!(
        a.dtype().ok()?.to_descriptor().ok()?,
        TypeDescriptor::Float(_) | TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_)
    ) {
        return None;
    }
    a.read_raw::<f64>().ok()
}

pub(super) fn attr_f64(location: &Location, name: &str) -> Option<f64> {
    attr_f64s(location, name)?.first().copied()
}

fn attr_u64s(location: &Location, name: &str) -> Option<Vec<u64>> {
    let a = attribute(location, name)?;
    match a.dtype().ok()?.to_descriptor().ok()? {
        TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) => {
            let signed = a.read_raw::<i64>().ok()?;
            Some(signed.into_iter().map(|v| v.max(0) as u64).collect())
        }
        // Some writers store counts as doubles.
        TypeDescriptor::Float(_) => Some(
            a.read_raw::<f64>()
                .ok()?
                .into_iter()
                .map(|v| {
                    if v.is_finite() && v > 0.0 {
                        v as u64
                    } else {
                        0
                    }
                })
                .collect(),
        ),
        _ => None,
    }
}

/// A string attribute, fixed or variable length (h5py writes either, SWIFT fixed).
pub(super) fn attr_string(location: &Location, name: &str) -> Option<String> {
    let a = attribute(location, name)?;
    let text = match a.dtype().ok()?.to_descriptor().ok()? {
        TypeDescriptor::VarLenUnicode => a.read_raw::<VarLenUnicode>().ok()?.first()?.to_string(),
        TypeDescriptor::VarLenAscii => a.read_raw::<VarLenAscii>().ok()?.first()?.to_string(),
        TypeDescriptor::FixedAscii(_) => a.read_raw::<FixedAscii<256>>().ok()?.first()?.to_string(),
        TypeDescriptor::FixedUnicode(_) => {
            a.read_raw::<FixedUnicode<256>>().ok()?.first()?.to_string()
        }
        _ => return None,
    };
    Some(text.trim_end_matches('\0').trim().to_owned())
}
