//! The user's 1D maps over the normalised attribute `t` in [0, 1] (method.md §1): the colour
//! map C(t), the density map w(t), the radius map m(t), and the optical-density map from
//! normalised density to extinction. All are piecewise linear between control points and
//! serialisable; colour maps also come as presets or from ParaView's colour-map JSON.
//!
//! Every backend looks a map up in its baked table ([`crate::values::tables`]), never in its
//! control points: [`PiecewiseLinear::bake`] and [`ColorMap::bake`] make them.

mod colour;
mod density;
mod optical;
mod paraview;
mod piecewise;
mod radius;

pub use colour::{ColorMap, ColorPoint, PRESETS};
pub use density::DensityMap;
pub use optical::OpticalDensityMap;
pub use piecewise::PiecewiseLinear;
pub use radius::RadiusMap;

/// A problem with a map definition.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// A map whose values or control points are out of range.
    #[error("{what}: {problem}")]
    Invalid {
        /// Which map or value (`"radius map"`, `"density scale"`, ...).
        what: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A colour-map file that cannot be read or parsed.
    #[error("cannot read colour map {path}: {problem}")]
    File {
        /// The file's path.
        path: String,
        /// The read or parse error.
        problem: String,
    },
}

pub(crate) fn invalid(what: &str, problem: impl Into<String>) -> MapError {
    MapError::Invalid {
        what: what.to_owned(),
        problem: problem.into(),
    }
}
