//! Rendering: what a user chooses about an image ([`RenderSettings`]) and the session that
//! drives a backend through a series, deciding what each change costs and resolving the
//! automatic settings into the [`crate::values::FrameParams`] every backend renders. The
//! integrators themselves are shader code (`shaders_glsl/shared/integrators.glsl`) with their
//! CPU twin in [`crate::backend::cpu::integrators`].

pub mod auto;
pub mod converged;
mod cycles;
mod error;
pub mod legend;
pub mod session;
pub mod settings;
mod step_bias;
pub mod target;

pub use auto::AutoValues;
pub(crate) use cycles::CycleWeights;
pub use error::RenderError;
pub use session::{FrameBasis, RenderSession, Resolved, StepChange};
pub use settings::{Method, RenderSettings, SPLAT_K, VOXEL_GRID};
