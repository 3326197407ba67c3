//! The shot cost: keeps a window's camera on its shot preset ([`crate::shots`]).
//!
//! For a sample at time s ∈ [0, 1] within a window whose shot asks for the camera centre
//! c*(s) and the aim point a(s) (orbit, dolly, reveal, group), with c the camera centre, f its
//! forward axis and r̄ the shot's mean radius:
//!
//! ```text
//! L_shot = w_shot · ( ‖c − c*(s)‖²/r̄²  +  1 − f·(a(s) − c)/√(‖a(s) − c‖² + ε²) )
//! ```
//!
//! The first term holds the elevation, the radius and the sweep's progress at once (c*(s)
//! moves along the shot); the second keeps the aim point on the view's axis (0 when looking
//! straight at it): the object itself for all but a reveal, so that the object stays centred
//! even where the rendered mask is thin; for a reveal the point the pan looks at, so that the
//! object stays out of frame until the pan brings it in.
//! Windows without a shot cost 0. The shot's own `weight` is applied inside, one weight per
//! window, so the cost's own weight is 1. It needs each sample's time within its window
//! ([`CostInputs::times`]): a trajectory optimisation gives it; single poses do not.

use burn::tensor::{Tensor, TensorData};

use super::{Cost, CostError, CostInputs};
use crate::shots::ShotPath;

/// ε of the aim term's smoothed distance, scene units (keeps it finite at the object).
const AIM_EPSILON: f64 = 1e-6;

/// The shots of a run's windows, one per window (None: no shot), as a cost.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotCost {
    /// Per window in time order, its placed shot.
    pub shots: Vec<Option<ShotPath>>,
}

impl Cost for ShotCost {
    fn name(&self) -> &'static str {
        "shot"
    }
    fn weight(&self, _step: usize) -> f64 {
        1.0
    }
    fn validate(&self) -> Result<(), CostError> {
        match self
            .shots
            .iter()
            .flatten()
            .find(|s| !(s.weight.is_finite() && s.weight >= 0.0 && s.mean_radius() > 0.0))
        {
            Some(s) => Err(CostError::InvalidContext {
                field: "shots",
                reason: format!(
                    "weight {} must be finite and ≥ 0, mean radius {} > 0",
                    s.weight,
                    s.mean_radius()
                ),
            }),
            None => Ok(()),
        }
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let batch = inputs.batch();
        let times = inputs.times().ok_or_else(|| CostError::InvalidContext {
            field: "times",
            reason: "the shot cost needs each sample's time within its window (trajectory \
                     optimisation only)"
                .into(),
        })?;
        let centres = inputs.centres(); // [B, 3]
        let Some(shot) = self.shots.get(times.window).copied().flatten() else {
            return Ok(centres.sum_dim(1).reshape([batch]) * 0.0);
        };
        if times.within.len() != batch {
            return Err(CostError::Shape(format!(
                "{} sample times for {batch} poses",
                times.within.len()
            )));
        }
        let rows = |point: &dyn Fn(f64) -> glam::DVec3| -> Tensor<2> {
            let values: Vec<f64> = times
                .within
                .iter()
                .flat_map(|&s| point(s.clamp(0.0, 1.0)).to_array())
                .collect();
            splatraj_render::host::upload(
                TensorData::new(values, [batch, 3]),
                &centres.device(),
                inputs.dtype(),
            )
        };
        let wanted = rows(&|s| shot.centre_at(s)); // [B, 3]
        let aim_points = rows(&|s| shot.aim_at(s)); // [B, 3]
        let radius = shot.mean_radius();
        let position = (centres.clone() - wanted)
            .square()
            .sum_dim(1)
            .div_scalar(radius * radius); // [B, 1]
        let to_object = aim_points - centres; // [B, 3]
        let distance = to_object
            .clone()
            .square()
            .sum_dim(1)
            .add_scalar(AIM_EPSILON * AIM_EPSILON)
            .sqrt(); // [B, 1]
        let aim = (inputs.camera_axis(2) * to_object).sum_dim(1) / distance; // [B, 1]
        Ok((position - aim)
            .add_scalar(1.0)
            .mul_scalar(shot.weight)
            .reshape([batch]))
    }
}
