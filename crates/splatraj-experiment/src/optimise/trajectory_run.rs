//! The paper's method: optimise a trajectory from each start, keep the best, evaluate it.
//!
//! A run may write a [`Checkpoint`] of its best trajectory as it goes (at a bounded rate), and
//! may continue from one ([`RunOptions::resume`]): the restart in progress goes on from its
//! best weights for its remaining steps (with a fresh Adam, and the prior's weight where it
//! had decayed to), then the remaining restarts run, and the best of all is kept.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;
use splatraj_render::render::DeviceScene;
use splatraj_traj::clearance::Occupancy;
use splatraj_traj::costs::WeightedCosts;
use splatraj_traj::metrics::{
    Smoothness, WindowMetrics, WindowObject, ZoomAt, trajectory_ldj, verdict, window_metrics_zoomed,
};
use splatraj_traj::optimise::{
    Flow, Problem, StepPasses, StopReason, TrajectoryResult, TrajectoryStep, WindowTarget,
    optimise_trajectory,
};
use splatraj_traj::trajectory::{
    Lens, LensPath, Trajectory, TrajectoryModel, TrajectoryRecord, ZoomRange,
};

use crate::optimise::checkpoint::{Checkpoint, Checkpointer};
use crate::optimise::observer::{Observer, Progress};
use crate::prepare::experiment::Experiment;

/// Why a trajectory run ended (`metrics.json`'s `stop`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStop {
    /// Every restart ran all its iterations.
    Finished,
    /// The observer asked to stop (Ctrl-C).
    Interrupted,
    /// `optimiser.time_limit_s` was reached (over all restarts).
    TimeLimit,
}

/// How [`Experiment::run_trajectory_with`] runs besides the config.
#[derive(Debug, Default)]
pub struct RunOptions<'a> {
    /// Write `checkpoint.json` into this run folder while optimising.
    pub checkpoint_dir: Option<&'a Path>,
    /// Continue the run this checkpoint describes.
    pub resume: Option<&'a Checkpoint>,
}

/// What [`Experiment::run_trajectory`] did.
#[derive(Debug, Clone)]
pub struct TrajectoryRun {
    /// One result per start run (fewer than the starts when stopped early). A resumed run's
    /// first entry is the checkpoint's best (no history).
    pub results: Vec<TrajectoryResult>,
    /// Index in `results` of the best (lowest finite sampled loss).
    pub best: usize,
    /// Finished, interrupted or out of time.
    pub stop: RunStop,
    /// Wall time of the optimisation (this process only).
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

/// Share of a window at each end left out of its wobble (see [`Evaluation::with_frames`]): the
/// quarters where the start pans from and to the neighbours (`ROUTE_TRANSITION`), as the
/// `framed` check leaves them out. Measured at 0.15 on the first-try biker, the turn of a pan
/// away (the framing error's V as the camera leaves the jacket) counted as a wobble of 0.10.
pub const WOBBLE_EDGE: f64 = 0.25;

/// Metrics of a trajectory: per window and smoothness.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// Per-window TCE, TRE, IoU, visibility at the output resolution, each with its verdict.
    pub windows: Vec<WindowMetrics>,
    /// LDJ of the camera centre and rotation.
    pub ldj: Smoothness,
}

impl Evaluation {
    /// Every failed check of every window, as sentences naming the query, what is wrong and
    /// the likely fix (empty when every window passes).
    pub fn problems(&self) -> Vec<String> {
        self.windows
            .iter()
            .filter_map(|w| w.verdict.as_ref())
            .flat_map(|v| v.problems.iter().cloned())
            .collect()
    }

