//! HDF5 snapshots as SWIFT, GADGET-2/3/4, AREPO and GIZMO write them: `/Header` with the
//! particle counts, one group per particle type (`/PartType0` gas .. `/PartType5`), in one
//! file or split over `snap_012.0.hdf5`, `snap_012.1.hdf5`, ... (`NumFilesPerSnapshot`).
//!
//! Every dataset of the chosen type but `Coordinates` is an attribute; a vector dataset gives
//! `_x`, `_y`, `_z` and `_magnitude`. Only the datasets a selection keeps are read: each
//! whole by HDF5 (decompressed chunk by chunk), or a contiguous one directly from the file.
//! Without a `Masses` dataset the mass table gives `Masses`; without a smoothing length
//! (AREPO's cells) `SmoothingLength` is derived from the cell volume m / rho.

mod datasets;
mod header;

use std::path::{Path, PathBuf};

use ::hdf5::{File, Group};

use self::datasets::Column;
pub use self::header::Header;
use super::{At, AttributeSelection, Columns, DataError, Part, ReadOptions};
use crate::values::Attribute;
use glam::DVec3;
use rayon::prelude::*;

/// Neighbours the derived smoothing length's support (2 h) holds: as many cells of volume
/// m / rho as a sphere of radius 2 h has room for.
pub const DERIVED_NEIGHBOURS: f64 = 32.0;

/// The attribute a smoothing length derived from m / rho is called (GADGET's name).
pub const DERIVED_SMOOTHING_LENGTH: &str = "SmoothingLength";

const SMOOTHING_LENGTH_DATASETS: [&str; 2] = ["SmoothingLength", "SmoothingLengths"];
const DENSITY_DATASETS: [&str; 2] = ["Density", "Densities"];
const MASSES: &str = "Masses";
const COORDINATES: &str = "Coordinates";

/// Opens one file of a snapshot, read-only and without HDF5's file lock; the error says
/// whether it is not HDF5 at all. (The lock is what h5py users turn off with
/// `HDF5_USE_FILE_LOCKING=FALSE` on Lustre and NFS, where it fails; a reader gains nothing from
/// it, and it refused a file another thread of the same process had just written and closed.)
fn open(at: At<'_>) -> Result<File, DataError> {
    File::with_options()
        .with_fapl(|fapl| fapl.file_locking(false))
        .open(at.file)
        .map_err(|e| {
            let text = e.to_string();
            if text.contains("signature") {
                at.malformed(format!("not an HDF5 file (no HDF5 signature): {text}"))
            } else {
                at.malformed(format!(
                    "cannot open as HDF5 (truncated or damaged?): {text}"
                ))
            }
        })
}

/// The files of the snapshot whose (first) file is `first`: itself, or for a header that
/// says `NumFilesPerSnapshot` n > 1, `<prefix>.0.<ext>` .. `<prefix>.(n-1).<ext>`, every one
/// of which must exist.
pub fn snapshot_files(at: At<'_>, header: &Header) -> Result<Vec<PathBuf>, DataError> {
    if header.num_files <= 1 {
        return Ok(vec![at.file.to_path_buf()]);
    }
    let name = at
        .file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let Some((prefix, _, ext)) = super::stems::multi_file_part(&name) else {
        return Err(at.malformed(format!(
            "/Header says the snapshot is split over {} files (NumFilesPerSnapshot), but the \
             name is not of the form <name>.<file number>.{{hdf5,h5}}",
            header.num_files
        )));
    };
    let dir = at.file.parent().unwrap_or(Path::new(""));
    // Bounded by the files that exist: a header claiming millions stops at the first gap.
    let mut files = Vec::new();
    for i in 0..header.num_files {
        let part = dir.join(format!("{prefix}.{i}.{ext}"));
        if !part.is_file() {
            return Err(at.malformed(format!(
                "file {i} of the {} files of this snapshot (NumFilesPerSnapshot) is missing: {}",
                header.num_files,
                part.display()
            )));
        }
        files.push(part);
    }
    Ok(files)
}

/// The datasets of one particle type, as the first file that has the type holds them.
struct Catalog {
    group: String,
    columns: Vec<Column>,
    table_mass: Option<f64>,
    derive_smoothing_length: bool,
}

