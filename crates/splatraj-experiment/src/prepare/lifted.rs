//! The `lifted` source in an experiment: where its field is cached (beside the scene file,
//! unless the config says) and whether building it fits the memory limit.

use std::path::Path;

use anyhow::{Context, Result};
use splatraj_lift::field::{FieldOptions, memory_bytes};
use splatraj_lift::views::ViewOptions;
use splatraj_semantic::{SourceKind, TargetSourceConfig, TargetsConfig};

use crate::config::Config;
use crate::resources::{MemoryLimit, MemoryPlan, RAISE_LIMIT};

/// `targets` with `[targets.lifted] cache_dir` set to the default folder beside `scene_path`
/// when the source is `lifted` and the config left it out (the demo scene, made in memory,
/// gets no cache).
pub fn with_lifted_cache(targets: &TargetsConfig, scene_path: Option<&Path>) -> TargetsConfig {
    let mut targets = targets.clone();
    if targets.source == SourceKind::Lifted
        && let Some(scene_path) = scene_path
    {
        let table = targets
            .keys
            .entry("lifted")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let toml::Value::Table(table) = table
            && !table.contains_key("cache_dir")
        {
            let dir = splatraj_lift::default_cache_dir(scene_path);
            table.insert(
                "cache_dir".into(),
                toml::Value::String(dir.to_string_lossy().into_owned()),
            );
        }
    }
    targets
}

/// Refuses, before any view is rendered, a `lifted` field whose estimated peak memory is over
/// the limit (`max_memory_gb`); other sources pass.
pub fn check_lifted_memory(config: &Config, gaussians: usize) -> Result<()> {
    // A config the source cannot be built from, or without weights: building the source
    // names the key.
    let Ok(TargetSourceConfig::Lifted(lifted)) =
        config.targets.source_config(&crate::config::targets_key)
    else {
        return Ok(());
    };
    let Some(weights) = &lifted.text.text_encoder else {
        return Ok(());
    };
    let table = lifted.lifted.unwrap_or_default();
    fn part<T: serde::de::DeserializeOwned + Default>(table: &toml::Table, key: &str) -> Result<T> {
        Ok(table
            .get(key)
            .cloned()
            .map(toml::Value::try_into)
            .transpose()
            .with_context(|| format!("`targets.lifted.{key}`"))?
            .unwrap_or_default())
    }
    let views: ViewOptions = part(&table, "views")?;
    let field: FieldOptions = part(&table, "field")?;
    // The capture's cameras are every one a view (`views.count` is for planned views).
    let view_count = match table.get("cameras").and_then(toml::Value::as_str) {
        Some(cameras) => splatraj_lift::cameras::read_views(&config.resolve(Path::new(cameras)))
            .map(|v| v.len())
            .context("`targets.lifted.cameras`")?,
        None => views.count,
    };
    let path = config.resolve(weights);
    // A weights file that cannot be read is named by building the source, under the key or
    // option the user set it with (`--text-encoder` from `query`), not here.
    let Ok(metadata) = std::fs::metadata(&path) else {
        return Ok(());
    };
    let weights_bytes = metadata.len();
    let mut plan = MemoryPlan::default();
    plan.stage(
        format!(
            "the lifted field: {gaussians} Gaussians, {view_count} views \
             (`targets.lifted.views.count` or the cameras), `targets.lifted.field.components` = {}",
            field.components
        ),
        memory_bytes(gaussians, view_count, &field, weights_bytes, 512),
    );
    plan.check(MemoryLimit::new(config.max_memory_gb)?, RAISE_LIMIT)
}
