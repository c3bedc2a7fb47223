//! Which periodic box, if any, a command's field wraps at: `--periodic`, `--periodic L`,
//! `--periodic LX,LY,LZ`, `--no-periodic`, or by default the box an HDF5 snapshot's header
//! states when it says its run is periodic.

use anyhow::bail;
use serde::{Deserialize, Serialize};

use crate::field::PeriodicBox;
use crate::scene::TimeSeries;

/// What `--periodic` asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PeriodicSpec {
    /// `--periodic` alone: the box the snapshot's header states, periodic whatever its flags.
    FromHeader,
    /// `--periodic L` or `LX,LY,LZ`: the box `[0, L)` on each axis.
    Box([f64; 3]),
}

impl std::str::FromStr for PeriodicSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<PeriodicSpec, String> {
        if text == "header" {
            return Ok(PeriodicSpec::FromHeader);
        }
        let numbers: Vec<f64> = text
            .split(',')
            .map(|p| p.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("'{text}' is not a box size L or LX,LY,LZ"))?;
        let size = match numbers[..] {
            [l] => [l; 3],
            [x, y, z] => [x, y, z],
            _ => return Err(format!("'{text}' is not a box size L or LX,LY,LZ")),
        };
        PeriodicBox::from_origin(size).map_err(|e| e.to_string())?;
        Ok(PeriodicSpec::Box(size))
    }
}

/// A scene file's `periodic`: `true` (the header's box), `false` (open), or `[LX, LY, LZ]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PeriodicSetting {
    /// `true`: the snapshot header's box; `false`: open, no wrapping.
    Flag(bool),
    /// `[LX, LY, LZ]`: the box [0, L), in data units.
    Box([f64; 3]),
}

impl PeriodicSetting {
    /// The setting that reproduces `periodic`: its box, or an open box.
    pub fn of(periodic: Option<PeriodicBox>) -> PeriodicSetting {
        match periodic {
            Some(b) => PeriodicSetting::Box(b.size.to_array()),
            None => PeriodicSetting::Flag(false),
        }
    }
}

/// The flags over a scene file's setting: what `--periodic` asks for, and whether the box is
/// open (`--no-periodic`).
pub fn merge(
    flag: Option<PeriodicSpec>,
    no_periodic: bool,
    scene: Option<PeriodicSetting>,
) -> (Option<PeriodicSpec>, bool) {
    match (flag, no_periodic, scene) {
        (Some(spec), _, _) => (Some(spec), false),
        (None, true, _) | (None, false, Some(PeriodicSetting::Flag(false))) => (None, true),
        (None, false, Some(PeriodicSetting::Flag(true))) => (Some(PeriodicSpec::FromHeader), false),
        (None, false, Some(PeriodicSetting::Box(size))) => (Some(PeriodicSpec::Box(size)), false),
        (None, false, None) => (None, false),
    }
}

/// Particles may lie outside a header's periodic box by this fraction of its side (codes write
/// a few slightly outside) before the box is taken not to be the data's.
const OUTSIDE_TOLERANCE: f64 = 0.01;

/// The periodic box the field of `series` wraps at, as the flags ask: none with `no_periodic`;
/// `spec`'s box; by default the box the first step's header states where it says the run is
/// periodic (said in the log), unless the series' particles lie well outside it (then it is
/// not used, with a warning saying how to force it).
pub fn choose(
    series: &TimeSeries,
    spec: Option<PeriodicSpec>,
    no_periodic: bool,
) -> anyhow::Result<Option<PeriodicBox>> {
    if no_periodic {
        return Ok(None);
    }
    if let Some(PeriodicSpec::Box(size)) = spec {
        let b = PeriodicBox::from_origin(size)?;
        tracing::info!(
            "periodic box [0, {}) x [0, {}) x [0, {}) (--periodic)",
            size[0],
            size[1],
            size[2]
        );
        return Ok(Some(b));
    }
    let header = series.simulation_box(0)?;
    let Some(stated) = header else {
        if spec.is_some() {
            bail!(
                "--periodic without a box size needs an HDF5 snapshot whose /Header has BoxSize; \
                 give the box: --periodic L or --periodic LX,LY,LZ (the box [0, L) on each axis)"
            );
        }
        return Ok(None);
    };
    if spec.is_none() && !stated.periodic {
        return Ok(None);
    }
    let b = PeriodicBox::from_origin(stated.size).map_err(|e| {
        anyhow::anyhow!(
            "{e} (the snapshot's /Header BoxSize); --no-periodic reads it as an open box"
        )
    })?;
    // Under --physical the box scales with the scale factor, which differs between steps.
    if series.len() > 1
        && let Some(last) = series.simulation_box(series.len() - 1)?
        && last.size != stated.size
    {
        bail!(
            "the periodic box differs between steps ({:?} in the first, {:?} in the last; \
             physical units of a cosmological run grow with the scale factor): render in \
             comoving units (without --physical), or pass --no-periodic",
            stated.size,
            last.size
        );
    }
    let size = b.size;
    if spec.is_none() {
        let data = series.bounds();
        let slack = size * OUTSIDE_TOLERANCE;
        if !data.is_empty()
            && (data.min.cmplt(b.min - slack).any() || data.max.cmpgt(b.min + size + slack).any())
        {
            tracing::warn!(
                "the snapshot's header says its box [0, {}) x [0, {}) x [0, {}) is periodic \
                 ({}), but the particles reach {:?}..{:?}, well outside it: the field is not \
                 wrapped (--periodic wraps it anyway, --no-periodic says it is open)",
                size.x,
                size.y,
                size.z,
                stated.because,
                data.min.to_array(),
                data.max.to_array()
            );
            return Ok(None);
        }
    }
    tracing::info!(
        "periodic box [0, {}) x [0, {}) x [0, {}) from the snapshot's header ({}): particles \
         near a face are felt across it (--no-periodic turns this off)",
        size.x,
        size.y,
        size.z,
        if spec.is_some() {
            "--periodic".to_owned()
        } else {
            stated.because
        }
    );
    Ok(Some(b))
}
