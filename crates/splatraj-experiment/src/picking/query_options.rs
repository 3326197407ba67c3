//! What `splatraj query`'s scene and source options set, typed, and the one function that
//! makes the config of them: the options' own config (`name = "query"`, one `[[queries]]`),
//! or a run config's with the options over its keys; `--set` over both. The options are
//! written into the config's tables through the schema's own types
//! ([`splatraj_semantic::TextKeys`], [`LabelsConfig`], [`RegionConfig`], …), so an option
//! and the key a config file writes reach the same [`Config`] by the same reading.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use splatraj_scene::{InvalidPolicy, ReadOptions};
use splatraj_semantic::{
    FeaturesConfig, LabelsConfig, LangsplatConfig, LiftedConfig, RegionConfig, RegionSpec,
    SourceKind, TargetsConfig, TextKeys,
};

use super::query::option_of_key;
use crate::config::{Config, ConfigFile, Override};
use crate::extensions::Extensions;

/// The scene and source options of a query, typed; unset ones leave a config's keys as they
/// are.
#[derive(Debug, Clone, Default)]
pub struct QueryOptions {
    /// `[scene] path`.
    pub scene: Option<PathBuf>,
    /// `[scene] labels` and `drop_invalid`.
    pub read: ReadOptions,
    /// The query: the `[[queries]]` entry of the options' own config, and the name of the
    /// region of [`TargetOptions::region`].
    pub query: Option<String>,
    /// The `[targets]` keys.
    pub targets: TargetOptions,
}

/// The `[targets]` keys of a query's options.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TargetOptions {
    /// `source`; `None`: the config's (else chosen from the inputs).
    pub source: Option<SourceKind>,
    /// `synonyms` (`label_names` stays empty).
    pub labels: LabelsConfig,
    /// One region, named after the query (`regions = { <query> = … }`).
    pub region: Option<RegionSpec>,
    /// `features`.
    pub features: FeaturesConfig,
    /// `latents`, `checkpoint`.
    pub langsplat: LangsplatConfig,
    /// The text keys (`phrases`, `text_encoder`, `negatives`, …).
    pub text: TextKeys,
    /// A registered source's own keys (`[targets.custom.<name>]`, with the keys above moved
    /// into it), else `[targets.lifted]`.
    pub source_keys: toml::Table,
    /// `[targets.selection]` keys set.
    pub selection: SelectionKeys,
}

/// The `[targets.selection]` keys of a query's options, only those given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct SelectionKeys {
    /// `top_fraction`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub top_fraction: Option<f32>,
    /// `floor`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor: Option<f32>,
    /// `cluster` (`false`: no density clustering).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<bool>,
}

/// `[scene]` keys of a query's options, only those given.
#[derive(Serialize)]
struct SceneKeys<'a> {
    #[serde(skip_serializing_if = "Option::is_none")]
    path: Option<&'a Path>,
    #[serde(skip_serializing_if = "Option::is_none")]
    labels: Option<&'a Path>,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    drop_invalid: bool,
}

/// The top level of the options' own config.
#[derive(Serialize)]
struct OwnConfig<'a> {
    name: &'a str,
    queries: [OwnQuery<'a>; 1],
}

/// Its one `[[queries]]` entry.
#[derive(Serialize)]
struct OwnQuery<'a> {
    text: &'a str,
}

impl QueryOptions {
    /// The config of these options with `set` (`--set KEY=VALUE`) over them: `file`'s (a run
    /// config; relative paths of the options are made absolute, since the file reads its own
    /// from its folder), else the options' own (paths as given). Low to high: the file, the
    /// options, `set`.
    pub fn config(
        &self,
        file: Option<&Path>,
        set: &[String],
        extensions: &Extensions,
    ) -> Result<Config> {
        match file {
            Some(path) => {
                let layer = self.absolute()?.table()?;
                let file = ConfigFile::read(path)?.with_layer(layer);
                file.config(&Override::parse_all(set)?, extensions)
            }
            None => {
                let query = self
                    .query
                    .as_deref()
                    .context("--query is needed without --config")?;
                if self.scene.is_none() {
                    bail!("--scene (or --config) is needed");
                }
                let mut table = self.table()?;
                table.extend(toml::Table::try_from(OwnConfig {
                    name: "query",
                    queries: [OwnQuery { text: query }],
                })?);
                let set = Override::parse_all(set)?;
                Config::from_edited_table(
                    table,
                    Path::new(""),
                    &set,
                    "the query options",
                    extensions,
                )
            }
        }
    }

