//! Single-pose optimisation: Φ = (ω, c) itself is the parameter (the paper's Table I ablation).
//!
//! Each step k renders the object's mask at Φ (only if some cost reads it), evaluates the
//! [`WeightedCosts`] at step k (so the prior's weight α_k decays), backpropagates the total to
//! Φ and moves Φ with Adam. The best pose seen (lowest total) is returned, with the history.
//!
//! **Why a hand-written Adam.** burn's optimisers step Modules through `GradientsParams`; here
//! the parameter is one `[1, 6]` tensor, so a Module would be plumbing only. More to the point,
//! burn's Adam takes one learning rate per call, and Φ mixes units: ω in radians, c in scene
//! units, which want separate step sizes ([`SinglePoseOptions::lr_rotation`],
//! [`SinglePoseOptions::lr_position`]). And the gradient has to come to the host anyway to
//! check it is finite before it touches the parameters. So the six numbers, Adam's moments
//! m and v, and the bias correction live on the host in f64; only the cost graph is on the
//! device. Adam also suits the problem: its step is about the learning rate whatever the
//! gradient's scale, so the large (finite) gradient of the prior's guard near the object
//! centre, or a faint mask at the frame's edge, neither throws the camera away nor stalls it.
//!
//! **Staying finite.** A step whose total or gradient is not finite is skipped (counted in
//! [`SinglePoseResult::skipped_steps`]): Φ and Adam's moments keep their previous values, so
//! one bad render cannot poison the rest of the run.
//!
//! **Best pose.** The total at step k uses α_k, which decays, so totals of different steps
//! are not quite comparable; later steps are favoured slightly, which is what one wants of a
//! run that converges. The pose after the last update is evaluated too (at k = iterations).
//!
//! The rotation vector is not wrapped back into |ω| ≤ π: Rodrigues is well defined for any ω,
//! and re-charting ω would invalidate Adam's moments, which belong to one chart.

use std::time::{Duration, Instant};

use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{Channel, DeviceScene, Pruning, RenderError, RenderRequest, render};

use crate::costs::{CostError, CostInputs, CostTerms, QueryContext, WeightedCosts};

/// Why a single-pose optimisation could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptimiseError {
    /// An option is out of range; `field` names it.
    #[error("single-pose option `{field}` {reason}")]
    InvalidOptions {
        /// Field of [`SinglePoseOptions`].
        field: &'static str,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// Gradients need the scene on an autodiff device (`Device::flex().autodiff()`).
    #[error("the scene must live on an autodiff device (`device.autodiff()`) to take gradients")]
    NotAutodiff,
    /// The start pose holds NaN or infinite values.
    #[error("start pose {0:?} is not finite")]
    StartNotFinite([f64; 6]),
    /// The costs could not be evaluated (context, shapes, a missing mask).
    #[error(transparent)]
    Cost(#[from] CostError),
    /// The mask could not be rendered (e.g. the target mask's length is not the scene's).
    #[error(transparent)]
    Render(#[from] RenderError),
}

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
        let bad = |field, reason: String| Err(OptimiseError::InvalidOptions { field, reason });
        for (field, lr) in [
            ("lr_rotation", self.lr_rotation),
            ("lr_position", self.lr_position),
        ] {
            if !(lr.is_finite() && lr >= 0.0) {
                return bad(field, format!("= {lr} must be finite and ≥ 0"));
            }
        }
        for (field, beta) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&beta) {
                return bad(field, format!("= {beta} must be in [0, 1)"));
            }
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return bad(
                "epsilon",
                format!("= {} must be finite and > 0", self.epsilon),
            );
        }
        Ok(())
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
}

