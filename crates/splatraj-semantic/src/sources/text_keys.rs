//! The text-embedding keys every language-field source shares (`phrases`, `text_encoder`,
//! `negatives`, ...), for the config tables of registered sources.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::config::{SourceKind, TargetsConfig};
use crate::error::{Result, SemanticError};
use crate::sources::{FeatureInput, FeaturesSource, SourceContext};
use crate::text_encoder::Activation;

/// Where the text embeddings of a language-field source come from, and how they are scored:
/// the same keys, meanings and checks as the `features` source's (see [`crate::config`]).
/// A source's config flattens it into its own table.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct TextKeys {
    /// Phrase table of text embeddings.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrases: Option<PathBuf>,
    /// Phrases of an `.npy` (or `.safetensors`) table, one per line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrase_names: Option<PathBuf>,
    /// CLIP text-tower weights that encode the phrases the table lacks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_encoder: Option<PathBuf>,
    /// The text tower's MLP activation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_activation: Option<Activation>,
    /// Canonical negative phrases (default: object, things, stuff, texture).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub negatives: Option<Vec<String>>,
    /// Temperature of the relevancy softmax (default 10).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f32>,
}

impl TextKeys {
    /// The `features` scoring of `features` with these keys, built and checked exactly as a
    /// `features` source's (errors name the key, e.g. `phrases`).
    pub fn features_source(
        &self,
        features: FeatureInput,
        context: &SourceContext,
    ) -> Result<FeaturesSource> {
        let config = TargetsConfig {
            source: SourceKind::Features,
            phrases: self.phrases.clone(),
            phrase_names: self.phrase_names.clone(),
            text_encoder: self.text_encoder.clone(),
            text_activation: self.text_activation,
            negatives: self.negatives.clone(),
            temperature: self.temperature,
            ..Default::default()
        };
        config.features_source(features, &|p| context.resolve(p), context.device, &|k| {
            k.to_string()
        })
    }
}

/// A key of a source's table that neither the source nor [`TextKeys`] knows is an error
/// (serde's `deny_unknown_fields` does not work with a flattened table, so the leftovers are
/// collected and refused here).
pub fn refuse_unknown_keys(
    unknown: &BTreeMap<String, toml::Value>,
    source: &str,
    known: &[&str],
) -> Result<()> {
    match unknown.keys().next() {
        None => Ok(()),
        Some(key) => Err(SemanticError::option(
            key.clone(),
            format!(
                "is not a key of the {source} source (its keys: {}, phrases, phrase_names, \
                 text_encoder, text_activation, negatives, temperature)",
                known.join(", ")
            ),
        )),
    }
}
