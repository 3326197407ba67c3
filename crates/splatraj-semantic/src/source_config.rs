//! The typed config of the target source a `[targets]` table names: one variant per source,
//! each holding exactly its keys (the text keys as one [`TextKeys`]), and one
//! [`TargetSourceConfig::init`] that builds the source (burn's `XConfig` → `init()`).
//!
//! The per-source structs also serialise, set keys only: a command line's options
//! (`splatraj query --phrases`) are written into a `[targets]` table through them, so that
//! the options and a config file name each key the same way.
//!
//! [`crate::TargetsConfig`] holds the table as written (so that the source can still be chosen
//! after reading it, e.g. from the scene); [`TargetSourceConfig::from_keys`] turns its keys into
//! this type, refusing a key of another source by name.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::embeddings::read_feature_sidecar;
use crate::error::{Result, SemanticError};
use crate::source_kind::{LIFTED, RegionSpec, SourceKind};
use crate::sources::{
    FeatureInput, LabelsSource, LangsplatDecoder, LangsplatSource, RegionSource, SelectionFile,
    SourceContext, SourceRegistry, TargetSource, TextKeys,
};
use crate::struct_keys::struct_keys;

/// The typed config of one target source.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetSourceConfig {
    /// `labels`: per-Gaussian label ids with names ([`LabelsSource`]).
    Labels(LabelsConfig),
    /// `region`: named boxes and spheres ([`RegionSource`]).
    Region(RegionConfig),
    /// `features`: per-Gaussian embeddings scored against text embeddings.
    Features(FeaturesConfig),
    /// `langsplat`: LangSplat latents decoded by the checkpoint's decoder, then as `features`.
    Langsplat(LangsplatConfig),
    /// `lifted`: a language field lifted from the scene's own renders (built by the source
    /// registered as [`LIFTED`]).
    Lifted(LiftedConfig),
    /// `custom.<name>`: a source registered in a [`SourceRegistry`], with its own table.
    Custom {
        /// The registered name.
        name: String,
        /// `[targets.custom.<name>]`, deserialised by the source's own config type.
        table: toml::Table,
    },
}

/// `labels`: `label_names = { "3" = "apple" }`, `synonyms = { "red mug" = ["cup", "mug"] }`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabelsConfig {
    /// Label id (written as a string key) → name, adding to or replacing the names the scene
    /// carries.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub label_names: BTreeMap<String, String>,
    /// Label name → other words that mean it.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub synonyms: BTreeMap<String, Vec<String>>,
}

/// `region`: `regions = { shelf = { box = [x0, y0, z0, x1, y1, z1] }, head = { selection =
/// "head.ply" } }`; a query names one.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionConfig {
    /// Regions by name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub regions: BTreeMap<String, RegionSpec>,
}

/// `features`: the per-Gaussian vectors and the [`TextKeys`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeaturesConfig {
    /// Per-Gaussian feature sidecar `[N, D]`; `None`: the scene's own features.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub features: Option<PathBuf>,
    /// Text embeddings and scoring (the table's text keys).
    #[serde(skip)]
    pub text: TextKeys,
}

/// `langsplat`: latents, the autoencoder checkpoint and the [`TextKeys`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LangsplatConfig {
    /// Per-Gaussian 3-d latents `[N, 3]` (`.npy`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latents: Option<PathBuf>,
    /// The LangSplat autoencoder checkpoint (`.pth`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub checkpoint: Option<PathBuf>,
    /// Text embeddings and scoring (the table's text keys).
    #[serde(skip)]
    pub text: TextKeys,
}

/// `lifted`: `[targets.lifted]` and the text keys the lifted source takes
/// ([`LIFTED_TEXT_KEYS`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LiftedConfig {
    /// Views, field and cache options (`views.count`, `field.components`, `cache_dir`, …),
    /// read by the registered `lifted` source.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lifted: Option<toml::Table>,
    /// The text keys of [`LIFTED_TEXT_KEYS`].
    #[serde(skip)]
    pub text: TextKeys,
}

/// The text keys the `lifted` source takes, and their names in its own table (it scores with
/// the image tower's field, so the phrase-table keys do not apply).
pub const LIFTED_TEXT_KEYS: [(&str, &str); 4] = [
    ("text_encoder", "weights"),
    ("text_activation", "activation"),
    ("negatives", "negatives"),
    ("temperature", "temperature"),
];

