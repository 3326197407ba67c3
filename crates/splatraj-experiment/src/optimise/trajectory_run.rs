//! The paper's method: optimise a trajectory from each start and keep the best
//! ([`TrajectoryOptimisation`], the optimisation stage's state); the outputs stage evaluates
//! it (`crate::outputs::evaluation`).
//!
//! A run may write a [`Checkpoint`] of its best trajectory as it goes (at a bounded rate), and
//! may continue from one ([`RunOptions::resume`]): the restart in progress goes on from its
//! best weights for its remaining steps (with a fresh Adam, and the prior's weight where it
//! had decayed to), then the remaining restarts run, and the best of all is kept.

use std::borrow::Cow;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Result;
use serde::Serialize;
use splatraj_render::render::DeviceScene;
use splatraj_traj::clearance::Occupancy;
use splatraj_traj::costs::WeightedCosts;
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

/// How [`TrajectoryOptimisation::run`] runs besides the config.
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

/// The optimisation stage, built once from the [`Experiment`] ([`TrajectoryOptimisation::new`]):
/// what every restart shares. It takes the experiment's windows and config and gives a
/// [`TrajectoryRun`], which the outputs stage turns into files.
pub struct TrajectoryOptimisation<'a> {
    experiment: &'a Experiment,
    /// One start per restart ([`Experiment::start_trajectories`]).
    pub starts: Vec<TrajectoryRecord>,
    /// `[costs]`, with the shots' cost when some query has a shot.
    pub costs: WeightedCosts,
    /// The run's model: `[trajectory]`'s, cut where the windows cut
    /// ([`Experiment::run_model`]).
    pub model: TrajectoryModel,
    /// The scene the passes render (the coarse copy when `optimise_gaussians` asks), on the
    /// autodiff device.
    scene: DeviceScene,
    /// The windows, their masks over that scene.
    windows: Cow<'a, [WindowTarget]>,
    /// The clearance cost's geometry, when it is on.
    occupancy: Option<Occupancy>,
}

impl<'a> TrajectoryOptimisation<'a> {
    /// The starts, costs, model, scene and windows of the experiment's optimisation.
    pub fn new(experiment: &'a Experiment) -> Result<Self> {
        let starts = experiment.start_trajectories()?;
        let costs = experiment.with_shot_cost(experiment.costs()?)?;
        let model = experiment.run_model()?;
        let scene = experiment.autodiff_scene();
        let occupancy = experiment.occupancy()?;
        let windows = experiment.optimisation_windows();
        Ok(TrajectoryOptimisation {
            experiment,
            starts,
            costs,
            model,
            scene,
            windows,
            occupancy,
        })
    }

    /// The trajectory problem of a run with `costs`: the windows on the optimisation scene,
    /// with its occupancy and the run's camera, rasterizer, shortcuts and duration, the
    /// windows sharing render calls as `passes` says (a run: `StepPasses::for_backend`).
    pub fn problem<'p>(&'p self, costs: &'p WeightedCosts, passes: StepPasses) -> Problem<'p> {
        let experiment = self.experiment;
        Problem::new(&self.scene, &self.windows, costs, experiment.intrinsics)
            .with_rasterizer(experiment.config.rasterizer)
            .with_approximations(experiment.config.approximations)
            .with_occupancy(self.occupancy.as_ref())
            .with_step_passes(passes)
            .with_seconds(experiment.path_seconds())
    }

    /// Optimises a trajectory from each start (restart r uses seed `seed + r`), checkpointing
    /// into a run folder and/or continuing a checkpoint as `options` say; `observer` sees every
    /// step and may stop the run, which keeps the best trajectory so far.
    /// `optimiser.time_limit_s` bounds the whole run (every restart, this process).
    pub fn run(
        &self,
        options: RunOptions<'_>,
        observer: &mut dyn Observer,
    ) -> Result<TrajectoryRun> {
        let experiment = self.experiment;
        let (starts, costs, model) = (&self.starts, &self.costs, &self.model);
        let steps = experiment.config.optimiser.iterations;
        // The time limit is the run's, not each restart's: this loop enforces it.
        let mut optimiser = experiment.config.optimiser.clone();
        let time_limit = optimiser.time_limit_s.take();
        let base_dir = std::path::absolute(&experiment.config.base_dir)
            .unwrap_or_else(|_| experiment.config.base_dir.clone());
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
            model,
            zoom_range: match experiment.config.camera.lens()? {
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
                c.model == *model,
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
            let start = start.with_lens(experiment.config.camera.lens()?);
            // A resumed restart's zoom is its own; a fresh one's dolly zooms are fitted.
            let start = if steps_before > 0 && start.lens.is_some() {
                start
            } else {
                experiment.with_shot_zoom(start)?
            };
            let shifted_costs;
            let costs = if steps_before > 0 {
                shifted_costs =
                    experiment.with_shot_cost(experiment.costs_from_step(steps_before)?)?;
                &shifted_costs
            } else {
                costs
            };
            let passes = StepPasses::for_backend(experiment.config.backend);
            let problem = self.problem(costs, passes);
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
                experiment.config.seed.wrapping_add(r as u64),
                &mut step_observer,
            )?;
            // A dolly zoom holds the object's size exactly: its zoom follows the distance.
            let result = TrajectoryResult {
                best: experiment.lock_shot_zoom(result.best)?,
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
}

impl Experiment {
    /// Optimises a trajectory from each of [`Experiment::start_trajectories`] with the
    /// experiment's optimisation stage ([`TrajectoryOptimisation::run`], no checkpoint).
    pub fn run_trajectory(&self, observer: &mut dyn Observer) -> Result<TrajectoryRun> {
        TrajectoryOptimisation::new(self)?.run(RunOptions::default(), observer)
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
}

/// An observer that stops when `stop()` says so (e.g. a Ctrl-C flag), after calling `each`.
pub fn stop_when(mut stop: impl FnMut() -> bool, mut each: impl FnMut(&Progress)) -> impl Observer {
    move |p: &Progress| {
        each(p);
        if stop() { Flow::Stop } else { Flow::Continue }
    }
}
