//! Target sources from outside the crate: a config type per source ([`SourceConfig`], burn's
//! `XConfig` → `init()` style, as for costs and trajectory models) and a [`SourceRegistry`]
//! that maps the names configs use to those types.
//!
//! ```ignore
//! let mut sources = SourceRegistry::default();
//! sources.register::<NearConfig>("near");
//! // [targets]
//! // source = "custom.near"
//! // [targets.custom.near]
//! // point = [0.0, 0.0, 1.0]
//! let source = config.targets.build_with(base_dir, &device, &sources)?;
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use burn::tensor::Device;
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::TargetSource;
use super::feature3dgs::{FEATURE3DGS, Feature3dgsConfig};
use super::gaussian_grouping::{GAUSSIAN_GROUPING, GaussianGroupingConfig};
use super::legaussians::{LEGAUSSIANS, LeGaussiansConfig};
use super::opengaussian::{OPENGAUSSIAN, OpenGaussianConfig};
use crate::error::{Result, SemanticError};

/// What a source's `init` may need besides its own table: where relative paths start and the
/// device (for sources that run a model).
#[derive(Debug, Clone, Copy)]
pub struct SourceContext<'a> {
    /// Folder relative paths are read from (the config file's folder).
    pub base_dir: &'a Path,
    /// Device for sources that run a burn model.
    pub device: &'a Device,
}

impl SourceContext<'_> {
    /// `p` resolved against [`SourceContext::base_dir`] (absolute paths unchanged).
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base_dir.join(p)
        }
    }
}

/// The config of one target source: deserialised from its `[targets.custom.<name>]` table,
/// checked and turned into the source by [`SourceConfig::init`].
pub trait SourceConfig: Serialize + DeserializeOwned + 'static {
    /// Checks the values, reads what the source needs and builds it.
    fn init(&self, context: &SourceContext) -> Result<Box<dyn TargetSource>>;
}

type Factory =
    Arc<dyn Fn(&toml::Value, &SourceContext, &str) -> Result<Box<dyn TargetSource>> + Send + Sync>;

/// Names → source configs, for `[targets] source = "custom.<name>"`. The default registry
/// holds the language fields that ship with splatraj as registered sources
/// (`custom.feature3dgs`, `custom.opengaussian`, `custom.gaussian_grouping`,
/// `custom.legaussians`); [`SourceRegistry::empty`] holds none.
#[derive(Clone)]
pub struct SourceRegistry {
    factories: BTreeMap<String, Factory>,
}

impl Default for SourceRegistry {
    fn default() -> Self {
        let mut registry = SourceRegistry::empty();
        registry.register::<Feature3dgsConfig>(FEATURE3DGS);
        registry.register::<OpenGaussianConfig>(OPENGAUSSIAN);
        registry.register::<GaussianGroupingConfig>(GAUSSIAN_GROUPING);
        registry.register::<LeGaussiansConfig>(LEGAUSSIANS);
        registry
    }
}

impl std::fmt::Debug for SourceRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.factories.keys()).finish()
    }
}

impl SourceRegistry {
    /// A registry without any source.
    pub fn empty() -> Self {
        SourceRegistry {
            factories: BTreeMap::new(),
        }
    }

    /// Registers `C` under `name` (replacing an earlier registration of that name).
    pub fn register<C: SourceConfig>(&mut self, name: &str) -> &mut Self {
        let factory: Factory =
            Arc::new(|table: &toml::Value, context: &SourceContext, key: &str| {
                // Through serde_path_to_error so a bad value names its own key inside the
                // table (`targets.custom.min_probability`), not just the table.
                let config: C = serde_path_to_error::deserialize(table.clone()).map_err(|e| {
                    let path = e.path().to_string();
                    let where_ = if path == "." {
                        key.to_string()
                    } else {
                        format!("{key}.{path}")
                    };
                    SemanticError::option(where_, e.into_inner().message().trim_end())
                })?;
                config.init(context).map_err(|e| e.in_key(key))
            });
        self.factories.insert(name.to_string(), factory);
        self
    }

    /// The registered names, sorted.
    pub fn names(&self) -> Vec<&str> {
        self.factories.keys().map(String::as_str).collect()
    }

    /// Whether `name` is registered.
    pub fn contains(&self, name: &str) -> bool {
        self.factories.contains_key(name)
    }

    /// Builds the source registered as `name` from its config table; errors name `key` (the
    /// table's config key, e.g. `targets.custom.near`).
    pub fn build(
        &self,
        name: &str,
        table: &toml::Value,
        context: &SourceContext,
        key: &str,
    ) -> Result<Box<dyn TargetSource>> {
        match self.factories.get(name) {
            Some(factory) => factory(table, context, key),
            None => Err(SemanticError::option(
                key,
                format!(
                    "names no registered target source (registered: {})",
                    if self.factories.is_empty() {
                        "none".to_string()
                    } else {
                        self.names().join(", ")
                    }
                ),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_badly_typed_value_names_its_key_inside_the_table() {
        let registry = SourceRegistry::default();
        let table: toml::Value = toml::from_str("min_probability = \"abc\"").unwrap();
        let device = Device::default();
        let context = SourceContext {
            base_dir: Path::new("."),
            device: &device,
        };
        let Err(error) = registry.build(GAUSSIAN_GROUPING, &table, &context, "targets.custom")
        else {
            panic!("a string where a number belongs is refused");
        };
        let error = error.to_string();
        assert!(
            error.contains("targets.custom.min_probability"),
            "the error names the key: {error}"
        );
    }
}
