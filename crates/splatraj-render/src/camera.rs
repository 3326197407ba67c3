//! Pinhole camera (OpenCV axes) and the pose vector Φ = (ω, c).
//!
//! Conventions (docs/conventions.md): camera x right, y down, z forward; pixel (i, j) has its
//! centre at (i + 0.5, j + 0.5). Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z] where ω is the rotation vector
//! of R_wc (camera-to-world) and c the camera centre in world coordinates, so that p_cam = R_wcᵀ
//! (p_world − c). Host-side maths is f64 with glam; [`rotation_matrices`] is the differentiable
//! tensor version used inside the optimisation graph.

use burn::tensor::{Bool, Tensor};
use glam::{DMat3, DMat4, DVec3, DVec4};
use serde::{Deserialize, Serialize};

/// Problems with camera input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// Intrinsics that cannot describe a camera.
    #[error("invalid intrinsics: {0}")]
    Intrinsics(String),
    /// A matrix that is not a rigid world-to-camera transform.
    #[error("world_to_camera is not a rigid transform: {0}")]
    NotRigid(String),
    /// A look-at whose direction is undefined.
    #[error("look-at is degenerate: {0}")]
    DegenerateLookAt(String),
}

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (the image centre is width / 2).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
}

impl Intrinsics {
    /// Checked intrinsics: focal lengths and principal point finite, focal lengths > 0, size ≥ 1.
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: usize,
        height: usize,
    ) -> Result<Self, CameraError> {
        let intrinsics = Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        };
        if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
            return Err(CameraError::Intrinsics(format!(
                "fx = {fx}, fy = {fy} must be finite and > 0"
            )));
        }
        if !(cx.is_finite() && cy.is_finite()) {
            return Err(CameraError::Intrinsics(format!(
                "cx = {cx}, cy = {cy} must be finite"
            )));
        }
        // Beyond these the projection (x·f/z) and the 1.3·tan(fov) clamp overflow f32.
        if !(fx.max(fy) <= 1e12 && fx.min(fy) >= 1e-6 && cx.abs().max(cy.abs()) <= 1e12) {
            return Err(CameraError::Intrinsics(format!(
                "fx = {fx}, fy = {fy} must be in [1e-6, 1e12] pixels and |cx|, |cy| = {}, {} \
                 at most 1e12",
                cx.abs(),
                cy.abs()
            )));
        }
        if width == 0 || height == 0 {
            return Err(CameraError::Intrinsics(format!(
                "image size {width}×{height} must be at least 1×1"
            )));
        }
        Ok(intrinsics)
    }

    /// Square pixels, principal point at the centre, from the horizontal field of view.
    pub fn from_fov_x(
        fov_x_degrees: f64,
        width: usize,
        height: usize,
    ) -> Result<Self, CameraError> {
        if !(fov_x_degrees > 0.0 && fov_x_degrees < 180.0) {
            return Err(CameraError::Intrinsics(format!(
                "horizontal field of view {fov_x_degrees}° must be in (0°, 180°)"
            )));
        }
        let f = 0.5 * width as f64 / (0.5 * fov_x_degrees.to_radians()).tan();
        Self::new(f, f, 0.5 * width as f64, 0.5 * height as f64, width, height)
    }

    /// The same camera at another resolution: focal lengths and principal point scale with it.
    pub fn rescaled(&self, width: usize, height: usize) -> Result<Self, CameraError> {
        let (sx, sy) = (
            width as f64 / self.width as f64,
            height as f64 / self.height as f64,
        );
        Self::new(
            self.fx * sx,
            self.fy * sy,
            self.cx * sx,
            self.cy * sy,
            width,
            height,
        )
    }

    /// tan of half the field of view along x and y (for the 1.3·tan(fov) Jacobian clamp).
    pub fn tan_half_fov(&self) -> (f64, f64) {
        (
            0.5 * self.width as f64 / self.fx,
            0.5 * self.height as f64 / self.fy,
        )
    }
}

/// A camera pose Φ = [ω, c]: rotation vector of R_wc and camera centre, world coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose(pub [f64; 6]);

impl Pose {
    /// From the rotation R_wc (camera-to-world) and the camera centre.
    pub fn from_rotation_and_centre(rotation_wc: DMat3, centre: DVec3) -> Self {
        let omega = matrix_to_rotation_vector(rotation_wc);
        Pose([omega.x, omega.y, omega.z, centre.x, centre.y, centre.z])
    }