impl Catalog {
    fn of(group_name: &str, group: &Group, header: &Header, t: usize) -> Catalog {
        let mut columns: Vec<Column> = group
            .member_names()
            .unwrap_or_default()
            .into_iter()
            .filter_map(|n| Column::of(&n, &group.dataset(&n).ok()?))
            .collect();
        columns.sort_by(|a, b| super::natural::compare(&a.name, &b.name));
        let has = |names: &[&str]| columns.iter().any(|c| names.contains(&c.name.as_str()));
        let table_mass = (!has(&[MASSES])).then(|| header.table_mass(t)).flatten();
        let derive_smoothing_length = !has(&SMOOTHING_LENGTH_DATASETS)
            && has(&DENSITY_DATASETS)
            && (has(&[MASSES]) || table_mass.is_some());
        Catalog {
            group: group_name.to_owned(),
            columns,
            table_mass,
            derive_smoothing_length,
        }
    }

    fn column(&self, names: &[&str]) -> Option<&Column> {
        self.columns
            .iter()
            .find(|c| names.contains(&c.name.as_str()))
    }

    /// Every attribute the type offers, in order.
    fn attribute_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .columns
            .iter()
            .filter(|c| c.name != COORDINATES)
            .flat_map(|c| super::array_attribute_names(&c.name, c.components))
            .collect();
        if self.table_mass.is_some() {
            names.push(MASSES.to_owned());
        }
        if self.derive_smoothing_length {
            names.push(DERIVED_SMOOTHING_LENGTH.to_owned());
        }
        names
    }
}

/// Reads the chosen particle type of the snapshot whose (first) file `at` names.
///
/// Of that, `part`'s particles of the chosen type, and how many: the type's particles
/// numbered over the snapshot's files in order, each dataset read only over the rows of the
/// files the part spans (a hyperslab, or directly from the file where it is contiguous);
/// the other files have only their header read.
pub(crate) fn read_step(
    at: At<'_>,
    options: &ReadOptions,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let t = options.particle_type.index();
    let group_name = options.particle_type.group();
    let first = open(at)?;
    let header = Header::read(at, &first)?;
    let files = snapshot_files(at, &header)?;
    let total = header.num_total.get(t).copied().unwrap_or(0);
    if total == 0 {
        return Err(at.malformed(format!(
            "the snapshot holds no {} particles (/{group_name}); it holds: {}. Pass \
             --particle-type to choose another",
            options.particle_type,
            type_counts(&header)
        )));
    }
    say_particle_type(options, &header);
    let mut parts = Vec::with_capacity(files.len());
    for (i, path) in files.iter().enumerate() {
        let part_at = At::new(path, at.step);
        let file = if i == 0 {
            first.clone()
        } else {
            open(part_at)?
        };
        let part_header = if i == 0 {
            header.clone()
        } else {
            Header::read(part_at, &file)?
        };
        parts.push((path, file, part_header.this_file(t)));
    }
    let counted: u64 = parts.iter().map(|p| p.2).sum();
    if counted != total {
        return Err(at.malformed(format!(
            "/Header NumPart_Total says {total} {} particles but the files' NumPart_ThisFile \
             add up to {counted}",
            options.particle_type
        )));
    }
    let (catalog_path, catalog_file, _) = parts
        .iter()
        .find(|p| p.2 > 0)
        .expect("a file holds the particles counted");
    let catalog_at = At::new(catalog_path, at.step);
    let group = catalog_file.group(&group_name).map_err(|_| {
        catalog_at.malformed(format!(
            "no /{group_name} group, though /Header counts its particles"
        ))
    })?;
    let catalog = Catalog::of(&group_name, &group, &header, t);
    let coordinates = catalog
        .column(&[COORDINATES])
        .ok_or_else(|| catalog_at.malformed(format!("/{group_name} has no Coordinates dataset")))?;
    if coordinates.components != 3 {
        return Err(catalog_at.malformed(format!(
            "dataset '/{group_name}/Coordinates' is {} x {}; expected N x 3",
            coordinates.rows, coordinates.components
        )));
    }
    let physical = Scaling::new(&header, options.physical);
    // Each file's rows of the part (in the file's own numbering).
    let wanted = part.range(total as usize);
    let mut first_row = 0;
    let spans: Vec<std::ops::Range<usize>> = parts
        .iter()
        .map(|p| {
            let rows = first_row..first_row + p.2 as usize;
            first_row = rows.end;
            let (start, end) = (wanted.start.max(rows.start), wanted.end.min(rows.end));
            if start < end {
                start - rows.start..end - rows.start
            } else {
                0..0
            }
        })
        .collect();
    let read = |column: &Column| -> Result<Values, DataError> {
        // One array for the part, each file's rows read into their place in it.
        let mut values = datasets::fresh::<f64>(wanted.len() * column.components);
        let mut finite = true;
        let mut offset = 0;
        for ((path, file, count), rows) in parts.iter().zip(&spans) {
            if !rows.is_empty() {
                let len = rows.len() * column.components;
                let out = &mut values[offset..offset + len];
                let file_at = At::new(path, at.step);
                finite &= read_rows(file_at, file, &catalog, column, *count, rows, out)?;
                offset += len;
            }
        }
        let factor = physical.factor(&group, column)?;
        if factor != 1.0 {
            // Finite values times a finite factor can overflow: checked again as scaled.
            finite = values
                .par_chunks_mut(super::FINITE_BLOCK)
                .map(|block| {
                    block.iter_mut().fold(true, |all, v| {
                        *v *= factor;
                        all & v.is_finite()
                    })
                })
                .reduce(|| true, |a, b| a & b);
        }
        Ok((values, finite))
    };
    // N x 3 doubles are N points as they lie in memory: the array becomes the positions
    // without a copy.
    let (coordinates, positions_finite) = read(coordinates)?;
    let positions: Vec<DVec3> =
        bytemuck::allocation::try_cast_vec(coordinates).unwrap_or_else(|(_, values)| {
            values
                .par_chunks_exact(3)
                .map(|p| DVec3::new(p[0], p[1], p[2]))
                .collect()
        });
    let (attributes, attributes_finite) =
        read_attributes(at, &catalog, selection, positions.len(), &read)?;
    let skipped = catalog
        .attribute_names()
        .into_iter()
        .filter(|n| !attributes.iter().any(|a| &a.name == n))
        .collect();
    let columns = Columns {
        positions,
        attributes,
        skipped,
        finite: positions_finite && attributes_finite,
    };
    Ok((columns, wanted.len()))
}

