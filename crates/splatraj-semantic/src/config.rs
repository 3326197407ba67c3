//! The `[targets]` table of a config file: which source grounds the queries, and its options.
//!
//! ```toml
//! [targets]
//! source = "features"              # labels | region | features | langsplat | lifted
//! phrases = "clip_table.json"      # relative paths are read from the config file's folder
//! negatives = ["object", "things", "stuff", "texture"]
//! temperature = 10
//!
//! [targets.selection]
//! top_fraction = 0.02
//! floor = 0.5
//! cluster = { min_points = 5, eps = { scene = { neighbours = 16, factor = 2 } }, keep = "largest" }
//! ```
//!
//! Keys by source (a key of another source is an error, not silently ignored):
//! - `labels`: `label_names = { "3" = "apple" }` (id → name, adding to the scene's names),
//!   `synonyms = { "red mug" = ["cup", "mug"] }`;
//! - `region`: `regions = { shelf = { box = [x0, y0, z0, x1, y1, z1] }, ball = { sphere = [cx, cy, cz, r] } }`;
//! - `features`: `features` (`.npy`/`.safetensors` `[N, D]`; default: the scene's own feature
//!   properties), `phrases` (phrase table: `.json`, `.npy` with `phrase_names`, `.safetensors`),
//!   `phrase_names`, `negatives`, `temperature`, `text_encoder` (CLIP weights: any phrase can
//!   then be queried; see [`crate::text_encoder`]), `text_activation` (`"gelu"` or
//!   `"quick-gelu"`) and `text_heads` (attention heads), for weights without an
//!   `open_clip_config.json` beside them; at least one of `phrases` and `text_encoder`;
//! - `langsplat`: `latents` (`.npy` `[N, 3]`), `checkpoint` (LangSplat `.pth`), and the phrase
//!   keys of `features`.
//!
//! - `lifted`: a language field lifted from the scene's own renders (built by splatraj-lift,
//!   registered in the experiment's registry): `text_encoder` (CLIP weights with both towers),
//!   `text_activation`, `negatives`, `temperature`, and `[targets.lifted]` (`views`, `field`,
//!   `up`, `cache_dir`); see `docs/lifted.md`.
//!
//! - `custom.<name>`: a source another crate registered in a [`SourceRegistry`]; its keys go in
//!   `[targets.custom.<name>]` (deserialised by its [`crate::sources::SourceConfig`]).
//!   The default registry holds `custom.feature3dgs` (`decoder`, Feature 3DGS's
//!   `decoder_chkpnt*.pth`, optional), `custom.opengaussian` (`cluster_lang`, OpenGaussian's
//!   `cluster_lang.npz`; `min_views`, default 1) and `custom.legaussians` (`index_decoder`,
//!   LEGaussians' `index_decoder_chkpnt*.pth`; `codebook`, its `*_codebook.pt`; `combine`,
//!   `"argmax"` (default) or `"softmax"`; temperature default 100), each also taking the
//!   phrase keys of `features` in its table, and `custom.gaussian_grouping` (`classifier`,
//!   Gaussian Grouping's `classifier.pth`; `min_probability`, default 0.3; `label_names` and
//!   `synonyms` as for `labels`; queries name instance ids or those names); see
//!   `docs/open-vocabulary.md`.
//!
//! `[targets.selection]` holds [`SelectionOptions`] for every source.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use crate::embeddings::{PhraseTable, read_feature_sidecar};
use crate::error::{Result, SemanticError};
use crate::selection::SelectionOptions;
use crate::sources::{
    FeatureInput, FeaturesSource, LabelsSource, LangsplatDecoder, LangsplatSource, Region,
    RegionSource, SourceContext, SourceRegistry, TargetSource,
};
use crate::text_encoder::{Activation, TextEncoder, TextEncoderOptions};
use crate::vectors::{DEFAULT_NEGATIVES, DEFAULT_TEMPERATURE};

