//! Target sources from outside the crate: a config type per source ([`SourceConfig`], burn's
//! `XConfig` → `init()` style, as for costs and trajectory models) and a [`SourceRegistry`]
//! that maps the names configs use to those types.
//!
//! ```
//! use std::path::Path;
//!
//! use burn::tensor::Device;
//! use serde::{Deserialize, Serialize};
//! use splatraj_scene::Scene;
//! use splatraj_semantic::{
//!     Relevancy, Scoring, SourceConfig, SourceContext, SourceRegistry, TargetSource,
//!     TargetsConfig,
//! };
//!
//! /// `[targets.custom.near]`: the Gaussians within `radius` of `point`, whatever the query.
//! #[derive(Debug, Clone, Serialize, Deserialize)]
//! struct NearConfig {
//!     point: [f32; 3],
//!     radius: f32,
//! }
//!
//! impl SourceConfig for NearConfig {
//!     fn init(&self, _context: &SourceContext) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
//!         Ok(Box::new(self.clone()))
//!     }
//! }
//!
//! impl TargetSource for NearConfig {
//!     fn kind(&self) -> &'static str {
//!         "near"
//!     }
//!     fn relevancy(&self, scene: &Scene, query: &str) -> splatraj_semantic::Result<Relevancy> {
//!         let near = |m: &[f32; 3]| (0..3).map(|i| (m[i] - self.point[i]).powi(2)).sum::<f32>();
//!         Ok(Relevancy {
//!             name: query.to_string(),
//!             values: scene.means.iter().map(|m| f32::from(near(m) <= self.radius.powi(2))).collect(),
//!             scoring: Scoring::Mask { cluster: false },
//!             notes: Vec::new(),
//!         })
//!     }
//! }
//!
//! let mut sources = SourceRegistry::default();
//! sources.register::<NearConfig>("near");
//! let targets: TargetsConfig = toml::from_str(
//!     "source = \"custom.near\"\n[custom.near]\npoint = [0.0, 0.0, 1.0]\nradius = 0.1\n",
//! )
//! .unwrap();
//! let source = targets.build_with(Path::new("."), &Device::flex(), &sources).unwrap();
//! assert_eq!(source.kind(), "near");
//! ```

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::Serialize;
use serde::de::DeserializeOwned;
use splatraj_config::{Kind, Registry};

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

/// What the source registry builds: a target source from its config table and context.
#[derive(Debug)]
pub struct SourceParts;

impl Kind for SourceParts {
    type Context<'a> = SourceContext<'a>;
    type Output = Box<dyn TargetSource>;
    type Error = SemanticError;
    const WHAT: &'static str = "target source";
}

/// Names → source configs, for `[targets] source = "custom.<name>"`. The default registry
/// holds the language fields that ship with splatraj as registered sources
/// (`custom.feature3dgs`, `custom.opengaussian`, `custom.gaussian_grouping`,
/// `custom.legaussians`); [`SourceRegistry::empty`] holds none.
#[derive(Clone, Debug)]
pub struct SourceRegistry(Registry<SourceParts>);

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

impl SourceRegistry {
    /// A registry without any source.
    pub fn empty() -> Self {
        SourceRegistry(Registry::default())
    }

    /// Registers `C` under `name` (replacing an earlier registration of that name).
    pub fn register<C: SourceConfig>(&mut self, name: &str) -> &mut Self {
        self.0.insert::<C>(name, |config, context, key| {
            config.init(context).map_err(|e| e.in_key(key))
        });
        self
    }

    /// The registered names, sorted.
    pub fn names(&self) -> Vec<&str> {
        self.0.names()
    }

    /// Whether `name` is registered.
    pub fn contains(&self, name: &str) -> bool {
        self.0.contains(name)
    }

    /// Why a name that is not registered is refused, listing the registered ones.
    pub fn unregistered(&self) -> String {
        self.0.unregistered()
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
        self.0.build(name, table, context, key)
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
