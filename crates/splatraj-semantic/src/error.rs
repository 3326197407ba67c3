//! Errors of semantic selection. Each names the file, key, phrase or option at fault and what
//! is wrong, so that a user can fix the input without reading the code.

use std::path::PathBuf;

/// Everything that can go wrong between a query and its target.
#[derive(Debug, thiserror::Error)]
pub enum SemanticError {
    /// A file (feature sidecar, phrase table) could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is not what splatraj expects.
    #[error("{path}: {detail}")]
    File {
        /// File concerned.
        path: PathBuf,
        /// What is wrong, naming the key, tensor or line.
        detail: String,
    },
    /// The query matched no label, phrase or region; `closest` lists the nearest known
    /// names, best first.
    #[error("{}", no_match_message(.what, .query, .closest))]
    NoMatch {
        /// What was searched ("label", "phrase", "region", "canonical negative phrase").
        what: String,
        /// The query as given.
        query: String,
        /// Closest known names, best first.
        closest: Vec<String>,
    },
    /// The scene lacks the data a source needs (no labels, no features).
    #[error("{source_kind} source: {detail}")]
    MissingData {
        /// Source kind ("labels", "features").
        source_kind: &'static str,
        /// What is missing and how to provide it.
        detail: String,
    },
    /// Two inputs that must agree do not (feature count vs scene size, dimensions).
    #[error("{0}")]
    Mismatch(String),
    /// A vector has zero (or non-finite) norm, so its cosine similarity is undefined.
    #[error(
        "{what} has zero length (norm {norm}): its cosine similarity is undefined; fix or drop it"
    )]
    ZeroVector {
        /// Which vector ("feature vector of Gaussian 12 (from x.npy)", "phrase \"apple\"").
        what: String,
        /// Its norm.
        norm: f32,
    },
    /// A value is NaN or infinite.
    #[error("{what} holds a non-finite value ({value})")]
    NonFinite {
        /// Which value.
        what: String,
        /// The value.
        value: f32,
    },
    /// The scene holds no Gaussian.
    #[error("the scene holds no Gaussian: there is nothing to select")]
    EmptyScene,
    /// No Gaussian survived the selection.
    #[error("query {query:?}: {detail}")]
    NothingSelected {
        /// The query.
        query: String,
        /// Why, with the numbers and the option to change.
        detail: String,
    },
    /// The relevancies cannot separate anything (all equal).
    #[error("query {query:?}: {detail}")]
    Degenerate {
        /// The query.
        query: String,
        /// What is degenerate.
        detail: String,
    },
    /// An option is out of range or inconsistent: the config key (or command-line option)
    /// and what is wrong, as every crate reports a bad key.
    #[error("option `{}`: {}", .0.key, .0.reason)]
    InvalidOption(splatraj_config::ConfigError),
    /// A key of the `[targets]` config (or its command-line option) led to an error, e.g. the
    /// file it names cannot be read; the message names the key, then the error.
    #[error("{key}: {error}")]
    Config {
        /// The key (`targets.phrases`) or option (`--phrases`).
        key: String,
        /// What went wrong with it.
        error: Box<SemanticError>,
    },
}

fn no_match_message(what: &str, query: &str, closest: &[String]) -> String {
    if closest.is_empty() {
        format!("no {what} matches {query:?}, and none is known")
    } else {
        let list: Vec<String> = closest.iter().map(|c| format!("{c:?}")).collect();
        format!("no {what} matches {query:?}; closest: {}", list.join(", "))
    }
}

impl From<splatraj_config::ConfigError> for SemanticError {
    fn from(e: splatraj_config::ConfigError) -> Self {
        SemanticError::InvalidOption(e)
    }
}

impl SemanticError {
    /// A [`SemanticError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SemanticError::Io {
            path: path.into(),
            source,
        }
    }

    /// A [`SemanticError::File`] for `path`.
    pub fn file(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        SemanticError::File {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`SemanticError::InvalidOption`].
    pub fn option(key: impl Into<String>, detail: impl Into<String>) -> Self {
        SemanticError::InvalidOption(splatraj_config::ConfigError::new(key, detail))
    }
}

impl SemanticError {
    /// Wraps `self` as a [`SemanticError::Config`] error of `key`.
    pub fn in_key(self, key: impl Into<String>) -> Self {
        SemanticError::Config {
            key: key.into(),
            error: Box::new(self),
        }
    }
}

/// Result with a [`SemanticError`].
pub type Result<T> = std::result::Result<T, SemanticError>;
