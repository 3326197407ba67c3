//! What the clearance cost and the motion limits read besides the windows: the clearance
//! margin, the scene's solid geometry ([`Occupancy`], built once per spec) and the path's
//! duration. The starts, the joins, the optimisation and the metrics all ask for them.

use anyhow::{Result, bail};
use splatraj_traj::clearance::Occupancy;

use crate::prepare::experiment::Experiment;

impl Experiment {
    /// The clearance cost's margin (resolved from the scene when it was `"auto"`), when the
    /// cost is on.
    pub fn clearance_margin(&self) -> Option<f64> {
        self.config
            .costs
            .clearance
            .as_ref()
            .and_then(|c| c.margin.value())
    }

    /// The scene's solid ellipsoids, indexed, when a configured cost reads them (clearance);
    /// None otherwise. Errors when a motion limit is set without the path's duration.
    pub fn occupancy(&self) -> Result<Option<Occupancy>> {
        if let Some(motion) = &self.config.costs.motion
            && motion.needs_duration()
            && self.path_seconds().is_none()
        {
            bail!(
                "`costs.motion` limits rates per second: give the path's duration in `[output] \
                 seconds`"
            );
        }
        let Some(spec) = self.costs()?.occupancy() else {
            return Ok(None);
        };
        // Built once per spec (`self.scene` is not expected to change after `prepare`).
        let occupancy = self.occupancy_memo.get_or_make(spec, || {
            Ok::<_, anyhow::Error>(Occupancy::new(&self.scene, spec))
        })?;
        Ok(Some(occupancy))
    }

    /// Duration of the whole trajectory in seconds (`[output] seconds`, else `frames / fps`,
    /// else the default seconds per query: [`crate::config::OutputConfig::duration`]).
    pub fn path_seconds(&self) -> Option<f64> {
        Some(self.config.output.duration(self.windows.len()))
    }
}
