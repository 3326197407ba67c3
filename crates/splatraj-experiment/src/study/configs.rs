//! The config of each run of a study and of its fixed evaluation, from the typed configs its
//! plan was made of ([`PlannedStudy`]): a run's is its variant's with the seed (trajectory) or
//! the starts (pose) set, the evaluation's is the base's at the evaluation's size and sample
//! counts. Typed fields changed; nothing read or parsed again.

use anyhow::{Context, Result};

use super::StudyTask;
use super::plan::{PlannedStudy, Run};
use crate::config::Config;
use crate::extensions::Extensions;

impl PlannedStudy {
    /// Run `run`'s config: its variant's, with its seed (trajectory: the base seed plus the
    /// repeat) or its starts (pose: `--seeds` restarts).
    pub fn run_config(&self, run: &Run, extensions: &Extensions) -> Result<Config> {
        let mut config = self.variants[run.variant].clone();
        match self.plan.task {
            StudyTask::Trajectory => {
                config.seed = self.plan.base_seed.wrapping_add(run.repeat as u64);
            }
            StudyTask::Pose => config.start.restarts = self.plan.seeds,
        }
        config
            .validate_with(extensions)
            .with_context(|| format!("config {}", config.path.display()))
            .with_context(|| {
                format!(
                    "study run {} (`{}`)",
                    run.index, self.plan.variants[run.variant].label
                )
            })?;
        Ok(config)
    }

    /// The config of the fixed evaluation: the base config at the evaluation's size and
    /// sample counts, whatever the variant.
    pub fn evaluation_config(&self, extensions: &Extensions) -> Result<Config> {
        let e = &self.plan.evaluation;
        let mut config = self.base.clone();
        config.output.width = e.width.unwrap_or(self.base.output.width);
        config.output.height = e.height.unwrap_or(self.base.output.height);
        config.output.metric_samples = e.samples;
        config.output.ldj_samples = e.ldj_samples;
        config
            .validate_with(extensions)
            .with_context(|| format!("config {}", config.path.display()))
            .context("the study's evaluation")?;
        Ok(config)
    }
}
