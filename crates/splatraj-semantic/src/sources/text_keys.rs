//! The text-embedding keys every source that scores text shares (`phrases`, `text_encoder`,
//! `negatives`, ...): one struct, read from `[targets]` by the `features`, `langsplat` and
//! `lifted` sources and flattened into the tables of registered sources. A new text option is
//! one field here: every source that scores text reads it, stray-key checks and key lists
//! follow from the struct.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::embeddings::PhraseTable;
use crate::error::{Result, SemanticError};
use crate::sources::{FeatureInput, FeaturesSource, SourceContext};
use crate::struct_keys::struct_keys;
use crate::text_encoder::{Activation, TextEncoder, TextEncoderOptions};
use crate::vectors::{DEFAULT_NEGATIVES, DEFAULT_TEMPERATURE};

/// Where the text embeddings of a language-field source come from, and how they are scored
/// (at least one of `phrases` and `text_encoder`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TextKeys {
    /// Phrase table of text embeddings (`.json`, `.npy` with `phrase_names`, `.safetensors`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrases: Option<PathBuf>,
    /// Phrases of an `.npy` (or `.safetensors`) table, one per line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrase_names: Option<PathBuf>,
    /// CLIP text-tower weights (`open_clip_model.safetensors`, `open_clip_pytorch_model.bin`,
    /// a safetensors or `torch.save`d state dict) that encode the phrases the table lacks, so
    /// that any phrase can be queried. Never downloaded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_encoder: Option<PathBuf>,
    /// The text tower's MLP activation, `"gelu"` (open_clip's own towers) or `"quick-gelu"`
    /// (OpenAI's); default: `open_clip_config.json` beside the weights, else gelu.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_activation: Option<Activation>,
    /// Attention heads of the text tower, for weights without an `open_clip_config.json`
    /// beside them whose heads are not 64 wide (default: the config beside the weights, else
    /// width / 64).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_heads: Option<usize>,
    /// Canonical negative phrases (default: object, things, stuff, texture).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub negatives: Option<Vec<String>>,
    /// Temperature of the relevancy softmax (default 10).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f32>,
}

