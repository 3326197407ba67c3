//! Uprightness: keeps the image's up direction toward the world's up.
//!
//! R_wc's columns are the camera's x (right), y (down) and z (forward) axes in world
//! coordinates (docs/conventions.md "Conventions"), so the camera's up axis is −R_wc e_y. The paper
//! writes it as R e_x (its typo 4: in OpenCV axes the up axis is −y) and its cost as
//! −⟨e_z, R e_x⟩ ∈ [−1, 1]; we shift it to be ≥ 0, which changes no gradient.
//!
//! - [`UprightMode::UpVector`] (the paper's form): 1 − ⟨−R_wc e_y, u⟩ = 1 − cos(angle between
//!   camera up and world up u). 0 upright and level, 1 rolled 90° (or pitched straight down),
//!   2 upside down. It also penalises pitch: a camera looking 60° down pays 1 − cos 60° = ½.
//! - [`UprightMode::Roll`]: only the horizon's tilt, ⟨R_wc e_x, u⟩² = sin²(roll) for a camera
//!   that is not looking straight up or down. Pitch and yaw are free, so the camera may look
//!   down at low objects. It does not tell upright from upside down (both are 0): keep a small
//!   `up-vector` term or start upright if that matters.
//!
//! Both are smooth polynomials of R_wc's entries, finite with finite gradients everywhere.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use splatraj_render::rodrigues::Rotation;

use super::expansion::per_sample_on_host;
use super::{Cost, CostError, CostInputs, ImageChannel, check_weight};

/// Which uprightness cost (config `mode`, kebab-case).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UprightMode {
    /// 1 − cos(angle between camera up and world up) (the paper's form; `up-vector`).
    #[default]
    UpVector,
    /// (x_cam · up)²: only the horizon's tilt (`roll`).
    Roll,
}

/// Uprightness cost per sample `[B]` from rotations R_wc `[B, 3, 3]` and unit world up `[1, 3]`.
pub fn upright(rotations: Tensor<3>, unit_up: Tensor<2>, mode: UprightMode) -> Tensor<1> {
    let [batch, _, _] = rotations.dims();
    let column = |axis: usize| rotations.clone().narrow(2, axis, 1).reshape([batch, 3]);
    match mode {
        // 1 − ⟨−y_cam, u⟩ = 1 + ⟨y_cam, u⟩.
        UprightMode::UpVector => (column(1) * unit_up)
            .sum_dim(1)
            .reshape([batch])
            .add_scalar(1.0),
        UprightMode::Roll => (column(0) * unit_up).sum_dim(1).reshape([batch]).square(),
    }
}

/// [`upright`] of one pose on the host in f64, with its gradient in the pose (ω then c, the
/// centre's 0): what the cost evaluates; the tensor form is its specification
/// (`tests/cost_terms.rs`).
pub fn upright_on_host(pose: &[f64; 6], unit_up: [f64; 3], mode: UprightMode) -> (f64, [f64; 6]) {
    let rotation = Rotation::new([pose[0], pose[1], pose[2]]);
    let along = |axis: usize| {
        (0..3)
            .map(|i| rotation.matrix[i][axis] * unit_up[i])
            .sum::<f64>()
    };
    // d value/d(camera axis) = scale · up, on that axis's column of R.
    let (value, axis, scale) = match mode {
        UprightMode::UpVector => (along(1) + 1.0, 1, 1.0),
        UprightMode::Roll => (along(0).powi(2), 0, 2.0 * along(0)),
    };
    let mut v_matrix = [[0.0; 3]; 3];
    for (i, row) in v_matrix.iter_mut().enumerate() {
        row[axis] = scale * unit_up[i];
    }
    let v_omega = rotation.omega_gradient(&v_matrix);
    (value, [v_omega[0], v_omega[1], v_omega[2], 0.0, 0.0, 0.0])
}

/// Uprightness as a [`Cost`]: table `[costs.upright]`, keys `weight` (default 1) and `mode`
/// (`"up-vector"` default, or `"roll"`). World up comes from the query context.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UprightCost {
    /// Weight w_up (≥ 0).
    pub weight: f64,
    /// Which form of the cost.
    pub mode: UprightMode,
}

impl Default for UprightCost {
    /// Weight 1 and the paper's `up-vector` form.
    fn default() -> Self {
        Self {
            weight: 1.0,
            mode: UprightMode::UpVector,
        }
    }
}

impl Cost for UprightCost {
    fn name(&self) -> &'static str {
        "upright"
    }
    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }
    fn channels(&self) -> &'static [ImageChannel] {
        &[]
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "weight", self.weight)
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        // On the host (docs/gpu.md, "Costs on the host").
        per_sample_on_host(inputs, self.name(), |pose, query| {
            upright_on_host(pose, query.unit_up(), self.mode)
        })
    }
}
