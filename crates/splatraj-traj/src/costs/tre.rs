//! Target ratio error (TRE): how far the object's share of the frame is from the target.
//!
//! TRE = |Σ I_b / (W·H) − r_t|, with I_b the composited mask image and r_t the target ratio
//! (docs/conventions.md; default [`DEFAULT_TARGET_RATIO`]). It needs no guard: it is finite for any
//! mask, and for an empty mask it is r_t with the constant derivative −1/(W·H) per pixel. That
//! derivative does not move the camera: pixels the object does not reach do not depend on the pose,
//! so the pose gradient of an empty mask's TRE is zero. At exactly r_t, burn's |x| derivative is
//! sign(0) = 0.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::{
    Cost, CostError, CostInputs, HostMoments, ImageChannel, MaskMoments, check_weight, mask_mass,
};

/// Target ratio of the frame the object should cover when none is configured.
pub const DEFAULT_TARGET_RATIO: f64 = 0.15;

/// Share of the frame the mask covers, Σ I_b / (W·H), per sample: `[B]` of `[B, H, W]`.
pub fn coverage(mask: Tensor<3>) -> Tensor<1> {
    let [_, height, width] = mask.dims();
    mask_mass(mask).div_scalar((height * width) as f64)
}

/// Target ratio error per sample, `[B]`, of mask images `[B, H, W]` for target ratio `target`.
pub fn tre(mask: Tensor<3>, target: f64) -> Tensor<1> {
    tre_of(&MaskMoments::of(mask), target)
}

/// [`tre`] of a mask's moments (what a cost reads: [`CostInputs::require_mask_moments`]).
pub fn tre_of(moments: &MaskMoments, target: f64) -> Tensor<1> {
    moments.coverage().sub_scalar(target).abs()
}

/// [`tre_of`] of one mask's moments read back, in f64 on the host: the figure a frame or a
/// sample reports.
pub fn tre_on_host(moments: &HostMoments, target: f64) -> f64 {
    (moments.coverage() - target).abs()
}

/// TRE as a [`Cost`]: config table `[costs.tre]`, key `weight` (default 1). The target ratio
/// r_t is per query ([`super::QueryContext::target_ratio`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TreCost {
    /// Weight w_tre (≥ 0).
    pub weight: f64,
}

impl Default for TreCost {
    /// Weight 1, as in the paper's unweighted sum.
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

impl Cost for TreCost {
    fn name(&self) -> &'static str {
        "tre"
    }
    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }
    fn channels(&self) -> &'static [ImageChannel] {
        &[ImageChannel::Mask]
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "weight", self.weight)
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let moments = inputs.require_mask_moments(self.name())?;
        if let Some(query) = inputs.single_query() {
            return Ok(tre_of(moments, query.target_ratio));
        }
        let target = inputs
            .context_rows(|q| [q.target_ratio])
            .reshape([inputs.batch()]);
        Ok((moments.coverage() - target).abs())
    }
}
