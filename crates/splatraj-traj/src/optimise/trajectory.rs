//! Trajectory optimisation: burn's Adam on the weights W of a [`Trajectory`], through the
//! renderer, on stratified samples of every query window.
//!
//! Each step k, for every query window i (docs/conventions.md "Optimisation problem"):
//! 1. draw S times stratified inside T_i ([`super::sampling`]);
//! 2. poses Φ(t) = Ψ(t)·W `[S, 6]` (one matmul, differentiable in W);
//! 3. render the window's object mask at all S poses, object-pruned; on a GPU every window's
//!    samples (and each object alone, when a cost reads it) share one render call
//!    ([`Problem::evaluate_windows`], [`super::StepPasses`]);
//! 4. evaluate the [`crate::costs::WeightedCosts`] at step k and average over the S samples.
//!
//! The loss is the mean over windows of those averages, the Monte Carlo estimate of
//! (1/n)·Σ_i n·∫_{T_i} L dt; one backward pass gives ∂loss/∂W, and burn's Adam steps W.
//! W is held in normalised units ([`PoseUnits`]), so one learning rate moves rotations in
//! radians and positions in `position` scene units.
//!
//! A step whose loss is not finite stops the loop with [`OptimiseError::LossNotFinite`]
//! (naming the step and the learning rate): W has left the range where the costs are finite,
//! and every later step would be evaluated at the same W, so nothing non-finite is ever
//! recorded. A step whose gradient alone is not finite is skipped (W and Adam's state
//! unchanged) and counted; the best weights seen (lowest sampled loss) are kept.
//! The sampled loss is noisy, so "best" is judged on the estimate; later steps are slightly
//! favoured because the prior's weight decays. An observer sees every step and may stop the
//! run (Ctrl-C, a time budget): the best trajectory so far is still returned.
//!
//! **One read a step.** On a GPU every read back is a wait for the device, so a step reads
//! once: every window's sample and path poses come from one forward of the model (the basis
//! evaluated on the host, [`Trajectory::forward_at`]) and are read together with the previous
//! step's results (each window's term means, the loss, whether the gradient was finite, the
//! weights it was measured at), which stay on the device until then. The renders' host
//! decisions and the clearance cost take the poses from that read. Adam steps W at once; a
//! step whose gradient turns out not to be finite is undone when the next step reads that
//! (the model and optimiser before it are kept), and the poses are evaluated again. So a
//! step's row reaches the observer during the next step, and the last step's after one more
//! read (`tests/step_reads.rs` counts them).

use std::time::{Duration, Instant};

use super::units::PoseUnits;
use super::{
    OptimiseError, Problem, StepEvaluation, WindowPath, WindowSamples, backward, check_adam,
    host_values, sampling,
};
use crate::costs::{HostPoses, QueryContext};
use crate::trajectory::{LensPath, POSE_DIM, Trajectory, TrajectoryModel, TrajectoryRecord};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Tensor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use splatraj_render::render::Zoom;

/// Default points per window of the path the path costs read each step.
pub const DEFAULT_PATH_SAMPLES: usize = 16;

/// Times of window `index`'s stretch of the path (of `windows`), `per_window` points per
/// window on the grid t_j = (j + phase)/(windows·per_window) shared by all windows, from one
/// point before the window to its next window's first point (so the differences of
/// consecutive points cover the joins between windows), kept inside [0, 1]; and the grid's
/// step. A new phase ∈ [0, 1) each step moves the grid, so over the steps every instant of
/// the path is judged (the optimiser uses phase 0, which holds both ends, every other step).
pub fn path_times(index: usize, windows: usize, per_window: usize, phase: f64) -> (Vec<f64>, f64) {
    let step = 1.0 / (windows.max(1) * per_window.max(1)) as f64;
    let first = (index * per_window) as i64 - 1;
    let last = ((index + 1) * per_window) as i64;
    let times = (first..=last)
        .map(|j| (j as f64 + phase) * step)
        .filter(|t| (0.0..=1.0).contains(t))
        .collect();
    (times, step)
}

