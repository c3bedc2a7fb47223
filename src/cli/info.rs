//! `aarbf info`: what a data set holds.

use std::path::PathBuf;

use clap::Args;

use crate::io::{Format, ParticleType, ReadOptions};
use crate::scene::{OpenOptions, TimeSeries};

/// The arguments of `aarbf info`: the data to describe (or `--devices`) and how to read it.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The data: a file, a directory or a glob.
    #[arg(required_unless_present = "devices")]
    pub data: Option<PathBuf>,
    /// List the GPU adapters wgpu finds (every backend it was built with) and their features.
    #[arg(long)]
    pub devices: bool,
    /// The file format, when the extension does not tell.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// The particle type of an HDF5 snapshot described: 0..5 or gas, dm, disk, bulge, stars,
    /// bh (default gas).
    #[arg(long, value_name = "TYPE")]
    pub particle_type: Option<ParticleType>,
    /// An HDF5 snapshot's comoving quantities in physical units.
    #[arg(long)]
    pub physical: bool,
}

pub(super) fn run(args: InfoArgs) -> anyhow::Result<()> {
    if args.devices {
        print!("{}", devices());
    }
    let Some(data) = &args.data else {
        return Ok(());
    };
    let read = ReadOptions {
        particle_type: args.particle_type.unwrap_or_default(),
        physical: args.physical,
    };
    // A snapshot's header first: it says which particle types there are, should the one
    // asked for be absent.
    let steps = crate::io::list_steps_reading(data, args.format, read)?;
    if let Some(first) = steps.first().filter(|s| s.format == Format::Hdf5) {
        print!("{}", snapshot(first)?);
    }
    let series = TimeSeries::open(
        data,
        &OpenOptions {
            format: args.format,
            read,
            ..OpenOptions::default()
        },
    )?;
    print!("{}", describe(data, &series));
    print!("{}", defaults(&series)?);
    Ok(())
}

#[cfg(feature = "hdf5")]
fn snapshot(first: &crate::io::StepRef) -> anyhow::Result<String> {
    Ok(crate::io::hdf5_snapshot::describe(&first.path)?)
}

#[cfg(not(feature = "hdf5"))]
fn snapshot(_first: &crate::io::StepRef) -> anyhow::Result<String> {
    Ok(String::new())
}

/// The adapters wgpu finds, with their features and the limits the backends depend on.
pub(super) fn devices() -> String {
    use std::fmt::Write;
    let adapters = crate::backend::wgpu_lbvh::adapters();
    let mut out = String::new();
    if adapters.is_empty() {
        let _ = writeln!(
            out,
            "no wgpu adapter found (`cargo xtask setup` installs Mesa lavapipe); the cpu backend works anywhere"
        );
    }
    for (i, a) in adapters.iter().enumerate() {
        let info = &a.info;
        let _ = writeln!(out, "adapter {i}: {}", info.name);
        let _ = writeln!(
            out,
            "  backend {:?}, type {:?}, driver {} {}",
            info.backend, info.device_type, info.driver, info.driver_info
        );
        let _ = writeln!(
            out,
            "  limits: storage binding {}, {} storage buffers per stage, buffer {}, workgroup \
             storage {} B, invocations {}",
            mib(a.limits.max_storage_buffer_binding_size as usize),
            a.limits.max_storage_buffers_per_shader_stage,
            mib(a.limits.max_buffer_size as usize),
            a.limits.max_compute_workgroup_storage_size,
            a.limits.max_compute_invocations_per_workgroup
        );
        let names: Vec<&str> = a.features.iter_names().map(|(n, _)| n).collect();
        let _ = writeln!(out, "  features ({}):", names.len());
        for chunk in names.chunks(3) {
            let _ = writeln!(out, "    {}", chunk.join(", "));
        }
    }
    let _ = writeln!(
        out,
        "the wgpu backend uses: {}",
        crate::backend::wgpu_lbvh::GpuContext::shared()
            .map(|c| c.describe())
            .unwrap_or_else(|e| e.to_string())
    );
    out
}

/// What `render`, `slice` and `view` choose for this data when not told.
fn defaults(series: &TimeSeries) -> anyhow::Result<String> {
    use std::fmt::Write;
    let first = series.first_step_in_full()?;
    let (_, radius) = crate::scene_file::resolve::default_radius(
        series,
        None,
        first
            .map(crate::scene_file::resolve::FirstStep::Whole)
            .as_ref(),
        crate::field::Kernel::GaussianRbf,
        &crate::scene_file::resolve::InOneProcess,
    )?;
    let camera = crate::scene::Camera::default_for(series.bounds());
    let mut out = String::new();
    let _ = writeln!(out, "defaults (render, slice, view):");
    let _ = writeln!(
        out,
        "  colour:   by density; --attribute NAME colours by one of the attributes above"
    );
    let _ = writeln!(out, "  radius:   {radius}");
    let _ = writeln!(
        out,
        "  up axis:  {} (--up x|y|z|-x|-y|-z)",
        crate::scene::UpAxis::along(camera.up).map_or("?".into(), |a| a.to_string())
    );
    Ok(out)
}

fn mib(bytes: usize) -> String {
    format!("{:.2} MiB", bytes as f64 / (1 << 20) as f64)
}

pub(super) fn describe(path: &std::path::Path, series: &TimeSeries) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let b = series.bounds();
    let _ = writeln!(out, "data:       {}", path.display());
    let _ = writeln!(out, "steps:      {}", series.len());
    let _ = writeln!(out, "particles:  {} at most per step", series.max_count());
    let _ = writeln!(
        out,
        "bounds:     [{}, {}, {}] .. [{}, {}, {}] (diagonal {:.6})",
        b.min.x,
        b.min.y,
        b.min.z,
        b.max.x,
        b.max.y,
        b.max.z,
        b.diagonal()
    );
    let _ = writeln!(out, "attributes:");
    if series.attributes().is_empty() {
        let _ = writeln!(out, "  (none)");
    }
    for a in series.attributes() {
        let _ = writeln!(out, "  {:<24} {} .. {}", a.name, a.min, a.max);
    }
    let _ = writeln!(out, "steps:");
    let _ = writeln!(
        out,
        "  {:>5}  {:<20} {:>12} {:>12}",
        "index", "name", "particles", "memory"
    );
    for (i, s) in series.steps().iter().enumerate() {
        let _ = writeln!(
            out,
            "  {:>5}  {:<20} {:>12} {:>12}",
            i,
            s.name,
            s.count,
            mib(s.bytes)
        );
    }
    out
}
