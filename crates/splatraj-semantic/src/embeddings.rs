//! Embedding files: per-Gaussian feature matrices and phrase → vector tables.
//!
//! Feature matrices (one row per Gaussian) come from the scene (`scene.extras.features`), an
//! `.npy` file of shape `[N, D]` (float32 or float64), or a `.safetensors` file (tensor
//! `features`, or its only tensor, shape `[N, D]`, F32/F64).
//!
//! Phrase tables (one row per text phrase) come from
//! - JSON: `{"phrase": [floats], ...}`;
//! - `.npy` `[P, D]` plus a phrases text file, one phrase per line in row order;
//! - `.safetensors`: tensor `embeddings` `[P, D]`, with the phrases either in the file's
//!   metadata under the key `phrases` (a JSON array of strings, in row order: the file is then
//!   self-contained, which is why this is the preferred form) or in a phrases text file given
//!   beside it (which wins when both are present).

use std::collections::HashMap;
use std::io::BufReader;
use std::path::Path;

use safetensors::{Dtype, SafeTensors};

use crate::error::{Result, SemanticError};
use crate::names;

/// Name of the tensor a feature `.safetensors` file is searched for first.
pub const FEATURES_TENSOR: &str = "features";
/// Name of the tensor of a phrase-table `.safetensors` file.
pub const EMBEDDINGS_TENSOR: &str = "embeddings";
/// Metadata key holding the phrases of a phrase-table `.safetensors` file.
pub const PHRASES_METADATA_KEY: &str = "phrases";

/// A row-major matrix of f32 read from a file, with where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    /// Description of the source (file path, tensor) for error messages.
    pub source: String,
    /// Number of rows.
    pub rows: usize,
    /// Row length.
    pub dim: usize,
    /// Flat `[rows, dim]` values.
    pub values: Vec<f32>,
}

impl Matrix {
    /// Row `i`.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.values[i * self.dim..(i + 1) * self.dim]
    }

    /// Reads a 2-D float32/float64 `.npy` file.
    pub fn from_npy(path: &Path) -> Result<Matrix> {
        let file = splatraj_scene::input::open(path)
            .map(|(file, _)| file)
            .map_err(|e| SemanticError::io(path, e))?;
        crate::npy_size::check_shape_product_file(path)
            .map_err(|e| SemanticError::file(path, e))?;
        let npy = npyz::NpyFile::new(BufReader::new(file))
            .map_err(|e| SemanticError::file(path, format!("not a readable .npy file: {e}")))?;
        let shape: Vec<u64> = npy.shape().to_vec();
        let [rows, dim] = shape[..] else {
            return Err(SemanticError::file(
                path,
                format!("shape {shape:?}: expected 2 dimensions [rows, dim]"),
            ));
        };
        crate::npy_size::check_npy_file(path, npy.header())
            .map_err(|e| SemanticError::file(path, e))?;
        if npy.order() != npyz::Order::C {
            return Err(SemanticError::file(
                path,
                "Fortran-ordered array: save it in C order (numpy.ascontiguousarray)",
            ));
        }
        let descr = npy.dtype().descr();
        let read_err = |e: std::io::Error| SemanticError::file(path, format!("reading data: {e}"));
        // `try_data` hands the file back when the dtype differs, so each type is tried in turn.
        let values: Vec<f32> = match npy.try_data::<f32>() {
            Ok(data) => data.collect::<std::io::Result<_>>().map_err(read_err)?,
            Err(npy) => match npy.try_data::<f64>() {
                Ok(data) => data
                    .map(|v| v.map(|x| x as f32))
                    .collect::<std::io::Result<_>>()
                    .map_err(read_err)?,
                Err(_) => {
                    return Err(SemanticError::file(
                        path,
                        format!("dtype {descr} is not supported: use float32 or float64"),
                    ));
                }
            },
        };
        Ok(Matrix {
            source: path.display().to_string(),
            rows: rows as usize,
            dim: dim as usize,
            values,
        })
    }

    /// Reads tensor `name` of a `.safetensors` file; with `name` = `None`, the file's only
    /// tensor.
    pub fn from_safetensors(path: &Path, name: Option<&str>) -> Result<Matrix> {
        let bytes =
            splatraj_scene::input::read_bytes(path).map_err(|e| SemanticError::io(path, e))?;
        let tensors = SafeTensors::deserialize(&bytes).map_err(|e| {
            SemanticError::file(path, format!("not a readable safetensors file: {e}"))
        })?;
        matrix_from_safetensors(&tensors, path, name)
    }
}

