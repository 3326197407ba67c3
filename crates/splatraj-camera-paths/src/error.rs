//! What can go wrong reading or writing a camera file: every error names the file, the element
//! (a JSON path such as `camera_path[3].fov`, or a line of a text file) and the problem.

use std::path::PathBuf;

/// A camera file that cannot be read, or a path that cannot be written in a format.
#[derive(Debug, thiserror::Error)]
pub enum InterchangeError {
    /// The file could not be read from disk.
    // The causes below are part of the message, not a `source`: an error chain printed whole
    // (anyhow's `{:#}`) would otherwise say them twice.
    #[error("cannot read {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The file is not JSON of the expected shape (serde says where and what).
    #[error("{file}: not a {format} file: {error}")]
    Json {
        /// The file's name as given.
        file: String,
        /// The format it was read as.
        format: &'static str,
        /// serde's message, with line and column.
        error: serde_json::Error,
    },
    /// One element of the file holds a bad value.
    #[error("{file}: {element}: {problem}")]
    Invalid {
        /// The file's name as given.
        file: String,
        /// Which element: a JSON path or a line of a text file.
        element: String,
        /// What is wrong with it.
        problem: String,
    },
    /// Nothing tells which format a file is in.
    #[error("{file}: {problem}")]
    UnknownFormat {
        /// The file's name as given.
        file: String,
        /// What was looked at.
        problem: String,
    },
    /// A path that cannot be written in a format (no frames, a frame without intrinsics, a
    /// value the format cannot hold).
    #[error("cannot export as {format}: {problem}")]
    Export {
        /// The target format.
        format: &'static str,
        /// Why.
        problem: String,
    },
}

/// Result of this crate's functions.
pub type Result<T, E = InterchangeError> = std::result::Result<T, E>;

/// An [`InterchangeError::Invalid`].
pub(crate) fn invalid(
    file: &str,
    element: impl Into<String>,
    problem: impl Into<String>,
) -> InterchangeError {
    InterchangeError::Invalid {
        file: file.to_string(),
        element: element.into(),
        problem: problem.into(),
    }
}

/// An [`InterchangeError::Export`].
pub(crate) fn export_error(format: &'static str, problem: impl Into<String>) -> InterchangeError {
    InterchangeError::Export {
        format,
        problem: problem.into(),
    }
}

/// Reads a whole text file, naming it in the error.
pub(crate) fn read_text(path: &std::path::Path) -> Result<String> {
    splatraj_scene::input::read_text(path).map_err(|error| InterchangeError::Read {
        path: path.to_path_buf(),
        error,
    })
}