/// The keys of `[targets]` that the source `kind` takes (besides `source` and `selection`).
pub fn source_keys(kind: &SourceKind) -> Vec<&'static str> {
    let (own, text): (&[&str], Vec<&str>) = match kind {
        SourceKind::Labels => (struct_keys::<LabelsConfig>(), vec![]),
        SourceKind::Region => (struct_keys::<RegionConfig>(), vec![]),
        SourceKind::Features => (struct_keys::<FeaturesConfig>(), TextKeys::keys().to_vec()),
        SourceKind::Langsplat => (struct_keys::<LangsplatConfig>(), TextKeys::keys().to_vec()),
        SourceKind::Lifted => (
            struct_keys::<LiftedConfig>(),
            LIFTED_TEXT_KEYS.iter().map(|(k, _)| *k).collect(),
        ),
        SourceKind::Custom(_) => (struct_keys::<CustomTables>(), vec![]),
    };
    own.iter().copied().chain(text).collect()
}

/// Checks that `value` is a well-typed value of `key` for the built-in source `kind` (which
/// takes the key); the error names `key` through `name`.
pub(crate) fn check_value(
    kind: &SourceKind,
    key: &str,
    value: &toml::Value,
    name: &dyn Fn(&str) -> String,
) -> Result<()> {
    let table = toml::Table::from_iter([(key.to_string(), value.clone())]);
    if TextKeys::keys().contains(&key) {
        return typed::<TextKeys>(table, name).map(drop);
    }
    match kind {
        SourceKind::Labels => typed::<LabelsConfig>(table, name).map(drop),
        SourceKind::Region => typed::<RegionConfig>(table, name).map(drop),
        SourceKind::Features => typed::<FeaturesConfig>(table, name).map(drop),
        SourceKind::Langsplat => typed::<LangsplatConfig>(table, name).map(drop),
        SourceKind::Lifted => typed::<LiftedConfig>(table, name).map(drop),
        SourceKind::Custom(_) => typed::<CustomTables>(table, name).map(drop),
    }
}

/// `[targets.custom]`: the table of each registered source, by name.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct CustomTables {
    custom: BTreeMap<String, toml::Table>,
}

/// `table` as `C`; an error names the key serde stopped at through `name`.
fn typed<C: DeserializeOwned>(table: toml::Table, name: &dyn Fn(&str) -> String) -> Result<C> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        SemanticError::option(
            name(&e.path().to_string()),
            e.into_inner().message().trim_end(),
        )
    })
}

impl TargetSourceConfig {
    /// The config of source `kind` from the `[targets]` keys `keys` (neither `source` nor
    /// `selection`): a key another source takes is refused, naming it through `name` and the
    /// sources it applies to, as is a key no source takes.
    pub fn from_keys(
        kind: &SourceKind,
        keys: &toml::Table,
        name: &dyn Fn(&str) -> String,
    ) -> Result<Self> {
        let accepted = source_keys(kind);
        for key in keys.keys() {
            if !accepted.contains(&key.as_str()) {
                return Err(stray_key(kind, key, keys, name));
            }
        }
        if let SourceKind::Custom(own) = kind
            && let Some(custom) = keys.get("custom").and_then(toml::Value::as_table)
            && let Some(other) = custom.keys().find(|n| *n != own)
        {
            return Err(stray_custom(kind, other, name));
        }
        let (text, own): (toml::Table, toml::Table) = keys
            .clone()
            .into_iter()
            .partition(|(k, _)| TextKeys::keys().contains(&k.as_str()));
        Ok(match kind {
            SourceKind::Labels => TargetSourceConfig::Labels(typed(own, name)?),
            SourceKind::Region => TargetSourceConfig::Region(typed(own, name)?),
            SourceKind::Features => TargetSourceConfig::Features(FeaturesConfig {
                text: typed(text, name)?,
                ..typed(own, name)?
            }),
            SourceKind::Langsplat => TargetSourceConfig::Langsplat(LangsplatConfig {
                text: typed(text, name)?,
                ..typed(own, name)?
            }),
            SourceKind::Lifted => TargetSourceConfig::Lifted(LiftedConfig {
                text: typed(text, name)?,
                ..typed(own, name)?
            }),
            SourceKind::Custom(custom) => {
                let mut tables: CustomTables = typed(own, name)?;
                TargetSourceConfig::Custom {
                    name: custom.clone(),
                    table: tables.custom.remove(custom).unwrap_or_default(),
                }
            }
        })
    }

