//! What can stop a render: the backend, the data, the camera or the settings.

use crate::backend::BackendError;
use crate::io::DataError;
use crate::scene::CameraError;

/// Why a render could not go on.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Backend(#[from] BackendError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error("render settings: {0}")]
    Settings(String),
}
