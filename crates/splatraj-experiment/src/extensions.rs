//! What a crate outside splatraj adds to an experiment: its own costs, trajectory models and
//! target sources, each registered by name (one pattern for the three: a config type with an
//! `init()` that builds the part, registered under a name that configs write as `custom.<name>`).
//!
//! ```no_run
//! # use burn::tensor::Tensor;
//! # use serde::{Deserialize, Serialize};
//! # use splatraj_traj::costs::{Cost, CostConfig, CostError, CostInputs};
//! use splatraj_experiment::{Config, Experiment, Extensions};
//! # #[derive(Debug, Clone, Serialize, Deserialize)]
//! # struct HeightConfig { weight: f64 }
//! # impl CostConfig for HeightConfig {
//! #     fn init(&self) -> Result<Box<dyn Cost>, CostError> { Ok(Box::new(self.clone())) }
//! # }
//! # impl Cost for HeightConfig {
//! #     fn name(&self) -> &'static str { "height" }
//! #     fn weight(&self, _step: usize) -> f64 { self.weight }
//! #     fn validate(&self) -> Result<(), CostError> { Ok(()) }
//! #     fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
//! #         Ok(inputs.centres().sum_dim(1).reshape([inputs.batch()]))
//! #     }
//! # }
//! # fn main() -> anyhow::Result<()> {
//! // HeightConfig: a `CostConfig` (a whole one is in the registry's documentation,
//! // `splatraj_traj::costs::registry`); models (`extensions.models`, `[trajectory] kind =
//! // "custom.<name>"`) and sources (`extensions.sources`, `[targets] source = "custom.<name>"`)
//! // are registered the same way.
//! let mut extensions = Extensions::default();
//! extensions.costs.register::<HeightConfig>("height"); // [costs.custom.height]
//! let config = Config::load_with("my.toml".as_ref(), &[], &extensions)?;
//! let experiment = Experiment::prepare_with(&config, &extensions)?;
//! # let _ = experiment;
//! # Ok(())
//! # }
//! ```

use splatraj_lift::LiftedConfig;
use splatraj_semantic::SourceRegistry;
use splatraj_traj::costs::CostRegistry;
use splatraj_traj::trajectory::ModelRegistry;

/// The registries an experiment builds its parts from.
#[derive(Debug, Clone)]
pub struct Extensions {
    /// Costs a config can turn on with `[costs.custom.<name>]`.
    pub costs: CostRegistry,
    /// Trajectory models a config can choose with `[trajectory] kind = "custom.<name>"`
    /// (parameters in `[trajectory.custom.<name>]`).
    pub models: ModelRegistry,
    /// Target sources a config can choose with `[targets] source = "custom.<name>"`
    /// (parameters in `[targets.custom.<name>]`).
    pub sources: SourceRegistry,
}

impl Default for Extensions {
    /// The shipped parts; sources also hold `lifted` (splatraj-lift), which the semantic crate
    /// cannot register itself because lifting renders and rendering comes after it.
    fn default() -> Self {
        let mut sources = SourceRegistry::default();
        sources.register::<LiftedConfig>(splatraj_lift::LIFTED);
        Extensions {
            costs: CostRegistry::default(),
            models: ModelRegistry::default(),
            sources,
        }
    }
}