/// Optimises one pose Φ from `start` on `costs` for the object whose per-Gaussian mask is
/// `target_mask` (one value per Gaussian of `scene`), rendered with `intrinsics`.
///
/// `scene` must live on an autodiff device; Φ takes its device and dtype. See the module docs
/// for the algorithm, the skipping of non-finite steps and the choice of the best pose.
pub fn optimise_single_pose(
    scene: &DeviceScene,
    target_mask: &[f32],
    context: &QueryContext,
    costs: &WeightedCosts,
    intrinsics: &Intrinsics,
    start: Pose,
    options: &SinglePoseOptions,
) -> Result<SinglePoseResult, OptimiseError> {
    options.validate()?;
    context.validate()?;
    if !start.0.iter().all(|v| v.is_finite()) {
        return Err(OptimiseError::StartNotFinite(start.0));
    }
    let device = scene.geometry.means.device();
    if !device.is_autodiff() {
        return Err(OptimiseError::NotAutodiff);
    }
    let dtype = scene.geometry.means.dtype();
    // The mask is rendered only when a cost reads it (the prior-only ablation needs none), and
    // pruned to the object: the same image and gradient for a fraction of the work.
    let request = costs.needs_mask().then(|| RenderRequest {
        pruning: Pruning::ObjectOnly,
        ..RenderRequest::new(*intrinsics, vec![Channel::Mask(target_mask.to_vec())])
    });
    let evaluate = |params: &[f64; 6], step: usize, grad: bool| {
        let phi =
            Tensor::<2>::from_data(TensorData::new(params.to_vec(), [1, 6]), (&device, dtype));
        let phi = if grad { phi.require_grad() } else { phi };
        let terms = evaluate_costs(scene, phi.clone(), request.as_ref(), step, context, costs)?;
        Ok::<_, OptimiseError>((phi, terms))
    };

    let started = Instant::now();
    let lr: [f64; 6] = std::array::from_fn(|i| {
        if i < 3 {
            options.lr_rotation
        } else {
            options.lr_position
        }
    });
    let mut params = start.0;
    let (mut m, mut v) = ([0.0f64; 6], [0.0f64; 6]);
    let mut updates = 0i32; // Adam's t: bias correction counts applied updates only.
    let mut skipped_steps = 0;
    let mut history = Vec::with_capacity(options.iterations + 1);
    // Index into `history` of the best finite evaluation so far.
    let mut best: Option<usize> = None;
    let consider = |history: &[HistoryRow], best: &mut Option<usize>| {
        let last = history.len() - 1;
        let total = history[last].total;
        if total.is_finite() && best.is_none_or(|b| total < history[b].total) {
            *best = Some(last);
        }
    };

    for step in 0..options.iterations {
        let evaluated = params;
        let (phi, terms) = evaluate(&params, step, true)?;
        let total = terms.total_mean();
        let means = terms.means();
        let grads = terms.total.mean().backward();
        // No gradient at all means no cost depends on Φ here: a zero step.
        let grad = phi
            .grad(&grads)
            .map(host_values)
            .unwrap_or_else(|| vec![0.0; 6]);
        let finite = total.is_finite() && grad.len() == 6 && grad.iter().all(|g| g.is_finite());
        if finite {
            updates += 1;
            let bc1 = 1.0 - options.beta1.powi(updates);
            let bc2 = 1.0 - options.beta2.powi(updates);
            for i in 0..6 {
                m[i] = options.beta1 * m[i] + (1.0 - options.beta1) * grad[i];
                v[i] = options.beta2 * v[i] + (1.0 - options.beta2) * grad[i] * grad[i];
                let m_hat = m[i] / bc1;
                let v_hat = v[i] / bc2;
                params[i] -= lr[i] * m_hat / (v_hat.sqrt() + options.epsilon);
            }
        } else {
            skipped_steps += 1;
        }
        history.push(HistoryRow {
            step,
            pose: Pose(evaluated),
            total,
            terms: means,
            updated: finite,
        });
        consider(&history, &mut best);
    }

    // The last update's result has not been evaluated yet: it may be the best.
    let step = options.iterations;
    let (_, terms) = evaluate(&params, step, false)?;
    let total = terms.total_mean();
    let means = terms.means();
    history.push(HistoryRow {
        step,
        pose: Pose(params),
        total,
        terms: means,
        updated: false,
    });
    consider(&history, &mut best);

    // A run whose every evaluation was non-finite still answers: the start, with its values.
    let best = &history[best.unwrap_or(0)];
    Ok(SinglePoseResult {
        pose: best.pose,
        total: best.total,
        terms: best.terms.clone(),
        best_step: best.step,
        last_pose: Pose(params),
        history,
        skipped_steps,
        elapsed: started.elapsed(),
    })
}

/// Renders the mask (when `request` is given) and evaluates the costs at Φ `[1, 6]`.
fn evaluate_costs(
    scene: &DeviceScene,
    phi: Tensor<2>,
    request: Option<&RenderRequest>,
    step: usize,
    context: &QueryContext,
    costs: &WeightedCosts,
) -> Result<CostTerms, OptimiseError> {
    let masks = match request {
        Some(request) => {
            let images = render(scene, phi.clone(), request)?.images;
            let [batch, height, width, _] = images.dims();
            Some(images.reshape([batch, height, width]))
        }
        None => None,
    };
    let inputs = CostInputs::new(phi, masks, step, *context)?;
    Ok(costs.evaluate(&inputs)?)
}

/// A tensor's values on the host as f64.
fn host_values<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .unwrap_or_default()
}