    /// Reads the source's files (paths relative to `base_dir`) and builds it, with the
    /// sources of `registry` for `custom.<name>` and `lifted`, models on `device`. Errors
    /// name the key through `key` (`phrases` → `targets.phrases`, or a command-line option).
    pub fn init(
        &self,
        base_dir: &Path,
        device: &Device,
        registry: &SourceRegistry,
        key: &dyn Fn(&str) -> String,
    ) -> Result<Box<dyn TargetSource>> {
        let context = SourceContext { base_dir, device };
        let resolve = |p: &Path| context.resolve(p);
        Ok(match self {
            // A key inside the source's table is named whole (`custom.<name>.<key>`), so that a
            // command line names the option that set it (`--text-encoder`), a config its key.
            TargetSourceConfig::Custom { name, table } => registry
                .build(
                    name,
                    &toml::Value::Table(table.clone()),
                    &context,
                    &key(&format!("custom.{name}")),
                )
                .map_err(|e| match e {
                    SemanticError::Config { key: outer, error } => match *error {
                        SemanticError::Config { key: inner, error } => {
                            error.in_key(key(&format!("custom.{name}.{inner}")))
                        }
                        error => error.in_key(outer),
                    },
                    other => other,
                })?,
            TargetSourceConfig::Lifted(c) => c.init(&context, registry, key)?,
            TargetSourceConfig::Labels(c) => {
                let mut names = BTreeMap::new();
                for (id, label) in &c.label_names {
                    let parsed = id.trim().parse::<i32>().map_err(|_| {
                        SemanticError::option(
                            key(&format!("label_names.{id:?}")),
                            format!("{id:?} is not a label id (an integer)"),
                        )
                    })?;
                    names.insert(parsed, label.clone());
                }
                Box::new(LabelsSource {
                    names,
                    synonyms: c.synonyms.clone(),
                    cluster: false,
                })
            }
            TargetSourceConfig::Region(c) => {
                if c.regions.is_empty() {
                    return Err(SemanticError::option(
                        key("regions"),
                        "the region source needs at least one region, e.g. regions = { shelf = \
                         { box = [x0, y0, z0, x1, y1, z1] } }",
                    ));
                }
                let mut regions = BTreeMap::new();
                let mut selections = BTreeMap::new();
                for (name, spec) in &c.regions {
                    let at = key(&format!("regions.{name}"));
                    match (spec, spec.shape()) {
                        (RegionSpec::Selection(path), _) => {
                            let file = SelectionFile::read(&resolve(path))
                                .map_err(|e| e.in_key(key(&format!("regions.{name}.selection"))))?;
                            selections.insert(name.clone(), file);
                        }
                        (_, Some(region)) => {
                            region.validate(&at)?;
                            regions.insert(name.clone(), region);
                        }
                        (_, None) => unreachable!("a box or a sphere has a shape"),
                    }
                }
                Box::new(RegionSource {
                    regions,
                    selections,
                })
            }
            TargetSourceConfig::Features(c) => {
                let features = match &c.features {
                    Some(p) => FeatureInput::Sidecar(
                        read_feature_sidecar(&resolve(p)).map_err(|e| e.in_key(key("features")))?,
                    ),
                    None => FeatureInput::Scene,
                };
                Box::new(
                    c.text
                        .scoring(features, &resolve, device, key, "features")?,
                )
            }
            TargetSourceConfig::Langsplat(c) => {
                // Checked before the (slow) decoding, which would be wasted without it.
                c.text.check(key, "langsplat")?;
                let required = |name: &str, value: &Option<PathBuf>, what: &str| {
                    value.as_deref().map(resolve).ok_or_else(|| {
                        SemanticError::option(
                            key(name),
                            format!("the langsplat source needs {what}"),
                        )
                    })
                };
                let checkpoint = required(
                    "checkpoint",
                    &c.checkpoint,
                    "the scene's LangSplat autoencoder checkpoint (best_ckpt.pth)",
                )?;
                let latents = required(
                    "latents",
                    &c.latents,
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
                    features: c.text.scoring(
                        FeatureInput::Sidecar(decoded),
                        &resolve,
                        device,
                        key,
                        "langsplat",
                    )?,
                })
            }
        })
    }
}