/// A dataset's values, and whether every one is finite.
type Values = (Vec<f64>, bool);

/// The attributes `selection` keeps: datasets split into components, the mass table's
/// masses and the derived smoothing length; and whether every value of them is finite.
fn read_attributes(
    at: At<'_>,
    catalog: &Catalog,
    selection: &AttributeSelection,
    n: usize,
    read: &dyn Fn(&Column) -> Result<Values, DataError>,
) -> Result<(Vec<Attribute>, bool), DataError> {
    let mut attributes = Vec::new();
    let mut finite = true;
    for column in catalog.columns.iter().filter(|c| c.name != COORDINATES) {
        let names = super::array_attribute_names(&column.name, column.components);
        if names.iter().any(|n| selection.keeps(n)) {
            let (values, values_finite) = read(column)?;
            if column.components == 1 {
                // A scalar's array is the attribute as read: no copy.
                finite &= values_finite;
                attributes.push(Attribute {
                    name: column.name.clone(),
                    values,
                });
            } else {
                // (A magnitude of finite components can overflow: those are checked.)
                let split = super::split_components(&column.name, &values, column.components);
                finite &= split.iter().all(|a| super::all_finite(&a.values));
                attributes.extend(split);
            }
        }
    }
    if let Some(mass) = catalog.table_mass.filter(|_| selection.keeps(MASSES)) {
        finite &= mass.is_finite();
        attributes.push(Attribute {
            name: MASSES.to_owned(),
            values: vec![mass; n],
        });
    }
    if catalog.derive_smoothing_length && selection.keeps(DERIVED_SMOOTHING_LENGTH) {
        let density = catalog
            .column(&DENSITY_DATASETS)
            .expect("checked in the catalog");
        let (rho, _) = read(density)?;
        let masses = match catalog.column(&[MASSES]) {
            Some(m) => read(m)?.0,
            None => vec![catalog.table_mass.expect("checked in the catalog"); n],
        };
        tracing::info!(
            "{}: no smoothing length in /{}: '{DERIVED_SMOOTHING_LENGTH}' is derived from the \
             cell volume m / rho, its support 2h holding about {DERIVED_NEIGHBOURS} cells",
            at.location(),
            catalog.group
        );
        let values: Vec<f64> = masses
            .iter()
            .zip(&rho)
            .map(|(m, rho)| derived_smoothing_length(*m, *rho))
            .collect();
        finite &= super::all_finite(&values);
        attributes.push(Attribute {
            name: DERIVED_SMOOTHING_LENGTH.to_owned(),
            values,
        });
    }
    Ok((attributes, finite))
}

