//! What a crate outside splatraj adds to an experiment: its own costs, by name.
//!
//! ```ignore
//! let mut extensions = Extensions::default();
//! extensions.costs.register::<HeightConfig>("height");
//! let config = Config::load_with(path, &[], &extensions)?;      // may hold [costs.custom.height]
//! let experiment = Experiment::prepare_with(&config, &extensions)?;
//! ```

use splatraj_traj::costs::CostRegistry;

/// The registries an experiment builds its parts from.
#[derive(Debug, Clone, Default)]
pub struct Extensions {
    /// Costs a config can turn on with `[costs.custom.<name>]`.
    pub costs: CostRegistry,
}