/// [`path_times`] kept to the times of window `index`'s shot when the trajectory is cut
/// into `shots` ([`crate::trajectory::cuts`]): the path costs then never see the jump at a
/// cut, which is no motion.
pub fn shot_path_times(
    index: usize,
    shots: &crate::trajectory::ShotSpans,
    per_window: usize,
    phase: f64,
) -> (Vec<f64>, f64) {
    let (times, step) = path_times(index, shots.windows, per_window, phase);
    let shot = shots.shot_of_window(index);
    let times = times
        .into_iter()
        .filter(|&t| shots.shot_of(t) == shot)
        .collect();
    (times, step)
}

/// One query window's object: its per-Gaussian mask and cost context.
#[derive(Debug, Clone)]
pub struct WindowTarget {
    /// Name shown in logs and metrics (the query).
    pub name: String,
    /// One value per Gaussian of the scene: 1 for the object's Gaussians.
    pub mask: Vec<f32>,
    /// Object centre, prior radius, world up, target ratio.
    pub context: QueryContext,
}

/// Settings of [`optimise_trajectory`] (the config's `[optimiser]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajectoryOptions {
    /// Adam steps (each renders `samples_per_window` poses per window). Default 200 (the paper).
    pub iterations: usize,
    /// Stratified time samples per window per step (≥ 1). Default 4.
    pub samples_per_window: usize,
    /// Adam learning rate in normalised units (radians; `position_unit` scene units). Default 0.02.
    pub learning_rate: f64,
    /// Adam's β1 ∈ [0, 1). Default 0.9.
    pub beta1: f64,
    /// Adam's β2 ∈ [0, 1). Default 0.999.
    pub beta2: f64,
    /// Adam's ε > 0. Default 1e-8.
    pub epsilon: f64,
    /// Scene units per normalised position unit: a step of `learning_rate` moves the camera
    /// about `learning_rate × position_unit`. Default (None): the mean prior radius of the
    /// windows, so the step scales with the objects' working distance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position_unit: Option<f64>,
    /// Stop after this many seconds (the best trajectory so far is returned). Default: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_limit_s: Option<f64>,
    /// Points per window of the densely sampled path that path costs (clearance, motion)
    /// read each step (≥ 2; only used when such a cost is on). Default 16.
    pub path_samples: usize,
}

impl Default for TrajectoryOptions {
    /// 200 iterations, 4 samples per window, learning rate 0.02, β = (0.9, 0.999), ε = 1e-8.
    fn default() -> Self {
        Self {
            iterations: 200,
            samples_per_window: 4,
            learning_rate: 0.02,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            position_unit: None,
            time_limit_s: None,
            path_samples: DEFAULT_PATH_SAMPLES,
        }
    }
}

impl TrajectoryOptions {
    /// Checks every field; errors name the field.
    pub fn validate(&self) -> Result<(), OptimiseError> {
        // Zero steps would optimise nothing and leave the run without a trajectory at its end.
        if self.iterations == 0 {
            return Err(OptimiseError::InvalidOptions {
                field: "iterations",
                reason: "= 0 must be at least 1".into(),
            });
        }
        if self.path_samples < 2 {
            return Err(OptimiseError::InvalidOptions {
                field: "path_samples",
                reason: format!("= {} must be at least 2", self.path_samples),
            });
        }
        if self.samples_per_window == 0 {
            return Err(OptimiseError::InvalidOptions {
                field: "samples_per_window",
                reason: "must be at least 1".into(),
            });
        }
        for (field, value) in [
            ("position_unit", self.position_unit),
            ("time_limit_s", self.time_limit_s),
        ] {
            if let Some(v) = value
                && !(v.is_finite() && v > 0.0)
            {
                return Err(OptimiseError::InvalidOptions {
                    field,
                    reason: format!("= {v} must be finite and > 0"),
                });
            }
        }
        check_adam(
            ("learning_rate", self.learning_rate),
            self.beta1,
            self.beta2,
            self.epsilon,
        )
    }

    /// The normalised units for `windows`: `position_unit`, or their mean prior radius.
    pub fn units(&self, windows: &[WindowTarget]) -> PoseUnits {
        let mean_radius = windows.iter().map(|w| w.context.prior_radius).sum::<f64>()
            / windows.len().max(1) as f64;
        PoseUnits::with_position(self.position_unit.unwrap_or(mean_radius))
    }
}