    /// The config keys the options set, only those given: `[scene]` and `[targets]`.
    fn table(&self) -> Result<toml::Table> {
        let scene = toml::Table::try_from(SceneKeys {
            path: self.scene.as_deref(),
            labels: self.read.labels.as_deref(),
            drop_invalid: self.read.invalid == InvalidPolicy::Drop,
        })?;
        let targets = self.targets.table(self.query.as_deref())?;
        let mut table = toml::Table::new();
        for (key, keys) in [("scene", scene), ("targets", targets)] {
            if !keys.is_empty() {
                table.insert(key.into(), toml::Value::Table(keys));
            }
        }
        Ok(table)
    }

    /// The options with every path made absolute (against the working directory).
    fn absolute(&self) -> Result<QueryOptions> {
        let absolute = |path: &Path| {
            std::path::absolute(path)
                .with_context(|| format!("cannot make {} absolute", path.display()))
        };
        let mut options = self.clone();
        let t = &mut options.targets;
        for path in [
            &mut options.scene,
            &mut options.read.labels,
            &mut t.features.features,
            &mut t.langsplat.latents,
            &mut t.langsplat.checkpoint,
            &mut t.text.phrases,
            &mut t.text.phrase_names,
            &mut t.text.text_encoder,
        ]
        .into_iter()
        .flatten()
        {
            *path = absolute(path)?;
        }
        if let Some(RegionSpec::Selection(path)) = &mut t.region {
            *path = absolute(path)?;
        }
        Ok(options)
    }
}

impl TargetOptions {
    /// The `[targets]` table of these options: each under its key; for a registered source
    /// (`custom.<name>`) its keys (`source_keys`, the text keys, `synonyms`) in its own
    /// `[targets.custom.<name>]`, and else `source_keys` in `[targets.lifted]`. The region is
    /// named `query`, which it then needs.
    fn table(&self, query: Option<&str>) -> Result<toml::Table> {
        let mut keys = toml::Table::try_from(&self.labels)?;
        if let Some(region) = &self.region {
            let query = query.context(match region {
                RegionSpec::Selection(_) => "--selection needs --query: it names the region",
                _ => "--box/--sphere need --query: it names the region",
            })?;
            let regions = RegionConfig {
                regions: [(query.trim().to_string(), region.clone())].into(),
            };
            keys.extend(toml::Table::try_from(regions)?);
        }
        keys.extend(toml::Table::try_from(&self.features)?);
        keys.extend(toml::Table::try_from(&self.langsplat)?);
        keys.extend(self.text.set_keys());
        let mut targets = toml::Table::new();
        match &self.source {
            Some(SourceKind::Custom(name)) => {
                let mut own = self.source_keys.clone();
                for (key, value) in std::mem::take(&mut keys) {
                    if own.contains_key(&key) {
                        bail!(
                            "--source-key {key}=… and {} both set `{key}`: give it once",
                            option_of_key(&key)
                        );
                    }
                    own.insert(key, value);
                }
                targets.extend(TargetsConfig::custom(name, own).keys);
            }
            _ if !self.source_keys.is_empty() => {
                keys.extend(toml::Table::try_from(LiftedConfig {
                    lifted: Some(self.source_keys.clone()),
                    ..LiftedConfig::default()
                })?);
            }
            _ => {}
        }
        if let Some(source) = &self.source {
            targets.insert("source".into(), toml::Value::String(source.name()));
        }
        targets.extend(keys);
        let selection = toml::Table::try_from(self.selection)?;
        if !selection.is_empty() {
            targets.insert("selection".into(), toml::Value::Table(selection));
        }
        Ok(targets)
    }
}
