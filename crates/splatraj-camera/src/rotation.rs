//! Rotations: rotation vector ↔ matrix (Rodrigues, f64 on the host) and the nearest rotation
//! to a matrix read from a file. The renderer's differentiable tensor version of Rodrigues is
//! `splatraj_render::camera::rotation_matrices`.

use glam::{DMat3, DQuat, DVec3};

/// How far from a rotation a matrix read from a file may be (largest entry of RᵀR − I, and
/// |det R − 1|) before it is refused; within it, the matrix is projected onto the nearest
/// rotation. Files written with 6–7 significant digits pass.
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// sin θ/θ and (1 − cos θ)/θ² as functions of θ², exact-to-rounding series near 0.
fn rodrigues_coefficients(theta_sq: f64) -> (f64, f64) {
    if theta_sq < 1e-6 {
        (
            1.0 - theta_sq / 6.0 + theta_sq * theta_sq / 120.0,
            0.5 - theta_sq / 24.0 + theta_sq * theta_sq / 720.0,
        )
    } else {
        let theta = theta_sq.sqrt();
        (theta.sin() / theta, (1.0 - theta.cos()) / theta_sq)
    }
}

/// Rotation vector → matrix (Rodrigues), f64 on the host.
pub fn rotation_vector_to_matrix(omega: DVec3) -> DMat3 {
    let (a, b) = rodrigues_coefficients(omega.length_squared());
    let k = skew(omega);
    DMat3::IDENTITY + k * a + k * k * b
}

/// Matrix → rotation vector with |ω| ≤ π, accurate near 0 and near π.
pub fn matrix_to_rotation_vector(r: DMat3) -> DVec3 {
    let vee = DVec3::new(
        r.y_axis.z - r.z_axis.y,
        r.z_axis.x - r.x_axis.z,
        r.x_axis.y - r.y_axis.x,
    ); // 2 sin θ · axis
    let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) * 0.5).clamp(-1.0, 1.0);
    let sin = 0.5 * vee.length();
    let theta = sin.atan2(cos);
    if theta < 1e-6 {
        return 0.5 * vee; // θ/(2 sin θ) → 1/2
    }
    if cos > -0.9 {
        return vee * (theta / (2.0 * sin));
    }
    // Near π, sin θ loses the axis: read it from the symmetric part, R + Rᵀ = 2cosθ I + 2(1 − cosθ) a aᵀ.
    let s = (r + r.transpose()) * 0.5 - DMat3::IDENTITY * cos; // (1 − cos θ) a aᵀ
    let k = (0..3)
        .max_by(|&i, &j| s.col(i)[i].total_cmp(&s.col(j)[j]))
        .unwrap_or(0);
    let mut axis = s.col(k).normalize();
    if axis.dot(vee) < 0.0 {
        axis = -axis;
    }
    axis * theta
}

/// The cross-product matrix [v]ₓ (so that [v]ₓ u = v × u).
fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// `m` projected onto the nearest rotation, or why it is not close to one.
pub fn nearest_rotation(m: DMat3) -> Result<DMat3, String> {
    if !m.is_finite() {
        return Err("the rotation holds a value that is not finite".into());
    }
    let gram = m.transpose() * m - DMat3::IDENTITY;
    let off = gram
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    let det = m.determinant();
    if off > ROTATION_TOLERANCE || (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!(
            "not a rotation (RᵀR differs from I by {off:.2e}, det R = {det:.6}); scaled, \
             sheared or mirrored cameras are not supported"
        ));
    }
    Ok(DMat3::from_quat(DQuat::from_mat3(&m).normalize()))
}
