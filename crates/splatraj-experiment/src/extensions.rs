//! What a crate outside splatraj adds to an experiment: its own costs, trajectory models and
//! target sources, each registered by name (one pattern for the three: a config type with an
//! `init()` that builds the part, registered under a name that configs write as `custom.<name>`).
//!
//! ```ignore
//! let mut extensions = Extensions::default();
//! extensions.costs.register::<HeightConfig>("height");   // [costs.custom.height]
//! extensions.models.register::<HatConfig>("hat");        // [trajectory] kind = "custom.hat"
//! extensions.sources.register::<NearConfig>("near");     // [targets] source = "custom.near"
//! let config = Config::load_with(path, &[], &extensions)?;
//! let experiment = Experiment::prepare_with(&config, &extensions)?;
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