/// What the observer may tell the loop after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Continue,
    /// Stop now and return the best trajectory so far.
    Stop,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// All iterations ran.
    Finished,
    /// The observer asked to stop (e.g. Ctrl-C), or the time limit was reached.
    Interrupted,
}

/// One step of a trajectory optimisation (a `history.csv` row).
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryStep {
    /// Step k (0 first).
    pub step: usize,
    /// Time since the loop started.
    pub elapsed: Duration,
    /// Sampled loss: mean over windows of each window's mean weighted total.
    pub total: f64,
    /// Per window, each term as `(name, weight at k, unweighted mean over the samples)`.
    pub windows: Vec<Vec<(&'static str, f64, f64)>>,
    /// Whether Adam updated W after this evaluation (false when the step was skipped).
    pub updated: bool,
    /// Lowest sampled loss so far (this step included).
    pub best_total: f64,
    /// The weights `[K][6]` (scene units) when this step set a new best, so that an observer
    /// can checkpoint the best trajectory while the loop runs; `None` otherwise.
    pub new_best: Option<Vec<[f64; 6]>>,
    /// The zoom's weights w_s `[K]` of that new best when the lens zooms.
    pub new_best_lens: Option<Vec<f64>>,
    /// Where the step's time went.
    pub timing: StepTiming,
}

/// Wall time of one step's phases (what `splatraj study` reports per stage).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepTiming {
    /// Poses (with the step's one read), renders and costs of every window, up to the loss.
    pub evaluate: Duration,
    /// The backward pass (on a GPU the time to queue it: it is read with the next step).
    pub backward: Duration,
    /// Adam's update.
    pub update: Duration,
}

/// What [`optimise_trajectory`] found.
#[derive(Debug, Clone)]
pub struct TrajectoryResult {
    /// The best trajectory seen (lowest sampled loss), in scene units.
    pub best: TrajectoryRecord,
    /// Its sampled loss.
    pub best_total: f64,
    /// The step at which it was evaluated.
    pub best_step: usize,
    /// One row per step run.
    pub history: Vec<TrajectoryStep>,
    /// Steps skipped because the gradient was not finite.
    pub skipped_steps: usize,
    /// Whether all iterations ran.
    pub stop: StopReason,
    /// Wall time of the loop.
    pub elapsed: Duration,
}

