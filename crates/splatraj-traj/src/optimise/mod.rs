//! Optimisers: what moves the camera parameters downhill on the costs of [`crate::costs`].
//!
//! - [`single_pose`]: Φ itself is the parameter (the paper's Table I setting), a batch of
//!   independent starts at once, stepped by burn's Adam;
//! - [`trajectory`]: the weights of a trajectory model, stepped by burn's Adam on stratified
//!   time samples of every query window;
//! - [`sgld`]: stochastic gradient Langevin dynamics, many chains of one pose at once, for
//!   samples of the pose posterior ∝ exp(−L/τ);
//! - [`start`]: starting poses (seeded random ones, or ones that look at each object);
//! - [`route`]: planned starts that go around the scene's geometry between windows;
//! - [`views`]: the search for each window's starting viewpoint, where its object shows;
//! - [`backward`]: a loss's gradient, its forward handed to the device first;
//! - [`sampling`] and [`units`]: the stratified times and the normalised parameter units the
//!   loops share.

pub mod backward;
pub mod pans;
pub mod problem;
pub mod route;
pub mod sampling;
pub mod sgld;
pub mod single_pose;
pub mod start;
pub mod trajectory;
pub mod units;
pub mod views;

use burn::tensor::Tensor;
use splatraj_render::camera::Pose;
use splatraj_render::render::RenderError;

use crate::costs::{CostError, CostTerms};
use crate::trajectory::TrajectoryError;

pub use backward::backward;
pub use pans::{PanLimits, pan_shares};
pub use problem::{
    Evaluated, PoseLoss, Problem, StepEvaluation, StepPasses, WindowPath, WindowRenders,
    WindowSamples,
};
pub use route::{Route, RouteKind, RoutePlanner, Transition, plan_transitions};
pub use sgld::{SgldOptions, SgldResult, SgldSample, sample_poses_sgld};
pub use single_pose::{
    HistoryRow, SinglePoseOptions, SinglePoseResult, optimise_poses, optimise_poses_observed,
    optimise_single_pose,
};
pub use start::{
    ObjectView, StartDistribution, WindowStart, object_side, object_start_poses,
    random_start_poses, routed_start_trajectory, start_trajectory, unwrap_rotation,
    window_start_trajectory,
};
pub use trajectory::{
    Flow, StepTiming, StopReason, TrajectoryOptions, TrajectoryResult, TrajectoryStep,
    WindowTarget, optimise_trajectory,
};
pub use units::PoseUnits;
pub use views::{
    Candidate, VIEW_SEARCH_BATCH, ViewSearch, ViewWeights, ViewedObject, WindowViews,
    calibrated_radius, choose_views, search_views,
};