/// The kinds of target source: the built-in ones, or `custom.<name>` for a source registered
/// in a [`SourceRegistry`].
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum SourceKind {
    /// Per-Gaussian label ids with names ([`LabelsSource`]).
    #[default]
    Labels,
    /// Named boxes and spheres ([`RegionSource`]).
    Region,
    /// Per-Gaussian embeddings and a phrase table ([`FeaturesSource`]).
    Features,
    /// LangSplat latents decoded by the checkpoint's decoder, then as `features`.
    Langsplat,
    /// A language field lifted from the scene's own renders (no training): built by the
    /// source registered as [`LIFTED`] (splatraj-lift), from `text_encoder` and `[targets.lifted]`.
    Lifted,
    /// A registered source, by its registered name (configs write `custom.<name>`).
    Custom(String),
}

/// The registry name of the `lifted` source (registered by splatraj-lift's users: the
/// experiment crate's registry holds it).
pub const LIFTED: &str = "lifted";

/// How configs name a registered source: `source = "custom.<name>"`.
pub const CUSTOM_PREFIX: &str = "custom.";

impl SourceKind {
    /// The built-in kinds, in documentation order.
    pub const ALL: [SourceKind; 5] = [
        SourceKind::Labels,
        SourceKind::Region,
        SourceKind::Features,
        SourceKind::Langsplat,
        SourceKind::Lifted,
    ];

    /// The name used in configs and on the command line (`custom.<name>` for a registered
    /// source).
    pub fn name(&self) -> String {
        match self {
            SourceKind::Labels => "labels".into(),
            SourceKind::Region => "region".into(),
            SourceKind::Features => "features".into(),
            SourceKind::Langsplat => "langsplat".into(),
            SourceKind::Lifted => LIFTED.into(),
            SourceKind::Custom(name) => format!("{CUSTOM_PREFIX}{name}"),
        }
    }
}

impl fmt::Display for SourceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

impl FromStr for SourceKind {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if let Some(name) = s.strip_prefix(CUSTOM_PREFIX)
            && !name.is_empty()
        {
            return Ok(SourceKind::Custom(name.to_string()));
        }
        SourceKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown source {s:?}: use labels, region, features, langsplat or lifted, \
                     or custom.<name> for a registered source"
                )
            })
    }
}

impl TryFrom<String> for SourceKind {
    type Error = String;

    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl From<SourceKind> for String {
    fn from(kind: SourceKind) -> String {
        kind.name()
    }
}

/// A region as written in a config: `{ box = [x0, y0, z0, x1, y1, z1] }` (two opposite corners)
/// or `{ sphere = [cx, cy, cz, r] }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum RegionSpec {
    /// Axis-aligned box: smallest corner then largest corner.
    Box([f32; 6]),
    /// Ball: centre then radius.
    Sphere([f32; 4]),
}

impl From<RegionSpec> for Region {
    fn from(spec: RegionSpec) -> Region {
        match spec {
            RegionSpec::Box(v) => Region::Box {
                min: [v[0], v[1], v[2]],
                max: [v[3], v[4], v[5]],
            },
            RegionSpec::Sphere(v) => Region::Sphere {
                centre: [v[0], v[1], v[2]],
                radius: v[3],
            },
        }
    }
}