/// Optimises `start` (any model, weights in scene units) on the costs of every window of
/// `problem`.
///
/// `problem.scene` must live on an autodiff device; the trajectory takes its device and dtype.
/// `seed` drives the stratified sampling. `observer` sees each step and may stop the loop, as
/// does `options.time_limit_s`.
pub fn optimise_trajectory(
    problem: &Problem<'_>,
    start: &TrajectoryRecord,
    options: &TrajectoryOptions,
    seed: u64,
    observer: &mut dyn FnMut(&TrajectoryStep) -> Flow,
) -> Result<TrajectoryResult, OptimiseError> {
    options.validate()?;
    // A copy: a step may turn a shared render call into a call per window for the rest.
    let mut problem = *problem;
    let (device, dtype) = problem.gradient_setup()?;
    let windows = problem.windows;
    let units = options.units(windows);
    units.validate()?;
    let renders = problem.renders();
    let normalised: Vec<_> = start.weights.iter().map(|w| units.normalise(w)).collect();
    let mut module = Trajectory::from_weights(start.model.clone(), &normalised, &device, dtype)?
        .with_lens(start.lens.as_ref())?;
    let mut optim = AdamConfig::new()
        .with_beta_1(options.beta1 as f32)
        .with_beta_2(options.beta2 as f32)
        .with_epsilon(options.epsilon as f32)
        .init();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let needs_path = problem.costs.needs_path();
    let shots = start.model.shots(windows.len());
    let started = Instant::now();
    let n = windows.len();
    let mut stop = StopReason::Finished;
    // Step k's results stay on the device until step k + 1 reads its poses: one read a step.
    let mut pending: Option<Pending> = None;
    let mut bookkeeping = Bookkeeping {
        options,
        units: &units,
        started,
        // Grown as steps run: a time limit may stop it long before `iterations`.
        history: Vec::with_capacity(options.iterations.min(1 << 12)),
        best: None,
        skipped_steps: 0,
        observer,
    };

    for step in 0..options.iterations {
        let step_started = Instant::now();
        // Every other step the grid holds t = 0 and t = 1 exactly (the path's ends, which a
        // shifted grid reaches only rarely); in between, a random shift covers the rest.
        let phase: f64 = if needs_path && step % 2 == 1 {
            rng.random()
        } else {
            0.0
        };
        let times: Vec<StepTimes> = (0..n)
            .map(|i| StepTimes {
                samples: sampling::stratified_times(
                    i,
                    n,
                    options.samples_per_window,
                    Some(&mut rng),
                ),
                path: needs_path.then(|| shot_path_times(i, &shots, options.path_samples, phase)),
            })
            .collect();
        let (mut poses, mut host) = step_poses(&module, &units, &times, pending.as_ref())?;
        if let Some(done) = pending.take() {
            let previous = std::mem::take(&mut host.previous);
            match bookkeeping.finish(done, &previous)? {
                Finished::Continue => {}
                Finished::Stop => {
                    stop = StopReason::Interrupted;
                    break;
                }
                Finished::Skipped(restored) => {
                    // The previous step's gradient was not finite: undo its update and take
                    // this step's poses from the restored weights (a second read, rare).
                    (module, optim) = *restored;
                    (poses, host) = step_poses(&module, &units, &times, None)?;
                }
            }
        }

        // Every window's samples together: one render call a step on a GPU (`StepPasses`).
        let window_samples: Vec<WindowSamples> = host
            .windows
            .iter()
            .enumerate()
            .map(|(i, segment)| WindowSamples {
                window: i,
                count: segment.samples.1,
                times: Some(&times[i].samples),
                // Rows of `poses` after the samples: cut out only where a cost reads it alone.
                path: segment
                    .path
                    .map(|(_, count, time_step)| WindowPath::Rows(count, time_step)),
                host: Some(&segment.poses),
                zoom: host.zoom.as_ref().map(|(zoom, values)| {
                    let (offset, count) = segment.samples;
                    Zoom::at(
                        zoom.clone().narrow(0, offset, count),
                        values[offset..offset + count].to_vec(),
                    )
                }),
            })
            .collect();
        // The samples, then the paths: the joined path is one slice of these rows.
        let evaluated =
            problem.evaluate_windows(poses.clone(), window_samples, step, renders.as_ref())?;
        // A shared call the device could not hold is not tried again.
        problem = problem.with_step_passes(evaluated.passes);
        let StepEvaluation {
            loss,
            means,
            labels,
            ..
        } = evaluated;
        let mut means = vec![means];
        // Weights before the update: they are what the loss is measured at.
        let evaluated = module.weights.val().without_autodiff();
        let evaluated_lens = module.lens.as_ref().map(|l| l.val().without_autodiff());
        let backward_started = Instant::now();
        let grads = backward(&loss)?;
        let [rows, _] = evaluated.dims();
        // The gradient itself is read back (K·6 values) and checked on the host: on a GPU the
        // check as tensor ops (`is_finite().all()` and its casts) was 8 launches a step.
        let gradient = match module.weights.val().grad(&grads) {
            Some(g) => g.cast(evaluated.dtype()).reshape([rows * POSE_DIM]),
            None => Tensor::<1>::zeros([rows * POSE_DIM], (&evaluated.device(), evaluated.dtype())),
        };
        let backward_done = Instant::now();
        // Adam steps now; the finiteness of the gradient is read with the next step's poses,
        // and a step that should have been skipped is undone from these copies.
        let before = Box::new((module.clone(), optim.clone()));
        let grads = GradientsParams::from_grads(grads, &module);
        module = optim.step(options.learning_rate, module, grads);
        means.push(loss.clone().without_autodiff());
        means.push(gradient);
        means.push(evaluated.reshape([rows * POSE_DIM]));
        let lens_weights = if let Some(lens) = evaluated_lens {
            means.push(lens.reshape([rows]));
            rows
        } else {
            0
        };
        pending = Some(Pending {
            step,
            labels,
            values: Tensor::cat(means, 0),
            lens_weights,
            before,
            timing: StepTiming {
                evaluate: backward_started - step_started,
                backward: backward_done - backward_started,
                update: backward_done.elapsed(),
            },
        });
    }
    // The last step's results: one more read.
    if let Some(done) = pending.take() {
        let values = host_values(done.values.clone())?;
        if let Finished::Stop = bookkeeping.finish(done, &values)? {
            stop = StopReason::Interrupted;
        }
    }

    let Bookkeeping {
        history,
        best,
        skipped_steps,
        ..
    } = bookkeeping;
    let model: TrajectoryModel = module.model().clone();
    let Best {
        total: best_total,
        step: best_step,
        weights,
        lens,
    } = best.unwrap_or_else(|| Best {
        total: f64::NAN,
        step: 0,
        weights: module.host_weights(),
        lens: module.lens_path().map(|l| l.weights),
    });
    let lens = module.lens_path().map(|path| LensPath {
        weights: lens.unwrap_or(path.weights),
        ..path
    });
    Ok(TrajectoryResult {
        best: TrajectoryRecord {
            model,
            weights: weights.iter().map(|w| units.denormalise(w)).collect(),
            lens,
        },
        best_total,
        best_step,
        history,
        skipped_steps,
        stop,
        elapsed: started.elapsed(),
    })
}