/// Why an optimisation could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptimiseError {
    /// An option is out of range; `field` names it.
    #[error("optimiser option `{field}` {reason}")]
    InvalidOptions {
        /// Field of the options struct.
        field: &'static str,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// Gradients need the scene on an autodiff device (`Device::flex().autodiff()`).
    #[error("the scene must live on an autodiff device (`device.autodiff()`) to take gradients")]
    NotAutodiff,
    /// A start pose holds NaN or infinite values.
    #[error("start pose {0:?} is not finite")]
    StartNotFinite([f64; 6]),
    /// The costs could not be evaluated (context, shapes, a missing mask).
    #[error(transparent)]
    Cost(#[from] CostError),
    /// The mask could not be rendered (e.g. the target mask's length is not the scene's).
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The start trajectory does not fit its model.
    #[error(transparent)]
    Trajectory(#[from] TrajectoryError),
    /// A tensor could not be read back to the host.
    #[error("{0}")]
    ReadBack(String),
    /// The sampled loss went NaN or infinite: a cost overflowed with its weight, a cost is
    /// not finite at the start, or the weights stepped to where the costs overflow (a learning
    /// rate far too large).
    #[error("the loss is {total} at step {step}: {why}")]
    LossNotFinite {
        /// The step whose loss is not finite (0: the start).
        step: usize,
        /// The loss.
        total: f64,
        /// Which cost and what to change ([`loss_blame`]).
        why: String,
    },
}

/// Why a loss is not finite, from each window's `(cost, weight, mean)` at that step. A cost
/// whose mean is not finite is the start's fault at step 0 and the learning rate's later;
/// when every cost is finite, their weighted sum overflowed, and the largest weighted cost's
/// weight is to blame.
pub fn loss_blame(
    windows: &[Vec<(&'static str, f64, f64)>],
    step: usize,
    learning_rate: f64,
) -> String {
    let terms = || {
        windows.iter().enumerate().flat_map(|(w, terms)| {
            terms
                .iter()
                .map(move |&(name, weight, mean)| (w, name, weight, mean))
        })
    };
    if let Some((w, name, _, mean)) = terms().find(|(_, _, _, mean)| !mean.is_finite()) {
        return if step == 0 {
            format!(
                "cost `{name}` of window {w} is {mean} at the start; check the start \
                 (`[start]`) and the cost's settings (`costs.{name}`)"
            )
        } else {
            format!(
                "cost `{name}` of window {w} is {mean}: the trajectory left the range where the \
                 costs are finite; lower `optimiser.learning_rate` (now {learning_rate:e}) or \
                 check the start"
            )
        };
    }
    match terms().max_by(|a, b| (a.2 * a.3).abs().total_cmp(&(b.2 * b.3).abs())) {
        Some((w, name, weight, mean)) => format!(
            "cost `{name}` of window {w} is {mean:.4}, and with its weight {weight:e} the \
             weighted costs overflow; lower `costs.{name}.weight`"
        ),
        None => format!(
            "no cost was evaluated; lower `optimiser.learning_rate` (now {learning_rate:e}) or \
             check the start"
        ),
    }
}

/// The largest learning rate in normalised units (radians of rotation per step).
pub const MAX_LEARNING_RATE: f64 = 1.0;

/// Checks Adam's settings (a learning rate named by the caller, β1, β2, ε).
pub(crate) fn check_adam(
    lr: (&'static str, f64),
    beta1: f64,
    beta2: f64,
    epsilon: f64,
) -> Result<(), OptimiseError> {
    let bad = |field, reason: String| Err(OptimiseError::InvalidOptions { field, reason });
    if !(lr.1 > 0.0 && lr.1 <= MAX_LEARNING_RATE) {
        return bad(
            lr.0,
            format!(
                "= {} must be in (0, {MAX_LEARNING_RATE}]: Adam moves each normalised \
                 coefficient by about the rate per step, so 0 never moves and more than one \
                 radian per step leaves the scene at the first step",
                lr.1
            ),
        );
    }
    for (field, beta) in [("beta1", beta1), ("beta2", beta2)] {
        if !(0.0..1.0).contains(&beta) {
            return bad(field, format!("= {beta} must be in [0, 1)"));
        }
    }
    if !(epsilon.is_finite() && epsilon > 0.0) {
        return bad("epsilon", format!("= {epsilon} must be finite and > 0"));
    }
    Ok(())
}

/// Checks a batch of start poses: at least one (`field` names the batch), all finite.
pub(crate) fn check_starts(starts: &[Pose], field: &'static str) -> Result<(), OptimiseError> {
    if starts.is_empty() {
        return Err(OptimiseError::InvalidOptions {
            field,
            reason: "at least one start pose is needed".into(),
        });
    }
    match starts.iter().find(|s| !s.0.iter().all(|v| v.is_finite())) {
        Some(bad) => Err(OptimiseError::StartNotFinite(bad.0)),
        None => Ok(()),
    }
}

/// A tensor's values on the host as f64; a device's failure is [`OptimiseError::ReadBack`].
pub(crate) fn host_values<const D: usize>(t: Tensor<D>) -> Result<Vec<f64>, OptimiseError> {
    splatraj_render::host::to_host(t).map_err(|e| OptimiseError::ReadBack(e.to_string()))
}

/// One sample's terms as `(name, weight, unweighted value)`.
pub(crate) type TermRow = Vec<(&'static str, f64, f64)>;

/// Each sample's weighted total and its terms, on the host.
pub(crate) type SampleRows = Vec<(f64, TermRow)>;

/// Each sample's weighted total and terms on the host, and the values of `extra` (e.g. the
/// step's gradient) when given: all of it in **one read** (one wait for the device on a GPU).
pub(crate) fn per_sample(
    terms: &CostTerms,
    extra: Option<Tensor<1>>,
) -> Result<(SampleRows, Option<Vec<f64>>), OptimiseError> {
    let batch = terms.total.dims()[0];
    let mut parts = vec![terms.total.clone().without_autodiff()];
    parts.extend(
        terms
            .terms
            .iter()
            .map(|t| t.value.clone().without_autodiff()),
    );
    let has_extra = extra.is_some();
    parts.extend(extra.map(Tensor::without_autodiff));
    let values = host_values(Tensor::cat(parts, 0))?;
    let at = |i: usize| values.get(i).copied().unwrap_or(f64::NAN);
    let rows = (0..batch)
        .map(|b| {
            let row = terms
                .terms
                .iter()
                .enumerate()
                .map(|(k, t)| (t.name, t.weight, at((k + 1) * batch + b)))
                .collect();
            (at(b), row)
        })
        .collect();
    let used = (terms.terms.len() + 1) * batch;
    let extra = has_extra.then(|| values.get(used..).unwrap_or_default().to_vec());
    Ok((rows, extra))
}

#[cfg(test)]
mod tests {
    use super::loss_blame;

    #[test]
    fn a_finite_cost_with_a_huge_weight_blames_that_weight() {
        let windows = vec![
            vec![("tce", 1.0, 0.3), ("prior", 1.0, 2.0)],
            vec![("tce", 1e308, 1.5), ("prior", 1.0, 2.0)],
        ];
        let why = loss_blame(&windows, 0, 0.02);
        assert!(
            why.contains("`costs.tce.weight`") && why.contains("window 1"),
            "{why}"
        );
        assert!(!why.contains("learning_rate"), "{why}");
    }

    #[test]
    fn a_cost_not_finite_blames_the_start_at_step_0_and_the_learning_rate_later() {
        let windows = vec![vec![("tce", 1.0, 0.3), ("clearance", 1.0, f64::NAN)]];
        let start = loss_blame(&windows, 0, 0.02);
        assert!(
            start.contains("`clearance`") && start.contains("at the start"),
            "{start}"
        );
        assert!(!start.contains("learning_rate"), "{start}");
        let later = loss_blame(&windows, 7, 0.5);
        assert!(
            later.contains("`optimiser.learning_rate` (now 5e-1)"),
            "{later}"
        );
    }
}