/// The `[targets]` table: the source that grounds queries and its options (see the module
/// docs for the keys). The default is the `labels` source with default selection.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, rename_all = "snake_case", deny_unknown_fields)]
pub struct TargetsConfig {
    /// Which source turns a query into per-Gaussian values.
    pub source: SourceKind,
    /// labels: label id (written as a string key) → name, adding to or replacing the names
    /// the scene carries.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub label_names: BTreeMap<String, String>,
    /// labels: label name → other words that mean it.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub synonyms: BTreeMap<String, Vec<String>>,
    /// region: regions by name; a query names one.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub regions: BTreeMap<String, RegionSpec>,
    /// features: per-Gaussian feature sidecar `[N, D]`; `None`: the scene's own features.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub features: Option<PathBuf>,
    /// features, langsplat: phrase table of text embeddings.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrases: Option<PathBuf>,
    /// features, langsplat: CLIP text-tower weights (`open_clip_model.safetensors`,
    /// `open_clip_pytorch_model.bin`, a safetensors or `torch.save`d state dict) that encode
    /// the phrases the table lacks, so that any phrase can be queried. Never downloaded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_encoder: Option<PathBuf>,
    /// features, langsplat: the text tower's MLP activation, `"gelu"` (open_clip's own towers)
    /// or `"quick-gelu"` (OpenAI's); default: `open_clip_config.json` beside the weights, else
    /// gelu.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_activation: Option<Activation>,
    /// features, langsplat: attention heads of the text tower, for weights without an
    /// `open_clip_config.json` beside them whose heads are not 64 wide (default: the config
    /// beside the weights, else width / 64).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text_heads: Option<usize>,
    /// features, langsplat: phrases of an `.npy` (or `.safetensors`) table, one per line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phrase_names: Option<PathBuf>,
    /// features, langsplat: canonical negative phrases (default: object, things, stuff,
    /// texture).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub negatives: Option<Vec<String>>,
    /// features, langsplat: temperature of the relevancy softmax (default 10).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f32>,
    /// langsplat: per-Gaussian 3-d latents `[N, 3]` (`.npy`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latents: Option<PathBuf>,
    /// langsplat: the LangSplat autoencoder checkpoint (`.pth`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub checkpoint: Option<PathBuf>,
    /// lifted: views, field and cache options (`[targets.lifted]`, read by the registered
    /// `lifted` source: `views.count`, `field.components`, `cache_dir`, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lifted: Option<toml::Table>,
    /// Percentile, floor and DBSCAN settings.
    pub selection: SelectionOptions,
    /// custom.<name>: the config table of each registered source, by name; only the one
    /// `source` names may be given.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub custom: BTreeMap<String, toml::Value>,
}

/// Which sources each optional key applies to, for refusing stray keys.
const KEY_SOURCES: [(&str, &[SourceKind]); 14] = [
    ("label_names", &[SourceKind::Labels]),
    ("synonyms", &[SourceKind::Labels]),
    ("regions", &[SourceKind::Region]),
    ("features", &[SourceKind::Features]),
    ("phrases", &[SourceKind::Features, SourceKind::Langsplat]),
    (
        "phrase_names",
        &[SourceKind::Features, SourceKind::Langsplat],
    ),
    (
        "negatives",
        &[
            SourceKind::Features,
            SourceKind::Langsplat,
            SourceKind::Lifted,
        ],
    ),
    (
        "text_encoder",
        &[
            SourceKind::Features,
            SourceKind::Langsplat,
            SourceKind::Lifted,
        ],
    ),
    (
        "text_activation",
        &[
            SourceKind::Features,
            SourceKind::Langsplat,
            SourceKind::Lifted,
        ],
    ),
    (
        "temperature",
        &[
            SourceKind::Features,
            SourceKind::Langsplat,
            SourceKind::Lifted,
        ],
    ),
    ("text_heads", &[SourceKind::Features, SourceKind::Langsplat]),
    ("latents", &[SourceKind::Langsplat]),
    ("checkpoint", &[SourceKind::Langsplat]),
    ("lifted", &[SourceKind::Lifted]),
];

impl TargetsConfig {
    /// Reads the source's files (paths relative to `base_dir`, the config file's folder) and
    /// builds it; the `langsplat` decoder runs on `device`. Errors name the key
    /// (`targets.phrases`) and, for file errors, the file.
    pub fn build(&self, base_dir: &Path, device: &Device) -> Result<Box<dyn TargetSource>> {
        self.build_with(base_dir, device, &SourceRegistry::default())
    }

    /// As [`TargetsConfig::build`], for a config that may name a source of `registry`.
    pub fn build_with(
        &self,
        base_dir: &Path,
        device: &Device,
        registry: &SourceRegistry,
    ) -> Result<Box<dyn TargetSource>> {
        self.build_named(base_dir, device, registry, &|k| format!("targets.{k}"))
    }

