//! `aarbf slice`: the fields on an axis-aligned plane through the data, as an image
//! (colour from Theta, brightness from Phi), the way yt's SlicePlot shows a field.

use std::path::PathBuf;

use clap::Args;
use glam::DVec3;

use crate::field::{Classification, FieldSettings, Particles, RegularGrid, Sample, normalise};
use crate::render::auto::AutoValues;
use crate::render::legend::Legend;
use crate::scene_file::resolve::{DataArgs, FieldOptions, resolve_for_images};
use crate::values::color_space::linear_to_srgb;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Axis {
    X,
    Y,
    Z,
}

/// The arguments of `aarbf slice`: the data and field, the plane (its axis and position) and the
/// output PNG.
#[derive(Debug, Args)]
pub struct SliceArgs {
    /// Where the data comes from (a scene file, or the data path and format), the step, and how
    /// it is read (particle type, units, smoothing, periodic box, cache).
    #[command(flatten)]
    pub data: DataArgs,
    /// How the field is defined: attribute and range, radii, maps, classification, cluster size,
    /// kernel.
    #[command(flatten)]
    pub field: FieldOptions,
    /// The axis normal to the slice.
    #[arg(long, value_enum, default_value = "z")]
    pub axis: Axis,
    /// Where along the axis, as a fraction of the data's bounds (0 to 1).
    #[arg(long, default_value_t = 0.5)]
    pub position: f64,
    /// Image width in pixels (the height follows the data's aspect ratio).
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    /// The density shown at full brightness (1 - exp(-2) of it) and, coloured by density, at
    /// the top of the colour map. Default: the series' automatic value, the one `aarbf
    /// render` and the viewer use for the same field.
    #[arg(long)]
    pub phi_ref: Option<f64>,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    /// Overwrite an existing output.
    #[arg(long)]
    pub force: bool,
    /// Draw the colour legend over the image's bottom-left corner (the attribute and its
    /// range, or the density), and fail where it cannot be drawn. Without --legend or
    /// --no-legend it is drawn on images of at least 120x64 pixels.
    #[arg(long)]
    pub legend: bool,
    /// Draw no colour legend.
    #[arg(long, conflicts_with = "legend")]
    pub no_legend: bool,
}

pub(super) fn run(args: SliceArgs) -> anyhow::Result<()> {
    check_args(&args)?;
    crate::io::output::check_writable(&args.out, args.force)?;
    let resolved = resolve_for_images(&args.data, &args.field)?;
    let step = resolved.series.step(resolved.step)?;
    // In a periodic box the particles near a face are felt across it, through their images,
    // and the slice spans the box.
    let images = match resolved.periodic {
        Some(b) => Some(b.images(&step, &resolved.field, resolved.series_range())?),
        None => None,
    };
    let bounds = resolved.domain();
    // The particles alone: scattering them onto the pixels needs no tree.
    let particles = Particles::prepare(
        images.as_ref().map_or(&*step, |i| &*i.step),
        &resolved.field,
        images
            .as_ref()
            .map_or(bounds, |i| bounds.grown(i.largest_reach)),
        resolved.series_range(),
    )?;
    let (grid, normal) = plane(&args, bounds);
    let [width, height, _] = grid.dims;
    let samples = particles.eval_grid(&grid);

    // Brightness: 1 - exp(-2 Phi / Phi_ref), Phi_ref the series' (as a render of the same
    // field uses), never one of this plane's: slices along other axes and the renders agree.
    let phi_ref = match args.phi_ref {
        Some(p) => p,
        None => AutoValues::of(&resolved.series, &resolved.field)?.phi_ref,
    };
    let range = particles.range;
    let mut image = colour(&samples, &resolved.field, range, phi_ref, width, height);
    let (min_w, min_h) = crate::render::legend::MIN_SIZE;
    if args.legend || (!args.no_legend && width as u32 >= min_w && height as u32 >= min_h) {
        Legend::of_field(
            &resolved.field,
            Some(range),
            resolved.range.label(),
            false,
            phi_ref,
        )
        .draw(&mut image)?;
    }
    crate::io::output::write_atomically(&args.out, args.force, |tmp| {
        image
            .save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })?;
    tracing::info!(
        "slice of step {} ({} particles) at {:?} = {:.4}: {}x{} pixels, Phi_ref {:.4} ({})",
        resolved.step,
        step.len(),
        args.axis,
        grid.origin[normal],
        width,
        height,
        phi_ref,
        if args.phi_ref.is_some() {
            "set"
        } else {
            "automatic, the series'"
        }
    );
    Ok(())
}

/// Checks the flags before the data is opened.
fn check_args(args: &SliceArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.position),
        "--position must lie in [0, 1], got {}",
        args.position
    );
    anyhow::ensure!(
        (1..=16384).contains(&args.width),
        "--width must lie in 1..=16384, got {}",
        args.width
    );
    if let Some(p) = args.phi_ref {
        anyhow::ensure!(
            p.is_finite() && p > 0.0,
            "--phi-ref must be a positive number, got {p}"
        );
    }
    if args.legend {
        let (w, h) = crate::render::legend::MIN_SIZE;
        anyhow::ensure!(
            args.width >= w,
            "--legend needs an image of at least {w}x{h} pixels: --width {} is too narrow",
            args.width
        );
    }
    Ok(())
}

/// The pixel centres of the slice over `bounds`, rows going down while the plane's v axis goes
/// up (the height following the data's aspect ratio), and the axis normal to it.
fn plane(args: &SliceArgs, bounds: crate::values::Bounds) -> (RegularGrid, usize) {
    let (lo, hi) = (bounds.min, bounds.max);
    let (normal, u, v) = match args.axis {
        Axis::X => (0, 2, 1),
        Axis::Y => (1, 0, 2),
        Axis::Z => (2, 0, 1),
    };
    let extent = hi - lo;
    let width = args.width as usize;
    let height =
        ((width as f64 * extent[v] / extent[u].max(1e-30)).round() as usize).clamp(1, 16384);
    // The field is scattered onto the pixel centres (each particle onto the pixels it
    // reaches), not queried pixel by pixel.
    let mut origin = DVec3::ZERO;
    origin[normal] = lo[normal] + args.position * extent[normal];
    origin[u] = lo[u] + 0.5 / width as f64 * extent[u];
    origin[v] = hi[v] - 0.5 / height as f64 * extent[v];
    let grid = RegularGrid {
        origin,
        axes: [u, v, normal],
        spacing: [extent[u] / width as f64, -extent[v] / height as f64, 0.0],
        dims: [width, height, 1],
    };
    (grid, normal)
}

/// The slice's pixels: colour from Theta (or, by density, from Phi), brightness from Phi.
fn colour(
    samples: &[Sample],
    field: &FieldSettings,
    range: (f64, f64),
    phi_ref: f64,
    width: usize,
    height: usize,
) -> image::RgbImage {
    let pre = field.classification == Classification::Pre;
    let mut image = image::RgbImage::new(width as u32, height as u32);
    for (pixel, s) in image.pixels_mut().zip(samples) {
        let alpha = 1.0 - (-2.0 * s.phi / phi_ref).exp();
        let colour = if field.attribute.is_none() {
            field.color_map.linear_rgb((s.phi / phi_ref).min(1.0))
        } else if pre {
            s.theta
        } else {
            field.color_map.linear_rgb(normalise(s.theta[0], range))
        };
        *pixel = image::Rgb(
            colour.map(|c| (linear_to_srgb((c * alpha).clamp(0.0, 1.0)) * 255.0).round() as u8),
        );
    }
    image
}