impl LiftedConfig {
    /// The lifted source's own table: `[targets.lifted]` with the text keys under the names it
    /// reads ([`LIFTED_TEXT_KEYS`]), built by the registry's `lifted` source.
    fn init(
        &self,
        context: &SourceContext,
        registry: &SourceRegistry,
        key: &dyn Fn(&str) -> String,
    ) -> Result<Box<dyn TargetSource>> {
        if self.text.text_encoder.is_none() {
            return Err(SemanticError::option(
                key("text_encoder"),
                "the lifted source needs CLIP weights with both towers (text_encoder = \
                 \"open_clip_model.safetensors\"): the image tower makes the field, the text \
                 tower reads the queries",
            ));
        }
        // The shared keys join the source's own table, which it deserialises; set there too,
        // one would silently win over the other.
        let mut table = self.lifted.clone().unwrap_or_default();
        for (shared, inner) in LIFTED_TEXT_KEYS {
            if table.contains_key(inner) {
                return Err(SemanticError::option(
                    key(&format!("lifted.{inner}")),
                    format!("is set in [targets] as `{shared}`, not in [targets.lifted]"),
                ));
            }
        }
        let set = self.text.set_keys();
        for (shared, inner) in LIFTED_TEXT_KEYS {
            if let Some(value) = set.get(shared) {
                table.insert(inner.to_string(), value.clone());
            }
        }
        if !registry.contains(LIFTED) {
            return Err(SemanticError::option(
                key("source"),
                "the lifted source is built by splatraj-lift: use a registry that holds it \
                 (splatraj-experiment's does)",
            ));
        }
        // The source names its own keys (`weights`) inside `lifted`; one the user set through a
        // shared key is named as they wrote it (`text_encoder`, `--text-encoder`), not as the
        // lifted table (`--source-key`) they never touched.
        registry
            .build(LIFTED, &toml::Value::Table(table), context, &key("lifted"))
            .map_err(|e| match e {
                SemanticError::Config { key: outer, error } => match *error {
                    SemanticError::Config { key: inner, error } => {
                        let shared = LIFTED_TEXT_KEYS
                            .iter()
                            .find(|(shared, own)| *own == inner && set.contains_key(*shared));
                        match shared {
                            Some((shared, _)) => error.in_key(key(shared)),
                            None => error.in_key(key(&format!("lifted.{inner}"))),
                        }
                    }
                    error => error.in_key(outer),
                },
                other => other,
            })
    }
}

/// The error of `key`, set for source `kind` that does not take it: the sources it applies
/// to, or that no source takes it.
fn stray_key(
    kind: &SourceKind,
    key: &str,
    keys: &toml::Table,
    name: &dyn Fn(&str) -> String,
) -> SemanticError {
    if key == "custom" {
        let other = keys
            .get("custom")
            .and_then(toml::Value::as_table)
            .and_then(|t| t.keys().next().cloned())
            .unwrap_or_default();
        return stray_custom(kind, &other, name);
    }
    let owners: Vec<String> = SourceKind::ALL
        .iter()
        .filter(|k| source_keys(k).contains(&key))
        .map(SourceKind::name)
        .collect();
    if owners.is_empty() {
        return SemanticError::option(
            name(key),
            format!("is not a key of any source: {}", unknown_key_hint()),
        );
    }
    SemanticError::option(
        name(key),
        format!(
            "applies to the {} source only, not to the {kind} source",
            owners.join(" and ")
        ),
    )
}

/// The error of `[targets.custom.<other>]` set for source `kind`.
fn stray_custom(kind: &SourceKind, other: &str, name: &dyn Fn(&str) -> String) -> SemanticError {
    SemanticError::option(
        name(&format!("custom.{other}")),
        format!("applies to the source custom.{other} only, not to the {kind} source"),
    )
}

/// The keys a `[targets]` table may hold, for the message of an unknown one.
pub(crate) fn unknown_key_hint() -> String {
    let mut keys = vec!["source", "selection"];
    for kind in SourceKind::ALL
        .iter()
        .chain([&SourceKind::Custom(String::new())])
    {
        for key in source_keys(kind) {
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
    }
    format!("the [targets] keys are {}", keys.join(", "))
}
