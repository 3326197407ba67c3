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
//! - `region`: `regions = { shelf = { box = [x0, y0, z0, x1, y1, z1] }, ball = { sphere = [cx, cy, cz, r] } }`,
//!   or `head = { selection = "head.ply" }`: the splats a user selected in an editor (SuperSplat)
//!   and exported, in any scene format, matched to the scene's Gaussians by position, scale and
//!   colour (refused when it is not part of the scene; `sources::editor_selection`);
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
//!
//! The text keys (`phrases`, `phrase_names`, `text_encoder`, `text_activation`, `text_heads`,
//! `negatives`, `temperature`) are one struct, [`crate::sources::TextKeys`], that every source
//! scoring text reads; each source's keys are one variant of
//! [`crate::source_config::TargetSourceConfig`], whose `init` builds it. [`TargetsConfig`]
//! keeps the table as written until the source is built.

use std::path::Path;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};
use splatraj_config::{ConfigError, from_table};

use crate::error::{Result, SemanticError};
use crate::selection::SelectionOptions;
use crate::source_config::{TargetSourceConfig, check_value, source_keys, unknown_key_hint};
pub use crate::source_kind::{CUSTOM_PREFIX, LIFTED, RegionSpec, SourceKind};
use crate::sources::{SourceRegistry, TargetSource};

/// The `[targets]` table: the source that grounds queries, its keys as written, and the
/// selection (see the module docs for the keys). The default is the `labels` source with
/// default selection.
///
/// The keys stay a table until the source is built, so that a query may choose the source
/// after reading them (from the scene: `splatraj query` without `--source`); reading the
/// table already refuses a key no source takes and a badly typed value, and
/// [`TargetsConfig::source_config`] refuses a key of another source.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(try_from = "toml::Table", into = "toml::Table")]
pub struct TargetsConfig {
    /// Which source turns a query into per-Gaussian values.
    pub source: SourceKind,
    /// The source's keys (every key of the table but `source` and `selection`), as written.
    pub keys: toml::Table,
    /// Percentile, floor and DBSCAN settings.
    pub selection: SelectionOptions,
}

impl TryFrom<toml::Table> for TargetsConfig {
    type Error = ConfigError;

    fn try_from(mut keys: toml::Table) -> std::result::Result<Self, ConfigError> {
        let source = take(&mut keys, "source")?;
        let selection = take(&mut keys, "selection")?;
        for (key, value) in &keys {
            let named = |k: &str| format!("targets.{k}");
            // The value is checked as the first source that takes the key reads it: a key
            // means the same in every source that takes it.
            let owner = SourceKind::ALL
                .into_iter()
                .chain([SourceKind::Custom(String::new())])
                .find(|kind| source_keys(kind).contains(&key.as_str()))
                .ok_or_else(|| {
                    ConfigError::new(
                        named(key),
                        format!("is an unknown field: {}", unknown_key_hint()),
                    )
                })?;
            check_value(&owner, key, value, &named).map_err(|e| match e {
                SemanticError::InvalidOption(e) => e,
                other => ConfigError::new(named(key), other.to_string()),
            })?;
        }
        Ok(TargetsConfig {
            source,
            keys,
            selection,
        })
    }
}

/// `key` removed from `keys` and read as a `T` (the default when it is not there).
fn take<T: serde::de::DeserializeOwned + Default>(
    keys: &mut toml::Table,
    key: &str,
) -> std::result::Result<T, ConfigError> {
    match keys.remove(key) {
        Some(value) => from_table(&value, &format!("targets.{key}")),
        None => Ok(T::default()),
    }
}

impl From<TargetsConfig> for toml::Table {
    fn from(config: TargetsConfig) -> toml::Table {
        let mut table = toml::Table::new();
        table.insert("source".into(), toml::Value::String(config.source.name()));
        table.extend(config.keys);
        // Plain numbers and tables: selection options always serialise.
        if let Ok(selection) = toml::Value::try_from(config.selection) {
            table.insert("selection".into(), selection);
        }
        table
    }
}

impl TargetsConfig {
    /// The config of source `source` with `keys` (as a `[targets]` table holds them) and
    /// default selection; the keys are checked when the source is built.
    pub fn new(source: SourceKind, keys: toml::Table) -> Self {
        TargetsConfig {
            source,
            keys,
            selection: SelectionOptions::default(),
        }
    }

    /// The config of the registered source `name` with its table `[targets.custom.<name>]`.
    pub fn custom(name: &str, table: toml::Table) -> Self {
        let custom = toml::Table::from_iter([(name.to_string(), toml::Value::Table(table))]);
        let keys = toml::Table::from_iter([("custom".to_string(), toml::Value::Table(custom))]);
        Self::new(SourceKind::Custom(name.to_string()), keys)
    }

    /// The typed config of the source, its keys checked: a key of another source is an error
    /// naming it through `key` (`phrases` → `targets.phrases`) and the sources it applies to.
    pub fn source_config(&self, key: &dyn Fn(&str) -> String) -> Result<TargetSourceConfig> {
        TargetSourceConfig::from_keys(&self.source, &self.keys, key)
    }

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
        self.source_config(key)?
            .init(base_dir, device, registry, key)
    }

    /// The selection options, checked; errors name `targets.selection.<key>`.
    pub fn selection(&self) -> Result<SelectionOptions> {
        self.selection.validate_as("targets.selection.")?;
        Ok(self.selection)
    }
}
