//! Costs from outside the crate: a config type per cost ([`CostConfig`], burn's `XConfig` →
//! `init()` style) and a [`CostRegistry`] that maps the names configs use to those types.
//!
//! ```ignore
//! let mut costs = CostRegistry::default();
//! costs.register::<HeightConfig>("height");
//! // [costs.custom.height]
//! // weight = 2.0
//! // preferred = 1.2
//! let weighted = config.costs.build_with(&costs)?;
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::{
    CONFIG_TABLE, ClearanceCost, Cost, CostError, MotionCost, PriorCost, TceCost, TreCost,
    UprightCost,
};

/// The config of one cost: deserialised from its config table, checked and turned into the
/// cost by [`CostConfig::init`].
pub trait CostConfig: Serialize + DeserializeOwned + 'static {
    /// Checks the values and builds the cost.
    fn init(&self) -> Result<Box<dyn Cost>, CostError>;
}

macro_rules! self_config {
    ($($t:ty),*) => {$(
        impl CostConfig for $t {
            fn init(&self) -> Result<Box<dyn Cost>, CostError> {
                Cost::validate(self)?;
                Ok(Box::new(self.clone()))
            }
        }
    )*};
}

// The built-in costs are their own configs.
self_config!(
    TceCost,
    TreCost,
    UprightCost,
    PriorCost,
    ClearanceCost,
    MotionCost
);

type Factory = Arc<dyn Fn(&toml::Value) -> Result<Box<dyn Cost>, CostError> + Send + Sync>;

/// Names → cost configs, for the `[costs.custom.<name>]` tables of a config.
#[derive(Clone, Default)]
pub struct CostRegistry {
    factories: BTreeMap<String, Factory>,
}

impl std::fmt::Debug for CostRegistry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.factories.keys()).finish()
    }
}

impl CostRegistry {
    /// Registers `C` under `name` (replacing an earlier registration of that name).
    pub fn register<C: CostConfig>(&mut self, name: &str) -> &mut Self {
        let key = name.to_string();
        let factory: Factory = Arc::new(move |table: &toml::Value| {
            let config = C::deserialize(table.clone()).map_err(|e| CostError::InvalidConfig {
                key: format!("{CONFIG_TABLE}.custom.{key}"),
                reason: e.message().trim_end().to_string(),
            })?;
            config.init()
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

    /// Builds the cost registered as `name` from its config table.
    pub fn build(&self, name: &str, table: &toml::Value) -> Result<Box<dyn Cost>, CostError> {
        match self.factories.get(name) {
            Some(factory) => factory(table),
            None => Err(CostError::InvalidConfig {
                key: format!("{CONFIG_TABLE}.custom.{name}"),
                reason: format!(
                    "names no registered cost (registered: {})",
                    if self.factories.is_empty() {
                        "none".to_string()
                    } else {
                        self.names().join(", ")
                    }
                ),
            }),
        }
    }
}
