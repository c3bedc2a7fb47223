//! What can stop a render: the backend, the data, the camera or the settings.

use crate::backend::BackendError;
use crate::io::DataError;
use crate::scene::CameraError;

/// Why a render could not go on.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The backend failed.
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// The series could not read a step.
    #[error(transparent)]
    Data(#[from] DataError),
    /// The camera cannot form an image.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// A setting is out of range or contradicts another; the message names it.
    #[error("render settings: {0}")]
    Settings(String),
    /// The ranks of a distributed render failed (`crate::dist::DistError`, which names the
    /// rank).
    #[error(transparent)]
    Ranks(Box<dyn std::error::Error + Send + Sync + 'static>),
}
