//! Target centring error (TCE): how far the object's mask centroid is from the image centre.
//!
//! TCE = ‖(c_x/W, c_y/H) − (½, ½)‖₂, with c the mask-weighted centroid in pixel coordinates,
//! pixel (column i, row j) having its centre at (i + 0.5, j + 0.5) (docs/conventions.md; the paper
//! swaps W and H). 0 is a centred object, √½ ≈ 0.707 an object in a corner.
//!
//! Two guards keep it finite and well-behaved in autodiff:
//! - **Mass floor.** The centroid divides by max(Σ m, [`MASS_FLOOR`]) and is taken relative to
//!   the image centre. Below the floor this equals placing the missing mass (floor − Σ m) at
//!   the image centre, so an empty mask has its centroid *at the centre*: TCE = 0, and (because
//!   the norm's derivative vanishes at 0) a zero gradient. An object leaving the frame fades
//!   smoothly to that state instead of jumping.
//! - **Smoothed norm.** √x has an infinite derivative at 0, so the norm is
//!   √(d_x² + d_y² + ε²) − ε with ε = [`NORM_EPSILON`]: exactly 0 at d = 0 (ε is a power of
//!   two, so ε² and its root are exact in f32 and f64), within ε of ‖d‖ elsewhere, and its
//!   derivative d/√(d² + ε²) is finite everywhere.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::{Cost, CostError, CostInputs, HostMoments, ImageChannel, MaskMoments, check_weight};

/// Total mask mass (in pixels) below which the centroid is pulled toward the image centre.
pub const MASS_FLOOR: f64 = 1e-3;

/// ε of the smoothed norm √(‖d‖² + ε²) − ε, 2⁻²⁰ ≈ 9.5e-7 (a power of two, see module docs).
pub const NORM_EPSILON: f64 = 1.0 / 1_048_576.0;

/// Offset of the mask centroid from the image centre, in image fractions: `[B, 2]` holding
/// (c_x/W − ½, c_y/H − ½) per sample, with the mass floor of the module docs (0 for an empty
/// mask). `mask` is `[B, H, W]`.
pub fn centroid_offset(mask: Tensor<3>) -> Tensor<2> {
    let [dx, dy] = centroid_offset_of(&MaskMoments::of(mask));
    Tensor::stack(vec![dx, dy], 1)
}

/// [`centroid_offset`] of a mask's moments (what a cost reads: [`CostInputs::require_mask_moments`]),
/// as its two columns `[B]` (x, y): every op after the moments elementwise on `[B]`.
pub fn centroid_offset_of(moments: &MaskMoments) -> [Tensor<1>; 2] {
    let mass = moments.mass().clamp_min(MASS_FLOOR);
    [moments.first_x() / mass.clone(), moments.first_y() / mass]
}

/// Target centring error per sample, `[B]`, of mask images `[B, H, W]` (see module docs).
pub fn tce(mask: Tensor<3>) -> Tensor<1> {
    tce_of(&MaskMoments::of(mask))
}

/// [`tce`] of a mask's moments.
pub fn tce_of(moments: &MaskMoments) -> Tensor<1> {
    let [dx, dy] = centroid_offset_of(moments);
    (dx.square() + dy.square())
        .add_scalar(NORM_EPSILON * NORM_EPSILON)
        .sqrt()
        .sub_scalar(NORM_EPSILON)
}

/// [`tce_of`] of one mask's moments read back, in f64 on the host: the figure a frame or a
/// sample reports (the cost's formula, guards included).
pub fn tce_on_host(moments: &HostMoments) -> f64 {
    let mass = moments.mass.max(MASS_FLOOR);
    let (dx, dy) = (moments.first_x / mass, moments.first_y / mass);
    (dx * dx + dy * dy + NORM_EPSILON * NORM_EPSILON).sqrt() - NORM_EPSILON
}

/// TCE as a [`Cost`]: config table `[costs.tce]`, key `weight` (default 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TceCost {
    /// Weight w_tce (≥ 0).
    pub weight: f64,
}

impl Default for TceCost {
    /// Weight 1, as in the paper's unweighted sum.
    fn default() -> Self {
        Self { weight: 1.0 }
    }
}

impl Cost for TceCost {
    fn name(&self) -> &'static str {
        "tce"
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
        Ok(tce_of(inputs.require_mask_moments(self.name())?))
    }
}