fn matrix_from_safetensors(
    tensors: &SafeTensors<'_>,
    path: &Path,
    name: Option<&str>,
) -> Result<Matrix> {
    let mut names: Vec<&str> = tensors.names();
    names.sort_unstable();
    let name = match name {
        Some(n) => n.to_string(),
        None if names.len() == 1 => names[0].to_string(),
        None => {
            return Err(SemanticError::file(
                path,
                format!(
                    "holds tensors {names:?}: name the one to use (expected {FEATURES_TENSOR:?} \
                     or a single tensor)"
                ),
            ));
        }
    };
    let view = tensors.tensor(&name).map_err(|_| {
        SemanticError::file(
            path,
            format!("no tensor named {name:?} (the file holds {names:?})"),
        )
    })?;
    let shape = view.shape().to_vec();
    let [rows, dim] = shape[..] else {
        return Err(SemanticError::file(
            path,
            format!("tensor {name:?} has shape {shape:?}: expected 2 dimensions [rows, dim]"),
        ));
    };
    let data = view.data();
    let values: Vec<f32> = match view.dtype() {
        Dtype::F32 => data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        Dtype::F64 => data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32)
            .collect(),
        other => {
            return Err(SemanticError::file(
                path,
                format!("tensor {name:?} has dtype {other:?}: use F32 or F64"),
            ));
        }
    };
    Ok(Matrix {
        source: format!("{} (tensor {name:?})", path.display()),
        rows,
        dim,
        values,
    })
}

/// Per-Gaussian feature vectors from a sidecar file, chosen by extension (`.npy`,
/// `.safetensors`).
pub fn read_feature_sidecar(path: &Path) -> Result<Matrix> {
    match extension(path).as_str() {
        "npy" => Matrix::from_npy(path),
        "safetensors" => {
            let bytes =
                splatraj_scene::input::read_bytes(path).map_err(|e| SemanticError::io(path, e))?;
            let tensors = SafeTensors::deserialize(&bytes).map_err(|e| {
                SemanticError::file(path, format!("not a readable safetensors file: {e}"))
            })?;
            let name = tensors
                .names()
                .contains(&FEATURES_TENSOR)
                .then_some(FEATURES_TENSOR);
            matrix_from_safetensors(&tensors, path, name)
        }
        other => Err(SemanticError::file(
            path,
            format!("unknown feature file extension {other:?}: use .npy or .safetensors"),
        )),
    }
}

/// A table of text embeddings: phrase → vector, all of one length.
#[derive(Debug, Clone, PartialEq)]
pub struct PhraseTable {
    /// Where the table came from, for messages.
    pub source: String,
    /// Phrases in row order.
    pub phrases: Vec<String>,
    /// The vectors, one row per phrase.
    pub vectors: Matrix,
    /// Normalised phrase → row, for lookups.
    index: HashMap<String, usize>,
}

impl PhraseTable {
    /// A table from phrases and their vectors (`vectors.rows == phrases.len()`). Two phrases
    /// that are equal once normalised (case, whitespace) are an error: a lookup would be
    /// ambiguous.
    pub fn new(source: impl Into<String>, phrases: Vec<String>, vectors: Matrix) -> Result<Self> {
        let source = source.into();
        if phrases.len() != vectors.rows {
            return Err(SemanticError::Mismatch(format!(
                "{source}: {} phrases for {} embedding rows",
                phrases.len(),
                vectors.rows
            )));
        }
        if vectors.dim == 0 {
            return Err(SemanticError::Mismatch(format!(
                "{source}: embeddings have length 0"
            )));
        }
        let mut index = HashMap::new();
        for (i, p) in phrases.iter().enumerate() {
            if p.trim().is_empty() {
                return Err(SemanticError::Mismatch(format!(
                    "{source}: phrase {i} is empty"
                )));
            }
            if let Some(j) = index.insert(names::normalise(p), i) {
                return Err(SemanticError::Mismatch(format!(
                    "{source}: phrases {j} ({:?}) and {i} ({p:?}) are the same once case and \
                     spacing are ignored",
                    phrases[j]
                )));
            }
        }
        Ok(PhraseTable {
            source,
            phrases,
            vectors,
            index,
        })
    }