    /// The rotation vector ω.
    pub fn omega(&self) -> DVec3 {
        DVec3::new(self.0[0], self.0[1], self.0[2])
    }

    /// The camera centre c in world coordinates.
    pub fn centre(&self) -> DVec3 {
        DVec3::new(self.0[3], self.0[4], self.0[5])
    }

    /// R_wc: columns are the camera's x (right), y (down), z (forward) axes in world.
    pub fn rotation_wc(&self) -> DMat3 {
        rotation_vector_to_matrix(self.omega())
    }

    /// 4×4 camera-to-world transform.
    pub fn camera_to_world(&self) -> DMat4 {
        let r = self.rotation_wc();
        DMat4::from_cols(
            r.x_axis.extend(0.0),
            r.y_axis.extend(0.0),
            r.z_axis.extend(0.0),
            self.centre().extend(1.0),
        )
    }

    /// 4×4 world-to-camera transform: p_cam = R_wcᵀ (p − c).
    pub fn world_to_camera(&self) -> DMat4 {
        let r_cw = self.rotation_wc().transpose();
        let t = -(r_cw * self.centre());
        DMat4::from_cols(
            r_cw.x_axis.extend(0.0),
            r_cw.y_axis.extend(0.0),
            r_cw.z_axis.extend(0.0),
            t.extend(1.0),
        )
    }

    /// From a 4×4 world-to-camera matrix, checking that it is rigid (tolerance 1e-4).
    pub fn from_world_to_camera(m: DMat4) -> Result<Self, CameraError> {
        if !m.is_finite() {
            return Err(CameraError::NotRigid(
                "it holds NaN or infinite values".into(),
            ));
        }
        if m.row(3).distance(DVec4::W) > 1e-6 {
            return Err(CameraError::NotRigid(format!(
                "last row is {:?}, expected [0, 0, 0, 1]",
                m.row(3)
            )));
        }
        let r_cw = DMat3::from_mat4(m);
        let error = (r_cw * r_cw.transpose() - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()));
        if error > 1e-4 || r_cw.determinant() < 0.0 {
            return Err(CameraError::NotRigid(format!(
                "its 3×3 block is not a rotation (|R Rᵀ − I| = {error:.2e}, det = {:.4})",
                r_cw.determinant()
            )));
        }
        let r_wc = r_cw.transpose();
        let centre = -(r_wc * m.w_axis.truncate());
        Ok(Self::from_rotation_and_centre(orthonormalise(r_wc), centre))
    }

    /// A camera at `eye` looking at `target`, with the image's up (−y) toward `world_up`.
    pub fn look_at(eye: DVec3, target: DVec3, world_up: DVec3) -> Result<Self, CameraError> {
        let forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || !forward.is_finite() {
            return Err(CameraError::DegenerateLookAt(format!(
                "eye {eye} and target {target} coincide"
            )));
        }
        let right = forward.cross(world_up).normalize_or_zero();
        if right == DVec3::ZERO || !right.is_finite() {
            return Err(CameraError::DegenerateLookAt(format!(
                "viewing direction {forward} is parallel to up {world_up}"
            )));
        }
        let down = forward.cross(right);
        Ok(Self::from_rotation_and_centre(
            DMat3::from_cols(right, down, forward),
            eye,
        ))
    }
}

/// Nearest rotation to an almost-orthonormal matrix (Gram–Schmidt on its columns).
fn orthonormalise(m: DMat3) -> DMat3 {
    let x = m.x_axis.normalize();
    let y = (m.y_axis - x * x.dot(m.y_axis)).normalize();
    DMat3::from_cols(x, y, x.cross(y))
}

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

fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// Below this θ², Rodrigues' coefficients come from their Taylor series (in f32, sin θ/θ
/// computed directly loses all precision well before θ = 0).
const SERIES_BELOW_THETA_SQ: f64 = 1e-2;

/// Differentiable Rodrigues: rotation vectors `[B, 3]` → rotation matrices `[B, 3, 3]`.
///
/// Neither value nor gradient is NaN at ω = 0: below [`SERIES_BELOW_THETA_SQ`] the
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