    /// As [`TargetsConfig::build_with`], with `key` turning each config key (`phrases`,
    /// `regions.shelf`) into the name errors use (e.g. a command-line option).
    pub fn build_named(
        &self,
        base_dir: &Path,
        device: &Device,
        registry: &SourceRegistry,
        key: &dyn Fn(&str) -> String,
    ) -> Result<Box<dyn TargetSource>> {
        self.refuse_stray_keys(key)?;
        let resolve = |p: &Path| -> PathBuf {
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                base_dir.join(p)
            }
        };
        Ok(match &self.source {
            SourceKind::Custom(name) => {
                let empty = toml::Value::Table(toml::Table::new());
                let table = self.custom.get(name).unwrap_or(&empty);
                let context = SourceContext { base_dir, device };
                registry.build(name, table, &context, &key(&format!("custom.{name}")))?
            }
            SourceKind::Lifted => {
                let Some(weights) = &self.text_encoder else {
                    return Err(SemanticError::option(
                        key("text_encoder"),
                        "the lifted source needs CLIP weights with both towers (text_encoder = \
                         \"open_clip_model.safetensors\"): the image tower makes the field, the \
                         text tower reads the queries",
                    ));
                };
                // The shared keys join the source's own table, which it deserialises; set
                // there too, one would silently win over the other.
                let mut table = self.lifted.clone().unwrap_or_default();
                for (inner, shared) in [
                    ("weights", "text_encoder"),
                    ("activation", "text_activation"),
                    ("negatives", "negatives"),
                    ("temperature", "temperature"),
                ] {
                    if table.contains_key(inner) {
                        return Err(SemanticError::option(
                            key(&format!("lifted.{inner}")),
                            format!("is set in [targets] as `{shared}`, not in [targets.lifted]"),
                        ));
                    }
                }
                let mut shared = |name: &str, value: Option<toml::Value>| {
                    if let Some(value) = value {
                        table.insert(name.to_string(), value);
                    }
                };
                shared(
                    "weights",
                    Some(toml::Value::String(weights.to_string_lossy().into())),
                );
                shared(
                    "activation",
                    self.text_activation
                        .map(|a| toml::Value::String(a.name().into())),
                );
                shared(
                    "negatives",
                    self.negatives.as_ref().map(|n| {
                        toml::Value::Array(
                            n.iter().map(|s| toml::Value::String(s.clone())).collect(),
                        )
                    }),
                );
                shared(
                    "temperature",
                    self.temperature.map(|t| toml::Value::Float(f64::from(t))),
                );
                if !registry.contains(LIFTED) {
                    return Err(SemanticError::option(
                        key("source"),
                        "the lifted source is built by splatraj-lift: use a registry that holds it \
                         (splatraj-experiment's does)",
                    ));
                }
                let context = SourceContext { base_dir, device };
                registry.build(LIFTED, &toml::Value::Table(table), &context, &key("lifted"))?
            }
            SourceKind::Labels => {
                let mut names = BTreeMap::new();
                for (id, name) in &self.label_names {
                    let parsed = id.trim().parse::<i32>().map_err(|_| {
                        SemanticError::option(
                            key(&format!("label_names.{id:?}")),
                            format!("{id:?} is not a label id (an integer)"),
                        )
                    })?;
                    names.insert(parsed, name.clone());
                }
                Box::new(LabelsSource {
                    names,
                    synonyms: self.synonyms.clone(),
                    cluster: false,
                })
            }
            SourceKind::Region => {
                if self.regions.is_empty() {
                    return Err(SemanticError::option(
                        key("regions"),
                        "the region source needs at least one region, e.g. regions = { shelf = \
                         { box = [x0, y0, z0, x1, y1, z1] } }",
                    ));
                }
                let mut regions = BTreeMap::new();
                for (name, spec) in &self.regions {
                    let region = Region::from(*spec);
                    region.validate(&key(&format!("regions.{name}")))?;
                    regions.insert(name.clone(), region);
                }
                Box::new(RegionSource { regions })
            }
            SourceKind::Features => {
                let features = match &self.features {
                    Some(p) => FeatureInput::Sidecar(
                        read_feature_sidecar(&resolve(p)).map_err(|e| e.in_key(key("features")))?,
                    ),
                    None => FeatureInput::Scene,
                };
                Box::new(self.features_source(features, &resolve, device, key)?)
            }
            SourceKind::Langsplat => {
                // Checked before the (slow) decoding, which would be wasted without it.
                self.text_inputs(key)?;
                let required = |name: &str, value: &Option<PathBuf>, what: &str| {
                    value.as_deref().map(&resolve).ok_or_else(|| {
                        SemanticError::option(
                            key(name),
                            format!("the langsplat source needs {what}"),
                        )
                    })
                };
                let checkpoint = required(
                    "checkpoint",
                    &self.checkpoint,
                    "the scene's LangSplat autoencoder checkpoint (best_ckpt.pth)",
                )?;
                let latents = required(
                    "latents",
                    &self.latents,
                    "the per-Gaussian latents ([N, 3], .npy)",
                )?;
                // The latents file is read before the (larger) checkpoint is decoded onto
                // the device, so that a wrong path fails fast.
                let latents =
                    read_feature_sidecar(&latents).map_err(|e| e.in_key(key("latents")))?;
                let decoder = LangsplatDecoder::from_checkpoint(&checkpoint, device)
                    .map_err(|e| e.in_key(key("checkpoint")))?;
                let decoded = decoder
                    .decode(&latents)
                    .map_err(|e| e.in_key(key("latents")))?;
                Box::new(LangsplatSource {
                    features: self.features_source(
                        FeatureInput::Sidecar(decoded),
                        &resolve,
                        device,
                        key,
                    )?,
                })
            }
        })
    }

    /// The selection options, checked; errors name `targets.selection.<key>`.
    pub fn selection(&self) -> Result<SelectionOptions> {
        self.selection.validate_as("targets.selection.")?;
        Ok(self.selection)
    }

    /// A key set for a source it does not apply to is an error: it would be silently ignored.
    /// The keys set are those the table writes back (unset ones are skipped when
    /// serialising), so a new key needs only its field and its entry in [`KEY_SOURCES`].
    fn refuse_stray_keys(&self, key: &dyn Fn(&str) -> String) -> Result<()> {
        let written = toml::Table::try_from(self).map_err(|e| {
            SemanticError::option(key("source"), format!("cannot be written back: {e}"))
        })?;
        for (name, sources) in KEY_SOURCES {
            if written.contains_key(name) && !sources.contains(&self.source) {
                let names: Vec<String> = sources.iter().map(|s| s.name()).collect();
                return Err(SemanticError::option(
                    key(name),
                    format!(
                        "applies to the {} source only, not to the {} source",
                        names.join(" and "),
                        self.source
                    ),
                ));
            }
        }
        for name in self.custom.keys() {
            if self.source != SourceKind::Custom(name.clone()) {
                return Err(SemanticError::option(
                    key(&format!("custom.{name}")),
                    format!(
                        "applies to the source custom.{name} only, not to the {} source",
                        self.source
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The error of a features or langsplat source without text embeddings.
    fn no_text_inputs(&self, key: &dyn Fn(&str) -> String) -> SemanticError {
        SemanticError::option(
            key("phrases"),
            format!(
                "the {} source needs text embeddings: a CLIP text encoder (text_encoder = \
                 \"open_clip_model.safetensors\") for any phrase, or a phrase table (.json, \
                 .npy with its phrase names file, or .safetensors)",
                self.source
            ),
        )
    }

    /// Whether the text embeddings have a source: a phrase table, a text encoder or both.
    fn text_inputs(&self, key: &dyn Fn(&str) -> String) -> Result<()> {
        if self.phrases.is_none() && self.text_encoder.is_none() {
            return Err(self.no_text_inputs(key));
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
    /// bad negative or temperature fails before any query.
    pub(crate) fn features_source(
        &self,
        features: FeatureInput,
        resolve: &dyn Fn(&Path) -> PathBuf,
        device: &Device,
        key: &dyn Fn(&str) -> String,
    ) -> Result<FeaturesSource> {
        self.text_inputs(key)?;
        let encoder = match &self.text_encoder {
            Some(p) => {
                let options = TextEncoderOptions {
                    activation: self.text_activation,
                    heads: self.text_heads,
                };
                let encoder = TextEncoder::from_file(&resolve(p), options, device)
                    .map_err(|e| e.in_key(key("text_encoder")))?;
                Some(std::sync::Arc::new(encoder))
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
            (None, None) => return Err(self.no_text_inputs(key)),
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