    /// This table with the rows of `more` after its own (same vector length, no phrase in
    /// both).
    pub fn extended(&self, more: &PhraseTable) -> Result<Self> {
        if more.phrases.is_empty() {
            return Ok(self.clone());
        }
        if more.dim() != self.dim() {
            return Err(SemanticError::Mismatch(format!(
                "{} has vectors of length {} but {} has {}",
                self.source,
                self.dim(),
                more.source,
                more.dim()
            )));
        }
        let mut phrases = self.phrases.clone();
        phrases.extend(more.phrases.iter().cloned());
        let mut values = self.vectors.values.clone();
        values.extend_from_slice(&more.vectors.values);
        let source = format!("{} + {}", self.source, more.source);
        let vectors = Matrix {
            source: source.clone(),
            rows: phrases.len(),
            dim: self.dim(),
            values,
        };
        Self::new(source, phrases, vectors)
    }

    /// Writes the table to `path` in the form its extension names
    /// ([`PhraseTable::to_bytes`]), whole or not at all.
    pub fn write(&self, path: &Path) -> Result<()> {
        let bytes = self.to_bytes(path)?;
        splatraj_scene::atomic::write_atomically(path, |w| w.write_all(&bytes))
            .map_err(|e| SemanticError::file(path, format!("cannot write: {e}")))
    }