/// The times one window samples in a step: its S samples and, when path costs are on, its
/// stretch of the path and the grid's step.
struct StepTimes {
    samples: Vec<f64>,
    path: Option<(Vec<f64>, f64)>,
}

/// One window's rows in a step's pose tensor (offset, count) and their values on the host.
struct WindowRows {
    samples: (usize, usize),
    /// (offset, count, time step)
    path: Option<(usize, usize, f64)>,
    poses: HostPoses,
}

/// What a step's one read brought back.
struct StepRead {
    windows: Vec<WindowRows>,
    /// Every row's zoom `[T]` (differentiable) and its host values, when the lens zooms.
    zoom: Option<(Tensor<1>, Vec<f64>)>,
    /// The previous step's values ([`Pending::values`]), empty at the first step.
    previous: Vec<f64>,
}

/// What step k leaves on the device for the host, read with step k + 1's poses.
struct Pending {
    step: usize,
    /// Per window, each term's `(name, weight)`.
    labels: Vec<Vec<(&'static str, f64)>>,
    /// Per window its terms' means, then the loss, the gradient of the weights `[K·6]` (for
    /// its finiteness) and the weights the loss was measured at `[K·6]`, then the zoom's `[K]`
    /// when it zooms.
    values: Tensor<1>,
    /// How many zoom weights end `values` (0 for the fixed lens).
    lens_weights: usize,
    /// The model and optimiser before this step's update, to undo it if its gradient was
    /// not finite.
    before: Box<(Trajectory, ModuleOptimizer)>,
    timing: StepTiming,
}

/// How a step's bookkeeping ended.
enum Finished {
    Continue,
    /// The observer or the time limit stopped the loop.
    Stop,
    /// The gradient was not finite: go on from the model and optimiser before its update.
    Skipped(Box<(Trajectory, ModuleOptimizer)>),
}

/// Every window's sample and path poses of a step in one forward of the model `[T, 6]`, and
/// their host values read in one read together with the previous step's `pending` values.
fn step_poses(
    module: &Trajectory,
    units: &PoseUnits,
    times: &[StepTimes],
    pending: Option<&Pending>,
) -> Result<(Tensor<2>, StepRead), OptimiseError> {
    // Every window's samples first, one window after the other (the step's one render takes
    // them as one block), then every window's path.
    let mut all = Vec::new();
    let mut sample_rows = Vec::with_capacity(times.len());
    for t in times {
        sample_rows.push((all.len(), t.samples.len()));
        all.extend_from_slice(&t.samples);
    }
    let mut layout = Vec::with_capacity(times.len());
    for (t, samples) in times.iter().zip(sample_rows) {
        let path = t.path.as_ref().map(|(path, time_step)| {
            let rows = (all.len(), path.len(), *time_step);
            all.extend_from_slice(path);
            rows
        });
        layout.push((samples, path));
    }
    let count = all.len();
    let poses = units.to_scene(module.forward_at(&all)); // [T, 6]
    let zoom = module.zoom_at(&all); // [T] when the lens zooms
    let mut read = vec![poses.clone().without_autodiff().reshape([count * POSE_DIM])];
    read.extend(zoom.clone().map(|z| z.without_autodiff()));
    read.extend(pending.map(|p| p.values.clone()));
    let mut values = host_values(Tensor::cat(read, 0))?;
    let zoom_rows = if zoom.is_some() { count } else { 0 };
    let previous = values.split_off(count * POSE_DIM + zoom_rows);
    let zoom = zoom.map(|z| (z, values.split_off(count * POSE_DIM)));
    let rows = |(offset, len): (usize, usize)| -> Vec<[f64; 6]> {
        values[offset * POSE_DIM..(offset + len) * POSE_DIM]
            .chunks_exact(POSE_DIM)
            .map(|p| std::array::from_fn(|k| p[k]))
            .collect()
    };
    let windows = layout
        .into_iter()
        .map(|(samples, path)| WindowRows {
            samples,
            path,
            poses: HostPoses {
                samples: rows(samples),
                path: path.map(|(offset, len, _)| rows((offset, len))),
            },
        })
        .collect();
    Ok((
        poses,
        StepRead {
            windows,
            zoom,
            previous,
        },
    ))
}

/// The lowest sampled loss so far, its step, weights (normalised) and zoom weights.
struct Best {
    total: f64,
    step: usize,
    weights: Vec<[f64; 6]>,
    lens: Option<Vec<f64>>,
}

/// The host side of the loop: history rows, the best weights, the observer.
struct Bookkeeping<'a> {
    options: &'a TrajectoryOptions,
    units: &'a PoseUnits,
    started: Instant,
    history: Vec<TrajectoryStep>,
    best: Option<Best>,
    skipped_steps: usize,
    observer: &'a mut dyn FnMut(&TrajectoryStep) -> Flow,
}