impl TextKeys {
    /// The keys, as configs write them.
    pub fn keys() -> &'static [&'static str] {
        struct_keys::<TextKeys>()
    }

    /// The keys that are set, with their values, as a config table holds them.
    pub fn set_keys(&self) -> toml::Table {
        // Unset keys are skipped when serialising; a plain struct of paths, strings and
        // numbers always serialises.
        toml::Table::try_from(self).unwrap_or_default()
    }

    /// The `features` scoring of `features` with these keys, as a registered source builds it
    /// (errors name the key inside the source's table, e.g. `phrases`).
    pub fn features_source(
        &self,
        features: FeatureInput,
        context: &SourceContext,
    ) -> Result<FeaturesSource> {
        self.scoring(
            features,
            &|p| context.resolve(p),
            context.device,
            &|k| k.to_string(),
            "features",
        )
    }

    /// Refuses keys without text embeddings (no phrase table and no encoder) and encoder
    /// options without an encoder, before any slow work; `source` names the source in
    /// messages.
    pub(crate) fn check(&self, key: &dyn Fn(&str) -> String, source: &str) -> Result<()> {
        if self.phrases.is_none() && self.text_encoder.is_none() {
            return Err(no_text_inputs(key, source));
        }
        for (name, set) in [
            ("text_activation", self.text_activation.is_some()),
            ("text_heads", self.text_heads.is_some()),
        ] {
            if set && self.text_encoder.is_none() {
                return Err(SemanticError::option(
                    key(name),
                    "applies to a text encoder, but none is given (text_encoder)",
                ));
            }
        }
        if self.text_heads == Some(0) {
            return Err(SemanticError::option(key("text_heads"), "must be ≥ 1"));
        }
        Ok(())
    }

    /// The phrase table, negatives and temperature around `features`, checked now so that a
    /// bad negative or temperature fails before any query. Paths go through `resolve`, errors
    /// name keys through `key`, and `source` names the source in messages.
    pub(crate) fn scoring(
        &self,
        features: FeatureInput,
        resolve: &dyn Fn(&Path) -> PathBuf,
        device: &Device,
        key: &dyn Fn(&str) -> String,
        source: &str,
    ) -> Result<FeaturesSource> {
        self.check(key, source)?;
        let encoder = match &self.text_encoder {
            Some(p) => {
                let options = TextEncoderOptions {
                    activation: self.text_activation,
                    heads: self.text_heads,
                };
                let encoder = TextEncoder::from_file(&resolve(p), options, device)
                    .map_err(|e| e.in_key(key("text_encoder")))?;
                Some(Arc::new(encoder))
            }
            None => None,
        };
        let negatives = match &self.negatives {
            Some(n) => n.clone(),
            None => DEFAULT_NEGATIVES.iter().map(|s| s.to_string()).collect(),
        };
        if negatives.is_empty() {
            return Err(SemanticError::option(
                key("negatives"),
                "at least one canonical negative phrase is needed: without one every relevancy \
                 is 1 and nothing can be told apart",
            ));
        }
        let table = match (&self.phrases, &encoder) {
            (Some(phrases), _) => {
                let phrase_names = self.phrase_names.as_deref().map(resolve);
                let table = PhraseTable::read(&resolve(phrases), phrase_names.as_deref())
                    .map_err(|e| e.in_key(key("phrases")))?;
                match &encoder {
                    Some(encoder) if encoder.dim() != table.dim() => {
                        return Err(SemanticError::Mismatch(format!(
                            "the phrase table {} has vectors of length {} but the text encoder \
                             {} makes {}: they must come from the same CLIP model",
                            table.source,
                            table.dim(),
                            encoder.source().display(),
                            encoder.dim()
                        ))
                        .in_key(key("text_encoder")));
                    }
                    // The negatives the table lacks are encoded once, here, not per query.
                    Some(encoder) => {
                        let missing: Vec<String> = negatives
                            .iter()
                            .filter(|n| table.get(n, "").is_err())
                            .cloned()
                            .collect();
                        table
                            .extended(&encoder.table(&missing)?)
                            .map_err(|e| e.in_key(key("phrases")))?
                    }
                    None => table,
                }
            }
            (None, Some(encoder)) => encoder
                .table(&negatives)
                .map_err(|e| e.in_key(key("negatives")))?,
            (None, None) => return Err(no_text_inputs(key, source)),
        };
        for n in &negatives {
            table
                .get(n, "canonical negative phrase")
                .map_err(|e| e.in_key(key("negatives")))?;
        }
        let temperature = self.temperature.unwrap_or(DEFAULT_TEMPERATURE);
        if !(temperature.is_finite() && temperature > 0.0) {
            return Err(SemanticError::option(
                key("temperature"),
                format!("{temperature} must be finite and > 0"),
            ));
        }
        Ok(FeaturesSource {
            features,
            table,
            negatives,
            temperature,
            encoder,
        })
    }
}

/// The error of a source that scores text without text embeddings.
fn no_text_inputs(key: &dyn Fn(&str) -> String, source: &str) -> SemanticError {
    SemanticError::option(
        key("phrases"),
        format!(
            "the {source} source needs text embeddings: a CLIP text encoder (text_encoder = \
             \"open_clip_model.safetensors\") for any phrase, or a phrase table (.json, .npy \
             with its phrase names file, or .safetensors)"
        ),
    )
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
        Some(key) => {
            let keys: Vec<&str> = known.iter().chain(TextKeys::keys()).copied().collect();
            Err(SemanticError::option(
                key.clone(),
                format!(
                    "is not a key of the {source} source (its keys: {})",
                    keys.join(", ")
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_keys_are_the_fields_and_set_keys_only_the_set_ones() {
        // Spelt out here, independently of the struct, so that a renamed key shows.
        assert_eq!(
            TextKeys::keys(),
            [
                "phrases",
                "phrase_names",
                "text_encoder",
                "text_activation",
                "text_heads",
                "negatives",
                "temperature"
            ]
        );
        let keys = TextKeys {
            text_heads: Some(4),
            temperature: Some(2.0),
            ..Default::default()
        };
        let set = keys.set_keys();
        assert_eq!(set.len(), 2);
        assert_eq!(set["text_heads"].as_integer(), Some(4));
        let back: TextKeys = set.try_into().unwrap();
        assert_eq!(back, keys);
    }
}