    /// Adds what the rendered frames tell (each window's framing wobble over its frames at
    /// `fps`, [`splatraj_traj::metrics::wobble()`]) and judges every window again.
    ///
    /// A window's wobble is taken over its frames that show the object, leaving out the first
    /// and last [`WOBBLE_EDGE`] of the window, where the camera pans from and to the
    /// neighbouring objects (a pan is a change the wobble must not count), over each unbroken
    /// run of such frames.
    pub fn with_frames(&mut self, frames: &[crate::frame_metrics::FrameMetrics], fps: f64) {
        let n = self.windows.len().max(1);
        for (i, w) in self.windows.iter_mut().enumerate() {
            let (start, end) = splatraj_traj::optimise::sampling::window_bounds(i, n);
            let edge = WOBBLE_EDGE * (end - start);
            let kept: Vec<&crate::frame_metrics::FrameMetrics> = frames
                .iter()
                .filter(|f| {
                    f.window == i && f.coverage > 0.0 && f.t >= start + edge && f.t <= end - edge
                })
                .collect();
            // Each unbroken run of frames on its own: frames on either side of a moment out
            // of frame are not neighbours, and the jump between them is no swing.
            w.framing.wobble = kept
                .chunk_by(|a, b| b.frame == a.frame + 1)
                .filter_map(|run| {
                    let series: Vec<f64> = run.iter().filter_map(|f| f.tce).collect();
                    splatraj_traj::metrics::wobble(&series, fps)
                })
                .reduce(f64::max);
            w.verdict = Some(verdict(w));
        }
    }

    /// How many windows fail their verdict.
    pub fn failing(&self) -> usize {
        self.windows
            .iter()
            .filter(|w| w.verdict.as_ref().is_some_and(|v| !v.pass))
            .count()
    }
}

/// The best trajectory seen so far in a run, for the checkpoint.
struct Tracker<'a> {
    checkpointer: Option<Checkpointer>,
    state: Checkpoint,
    model: &'a TrajectoryModel,
    /// The zoom's range when the lens zooms (the steps report only its weights).
    zoom_range: Option<ZoomRange>,
}

impl Tracker<'_> {
    /// Takes in one step of restart `restart`.
    fn step(&mut self, restart: usize, steps_before: usize, s: &TrajectoryStep) -> Result<()> {
        let state = &mut self.state;
        if state.restart != restart {
            state.restart = restart;
            state.restart_best = None;
            state.restart_best_lens = None;
        }
        state.steps_done = steps_before + s.step + 1;
        if let Some(weights) = &s.new_best {
            state.restart_best = Some((weights.clone(), s.total));
            let lens = self
                .zoom_range
                .zip(s.new_best_lens.clone())
                .map(|(range, weights)| LensPath { range, weights });
            state.restart_best_lens = lens.clone();
            // The first finite loss, or a lower one (best_total starts as NaN).
            if state.best_total.is_nan() || s.total < state.best_total {
                state.model = self.model.clone();
                state.weights = weights.clone();
                state.lens = lens;
                state.best_total = s.total;
                state.best_restart = restart;
                state.best_step = steps_before + s.step;
            }
        }
        match &mut self.checkpointer {
            Some(c) if state.best_total.is_finite() => c.offer(state.clone()),
            _ => Ok(()),
        }
    }

    fn flush(&mut self, elapsed_s: f64) -> Result<()> {
        self.state.elapsed_s = elapsed_s;
        match &mut self.checkpointer {
            Some(c) if self.state.best_total.is_finite() => {
                c.offer(self.state.clone())?;
                c.flush()
            }
            _ => Ok(()),
        }
    }
}

