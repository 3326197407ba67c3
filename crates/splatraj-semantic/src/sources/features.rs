//! `features` source: per-Gaussian embeddings scored against a text embedding, LERF style.

use std::sync::Arc;

use rayon::prelude::*;
use splatraj_scene::Scene;

use crate::embeddings::{Matrix, PhraseTable};
use crate::error::{Result, SemanticError};
use crate::sources::{Relevancy, Scoring, TargetSource};
use crate::text_encoder::TextEncoder;
use crate::vectors::{self, DEFAULT_NEGATIVES, DEFAULT_TEMPERATURE};

/// Where the per-Gaussian feature vectors come from.
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureInput {
    /// The scene's own `extras.features` (PLY properties such as `semantic_0..`).
    Scene,
    /// A matrix read from a sidecar (see [`crate::embeddings::read_feature_sidecar`]).
    Sidecar(Matrix),
}

/// Relevancy of each Gaussian to a phrase, as in LERF and LangSplat:
///
/// r = min over negatives n of exp(τ·cos(f, q)) / (exp(τ·cos(f, q)) + exp(τ·cos(f, n)))
///
/// with f the Gaussian's feature, q the query phrase's embedding and n each canonical negative
/// phrase's embedding, all looked up in the phrase table, or, for a phrase the table lacks,
/// computed by the text encoder when there is one (free-text queries). r lies in (0, 1); 0.5
/// means "no more like the query than like the most similar negative".
#[derive(Debug, Clone)]
pub struct FeaturesSource {
    /// Where the per-Gaussian features come from.
    pub features: FeatureInput,
    /// Text embeddings of the query phrases and the negatives.
    pub table: PhraseTable,
    /// Canonical negative phrases; each must be in the table.
    pub negatives: Vec<String>,
    /// Temperature τ scaling the cosines.
    pub temperature: f32,
    /// Encodes the phrases the table lacks; `None`: only the table's phrases can be queried.
    pub encoder: Option<Arc<TextEncoder>>,
}

impl FeaturesSource {
    /// A source with the default negatives ("object", "things", "stuff", "texture") and
    /// temperature (10).
    pub fn new(features: FeatureInput, table: PhraseTable) -> Self {
        FeaturesSource {
            features,
            table,
            negatives: DEFAULT_NEGATIVES.iter().map(|s| s.to_string()).collect(),
            temperature: DEFAULT_TEMPERATURE,
            encoder: None,
        }
    }

    /// The text embedding of `phrase`: its table row, else the encoder's output; without an
    /// encoder a phrase the table lacks is a no-match error listing the closest phrases.
    /// `what` names the role ("phrase", "canonical negative phrase").
    pub fn text_vector(&self, phrase: &str, what: &str) -> Result<Vec<f32>> {
        match (self.table.get(phrase, what), &self.encoder) {
            (Ok(v), _) => Ok(v.to_vec()),
            (Err(SemanticError::NoMatch { .. }), Some(encoder)) => {
                Ok(encoder.encode(&[phrase])?.values)
            }
            (Err(e), _) => Err(e),
        }
    }

    /// The relevancy of each row of `values` (`[rows, dim]`, named `source` in errors) to
    /// `query`: the scoring shared by every source whose features live in text-embedding
    /// space, whatever their rows stand for (`row_kind`: "Gaussian", "leaf cluster").
    pub fn score_rows(
        &self,
        query: &str,
        source: &str,
        row_kind: &str,
        dim: usize,
        values: &[f32],
    ) -> Result<Vec<f32>> {
        if !(self.temperature.is_finite() && self.temperature > 0.0) {
            return Err(SemanticError::option(
                "temperature",
                format!("{} must be finite and > 0", self.temperature),
            ));
        }
        if self.negatives.is_empty() {
            return Err(SemanticError::option(
                "negatives",
                "at least one canonical negative phrase is needed: without one every relevancy \
                 is 1 and nothing can be told apart",
            ));
        }
        if dim != self.table.dim() {
            return Err(SemanticError::Mismatch(format!(
                "{source} has vectors of length {dim} but the phrase table {} has length {}: \
                 they must come from the same embedding model",
                self.table.source,
                self.table.dim()
            )));
        }
        if let Some(encoder) = &self.encoder
            && encoder.dim() != dim
        {
            return Err(SemanticError::Mismatch(format!(
                "{source} has vectors of length {dim} but the text encoder {} makes {}: they \
                 must come from the same CLIP model",
                encoder.source().display(),
                encoder.dim()
            )));
        }
        let q = vectors::unit(&self.text_vector(query, "phrase")?, || {
            format!("the embedding of phrase {query:?} in {}", self.table.source)
        })?;
        let negatives = self
            .negatives
            .iter()
            .map(|n| {
                vectors::unit(&self.text_vector(n, "canonical negative phrase")?, || {
                    format!(
                        "the embedding of negative phrase {n:?} in {}",
                        self.table.source
                    )
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let tau = self.temperature;
        values
            .par_chunks_exact(dim)
            .enumerate()
            .map(|(i, f)| {
                let f = vectors::unit(f, || {
                    format!("the feature vector of {row_kind} {i} in {source}")
                })?;
                Ok(vectors::relevancy(&f, &q, &negatives, tau))
            })
            .collect()
    }
}

impl TargetSource for FeaturesSource {
    fn kind(&self) -> &'static str {
        "features"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let (source, dim, values): (String, usize, &[f32]) = match &self.features {
            FeatureInput::Scene => {
                let f = scene_features(scene, "features")?;
                (
                    format!(
                        "scene features ({})",
                        f.names.first().map_or("", String::as_str)
                    ),
                    f.dim,
                    &f.values,
                )
            }
            FeatureInput::Sidecar(m) => (m.source.clone(), m.dim, &m.values),
        };
        let rows = values.len().checked_div(dim).unwrap_or(0);
        if rows != scene.len() {
            return Err(SemanticError::Mismatch(format!(
                "{source}: {rows} feature vectors for a scene of {} Gaussians",
                scene.len()
            )));
        }
        Ok(Relevancy {
            name: query.trim().to_string(),
            values: self.score_rows(query, &source, "Gaussian", dim, values)?,
            scoring: Scoring::Graded,
            notes: Vec::new(),
        })
    }
}

/// The scene's own per-Gaussian features (PLY properties such as `semantic_0..`), or an error
/// naming `source_kind` when the scene has none.
pub fn scene_features<'a>(
    scene: &'a Scene,
    source_kind: &'static str,
) -> Result<&'a splatraj_scene::Features> {
    scene
        .extras
        .features
        .as_ref()
        .ok_or_else(|| SemanticError::MissingData {
            source_kind,
            detail: "the scene has no per-Gaussian features: give a feature sidecar (.npy or \
                     .safetensors, [N, D]) or a scene with feature properties (semantic_0.., \
                     f_lang_0..)"
                .to_string(),
        })
}