/// h such that a sphere of radius 2 h holds [`DERIVED_NEIGHBOURS`] cells of volume m / rho:
/// (4/3) pi (2h)^3 = N m / rho.
pub fn derived_smoothing_length(mass: f64, density: f64) -> f64 {
    0.5 * (DERIVED_NEIGHBOURS * 3.0 * mass / (4.0 * std::f64::consts::PI * density)).cbrt()
}

/// The rows `rows` of one file's `column` into `out`, the dataset checked against the file's
/// own header count; whether every value is finite.
fn read_rows(
    at: At<'_>,
    file: &File,
    catalog: &Catalog,
    column: &Column,
    count: u64,
    rows: &std::ops::Range<usize>,
    out: &mut [f64],
) -> Result<bool, DataError> {
    let path = format!("{}/{}", catalog.group, column.name);
    let dataset = file
        .dataset(&path)
        .map_err(|_| at.malformed(format!("no dataset '/{path}' in this file of the snapshot")))?;
    let here = Column::of(&column.name, &dataset).ok_or_else(|| {
        at.malformed(format!(
            "dataset '/{path}' is not a numeric N or N x k array"
        ))
    })?;
    if here.components != column.components {
        return Err(at.malformed(format!(
            "dataset '/{path}' has {} components here but {} in the snapshot's first file",
            here.components, column.components
        )));
    }
    if here.rows as u64 != count {
        return Err(at.malformed(format!(
            "dataset '/{path}' has {} rows but /Header NumPart_ThisFile says {count}",
            here.rows
        )));
    }
    here.read_into(at, &catalog.group, &dataset, rows.clone(), out)
}

/// Comoving to physical: each dataset times a^exponent (SWIFT states the exponent on every
/// dataset; GADGET-style files follow the GADGET convention for the datasets named here).
struct Scaling {
    scale_factor: Option<f64>,
    swift: bool,
}

impl Scaling {
    fn new(header: &Header, physical: bool) -> Scaling {
        if physical && header.scale_factor.is_none() {
            tracing::info!("--physical: not a cosmological run, comoving units are physical");
        }
        Scaling {
            scale_factor: header.scale_factor.filter(|_| physical),
            swift: header.swift,
        }
    }

    fn factor(&self, group: &Group, column: &Column) -> Result<f64, DataError> {
        let Some(a) = self.scale_factor else {
            return Ok(1.0);
        };
        let exponent = if self.swift {
            group
                .dataset(&column.name)
                .ok()
                .and_then(|d| header::attr_f64(&d, "a-scale exponent"))
        } else {
            gadget_exponent(&column.name)
        };
        Ok(exponent.map_or(1.0, |e| a.powf(e)))
    }
}

/// GADGET's comoving conventions: x_phys = a x, h_phys = a h, rho_phys = rho / a^3, and
/// velocities stored as v / sqrt(a).
fn gadget_exponent(dataset: &str) -> Option<f64> {
    match dataset {
        "Coordinates" | "SmoothingLength" => Some(1.0),
        "Density" => Some(-3.0),
        "Velocities" => Some(0.5),
        _ => None,
    }
}

