//! The paper's method: optimise a trajectory from each start, keep the best, evaluate it.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use splatraj_traj::metrics::{
    Smoothness, WindowMetrics, WindowObject, trajectory_ldj, window_metrics,
};
use splatraj_traj::optimise::{Flow, Problem, StopReason, TrajectoryResult, optimise_trajectory};
use splatraj_traj::trajectory::{Trajectory, TrajectoryModel, TrajectoryRecord};

use crate::experiment::Experiment;
use crate::observer::{Observer, Progress};

/// What [`Experiment::run_trajectory`] did.
#[derive(Debug, Clone)]
pub struct TrajectoryRun {
    /// One result per start run (fewer than the starts when stopped early).
    pub results: Vec<TrajectoryResult>,
    /// Index in `results` of the best (lowest finite sampled loss).
    pub best: usize,
    /// `interrupted` when the observer or the time limit stopped it.
    pub stop: StopReason,
    /// Wall time of the optimisation.
    pub elapsed: Duration,
    /// Names of the cost terms (the history's columns, per window).
    pub cost_names: Vec<&'static str>,
}

impl TrajectoryRun {
    /// The best result.
    pub fn best(&self) -> &TrajectoryResult {
        &self.results[self.best]
    }

    /// Steps run over all starts.
    pub fn iterations_run(&self) -> usize {
        self.results.iter().map(|r| r.history.len()).sum()
    }
}

/// Metrics of a trajectory: per window and smoothness.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// Per-window TCE, TRE, IoU, visibility at the output resolution.
    pub windows: Vec<WindowMetrics>,
    /// LDJ of the camera centre and rotation.
    pub ldj: Smoothness,
}

impl Experiment {
    /// Optimises a trajectory from each of [`Experiment::start_trajectories`] (restart r uses
    /// seed `seed + r`); `observer` sees every step and may stop the run, which keeps the best
    /// trajectory so far.
    pub fn run_trajectory(&self, observer: &mut dyn Observer) -> Result<TrajectoryRun> {
        let starts = self.start_trajectories()?;
        let costs = self.costs()?;
        let scene = self.autodiff_scene();
        let problem = Problem::new(&scene, &self.windows, &costs, self.intrinsics)
            .with_rasterizer(self.config.rasterizer);
        let steps = self.config.optimiser.iterations;
        let started = Instant::now();
        let mut results: Vec<TrajectoryResult> = Vec::new();
        for (r, start) in starts.iter().enumerate() {
            let mut step_observer = |s: &splatraj_traj::optimise::TrajectoryStep| {
                observer.progress(&Progress::Trajectory {
                    restart: r,
                    restarts: starts.len(),
                    step: s.step,
                    steps,
                    total: s.total,
                    best: s.best_total,
                })
            };
            let result = optimise_trajectory(
                &problem,
                start,
                &self.config.optimiser,
                self.config.seed.wrapping_add(r as u64),
                &mut step_observer,
            )?;
            let stop = result.stop;
            results.push(result);
            if stop == StopReason::Interrupted {
                break;
            }
        }
        let best = results
            .iter()
            .enumerate()
            .filter(|(_, r)| r.best_total.is_finite())
            .min_by(|a, b| a.1.best_total.total_cmp(&b.1.best_total))
            .map(|(i, _)| i)
            .unwrap_or(0);
        let stop = results.last().map_or(StopReason::Finished, |r| r.stop);
        anyhow::ensure!(!results.is_empty(), "no optimisation ran");
        Ok(TrajectoryRun {
            results,
            best,
            stop,
            elapsed: started.elapsed(),
            cost_names: costs.names(),
        })
    }

    /// The trajectory of `record` (e.g. a `trajectory.json` read back) on the experiment's
    /// device; a custom model is built from the experiment's registry.
    pub fn trajectory(&self, record: &TrajectoryRecord) -> Result<Trajectory> {
        let model = match &record.model {
            TrajectoryModel::Custom(c) => {
                let windows = c.windows.unwrap_or(self.windows.len());
                record.model.build_with(windows, &self.extensions.models)?
            }
            builtin => builtin.clone(),
        };
        Ok(Trajectory::from_weights(
            model,
            &record.weights,
            &self.device,
            self.dtype,
        )?)
    }

    /// Per-window metrics at the output resolution (`output.metric_samples` per window) and
    /// LDJ (`output.ldj_samples`) of `trajectory`.
    pub fn evaluate(&self, trajectory: &Trajectory) -> Result<Evaluation> {
        let output = self.output_intrinsics()?;
        let plain = self.plain_scene();
        let n = self.windows.len();
        let pose_at = |times: &[f64]| trajectory.poses_at(times);
        let windows = (0..n)
            .map(|i| {
                let samples = self.config.output.metric_samples;
                self.window_metrics(&plain, i, (i, n), samples, &output, &pose_at)
            })
            .collect::<Result<Vec<_>>>()?;
        let ldj = trajectory_ldj(trajectory, self.config.output.ldj_samples);
        Ok(Evaluation { windows, ldj })
    }

    /// Metrics of window `i`'s object on the time grid of window `grid.0` of `grid.1`, at the
    /// poses `pose_at` gives for the grid times.
    pub(crate) fn window_metrics(
        &self,
        plain: &splatraj_render::render::DeviceScene,
        i: usize,
        (index, n): (usize, usize),
        samples: usize,
        intrinsics: &splatraj_render::camera::Intrinsics,
        pose_at: &dyn Fn(&[f64]) -> Vec<[f64; 6]>,
    ) -> Result<WindowMetrics> {
        let w = &self.windows[i];
        let alone = self.object_alone(i);
        let object = WindowObject {
            name: &w.name,
            mask: &w.mask,
            alone: &alone,
            target_ratio: w.context.target_ratio,
            rasterizer: self.config.rasterizer,
        };
        window_metrics(plain, &object, index, n, samples, intrinsics, pose_at)
            .with_context(|| format!("metrics of window {i}"))
    }
}

/// An observer that stops when `stop()` says so (e.g. a Ctrl-C flag), after calling `each`.
pub fn stop_when(mut stop: impl FnMut() -> bool, mut each: impl FnMut(&Progress)) -> impl Observer {
    move |p: &Progress| {
        each(p);
        if stop() { Flow::Stop } else { Flow::Continue }
    }
}
