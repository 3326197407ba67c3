//! Where the `lifted` source keeps its field: beside the scene file, unless the config says.

use std::path::Path;

use splatraj_semantic::{SourceKind, TargetsConfig};

/// `targets` with `[targets.lifted] cache_dir` set to the default folder beside `scene_path`
/// when the source is `lifted` and the config left it out (the demo scene, made in memory,
/// gets no cache).
pub fn with_lifted_cache(targets: &TargetsConfig, scene_path: Option<&Path>) -> TargetsConfig {
    let mut targets = targets.clone();
    if targets.source == SourceKind::Lifted
        && let Some(scene_path) = scene_path
    {
        let table = targets.lifted.get_or_insert_with(toml::Table::new);
        if !table.contains_key("cache_dir") {
            let dir = splatraj_lift::default_cache_dir(scene_path);
            table.insert(
                "cache_dir".into(),
                toml::Value::String(dir.to_string_lossy().into_owned()),
            );
        }
    }
    targets
}