impl Experiment {
    /// The trajectory problem of a run: `windows` and `costs` on the autodiff `scene`, with
    /// the scene's `occupancy` and the run's camera, rasterizer, shortcuts and duration, its
    /// windows sharing render calls as `passes` says (a run: `StepPasses::for_backend`).
    pub fn trajectory_problem<'a>(
        &self,
        scene: &'a DeviceScene,
        windows: &'a [WindowTarget],
        costs: &'a WeightedCosts,
        occupancy: Option<&'a Occupancy>,
        passes: StepPasses,
    ) -> Problem<'a> {
        Problem::new(scene, windows, costs, self.intrinsics)
            .with_rasterizer(self.config.rasterizer)
            .with_approximations(self.config.approximations)
            .with_occupancy(occupancy)
            .with_step_passes(passes)
            .with_seconds(self.path_seconds())
    }

    /// Optimises a trajectory from each of [`Experiment::start_trajectories`] (restart r uses
    /// seed `seed + r`); `observer` sees every step and may stop the run, which keeps the best
    /// trajectory so far.
    pub fn run_trajectory(&self, observer: &mut dyn Observer) -> Result<TrajectoryRun> {
        self.run_trajectory_with(RunOptions::default(), observer)
    }

    /// [`Experiment::run_trajectory`] that checkpoints into a run folder and/or continues a
    /// checkpoint ([`RunOptions`]). `optimiser.time_limit_s` bounds the whole run (every
    /// restart, this process).
    pub fn run_trajectory_with(
        &self,
        options: RunOptions<'_>,
        observer: &mut dyn Observer,
    ) -> Result<TrajectoryRun> {
        let starts = self.start_trajectories()?;
        let costs = self.with_shot_cost(self.costs()?)?;
        // Cut into shots where the windows cut (`[output] transitions`).
        let model = self.run_model()?;
        let scene = self.autodiff_scene();
        let steps = self.config.optimiser.iterations;
        // The time limit is the run's, not each restart's: this loop enforces it.
        let mut optimiser = self.config.optimiser.clone();
        let time_limit = optimiser.time_limit_s.take();
        let base_dir = std::path::absolute(&self.config.base_dir)
            .unwrap_or_else(|_| self.config.base_dir.clone());
        let first_restart = options.resume.map_or(0, |c| c.restart);
        let mut tracker = Tracker {
            checkpointer: options.checkpoint_dir.map(Checkpointer::new),
            state: options
                .resume
                .cloned()
                .map(|c| Checkpoint { steps, ..c })
                .unwrap_or_else(|| Checkpoint {
                    model: model.clone(),
                    weights: Vec::new(),
                    best_total: f64::NAN,
                    best_restart: 0,
                    best_step: 0,
                    restart: 0,
                    steps_done: 0,
                    restart_best: None,
                    restarts: starts.len(),
                    steps,
                    elapsed_s: 0.0,
                    base_dir,
                    lens: None,
                    restart_best_lens: None,
                }),
            model: &model,
            zoom_range: match self.config.camera.lens()? {
                Lens::Zoom(range) => Some(range),
                Lens::Fixed => None,
            },
        };
        let elapsed_before = tracker.state.elapsed_s;
        let mut results: Vec<TrajectoryResult> = Vec::new();
        if let Some(c) = options.resume {
            anyhow::ensure!(
                c.restarts == starts.len(),
                "the checkpoint is of a run with {} restarts, the config asks for {} \
                 (`start.restarts`)",
                c.restarts,
                starts.len()
            );
            anyhow::ensure!(
                c.model == model,
                "the checkpoint's trajectory model differs from the config's `[trajectory]`"
            );
            results.push(TrajectoryResult {
                best: c.best_record(),
                best_total: c.best_total,
                best_step: c.best_step,
                history: Vec::new(),
                skipped_steps: 0,
                stop: StopReason::Finished,
                elapsed: Duration::ZERO,
            });
        }
        let occupancy = self.occupancy()?;
        let windows = self.optimisation_windows();
        let started = Instant::now();
        let mut stop = RunStop::Finished;
        for (r, fresh_start) in starts.iter().enumerate().skip(first_restart) {
            // A resumed restart goes on from its best so far, for the steps it has left.
            let (start, steps_before) = match options.resume {
                Some(c) if r == c.restart => match &c.restart_best {
                    Some((weights, _)) => (
                        TrajectoryRecord {
                            model: model.clone(),
                            weights: weights.clone(),
                            // Its zoom as checkpointed (None: a fixed lens, or an older
                            // checkpoint: the zoom starts again at s ≡ 1).
                            lens: c.restart_best_lens.clone(),
                        },
                        c.steps_done,
                    ),
                    None => (fresh_start.clone(), 0),
                },
                _ => (fresh_start.clone(), 0),
            };
            if steps_before >= steps {
                continue;
            }
            // `[camera] lens`: the zoom starts at s ≡ 1 (or as a start file has it), or as
            // the dolly-zoom shots ask.
            let start = start.with_lens(self.config.camera.lens()?);
            // A resumed restart's zoom is its own; a fresh one's dolly zooms are fitted.
            let start = if steps_before > 0 && start.lens.is_some() {
                start
            } else {
                self.with_shot_zoom(start)?
            };
            let shifted_costs;
            let costs = if steps_before > 0 {
                shifted_costs = self.with_shot_cost(self.costs_from_step(steps_before)?)?;
                &shifted_costs
            } else {
                &costs
            };
            let passes = StepPasses::for_backend(self.config.backend);
            let problem =
                self.trajectory_problem(&scene, &windows, costs, occupancy.as_ref(), passes);
            let mut restart_options = optimiser.clone();
            restart_options.iterations = steps - steps_before;
            let mut stopped_by = None;
            let mut failure = None;
            let mut step_observer = |s: &TrajectoryStep| {
                if let Err(e) = tracker.step(r, steps_before, s) {
                    failure = Some(e);
                    return Flow::Stop;
                }
                let flow = observer.progress(&Progress::Trajectory {
                    restart: r,
                    restarts: starts.len(),
                    step: steps_before + s.step,
                    steps,
                    total: s.total,
                    best: s.best_total,
                });
                if flow == Flow::Stop {
                    stopped_by = Some(RunStop::Interrupted);
                } else if time_limit.is_some_and(|l| started.elapsed().as_secs_f64() >= l) {
                    stopped_by = Some(RunStop::TimeLimit);
                }
                if stopped_by.is_some() {
                    Flow::Stop
                } else {
                    Flow::Continue
                }
            };
            let result = optimise_trajectory(
                &problem,
                &start,
                &restart_options,
                self.config.seed.wrapping_add(r as u64),
                &mut step_observer,
            )?;
            // A dolly zoom holds the object's size exactly: its zoom follows the distance.
            let result = TrajectoryResult {
                best: self.lock_shot_zoom(result.best)?,
                ..result
            };
            if let Some(e) = failure {
                return Err(e.context("writing the checkpoint"));
            }
            results.push(result);
            if let Some(why) = stopped_by {
                stop = why;
                break;
            }
        }
        tracker.flush(elapsed_before + started.elapsed().as_secs_f64())?;
        let best = results
            .iter()
            .enumerate()
            .filter(|(_, r)| r.best_total.is_finite())
            .min_by(|a, b| a.1.best_total.total_cmp(&b.1.best_total))
            .map(|(i, _)| i)
            .unwrap_or(0);
        anyhow::ensure!(!results.is_empty(), "no optimisation ran");
        Ok(TrajectoryRun {
            results,
            best,
            stop,
            elapsed: started.elapsed(),
            cost_names: costs.names(),
        })
    }

    /// The costs as they weigh at step `step` and after: the prior's α_0 becomes α_0·γ^step,
    /// so that a resumed restart's prior weight goes on decaying from where it was.
    fn costs_from_step(&self, step: usize) -> Result<splatraj_traj::costs::WeightedCosts> {
        let mut config = self.config.costs.clone();
        if let Some(prior) = &mut config.prior {
            prior.alpha0 *= prior.gamma.powi(step.min(i32::MAX as usize) as i32);
        }
        config
            .build_with(&self.extensions.costs)
            .map_err(anyhow::Error::msg)
    }

    /// The trajectory of `record` (e.g. a `trajectory.json` read back) on the experiment's
    /// device; a custom model is built from the experiment's registry.
    pub fn trajectory(&self, record: &TrajectoryRecord) -> Result<Trajectory> {
        record.validate()?;
        let model = match &record.model {
            TrajectoryModel::Custom(c) => {
                let windows = c.windows.unwrap_or(self.windows.len());
                record.model.build_with(windows, &self.extensions.models)?
            }
            builtin => builtin.clone(),
        };
        Ok(
            Trajectory::from_weights(model, &record.weights, &self.device, self.dtype)?
                .with_lens(record.lens.as_ref())?,
        )
    }

    /// Per-window metrics at the output resolution (`output.metric_samples` per window) and
    /// LDJ (`output.ldj_samples`) of `trajectory`.
    pub fn evaluate(&self, trajectory: &Trajectory) -> Result<Evaluation> {
        self.evaluate_since(trajectory, splatraj_scene::stop::Since::now())
    }

    /// [`Experiment::evaluate`] that a stop requested `since` ends before the next window's
    /// metrics ([`splatraj_scene::stop::Stopped`]; nothing is written).
    pub fn evaluate_since(
        &self,
        trajectory: &Trajectory,
        since: splatraj_scene::stop::Since,
    ) -> Result<Evaluation> {
        let output = self.output_intrinsics()?;
        let plain = self.plain_scene();
        let n = self.windows.len();
        let pose_at = |times: &[f64]| trajectory.poses_at(times);
        let zoom_at = |times: &[f64]| trajectory.zooms_at(times);
        let zoom_at: Option<ZoomAt<'_>> = trajectory.lens.is_some().then_some(&zoom_at);
        let windows = (0..n)
            .map(|i| {
                since.stop_point(|| format!("the metrics of {i} of {n} windows were computed"))?;
                let samples = self.config.output.metric_samples;
                let path = (&pose_at as &dyn Fn(&[f64]) -> Vec<[f64; 6]>, zoom_at);
                self.window_metrics(&plain, i, (i, n), samples, &output, path)
            })
            .collect::<Result<Vec<_>>>()?;
        let mut windows = self.with_path_metrics(windows, trajectory)?;
        for w in &mut windows {
            w.verdict = Some(verdict(w));
        }
        let ldj = trajectory_ldj(trajectory, self.config.output.ldj_samples);
        Ok(Evaluation { windows, ldj })
    }

    /// Metrics of window `i`'s object on the time grid of window `grid.0` of `grid.1`, at the
    /// poses `pose_at` gives for the grid times, through the zoom `zoom_at` gives (None: the
    /// fixed lens).
    pub(crate) fn window_metrics(
        &self,
        plain: &splatraj_render::render::DeviceScene,
        i: usize,
        (index, n): (usize, usize),
        samples: usize,
        intrinsics: &splatraj_render::camera::Intrinsics,
        (pose_at, zoom_at): PathAt<'_>,
    ) -> Result<WindowMetrics> {
        let w = &self.windows[i];
        let alone = self.object_alone(i);
        let object = WindowObject {
            name: &w.name,
            mask: &w.mask,
            alone: &alone,
            target_ratio: w.context.target_ratio,
            rasterizer: self.config.rasterizer,
            bounds: self.boxes.get(i).copied(),
        };
        window_metrics_zoomed(
            plain, &object, index, n, samples, intrinsics, pose_at, zoom_at,
        )
        .with_context(|| format!("metrics of window {i}"))
    }
}

/// Where a path is at given times: its poses, and its zooms when the lens zooms.
pub(crate) type PathAt<'a> = (&'a dyn Fn(&[f64]) -> Vec<[f64; 6]>, Option<ZoomAt<'a>>);

/// An observer that stops when `stop()` says so (e.g. a Ctrl-C flag), after calling `each`.
pub fn stop_when(mut stop: impl FnMut() -> bool, mut each: impl FnMut(&Progress)) -> impl Observer {
    move |p: &Progress| {
        each(p);
        if stop() { Flow::Stop } else { Flow::Continue }
    }
}
