//! Errors of the lifting crate.

use std::path::PathBuf;

/// Result with [`LiftError`].
pub type Result<T, E = LiftError> = std::result::Result<T, E>;

/// What can go wrong while planning views, lifting or reading a cache.
#[derive(Debug, thiserror::Error)]
pub enum LiftError {
    /// A rendering call refused its request.
    #[error("rendering a view: {0}")]
    Render(#[from] splatraj_render::render::RenderError),
    /// A camera could not be built.
    #[error("camera: {0}")]
    Camera(#[from] splatraj_render::camera::CameraError),
    /// A camera file could not be read (the error names the file and the element).
    #[error(transparent)]
    Cameras(#[from] splatraj_camera_paths::InterchangeError),
    /// The CLIP towers or their weights failed.
    #[error(transparent)]
    Semantic(#[from] splatraj_semantic::SemanticError),
    /// An option has a value the lifting cannot use; `key` names it.
    #[error("{key}: {reason}")]
    Option {
        /// The option's config key.
        key: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The scene cannot be lifted onto (no Gaussians, no view sees anything).
    #[error("{0}")]
    Scene(String),
    /// A file (cache, mask image, camera list) could not be read or written.
    #[error("{}: {reason}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

impl LiftError {
    /// An option error naming `key`.
    pub fn option(key: impl Into<String>, reason: impl Into<String>) -> Self {
        LiftError::Option {
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// A file error naming `path`.
    pub fn file(path: impl Into<PathBuf>, reason: impl std::fmt::Display) -> Self {
        LiftError::File {
            path: path.into(),
            reason: reason.to_string(),
        }
    }
}
