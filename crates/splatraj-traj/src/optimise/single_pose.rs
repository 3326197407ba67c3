//! Single-pose optimisation: Φ = (ω, c) itself is the parameter (the paper's Table I ablation).
//!
//! Each step k renders the object's mask at Φ (only if some cost reads it), evaluates the
//! [`crate::costs::WeightedCosts`] at step k (so the prior's weight α_k decays), backpropagates the
//! total to Φ and moves Φ with burn's Adam. Several starts run at once as one batch `[B, 6]` (the
//! restarts): the loss is the sum of their totals, so each start gets exactly its own gradient, and
//! Adam works element by element, so the starts do not interact. The best pose of each start
//! (lowest total) is returned, with its history.
//!
//! **Units.** Φ mixes radians and scene units, which want separate step sizes
//! ([`SinglePoseOptions::lr_rotation`], [`SinglePoseOptions::lr_position`]); burn's Adam takes
//! one learning rate. The parameter is held in normalised units ([`PoseUnits`] with
//! rotation = lr_rotation and position = lr_position) and Adam runs with learning rate 1: since
//! Adam's step is about the learning rate in each coordinate whatever the gradient's scale,
//! that is Adam with the two learning rates. It also suits the problem: neither the large
//! (finite) gradient of the prior's guard near the object centre nor a faint mask at the
//! frame's edge throws the camera away or stalls it.
//!
//! **Staying finite.** A step whose total or gradient is not finite (for any start) is
//! skipped (counted in [`SinglePoseResult::skipped_steps`]): Φ and Adam's moments keep their
//! previous values, so one bad render cannot poison the rest of the run.
//!
//! **Best pose.** The total at step k uses α_k, which decays, so totals of different steps
//! are not quite comparable; later steps are favoured slightly, which is what one wants of a
//! run that converges. The pose after the last update is evaluated too (at k = iterations).
//!
//! The rotation vector is not wrapped back into |ω| ≤ π: Rodrigues is well defined for any ω,
//! and re-charting ω would invalidate Adam's moments, which belong to one chart.

use std::time::{Duration, Instant};

use burn::module::{Module, Param};
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};
use splatraj_render::camera::Pose;

use super::trajectory::{Flow, StopReason};
use super::units::PoseUnits;
use super::{OptimiseError, Problem, backward, check_adam, check_starts, host_values, per_sample};
use crate::costs::HostPoses;

/// Settings of [`optimise_single_pose`]; the defaults suit scenes in metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SinglePoseOptions {
    /// Number of Adam steps (each one render, forward and backward). Default 150.
    pub iterations: usize,
    /// Adam step size for ω, radians. Default 0.02 (≈ 1.1° a step: a 35° error closes in ~30
    /// steps, and the jitter left at the optimum moves the object ~0.5 px at 64 px width).
    pub lr_rotation: f64,
    /// Adam step size for the camera centre c, scene units. Default 0.01 (1 cm a step in a
    /// metric scene: a metre in ~100 steps). Scale it with the scene (≈ 2 % of the prior radius).
    pub lr_position: f64,
    /// Adam's first-moment decay β1 ∈ [0, 1). Default 0.9.
    pub beta1: f64,
    /// Adam's second-moment decay β2 ∈ [0, 1). Default 0.999.
    pub beta2: f64,
    /// Adam's ε (> 0) in m̂/(√v̂ + ε). Default 1e-8.
    pub epsilon: f64,
}

impl Default for SinglePoseOptions {
    /// 150 iterations, lr 0.02 rad / 0.01 scene units, β = (0.9, 0.999), ε = 1e-8.
    fn default() -> Self {
        Self {
            iterations: 150,
            lr_rotation: 0.02,
            lr_position: 0.01,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        }
    }
}

