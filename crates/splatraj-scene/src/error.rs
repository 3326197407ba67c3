//! Errors of scene reading, writing and validation. Each names the file and what is wrong.

use std::path::PathBuf;

/// Everything that can go wrong while reading, checking or writing a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The file's format is not one splatraj reads.
    #[error("{path}: unknown scene format: {detail}")]
    UnknownFormat {
        /// File concerned.
        path: PathBuf,
        /// What was seen instead of a known format.
        detail: String,
    },
    /// The file is of a known format but its structure is wrong (bad header, missing
    /// property, wrong type, truncated payload).
    #[error("{path}: {detail}")]
    Malformed {
        /// File concerned.
        path: PathBuf,
        /// What is wrong, naming the element or property.
        detail: String,
    },
    /// A Gaussian holds a value that cannot be rendered (NaN/Inf, zero-norm quaternion,
    /// non-positive scale).
    #[error(
        "{path}: Gaussian {index}: {property} {problem} (--drop-invalid, or `drop_invalid = true` in a config's [scene], drops invalid Gaussians with a warning)"
    )]
    InvalidGaussian {
        /// File concerned.
        path: PathBuf,
        /// Index of the Gaussian in the file.
        index: usize,
        /// Property (or group of properties) at fault.
        property: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The scene cannot be written there: a format splatraj does not write, or a target that
    /// is not a regular file.
    #[error("{path}: cannot write: {detail}")]
    Unwritable {
        /// Target file concerned.
        path: PathBuf,
        /// Why, naming the extension or the kind of file found.
        detail: String,
    },
    /// A sidecar (labels, features) does not fit the scene it was given for.
    #[error("{path}: {detail}")]
    Sidecar {
        /// Sidecar file concerned.
        path: PathBuf,
        /// What does not fit.
        detail: String,
    },
}

impl SceneError {
    /// A [`SceneError::Malformed`] for `path`.
    pub fn malformed(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        SceneError::Malformed {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`SceneError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SceneError::Io {
            path: path.into(),
            source,
        }
    }

    /// A [`SceneError::Sidecar`] for `path`.
    pub fn sidecar(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        SceneError::Sidecar {
            path: path.into(),
            detail: detail.into(),
        }
    }
}

/// Result with a [`SceneError`].
pub type Result<T> = std::result::Result<T, SceneError>;
