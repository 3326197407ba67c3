//! Visibility: the share of the object that other geometry hides, made a cost.
//!
//! ```text
//! h     = 1 − Σ_p m_scene(p) / max(Σ_p m_alone(p), A_min)        (the hidden share)
//! L_vis = max(0, h − h_0) / (1 − h_0)
//! ```
//!
//! with m_scene the object's mask composited with the whole scene (what the camera sees: an
//! occluder in front lowers it) and m_alone the same mask rendered with the object's Gaussians
//! alone, both at the sampled pose. It is 0 when nothing hides the object and 1 when all of it
//! is hidden, the same figure as the metrics' occluded share ([`crate::metrics::window`]), so
//! the optimiser never trades a hidden object for a good centroid: TCE and TRE only see what
//! is left of the object and are content with a sliver. Both renders are differentiable in the
//! pose, so the gradient moves the camera toward where more of the object shows.
//!
//! **Tolerance.** h_0 (`tolerance`, default [`DEFAULT_TOLERANCE`]) is the hidden share that
//! costs nothing. A selection cut out of a surface (a region, a sphere) is never wholly
//! visible: its cut faces and the Gaussians that straddle its border are covered by the
//! neighbours it was cut from, and faint haze in front dims every mask a little; measured on
//! the first-try captures, the best view of such a part still hides 10–25 % of it. Without
//! the tolerance the optimiser gave up framing for those last percents (donut, near edge: TCE
//! 0.10 → 0.34 while the hidden share went 0.27 → 0.20); with it, only a real occluder costs.
//!
//! **Out of frame.** Where less than A_min = [`MIN_ALONE_PIXELS`] pixels of the object alone
//! are in frame, the ratio says nothing; the cost is then 0 with no gradient and the prior
//! brings the object back (the floor keeps the value finite).

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::{
    Cost, CostError, CostInputs, ImageChannel, MaskMoments, check_weight, invalid, mask_mass,
};

/// Mask mass (pixels' worth) of the object alone below which it counts as out of frame.
pub const MIN_ALONE_PIXELS: f64 = 1.0;

/// Hidden share that costs nothing (see the module docs).
pub const DEFAULT_TOLERANCE: f64 = 0.25;

/// The hidden share per sample `[B]` of masks seen with the scene and alone `[B, H, W]`.
pub fn hidden_share(seen: Tensor<3>, alone: Tensor<3>) -> Tensor<1> {
    hidden_share_of(&MaskMoments::of(seen), alone)
}

/// [`hidden_share`] with the seen mask's moments (shared with TCE and TRE in a cost pass).
pub fn hidden_share_of(seen: &MaskMoments, alone: Tensor<3>) -> Tensor<1> {
    // The object alone's pixels: its mass only (its first moments are not read).
    let whole = mask_mass(alone);
    // 1 where the object alone is in frame, else 0 (off the graph: a switch, not a slope);
    // in the masks' float type (a bool tensor becomes the default float, f32).
    let in_frame = whole
        .clone()
        .detach()
        .greater_equal_elem(MIN_ALONE_PIXELS)
        .float()
        .cast(whole.dtype());
    let ratio = seen.mass() / whole.clamp_min(MIN_ALONE_PIXELS);
    ratio.neg().add_scalar(1.0).clamp_min(0.0) * in_frame
}

/// The visibility cost: table `[costs.visibility]`, keys `weight` (default 1) and
/// `tolerance` (the hidden share that costs nothing, in [0, 1), default
/// [`DEFAULT_TOLERANCE`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VisibilityCost {
    /// Weight (≥ 0).
    pub weight: f64,
    /// Hidden share h_0 that costs nothing, in [0, 1).
    pub tolerance: f64,
}

impl Default for VisibilityCost {
    /// Weight 1, tolerance [`DEFAULT_TOLERANCE`].
    fn default() -> Self {
        Self {
            weight: 1.0,
            tolerance: DEFAULT_TOLERANCE,
        }
    }
}

impl Cost for VisibilityCost {
    fn name(&self) -> &'static str {
        "visibility"
    }
    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }
    fn channels(&self) -> &'static [ImageChannel] {
        &[ImageChannel::Mask, ImageChannel::MaskAlone]
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "weight", self.weight)?;
        if !(0.0..1.0).contains(&self.tolerance) {
            return Err(invalid(
                self.name(),
                "tolerance",
                format!("= {} must be in [0, 1)", self.tolerance),
            ));
        }
        Ok(())
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let seen = inputs.require_mask_moments(self.name())?;
        let alone = inputs.require_mask_alone(self.name())?;
        Ok(hidden_share_of(seen, alone)
            .sub_scalar(self.tolerance)
            .clamp_min(0.0)
            .div_scalar(1.0 - self.tolerance))
    }
}