impl SinglePoseOptions {
    /// Checks every field's range; errors name the field.
    pub fn validate(&self) -> Result<(), OptimiseError> {
        // Zero steps would only judge the starts: not an optimisation (and `pose` would
        // report a start as an optimised pose).
        if self.iterations == 0 {
            return Err(OptimiseError::InvalidOptions {
                field: "iterations",
                reason: "= 0 must be at least 1".into(),
            });
        }
        for (field, lr) in [
            ("lr_rotation", self.lr_rotation),
            ("lr_position", self.lr_position),
        ] {
            if !(lr.is_finite() && lr > 0.0) {
                return Err(OptimiseError::InvalidOptions {
                    field,
                    reason: format!("= {lr} must be finite and > 0"),
                });
            }
        }
        check_adam(
            ("lr_rotation", self.lr_rotation),
            self.beta1,
            self.beta2,
            self.epsilon,
        )
    }

    /// The normalised units in which Adam's unit learning rate is these two rates.
    pub fn units(&self) -> PoseUnits {
        PoseUnits {
            rotation: self.lr_rotation,
            position: self.lr_position,
        }
    }
}

/// One step of the history (a `history.csv` row).
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryRow {
    /// Step k (0 first; the evaluation after the last update has k = iterations).
    pub step: usize,
    /// The pose Φ evaluated at this step.
    pub pose: Pose,
    /// Weighted total Σ w_i(k)·cost_i.
    pub total: f64,
    /// Each term as `(name, weight at k, unweighted value)`, in the costs' order.
    pub terms: Vec<(&'static str, f64, f64)>,
    /// Whether an Adam update followed (false for a skipped non-finite step and the last row).
    pub updated: bool,
}

/// What [`optimise_single_pose`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct SinglePoseResult {
    /// The best pose seen (lowest total).
    pub pose: Pose,
    /// Its total.
    pub total: f64,
    /// Its terms, `(name, weight, value)`.
    pub terms: Vec<(&'static str, f64, f64)>,
    /// Step at which it was evaluated.
    pub best_step: usize,
    /// The pose after the last update (may differ from the best).
    pub last_pose: Pose,
    /// One row per evaluation: `iterations + 1` rows.
    pub history: Vec<HistoryRow>,
    /// Steps skipped because the total or the gradient was not finite.
    pub skipped_steps: usize,
    /// Wall time of the whole optimisation.
    pub elapsed: Duration,
    /// Whether all iterations ran.
    pub stop: StopReason,
}

/// The poses being optimised, in normalised units `[B, 6]`: the Module burn's Adam steps.
#[derive(Module, Debug)]
struct PoseBatch {
    poses: Param<Tensor<2>>,
}

/// Optimises one pose Φ from `start` on the costs of `problem`'s one window (its object's
/// mask and context), rendered with its camera.
///
/// `problem.scene` must live on an autodiff device; Φ takes its device and dtype. See the
/// module docs for the algorithm, the skipping of non-finite steps and the choice of the best
/// pose.
pub fn optimise_single_pose(
    problem: &Problem<'_>,
    start: Pose,
    options: &SinglePoseOptions,
) -> Result<SinglePoseResult, OptimiseError> {
    let mut results = optimise_poses(problem, &[start], options)?;
    Ok(results.remove(0))
}

/// [`optimise_single_pose`] from several starts at once (one batched render per step); one
/// result per start, in order. Callers keep the best with [`SinglePoseResult::total`].
pub fn optimise_poses(
    problem: &Problem<'_>,
    starts: &[Pose],
    options: &SinglePoseOptions,
) -> Result<Vec<SinglePoseResult>, OptimiseError> {
    optimise_poses_observed(problem, starts, options, &mut |_, _| Flow::Continue)
}

/// [`optimise_poses`] with an observer told `(step, lowest total so far over all starts)`
/// after each step; [`Flow::Stop`] ends the loop (each start keeps its best so far).
pub fn optimise_poses_observed(
    problem: &Problem<'_>,
    starts: &[Pose],
    options: &SinglePoseOptions,
    observer: &mut dyn FnMut(usize, f64) -> Flow,
) -> Result<Vec<SinglePoseResult>, OptimiseError> {
    options.validate()?;
    problem.single()?;
    check_starts(starts, "starts")?;
    let (device, dtype) = problem.gradient_setup()?;
    let renders = problem.renders();
    let units = options.units();
    let to_tensor = |rows: &[[f64; 6]]| {
        let flat: Vec<f64> = rows.iter().flat_map(|p| units.normalise(p)).collect();
        splatraj_render::host::upload::<2>(TensorData::new(flat, [rows.len(), 6]), &device, dtype)
    };
    // Scene poses (already denormalised on the device) as host rows.
    let from_tensor = |t: Tensor<2>| -> Result<Vec<[f64; 6]>, OptimiseError> {
        Ok(host_values(t)?
            .chunks_exact(6)
            .map(|r| r.try_into().expect("rows of six"))
            .collect())
    };
    let start_rows: Vec<[f64; 6]> = starts.iter().map(|p| p.0).collect();
    let mut module = PoseBatch {
        poses: Param::from_tensor(to_tensor(&start_rows)),
    };
    let mut optim = AdamConfig::new()
        .with_beta_1(options.beta1 as f32)
        .with_beta_2(options.beta2 as f32)
        .with_epsilon(options.epsilon as f32)
        .init();

    let started = Instant::now();
    let mut skipped_steps = 0;
    let mut histories: Vec<Vec<HistoryRow>> =
        vec![Vec::with_capacity(options.iterations.min(1 << 12) + 1); starts.len()];
    let mut lowest = f64::INFINITY;
    let mut stop = StopReason::Finished;
    for step in 0..=options.iterations {
        let last = step == options.iterations;
        let normalised = module.poses.val();
        let poses = units.to_scene(normalised.clone());
        // Two reads a step: the poses (the render's decisions and the history need them on
        // the host), then the totals, terms and gradient together.
        let evaluated = from_tensor(poses.clone().without_autodiff())?;
        let host = HostPoses {
            samples: evaluated.clone(),
            path: None,
        };
        let terms = problem
            .evaluate_along(0, poses, None, None, Some(&host), step, renders.as_ref())?
            .terms;
        let mut updated = false;
        let (samples, grad, grads) = if last {
            let (samples, _) = per_sample(&terms, None)?;
            (samples, None, None)
        } else {
            let grads = backward(&terms.total.clone().sum())?;
            let grad = normalised
                .grad(&grads)
                .map(|g| g.reshape([starts.len() * 6]));
            let (samples, grad) = per_sample(&terms, grad)?;
            (samples, grad, Some(grads))
        };
        if let Some(grads) = grads {
            let finite = samples.iter().all(|(t, _)| t.is_finite())
                && grad
                    .as_ref()
                    .is_none_or(|g| g.iter().all(|v| v.is_finite()));
            if finite {
                let grads = GradientsParams::from_grads(grads, &module);
                module = optim.step(1.0, module, grads);
                updated = true;
            } else {
                skipped_steps += 1;
            }
        }
        for (b, (total, row)) in samples.into_iter().enumerate() {
            if total.is_finite() {
                lowest = lowest.min(total);
            }
            histories[b].push(HistoryRow {
                step,
                pose: Pose(evaluated[b]),
                total,
                terms: row,
                updated,
            });
        }
        if !last && observer(step, lowest) == Flow::Stop {
            stop = StopReason::Interrupted;
            break;
        }
    }
    let elapsed = started.elapsed();
    Ok(histories
        .into_iter()
        .map(|history| {
            // A run whose every evaluation was non-finite still answers: the start.
            let best = (0..history.len())
                .filter(|&i| history[i].total.is_finite())
                .min_by(|&a, &b| history[a].total.total_cmp(&history[b].total))
                .unwrap_or(0);
            let best_row = &history[best];
            SinglePoseResult {
                pose: best_row.pose,
                total: best_row.total,
                terms: best_row.terms.clone(),
                best_step: best_row.step,
                last_pose: history[history.len() - 1].pose,
                skipped_steps,
                elapsed,
                stop,
                history,
            }
        })
        .collect())
}