/// Says once per process which particle type is read and which the snapshot holds (a default a
/// user of a multi-type snapshot must see: gas unless `--particle-type` says otherwise).
fn say_particle_type(options: &ReadOptions, header: &Header) {
    static SAID: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if !SAID.swap(true, std::sync::atomic::Ordering::Relaxed) {
        tracing::info!(
            "particles: {} (/{}); the snapshot holds {} (--particle-type NAME or 0..5 reads \
             another)",
            options.particle_type,
            options.particle_type.group(),
            type_counts(header)
        );
    }
}

fn type_counts(header: &Header) -> String {
    let held: Vec<String> = header
        .num_total
        .iter()
        .enumerate()
        .filter(|(_, n)| **n > 0)
        .map(|(i, n)| match super::ParticleType::NAMES.get(i) {
            Some(name) => format!("{n} {name} (type {i})"),
            None => format!("{n} of type {i}"),
        })
        .collect();
    if held.is_empty() {
        "no particles".into()
    } else {
        held.join(", ")
    }
}

/// The simulation box the snapshot's header states (`BoxSize`, scaled by the scale factor
/// under `--physical`) and whether it is periodic; `None` without a `BoxSize`.
pub fn simulation_box(
    path: &Path,
    read: &ReadOptions,
) -> Result<Option<super::SimulationBox>, DataError> {
    let at = At::new(path, None);
    let header = Header::read(at, &open(at)?)?;
    let Some(size) = header.box_size else {
        return Ok(None);
    };
    let scale = header.scale_factor.filter(|_| read.physical).unwrap_or(1.0);
    let (periodic, because) = header.periodic;
    Ok(Some(super::SimulationBox {
        size: size.map(|s| s * scale),
        periodic,
        because: because.to_owned(),
    }))
}

/// The snapshot's `/Header` `Time`, if it can be read.
pub fn time(path: &Path) -> Option<f64> {
    let at = At::new(path, None);
    Header::read(at, &open(at).ok()?).ok()?.time
}

/// What `aarbf info` says of a snapshot: its code, time, box, units and particle types with
/// their counts and the datasets that can be attributes.
pub fn describe(path: &Path) -> Result<String, DataError> {
    use std::fmt::Write;
    let at = At::new(path, None);
    let file = open(at)?;
    let header = Header::read(at, &file)?;
    let mut out = String::new();
    let opt = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v}"));
    let _ = writeln!(out, "snapshot:");
    let _ = writeln!(
        out,
        "  code:         {}",
        header
            .code
            .as_deref()
            .unwrap_or("GADGET-style (the file does not name its code)")
    );
    let _ = writeln!(out, "  files:        {}", header.num_files);
    let _ = writeln!(out, "  time:         {}", opt(header.time));
    let _ = writeln!(out, "  redshift:     {}", opt(header.redshift));
    let _ = writeln!(
        out,
        "  scale factor: {}",
        header
            .scale_factor
            .map_or("- (not a cosmological run)".to_owned(), |a| format!(
                "{a} (positions are comoving; --physical scales them by a)"
            ))
    );
    let _ = writeln!(
        out,
        "  box size:     {}",
        header.box_size.map_or("-".to_owned(), |b| format!(
            "{} x {} x {}",
            b[0], b[1], b[2]
        ))
    );
    let _ = writeln!(
        out,
        "  periodic:     {} ({}; --periodic or --no-periodic overrides)",
        if header.periodic.0 { "yes" } else { "no" },
        header.periodic.1
    );
    for (name, value) in &header.units {
        let _ = writeln!(out, "  unit:         {name} = {value:e}");
    }
    for (name, value) in &header.cosmology {
        let _ = writeln!(out, "  cosmology:    {name} = {value}");
    }
    let _ = writeln!(out, "  particle types (--particle-type):");
    for (t, total) in header.num_total.iter().enumerate() {
        let label = super::ParticleType::NAMES
            .get(t)
            .map_or(format!("type {t}"), |n| format!("{t} {n}"));
        let group_name = format!("PartType{t}");
        let names = match file.group(&group_name) {
            Ok(group) => Catalog::of(&group_name, &group, &header, t)
                .attribute_names()
                .join(", "),
            Err(_) => "-".to_owned(),
        };
        let _ = writeln!(out, "    {label:<10} {total:>12}  {names}");
    }
    Ok(out)
}