    /// The table as file bytes, in the form `path`'s extension names: `.safetensors`
    /// (tensor `embeddings` F32 `[P, D]`, phrases as a JSON array in the metadata key
    /// `phrases`: self-contained, the preferred form) or `.json` (`{"phrase": [floats]}`).
    /// [`PhraseTable::read`] reads either back.
    pub fn to_bytes(&self, path: &Path) -> Result<Vec<u8>> {
        match extension(path).as_str() {
            "safetensors" => {
                let bytes: Vec<u8> = self
                    .vectors
                    .values
                    .iter()
                    .flat_map(|v| v.to_le_bytes())
                    .collect();
                let view = safetensors::tensor::TensorView::new(
                    Dtype::F32,
                    vec![self.vectors.rows, self.dim()],
                    &bytes,
                )
                .map_err(|e| SemanticError::file(path, format!("cannot build the tensor: {e}")))?;
                let phrases = serde_json::to_string(&self.phrases)
                    .map_err(|e| SemanticError::file(path, e.to_string()))?;
                let metadata = HashMap::from([(PHRASES_METADATA_KEY.to_string(), phrases)]);
                safetensors::serialize([(EMBEDDINGS_TENSOR, view)], Some(metadata))
                    .map_err(|e| SemanticError::file(path, format!("cannot serialise: {e}")))
            }
            "json" => {
                let map: serde_json::Map<String, serde_json::Value> = self
                    .phrases
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (p.clone(), serde_json::json!(self.vectors.row(i))))
                    .collect();
                serde_json::to_vec_pretty(&serde_json::Value::Object(map))
                    .map_err(|e| SemanticError::file(path, e.to_string()))
            }
            other => Err(SemanticError::file(
                path,
                format!("unknown phrase table extension {other:?}: use .safetensors or .json"),
            )),
        }
    }

    /// Length of the vectors.
    pub fn dim(&self) -> usize {
        self.vectors.dim
    }

    /// The vector of `phrase` (case and spacing ignored), or a no-match error listing the
    /// closest phrases; `what` names the role ("phrase", "canonical negative phrase").
    pub fn get(&self, phrase: &str, what: &str) -> Result<&[f32]> {
        match self.index.get(&names::normalise(phrase)) {
            Some(&i) => Ok(self.vectors.row(i)),
            None => Err(SemanticError::NoMatch {
                what: format!("{what} in {}", self.source),
                query: phrase.to_string(),
                closest: names::closest(
                    phrase,
                    self.phrases.iter().map(String::as_str),
                    names::SUGGESTIONS,
                ),
            }),
        }
    }

    /// Reads a table, choosing the form by extension: `.json`, `.npy` (needs `phrases_file`),
    /// `.safetensors` (phrases from `phrases_file` if given, else from the metadata).
    pub fn read(path: &Path, phrases_file: Option<&Path>) -> Result<Self> {
        match extension(path).as_str() {
            "json" => Self::from_json(path),
            "npy" => {
                let phrases_file = phrases_file.ok_or_else(|| {
                    SemanticError::file(
                        path,
                        "an .npy phrase table needs a phrases file (one phrase per line, in row order)",
                    )
                })?;
                Self::from_npy(path, phrases_file)
            }
            "safetensors" => Self::from_safetensors(path, phrases_file),
            other => Err(SemanticError::file(
                path,
                format!(
                    "unknown phrase table extension {other:?}: use .json, .npy or .safetensors"
                ),
            )),
        }
    }

    /// Reads `{"phrase": [floats], ...}`.
    pub fn from_json(path: &Path) -> Result<Self> {
        let text =
            splatraj_scene::input::read_text(path).map_err(|e| SemanticError::io(path, e))?;
        let json: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| SemanticError::file(path, format!("not valid JSON: {e}")))?;
        let serde_json::Value::Object(map) = json else {
            return Err(SemanticError::file(
                path,
                "expected an object {\"phrase\": [floats], ...}",
            ));
        };
        let mut phrases = Vec::with_capacity(map.len());
        let mut values = Vec::new();
        let mut dim = None;
        for (phrase, v) in &map {
            let arr = v.as_array().ok_or_else(|| {
                SemanticError::file(
                    path,
                    format!("key {phrase:?}: expected an array of numbers"),
                )
            })?;
            match dim {
                None => dim = Some(arr.len()),
                Some(d) if d != arr.len() => {
                    return Err(SemanticError::file(
                        path,
                        format!(
                            "key {phrase:?}: vector of length {} where the others have {d}",
                            arr.len()
                        ),
                    ));
                }
                Some(_) => {}
            }
            for (i, x) in arr.iter().enumerate() {
                let x = x.as_f64().ok_or_else(|| {
                    SemanticError::file(
                        path,
                        format!("key {phrase:?}[{i}] is {x}: expected a number"),
                    )
                })?;
                values.push(x as f32);
            }
            phrases.push(phrase.clone());
        }
        if phrases.is_empty() {
            return Err(SemanticError::file(path, "the table holds no phrase"));
        }
        let vectors = Matrix {
            source: path.display().to_string(),
            rows: phrases.len(),
            dim: dim.unwrap_or(0),
            values,
        };
        Self::new(path.display().to_string(), phrases, vectors)
    }

    /// Reads an `.npy` `[P, D]` matrix and its phrases file.
    pub fn from_npy(path: &Path, phrases_file: &Path) -> Result<Self> {
        let vectors = Matrix::from_npy(path)?;
        let phrases = read_phrases_file(phrases_file)?;
        Self::new(
            format!("{} + {}", path.display(), phrases_file.display()),
            phrases,
            vectors,
        )
    }

    /// Reads tensor `embeddings` of a `.safetensors` file; phrases from `phrases_file` or
    /// from the metadata key `phrases` (a JSON array of strings).
    pub fn from_safetensors(path: &Path, phrases_file: Option<&Path>) -> Result<Self> {
        let bytes =
            splatraj_scene::input::read_bytes(path).map_err(|e| SemanticError::io(path, e))?;
        let tensors = SafeTensors::deserialize(&bytes).map_err(|e| {
            SemanticError::file(path, format!("not a readable safetensors file: {e}"))
        })?;
        let vectors = matrix_from_safetensors(&tensors, path, Some(EMBEDDINGS_TENSOR))?;
        let phrases = match phrases_file {
            Some(f) => read_phrases_file(f)?,
            None => {
                let (_, meta) = SafeTensors::read_metadata(&bytes)
                    .map_err(|e| SemanticError::file(path, format!("unreadable header: {e}")))?;
                let text = meta
                    .metadata()
                    .as_ref()
                    .and_then(|m| m.get(PHRASES_METADATA_KEY))
                    .ok_or_else(|| {
                        SemanticError::file(
                            path,
                            format!(
                                "no phrases: put a JSON array of strings under the metadata key \
                                 {PHRASES_METADATA_KEY:?}, or give a phrases file"
                            ),
                        )
                    })?;
                serde_json::from_str::<Vec<String>>(text).map_err(|e| {
                    SemanticError::file(
                        path,
                        format!(
                            "metadata {PHRASES_METADATA_KEY:?} is not a JSON array of strings: {e}"
                        ),
                    )
                })?
            }
        };
        Self::new(path.display().to_string(), phrases, vectors)
    }
}

/// Phrases, one per line; surrounding whitespace is trimmed and a final empty line ignored,
/// but an empty line in between is an error (it would shift every later row).
pub fn read_phrases_file(path: &Path) -> Result<Vec<String>> {
    let text = splatraj_scene::input::read_text(path).map_err(|e| SemanticError::io(path, e))?;
    let mut lines: Vec<&str> = text.lines().collect();
    while lines.last().is_some_and(|l| l.trim().is_empty()) {
        lines.pop();
    }
    lines
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let l = l.trim();
            if l.is_empty() {
                Err(SemanticError::file(
                    path,
                    format!("line {} is empty: one phrase per line, no gaps", i + 1),
                ))
            } else {
                Ok(l.to_string())
            }
        })
        .collect()
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}
