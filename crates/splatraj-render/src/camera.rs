//! The tensor side of the camera: Rodrigues on burn tensors, for the optimisation graph.
//!
//! The camera types and conventions (pinhole [`Intrinsics`], the pose Φ = [ω, c] as [`Pose`],
//! world-to-camera matrices, host-side rotations) live in the burn-free `splatraj-camera` crate,
//! which the report crate's camera files share; they are re-exported here so that renderer code
//! reads `camera::Pose`. [`rotation_matrices`] is the differentiable version of
//! [`rotation_vector_to_matrix`].

use burn::tensor::{Bool, Tensor};

pub use splatraj_camera::{
    CameraError, CameraPose, Intrinsics, Pose, matrix_to_rotation_vector, rotation_vector_to_matrix,
};

/// `intrinsics` zoomed by s > 0: focal lengths fx·s, fy·s about the same principal point and
/// image size (the field of view's tan shrinks as 1/s).
pub fn zoomed_intrinsics(intrinsics: &Intrinsics, zoom: f64) -> Intrinsics {
    Intrinsics {
        fx: intrinsics.fx * zoom,
        fy: intrinsics.fy * zoom,
        ..*intrinsics
    }
}

/// Below this θ², Rodrigues' coefficients come from their Taylor series (in f32, sin θ/θ
/// computed directly loses all precision well before θ = 0).
pub(crate) const SERIES_BELOW_THETA_SQ: f64 = 1e-2;

/// Differentiable Rodrigues: rotation vectors `[B, 3]` → rotation matrices `[B, 3, 3]`.
///
/// Neither value nor gradient is NaN at ω = 0: below `SERIES_BELOW_THETA_SQ` the
/// coefficients are series in θ² (no sqrt, no division), and the trigonometric branch takes
/// sqrt of θ² clamped away from 0, so the branch that is masked out stays finite too (a NaN in
/// an unused branch would still poison the gradient through the select).
pub fn rotation_matrices(omega: Tensor<2>) -> Tensor<3> {
    let [batch, _] = omega.dims();
    let theta_sq = omega.clone().square().sum_dim(1); // [B, 1]
    let small: Tensor<2, Bool> = theta_sq.clone().lower_elem(SERIES_BELOW_THETA_SQ);

    let t2 = theta_sq.clone();
    let t4 = t2.clone().square();
    // sin θ/θ = 1 − θ²/6 + θ⁴/120 − θ⁶/5040; (1 − cos θ)/θ² = 1/2 − θ²/24 + θ⁴/720 − θ⁶/40320.
    let t6 = t4.clone() * t2.clone();
    let a_series = t2.clone().mul_scalar(-1.0 / 6.0) + t4.clone().mul_scalar(1.0 / 120.0)
        - t6.clone().mul_scalar(1.0 / 5040.0)
        + 1.0;
    let b_series = t2.clone().mul_scalar(-1.0 / 24.0) + t4.mul_scalar(1.0 / 720.0)
        - t6.mul_scalar(1.0 / 40320.0)
        + 0.5;

    let safe_sq = theta_sq.clamp_min(SERIES_BELOW_THETA_SQ);
    let theta = safe_sq.clone().sqrt();
    let a_trig = theta.clone().sin() / theta.clone();
    let b_trig = (theta.cos().neg() + 1.0) / safe_sq;

    let a = a_trig
        .mask_where(small.clone(), a_series)
        .unsqueeze_dim::<3>(2); // [B, 1, 1]
    let b = b_trig.mask_where(small, b_series).unsqueeze_dim::<3>(2);

    let k = skew_tensor(omega); // [B, 3, 3]
    let k_sq = k.clone().matmul(k.clone());
    let eye = identity_like(&k, batch);
    eye + k * a + k_sq * b
}

/// Skew-symmetric cross-product matrices `[B, 3, 3]` of vectors `[B, 3]`.
pub fn skew_tensor(v: Tensor<2>) -> Tensor<3> {
    let [batch, _] = v.dims();
    let x = v.clone().narrow(1, 0, 1);
    let y = v.clone().narrow(1, 1, 1);
    let z = v.narrow(1, 2, 1);
    let zero = x.zeros_like();
    let rows = vec![
        zero.clone(),
        z.clone().neg(),
        y.clone(),
        z,
        zero.clone(),
        x.clone().neg(),
        y.neg(),
        x,
        zero,
    ];
    Tensor::cat(rows, 1).reshape([batch, 3, 3])
}

/// Identity matrices `[B, 3, 3]` with the dtype and device of `like`.
fn identity_like(like: &Tensor<3>, batch: usize) -> Tensor<3> {
    let mut eye = like.zeros_like();
    for d in 0..3 {
        eye = eye.slice_fill([0..batch, d..d + 1, d..d + 1], 1.0);
    }
    eye
}
