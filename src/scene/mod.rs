//! Scene and data: time series of particle steps, the user's maps, synthetic data sets and the
//! scene file.

pub mod maps;
pub mod scene_file;
pub mod series;
pub mod step;
pub mod synth;

pub use series::{AttributeInfo, OpenOptions, StepInfo, TimeSeries};
pub use step::{Attribute, Bounds, Step};
