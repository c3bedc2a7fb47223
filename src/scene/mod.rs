//! Scene and data: time series of particle steps, the user's maps, cameras and synthetic data
//! sets.

pub mod camera;
pub mod index;
pub mod maps;
pub mod prefetch;
pub mod series;
pub mod smoothing;
pub mod synth;

pub use camera::{Camera, CameraError, UpAxis};
pub use series::{AttributeInfo, OpenOptions, StepInfo, StepsScan, TimeSeries};