impl Bookkeeping<'_> {
    /// Records step `done` from its read `values`; fails when its loss is not finite.
    fn finish(&mut self, done: Pending, values: &[f64]) -> Result<Finished, OptimiseError> {
        let mut next = values.iter().copied();
        let windows: Vec<Vec<(&'static str, f64, f64)>> = done
            .labels
            .iter()
            .map(|labels| {
                labels
                    .iter()
                    .map(|&(name, weight)| (name, weight, next.next().unwrap_or(f64::NAN)))
                    .collect()
            })
            .collect();
        let total = next.next().unwrap_or(f64::NAN);
        let mut rest: Vec<f64> = next.collect();
        // The zoom's K weights follow the K·6 pose weights when the lens zooms; before them,
        // as many gradient values as pose weights.
        let lens = (done.lens_weights > 0).then(|| rest.split_off(rest.len() - done.lens_weights));
        let weights = rest.split_off(rest.len() / 2);
        let finite = !rest.is_empty() && rest.iter().all(|v| v.is_finite());
        let evaluated: Vec<[f64; 6]> = weights
            .chunks_exact(POSE_DIM)
            .map(|p| std::array::from_fn(|k| p[k]))
            .collect();
        let step = done.step;
        if !total.is_finite() {
            return Err(OptimiseError::LossNotFinite {
                step,
                total,
                why: super::loss_blame(&windows, step, self.options.learning_rate),
            });
        }
        if !finite {
            self.skipped_steps += 1;
        }
        let improved = self.best.as_ref().is_none_or(|b| total < b.total);
        let new_best = improved.then(|| {
            evaluated
                .iter()
                .map(|w| self.units.denormalise(w))
                .collect()
        });
        let new_best_lens = lens.clone().filter(|_| improved);
        if improved {
            self.best = Some(Best {
                total,
                step,
                weights: evaluated,
                lens,
            });
        }
        let row = TrajectoryStep {
            step,
            elapsed: self.started.elapsed(),
            total,
            windows,
            updated: finite,
            best_total: self.best.as_ref().map_or(f64::NAN, |b| b.total),
            new_best,
            new_best_lens,
            timing: done.timing,
        };
        let out_of_time = self
            .options
            .time_limit_s
            .is_some_and(|limit| row.elapsed.as_secs_f64() >= limit);
        let flow = if out_of_time {
            Flow::Stop
        } else {
            (self.observer)(&row)
        };
        self.history.push(row);
        Ok(if flow == Flow::Stop {
            Finished::Stop
        } else if finite {
            Finished::Continue
        } else {
            Finished::Skipped(done.before)
        })
    }
}
