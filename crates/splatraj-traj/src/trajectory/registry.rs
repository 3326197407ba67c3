//! Trajectory models from outside the crate: a config type per model ([`ModelConfig`], burn's
//! `XConfig` → `init()` style, as for costs) and a [`ModelRegistry`] that maps the names configs
//! use to those types.
//!
//! ```
//! use serde::{Deserialize, Serialize};
//! use splatraj_traj::trajectory::{Basis, ModelConfig, ModelRegistry, TrajectoryError, TrajectoryModel};
//!
//! /// `[trajectory.custom.hat]`: hat functions on `knots` evenly spaced knots.
//! #[derive(Debug, Clone, Serialize, Deserialize)]
//! struct HatConfig {
//!     knots: usize,
//! }
//!
//! #[derive(Debug)]
//! struct Hat {
//!     knots: usize,
//! }
//!
//! impl ModelConfig for HatConfig {
//!     fn init(&self, _windows: usize) -> Result<Box<dyn Basis>, TrajectoryError> {
//!         Ok(Box::new(Hat { knots: self.knots }))
//!     }
//! }
//!
//! impl Basis for Hat {
//!     fn count(&self) -> usize {
//!         self.knots
//!     }
//!     fn validate(&self) -> Result<(), TrajectoryError> {
//!         Ok(())
//!     }
//!     fn eval_into(&self, t: f64, row: &mut [f64]) {
//!         let last = (self.knots - 1) as f64;
//!         for (k, psi) in row.iter_mut().enumerate() {
//!             *psi = (1.0 - (t * last - k as f64).abs()).max(0.0);
//!         }
//!     }
//! }
//!
//! let mut models = ModelRegistry::default();
//! models.register::<HatConfig>("hat");
//! let config: TrajectoryModel =
//!     toml::from_str("kind = \"custom.hat\"\n[custom.hat]\nknots = 12\n").unwrap();
//! let model = config.build_with(2, &models).unwrap();
//! assert_eq!(model.basis().count(), 12);
//! ```
//!
//! A registered model is a [`CustomModel`] inside [`TrajectoryModel::Custom`]: its name, its
//! config table (kept to be written back to configs and `trajectory.json`), the window count it
//! was built for, and the [`Basis`] its config's `init` built.

use std::sync::Arc;

use serde::Serialize;
use serde::de::DeserializeOwned;
use splatraj_config::{Kind, Registry};

use super::{Basis, TrajectoryError, TrajectoryModel};

/// How configs name a registered model: `kind = "custom.<name>"`.
pub const CUSTOM_PREFIX: &str = "custom.";

/// The config of one trajectory model: deserialised from its `[trajectory.custom.<name>]`
/// table, checked and turned into the model's basis by [`ModelConfig::init`].
pub trait ModelConfig: Serialize + DeserializeOwned + 'static {
    /// Checks the values and builds the basis for `windows` query windows (a model whose
    /// basis does not depend on the queries ignores it).
    fn init(&self, windows: usize) -> Result<Box<dyn Basis>, TrajectoryError>;
}

/// What the model registry builds: a basis from a `[trajectory.custom.<name>]` table and the
/// window count.
#[derive(Debug)]
pub struct ModelParts;

impl Kind for ModelParts {
    type Context<'a> = usize;
    type Output = Box<dyn Basis>;
    type Error = TrajectoryError;
    const WHAT: &'static str = "trajectory model";
}

/// Names → model configs, for `[trajectory] kind = "custom.<name>"`.
#[derive(Clone, Default, Debug)]
pub struct ModelRegistry(Registry<ModelParts>);

impl ModelRegistry {
    /// Registers `C` under `name` (replacing an earlier registration of that name).
    pub fn register<C: ModelConfig>(&mut self, name: &str) -> &mut Self {
        self.0
            .insert::<C>(name, |config, &windows, _| config.init(windows));
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

    /// Builds the basis registered as `name` from its config table, for `windows` windows; an
    /// unknown name is an error on `trajectory.kind`, where the user wrote it.
    pub fn build(
        &self,
        name: &str,
        table: &toml::Value,
        windows: usize,
    ) -> Result<Box<dyn Basis>, TrajectoryError> {
        let key = if self.contains(name) {
            format!("trajectory.custom.{name}")
        } else {
            format!("trajectory.kind = \"{CUSTOM_PREFIX}{name}\"")
        };
        self.0.build(name, table, &windows, &key)
    }
}

/// A model registered in a [`ModelRegistry`], as a config names it: `name`, its parameters
/// and, once built ([`TrajectoryModel::build_with`]), its basis.
#[derive(Clone)]
pub struct CustomModel {
    /// The registered name (without `custom.`).
    pub name: String,
    /// Its `[trajectory.custom.<name>]` table (an empty table when the config gives none).
    pub params: toml::Value,
    /// The window count it was built for (written to `trajectory.json`).
    pub windows: Option<usize>,
    basis: Option<Arc<dyn Basis>>,
}

impl std::fmt::Debug for CustomModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CustomModel")
            .field("name", &self.name)
            .field("params", &self.params)
            .field("windows", &self.windows)
            .field("built", &self.basis.is_some())
            .finish()
    }
}

impl PartialEq for CustomModel {
    /// Same name, parameters and window count (the basis follows from them).
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name && self.params == other.params && self.windows == other.windows
    }
}

impl CustomModel {
    /// A model named `name` with config table `params`, not built yet.
    pub fn new(name: impl Into<String>, params: toml::Value) -> Self {
        Self {
            name: name.into(),
            params,
            windows: None,
            basis: None,
        }
    }

    /// Builds the basis from `registry` for `windows` windows.
    pub fn build(&self, windows: usize, registry: &ModelRegistry) -> Result<Self, TrajectoryError> {
        let basis = registry.build(&self.name, &self.params, windows)?;
        Ok(Self {
            name: self.name.clone(),
            params: self.params.clone(),
            windows: Some(windows),
            basis: Some(Arc::from(basis)),
        })
    }

    /// The built basis, or the placeholder whose `validate` says it is not built.
    pub fn basis(&self) -> &dyn Basis {
        match &self.basis {
            Some(b) => b.as_ref(),
            None => &Unbuilt,
        }
    }

    /// `custom.<name>`, as in `kind`.
    pub fn kind(&self) -> String {
        format!("{CUSTOM_PREFIX}{}", self.name)
    }
}

/// The basis of a custom model that was read but not built: every [`crate::trajectory::Trajectory`]
/// constructor validates first, and this says why it cannot go on.
#[derive(Debug)]
struct Unbuilt;

impl Basis for Unbuilt {
    fn count(&self) -> usize {
        0
    }
    fn validate(&self) -> Result<(), TrajectoryError> {
        Err(TrajectoryError::Config(splatraj_config::ConfigError::new(
            "trajectory.kind",
            "names a custom model that was not built: register it in a ModelRegistry and build \
             the model with `TrajectoryModel::build_with`",
        )))
    }
    fn eval_into(&self, _t: f64, _row: &mut [f64]) {}
}

impl TrajectoryModel {
    /// The model ready for `windows` query windows: a built-in one with
    /// [`TrajectoryModel::with_windows`], a custom one built from `registry`.
    pub fn build_with(
        &self,
        windows: usize,
        registry: &ModelRegistry,
    ) -> Result<Self, TrajectoryError> {
        Ok(match self {
            Self::Custom(custom) => Self::Custom(custom.build(windows, registry)?),
            builtin => builtin.clone().with_windows(windows),
        })
    }
}
