//! The global radius when none is given, from the data's smoothing lengths or spacing.

use super::DataReads;
use super::first_step::FirstStep;
use crate::field::Kernel;
use crate::scene::TimeSeries;
use crate::scene_file::RadiusSpec;

/// The default global radius over the particles' spacing: twice the median nearest-neighbour
/// distance joins neighbours (the particle's Gaussian then has a standard deviation of 2/3 of
/// the spacing), as SPH users expect of a kernel.
pub const RADIUS_PER_SPACING: f64 = 2.0;

/// The default global radius with a per-particle smoothing length h: radius 2 h, the support
/// of the cubic-spline SPH kernel as SWIFT and sarracen define h.
pub const RADIUS_PER_SMOOTHING_LENGTH: f64 = 2.0;

/// The global radius when none is given, derived from the data as the other automatic values
/// are, from the series' first step (so every step and command agrees), with a sentence saying
/// how (for the log and `aarbf info`). `first` is that step as the defaults see it (to find a
/// smoothing length the field does not use), `reads` how the particles' spacing is measured.
pub fn default_radius(
    series: &TimeSeries,
    radius_attribute: Option<&str>,
    first: Option<&FirstStep>,
    kernel: Kernel,
    reads: &dyn DataReads,
) -> anyhow::Result<(f64, String)> {
    if let Some(h) = radius_attribute {
        if kernel.is_sph() {
            let s = kernel.support();
            return Ok((
                s,
                format!(
                    "{s} x '{h}' for each particle (the {kernel} kernel's support, {s}h; \
                     --radius scales it, and h with it)"
                ),
            ));
        }
        return Ok((
            RADIUS_PER_SMOOTHING_LENGTH,
            format!(
                "{RADIUS_PER_SMOOTHING_LENGTH} x '{h}' for each particle (the SPH kernel's \
                 support, 2h; --radius sets the factor)"
            ),
        ));
    }
    // A smoothing length in the data: its median sets the radius (2h, the kernel's support).
    if let Some((name, Some(median))) = first.and_then(FirstStep::smoothing_length) {
        let r = RADIUS_PER_SMOOTHING_LENGTH * median;
        return Ok((
            r,
            format!(
                "{r:.6e}, {RADIUS_PER_SMOOTHING_LENGTH} x the median smoothing length \
                 '{name}' in step 0 ({median:.6e}); --radius-attribute {name} gives each \
                 particle its own, --radius sets a length or a percentage of the diagonal \
                 (\"1.5%\")"
            ),
        ));
    }
    let spacing = if series.is_empty() {
        None
    } else {
        reads.first_step_spacing(series)?
    };
    Ok(match spacing {
        Some(d) => {
            let r = RADIUS_PER_SPACING * d;
            (
                r,
                format!(
                    "{r:.6e}, {RADIUS_PER_SPACING} x the particles' spacing in step 0 (median \
                     nearest-neighbour distance {d:.6e}); --radius sets a length or a \
                     percentage of the diagonal (\"1.5%\")"
                ),
            )
        }
        None => {
            let r = RadiusSpec::DEFAULT.resolve(series.bounds().diagonal());
            (
                r,
                format!(
                    "{r:.6e}, {} of the bounding-box diagonal (step 0 has no two particles \
                     apart to measure a spacing); --radius sets it",
                    RadiusSpec::DEFAULT
                ),
            )
        }
    })
}
