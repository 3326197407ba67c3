//! Costs from outside the crate: a config type per cost ([`CostConfig`], burn's `XConfig` →
//! `init()` style) and a [`CostRegistry`] that maps the names configs use to those types.
//!
//! ```
//! use burn::tensor::Tensor;
//! use serde::{Deserialize, Serialize};
//! use splatraj_traj::costs::{Cost, CostConfig, CostError, CostInputs, CostRegistry, CostsConfig};
//!
//! /// `[costs.custom.height]`: (c·up − preferred)², the camera's height off a preferred one.
//! #[derive(Debug, Clone, Serialize, Deserialize)]
//! struct HeightConfig {
//!     weight: f64,
//!     preferred: f64,
//! }
//!
//! impl CostConfig for HeightConfig {
//!     fn init(&self) -> Result<Box<dyn Cost>, CostError> {
//!         Ok(Box::new(self.clone()))
//!     }
//! }
//!
//! impl Cost for HeightConfig {
//!     fn name(&self) -> &'static str {
//!         "height"
//!     }
//!     fn weight(&self, _step: usize) -> f64 {
//!         self.weight
//!     }
//!     fn validate(&self) -> Result<(), CostError> {
//!         Ok(())
//!     }
//!     fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
//!         let up = inputs.row(inputs.query().unit_up()); // [1, 3]
//!         let height = (inputs.centres() * up).sum_dim(1).reshape([inputs.batch()]); // [B]
//!         let off = height.sub_scalar(self.preferred);
//!         Ok(off.clone() * off)
//!     }
//! }
//!
//! let mut costs = CostRegistry::default();
//! costs.register::<HeightConfig>("height");
//! let config: CostsConfig = toml::from_str(
//!     "[tce]\n[custom.height]\nweight = 2.0\npreferred = 1.2\n",
//! )
//! .unwrap();
//! let weighted = config.build_with(&costs).unwrap();
//! assert!(weighted.names().contains(&"height"));
//! ```

use serde::Serialize;
use serde::de::DeserializeOwned;
use splatraj_config::{Kind, Registry};

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

/// What the cost registry builds: costs from their `[costs.custom.<name>]` tables.
#[derive(Debug)]
pub struct CostParts;

impl Kind for CostParts {
    type Context<'a> = ();
    type Output = Box<dyn Cost>;
    type Error = CostError;
    const WHAT: &'static str = "cost";
}

/// Names → cost configs, for the `[costs.custom.<name>]` tables of a config.
#[derive(Clone, Default, Debug)]
pub struct CostRegistry(Registry<CostParts>);

impl CostRegistry {
    /// Registers `C` under `name` (replacing an earlier registration of that name).
    pub fn register<C: CostConfig>(&mut self, name: &str) -> &mut Self {
        self.0.insert::<C>(name, |config, (), _| config.init());
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

    /// Builds the cost registered as `name` from its config table.
    pub fn build(&self, name: &str, table: &toml::Value) -> Result<Box<dyn Cost>, CostError> {
        self.0
            .build(name, table, &(), &format!("{CONFIG_TABLE}.custom.{name}"))
    }
}
