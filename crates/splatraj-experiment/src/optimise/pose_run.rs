//! The paper's Table I setting: one pose for one query (`[pose]`), its restarts as one batch,
//! and SGLD samples of the pose posterior from the best pose.

use std::time::{Duration, Instant};

use anyhow::Result;
use splatraj_render::camera::Pose;
use splatraj_traj::costs::WeightedCosts;
use splatraj_traj::metrics::WindowMetrics;
use splatraj_traj::optimise::{
    PoseUnits, Problem, SgldSample, SinglePoseResult, StopReason, optimise_poses_observed,
    sample_poses_sgld,
};

use crate::optimise::observer::{Observer, Progress};
use crate::prepare::experiment::Experiment;

/// What [`Experiment::optimise_pose`] did.
#[derive(Debug, Clone)]
pub struct PoseRun {
    /// The query's window index.
    pub window: usize,
    /// The start poses, in order.
    pub starts: Vec<Pose>,
    /// One result per start.
    pub results: Vec<SinglePoseResult>,
    /// Index of the best start (lowest finite total).
    pub best: usize,
    /// Names of the ablation's costs.
    pub cost_names: Vec<&'static str>,
    /// Wall time of the optimisation.
    pub elapsed: Duration,
}

impl PoseRun {
    /// The best start's result.
    pub fn best(&self) -> &SinglePoseResult {
        &self.results[self.best]
    }

    /// `interrupted` when the observer stopped it.
    pub fn stop(&self) -> StopReason {
        self.results[0].stop
    }

    /// Steps actually run (fewer than configured after a stop; a finished run's last row is
    /// the evaluation after the last update, not a step).
    pub fn iterations_run(&self) -> usize {
        let best = self.best();
        let finished = usize::from(best.stop == StopReason::Finished);
        best.history.len().saturating_sub(finished).max(1)
    }
}

/// SGLD samples and their spread.
#[derive(Debug, Clone)]
pub struct Posterior {
    /// Kept states of all chains, by step then chain.
    pub samples: Vec<SgldSample>,
    /// Chains run.
    pub chains: usize,
    /// Mean of each pose component over the samples.
    pub mean: [f64; 6],
    /// Standard deviation of each pose component over the samples.
    pub std: [f64; 6],
    /// Chain updates skipped because a total or gradient was not finite.
    pub skipped_updates: usize,
    /// Wall time.
    pub elapsed: Duration,
}

impl Experiment {
    /// The costs of the `[pose]` ablation.
    pub fn pose_costs(&self) -> Result<WeightedCosts> {
        self.config
            .pose
            .ablation
            .apply(&self.config.costs)
            .build_with(&self.extensions.costs)
            .map_err(anyhow::Error::msg)
    }

    /// The start poses of `[pose]`'s query: `start.pose`, or one per restart.
    pub fn pose_starts(&self) -> Result<Vec<Pose>> {
        Ok(match self.config.start.pose {
            Some(p) => vec![Pose(p)],
            None => self
                .start_poses(&[self.config.pose.query], self.config.start.restarts)?
                .into_iter()
                .map(|per_window| per_window[0])
                .collect(),
        })
    }

    /// Calls `work` with the single-window problem of `[pose]`'s query (its costs, on the
    /// autodiff scene with the geometry and objects alone those costs read) and the costs.
    /// The problem borrows what is built here, so it is lent, not returned.
    fn with_pose_problem<T>(
        &self,
        work: impl FnOnce(&Problem<'_>, &splatraj_traj::costs::WeightedCosts) -> Result<T>,
    ) -> Result<T> {
        let costs = self.pose_costs()?;
        let scene = self.autodiff_scene();
        let windows = self.optimisation_windows();
        let occupancy = self.occupancy()?;
        let problem = Problem::new(&scene, &windows, &costs, self.intrinsics)
            .with_rasterizer(self.config.rasterizer)
            .with_approximations(self.config.approximations)
            .with_occupancy(occupancy.as_ref())
            .window(self.config.pose.query)?;
        work(&problem, &costs)
    }

    /// Optimises `[pose]`'s query from every start at once (`[pose.optimiser]`); `observer`
    /// may stop it, each start keeping its best.
    pub fn optimise_pose(&self, observer: &mut dyn Observer) -> Result<PoseRun> {
        let window = self.config.pose.query;
        let starts = self.pose_starts()?;
        let options = &self.config.pose.optimiser;
        let started = Instant::now();
        let (results, cost_names) = self.with_pose_problem(|problem, costs| {
            let results = optimise_poses_observed(problem, &starts, options, &mut |step, best| {
                observer.progress(&Progress::Pose {
                    step,
                    steps: options.iterations,
                    best,
                })
            })?;
            Ok((results, costs.names()))
        })?;
        let best = (0..results.len())
            .filter(|&i| results[i].total.is_finite())
            .min_by(|&a, &b| results[a].total.total_cmp(&results[b].total))
            .unwrap_or(0);
        Ok(PoseRun {
            window,
            starts,
            results,
            best,
            cost_names,
            elapsed: started.elapsed(),
        })
    }

    /// `chains` SGLD chains (`[sgld]`) from `pose` on `[pose]`'s query and ablation.
    pub fn sample_posterior(&self, pose: Pose, chains: usize) -> Result<Posterior> {
        anyhow::ensure!(chains > 0, "SGLD needs at least one chain");
        let index = self.config.pose.query;
        let units = PoseUnits::with_position(self.windows[index].context.prior_radius);
        let sampled = self.with_pose_problem(|problem, _| {
            Ok(sample_poses_sgld(
                problem,
                &vec![pose; chains],
                units,
                &self.config.sgld,
                self.config.seed,
            )?)
        })?;
        let samples = sampled.samples;
        let count = samples.len().max(1) as f64;
        let mean: [f64; 6] =
            std::array::from_fn(|i| samples.iter().map(|s| s.pose.0[i]).sum::<f64>() / count);
        let std: [f64; 6] = std::array::from_fn(|i| {
            (samples
                .iter()
                .map(|s| (s.pose.0[i] - mean[i]).powi(2))
                .sum::<f64>()
                / count)
                .sqrt()
        });
        Ok(Posterior {
            samples,
            chains,
            mean,
            std,
            skipped_updates: sampled.skipped_updates,
            elapsed: sampled.elapsed,
        })
    }

    /// TCE, TRE, IoU and visibility of `pose` for `[pose]`'s query at the output resolution.
    pub fn evaluate_pose(&self, pose: Pose) -> Result<WindowMetrics> {
        let output = self.output_intrinsics()?;
        let plain = self.plain_scene();
        self.window_metrics(
            &plain,
            self.config.pose.query,
            (0, 1),
            1,
            &output,
            (&|t: &[f64]| vec![pose.0; t.len()], None),
        )
    }
}
