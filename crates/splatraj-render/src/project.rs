//! First stage of the tensor rasterizer: Gaussians → screen space for a batch of poses.
//!
//! Differentiable with respect to the pose tensor Φ `[B, 6]` (burn autodiff); the scene's
//! pose-independent quantities ([`SceneTensors`]) are constants. Rules (docs/conventions.md, INRIA
//! 3DGS):
//!
//! - p_cam = R_wcᵀ (p − c), R_wc from [`rotation_matrices`].
//! - Σ_cam = W Σ Wᵀ with W = R_wcᵀ.
//! - J = [[fx/z, 0, −fx·x̂/z], [0, fy/z, −fy·ŷ/z]] with x̂ = clamp(x/z, ±1.3·tan_x) and
//!   ŷ = clamp(y/z, ±1.3·tan_y) (tan of half the field of view); the projected mean
//!   u = fx·x/z + cx, v = fy·y/z + cy is *not* clamped.
//! - Σ_2D = J Σ_cam Jᵀ + 0.3·I, conic = Σ_2D⁻¹.
//!
//! Culling (z ≤ near, det ≤ 0) is integer data decided on the host without gradient
//! ([`radii_and_visibility`]). The tensor path never culls: it divides by z clamped to ≥ near,
//! so a culled entry holds *finite garbage* (values and gradients), never NaN or Inf, and must
//! be masked out by the caller.

use burn::tensor::{DType, Device, Int, Tensor, TensorData};
use glam::{DMat3, DQuat, DVec3};
use splatraj_scene::Scene;

use crate::camera::{Intrinsics, rotation_matrices};

/// Default near plane (camera z, scene units): Gaussians with z ≤ this are culled.
pub const NEAR_PLANE: f64 = 0.01;
/// x/z and y/z are clamped to ±`FOV_CLAMP`·tan(half fov) inside the Jacobian (INRIA).
pub const FOV_CLAMP: f64 = 1.3;
/// Added to the diagonal of every Σ_2D (INRIA's low-pass / anti-aliasing filter), pixels².
pub const LOW_PASS: f64 = 0.3;
/// Floor of the normalised determinant det(Σ_2D)/tr(Σ_2D)² (true value in (0, ¼]).
///
/// Below it the 2D footprint is more than ~10⁶ times longer than wide, where f32 rounding makes
/// the determinant noise (it can come out ≤ 0). The conic divides by the floored value so it
/// stays finite, and [`radii_and_visibility`] culls such entries. The floor is chosen so that
/// its square (which appears in the backward pass of the division) does not underflow in f32.
pub const NORMALISED_DET_FLOOR: f64 = 1e-12;

/// Scene quantities that do not depend on the pose, computed once per scene on the host and uploaded.
///
/// The projection reads them component-major ([`SceneTensors::components`]): every per-Gaussian
/// quantity of a pass is then one contiguous row of N values, so each tensor op is a plain
/// vectorised loop with its pose constants broadcast, instead of the strided, per-Gaussian 3×3
/// products and last-axis concatenations that made projection the slowest stage on CPU backends.
#[derive(Debug, Clone)]
pub struct SceneTensors {
    /// Gaussian centres, world coordinates (for SH view directions). `[N, 3]`
    pub means: Tensor<2>,
    /// Per-Gaussian rows: the centre's x, y, z, then the world covariance Σ = R S Sᵀ Rᵀ as
    /// xx, xy, xz, yy, yz, zz. `[9, N]`
    pub components: Tensor<2>,
    /// Activated opacities in [0, 1]. `[N]`
    pub opacities: Tensor<1>,
}

/// Rows of [`SceneTensors::components`].
const CENTRE_ROWS: usize = 0;
const COVARIANCE_ROWS: usize = 3;

impl SceneTensors {
    /// Uploads the Gaussians `indices` (all when `None`, in that order) with Σ computed in f64.
    ///
    /// Quaternions are normalised here (a zero quaternion, which validated scenes do not hold,
    /// is read as the identity rather than producing NaN). Panics if an index is out of range.
    pub fn new(scene: &Scene, indices: Option<&[usize]>, device: &Device, dtype: DType) -> Self {
        let all: Vec<usize>;
        let indices = match indices {
            Some(i) => i,
            None => {
                all = (0..scene.len()).collect();
                &all
            }
        };
        let n = indices.len();
        let mut means = Vec::with_capacity(3 * n);
        let mut components = vec![0.0f64; 9 * n];
        let mut opacities = Vec::with_capacity(n);
        for (column, &i) in indices.iter().enumerate() {
            let mean = scene.means[i].map(f64::from);
            means.extend(mean);
            let s = world_covariance(scene.scales[i], scene.rotations[i]);
            let values = [
                mean[0], mean[1], mean[2], s[0], s[1], s[2], s[4], s[5], s[8],
            ];
            for (row, value) in values.into_iter().enumerate() {
                components[row * n + column] = value;
            }
            opacities.push(f64::from(scene.opacities[i]));
        }
        let options = (device, dtype);
        Self {
            means: Tensor::from_data(TensorData::new(means, [n, 3]), options),
            components: Tensor::from_data(TensorData::new(components, [9, n]), options),
            opacities: Tensor::from_data(TensorData::new(opacities, [n]), options),
        }
    }

    /// The Gaussians at `indices` (a device-side gather). `indices` `[M]`
    pub fn select(&self, indices: Tensor<1, Int>) -> Self {
        Self {
            means: self.means.clone().select(0, indices.clone()),
            components: self.components.clone().select(1, indices.clone()),
            opacities: self.opacities.clone().select(0, indices),
        }
    }

    /// The Gaussians `start .. start + len`.
    pub fn narrow(&self, start: usize, len: usize) -> Self {
        Self {
            means: self.means.clone().narrow(0, start, len),
            components: self.components.clone().narrow(1, start, len),
            opacities: self.opacities.clone().narrow(0, start, len),
        }
    }

    /// The same tensors off the autodiff graph (for passes that need no gradient).
    pub fn without_autodiff(&self) -> Self {
        Self {
            means: self.means.clone().without_autodiff(),
            components: self.components.clone().without_autodiff(),
            opacities: self.opacities.clone().without_autodiff(),
        }
    }

    /// Number of Gaussians N.
    pub fn len(&self) -> usize {
        self.means.dims()[0]
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row `row` of the components as `[1, 1, N]`, ready to broadcast against a batch.
    fn row(&self, row: usize) -> Tensor<3> {
        self.components
            .clone()
            .narrow(0, row, 1)
            .unsqueeze_dim::<3>(0)
    }
}

/// Σ = R S Sᵀ Rᵀ, row-major, in f64. `rotation` is (w, x, y, z), normalised here.
pub(crate) fn world_covariance(scale: [f32; 3], rotation: [f32; 4]) -> [f64; 9] {
    let [w, x, y, z] = rotation.map(f64::from);
    let q = DQuat::from_xyzw(x, y, z, w);
    let q = if q.length_squared() > 0.0 {
        q.normalize()
    } else {
        DQuat::IDENTITY
    };
    let m = DMat3::from_quat(q) * DMat3::from_diagonal(DVec3::from(scale.map(f64::from)));
    let sigma = m * m.transpose();
    // glam is column-major; Σ is symmetric anyway, the transpose makes the row-major intent explicit.
    sigma.transpose().to_cols_array()
}

/// Screen-space Gaussians for a batch of poses (all batched tensors; see the module docs).
#[derive(Debug, Clone)]
pub struct Projected {
    /// Projected means (u, v) in pixels, not clamped; garbage where culled. `[B, N, 2]`
    pub means_2d: Tensor<3>,
    /// Camera-space z (unclamped: this is what the near-plane cull reads). `[B, N]`
    pub depth: Tensor<2>,
    /// (a, b, c) of the inverse 2D covariance [[a, b], [b, c]]. `[B, N, 3]`
    pub conics: Tensor<3>,
    /// (Σ₁₁, Σ₁₂, Σ₂₂) of Σ_2D, low-pass included. `[B, N, 3]`
    pub cov_2d: Tensor<3>,
}

/// [`project_with_near`] with the default [`NEAR_PLANE`].
pub fn project(scene: &SceneTensors, poses: Tensor<2>, intrinsics: &Intrinsics) -> Projected {
    project_with_near(scene, poses, intrinsics, NEAR_PLANE)
}

/// Projects every Gaussian for every pose Φ = (ω, c) in `poses` `[B, 6]`; differentiable in Φ.
///
/// `near` only sets the depth that divisions are clamped to (z ≥ near), which keeps culled
/// entries finite; pass the same value to [`radii_and_visibility`].
pub fn project_with_near(
    scene: &SceneTensors,
    poses: Tensor<2>,
    intrinsics: &Intrinsics,
    near: f64,
) -> Projected {
    project_zoomed(scene, poses, None, intrinsics, near)
}

/// [`project_with_near`] through `intrinsics` zoomed per pose by `zoom` `[B]` (s > 0; `None`:
/// s = 1); differentiable in Φ and s.
///
/// The zoom enters exactly where fx and fy do: fx·s and fy·s in the projected mean and the
/// Jacobian, and the Jacobian's clamp bound ±1.3·tan(half fov) on x/z, y/z, which shrinks to
/// ±1.3·tan/s (written as clamp(s·x/z, ±1.3·tan)/s, so the gradient also flows through the
/// bound where a Gaussian is clamped). Equal to rendering with fx·s, fy·s in the intrinsics.
pub fn project_zoomed(
    scene: &SceneTensors,
    poses: Tensor<2>,
    zoom: Option<Tensor<1>>,
    intrinsics: &Intrinsics,
    near: f64,
) -> Projected {
    let [batch, _] = poses.dims();
    let zoom = zoom.map(|s| s.reshape([batch, 1, 1])); // [B, 1, 1]
    // t·fx (or fy) with the focal length zoomed per pose: a broadcast product with s, or the
    // unzoomed scalar product (the same ops as before zoom existed).
    let focal = |t: Tensor<3>, f: f64| match &zoom {
        Some(s) => t * s.clone().mul_scalar(f),
        None => t.mul_scalar(f),
    };
    let n = scene.len();
    let Intrinsics { fx, fy, cx, cy, .. } = *intrinsics;
    let (tan_x, tan_y) = intrinsics.tan_half_fov();
    let (lim_x, lim_y) = (FOV_CLAMP * tan_x, FOV_CLAMP * tan_y);

    let omega = poses.clone().narrow(1, 0, 3); // [B, 3]
    let centre = poses.narrow(1, 3, 3).unsqueeze_dim::<3>(2); // [B, 3, 1]
    let r_wc = rotation_matrices(omega); // [B, 3, 3]; column k = camera axis k in world

    // Every per-Gaussian quantity below is [B, 1, N]: one contiguous row per pose.
    // p_cam = R_wcᵀ (p − c) for all Gaussians at once; subtracting before rotating keeps f32
    // precision when the scene sits far from the origin.
    let centres = scene
        .components
        .clone()
        .narrow(0, CENTRE_ROWS, 3)
        .unsqueeze_dim::<3>(0)
        .repeat_dim(0, batch); // [B, 3, N]
    let p_cam = r_wc.clone().swap_dims(1, 2).matmul(centres - centre); // [B, 3, N]
    let x = p_cam.clone().narrow(1, 0, 1); // [B, 1, N]
    let y = p_cam.clone().narrow(1, 1, 1); // [B, 1, N]
    let z = p_cam.narrow(1, 2, 1); // [B, 1, N]

    // Divide only by z ≥ near: behind-camera entries stay finite, and clamp_min's backward
    // masks their z-gradient to 0 instead of multiplying (so no 0·Inf).
    let z_safe = z.clone().clamp_min(near); // [B, 1, N]
    let inv_z = z_safe.recip(); // [B, 1, N]
    let x_over_z = x * inv_z.clone(); // [B, 1, N]
    let y_over_z = y * inv_z.clone(); // [B, 1, N]

    let u = focal(x_over_z.clone(), fx).add_scalar(cx); // [B, 1, N]
    let v = focal(y_over_z.clone(), fy).add_scalar(cy); // [B, 1, N]
    let means_2d = interleave(vec![u, v]); // [B, N, 2]

    // Jacobian entries with clamped x/z, y/z: J00 = fx/z, J02 = −fx·x̂/z, J11 = fy/z, J12 = −fy·ŷ/z.
    // Zoomed: clamp(x/z, ±lim/s) = clamp(s·x/z, ±lim)/s, with burn's scalar clamp.
    let (tx, ty) = match &zoom {
        Some(s) => (
            (x_over_z * s.clone()).clamp(-lim_x, lim_x) / s.clone(),
            (y_over_z * s.clone()).clamp(-lim_y, lim_y) / s.clone(),
        ),
        None => (x_over_z.clamp(-lim_x, lim_x), y_over_z.clamp(-lim_y, lim_y)),
    }; // [B, 1, N] each
    let j00 = focal(inv_z.clone(), fx); // [B, 1, N]
    let j11 = focal(inv_z.clone(), fy); // [B, 1, N]
    let j02 = focal(tx * inv_z.clone(), -fx); // [B, 1, N]
    let j12 = focal(ty * inv_z, -fy); // [B, 1, N]

    // T = J W with W = R_wcᵀ: row k of W is camera axis k in world (column k of R_wc), so T's
    // rows are t1 = J00·r0 + J02·r2 and t2 = J11·r1 + J12·r2, component by component.
    let axis = |k: usize, e: usize| r_wc.clone().narrow(1, e, 1).narrow(2, k, 1); // [B, 1, 1]
    let t1: [Tensor<3>; 3] =
        std::array::from_fn(|e| j00.clone() * axis(0, e) + j02.clone() * axis(2, e)); // [B, 1, N] each
    let t2: [Tensor<3>; 3] =
        std::array::from_fn(|e| j11.clone() * axis(1, e) + j12.clone() * axis(2, e)); // [B, 1, N] each

    // Σ_2D = T Σ Tᵀ from the six covariance rows (xx, xy, xz, yy, yz, zz).
    let s: [Tensor<3>; 6] = std::array::from_fn(|k| scene.row(COVARIANCE_ROWS + k)); // [1, 1, N] each
    let sigma_rows = [[0, 1, 2], [1, 3, 4], [2, 4, 5]]; // Σ[i][j] = s[sigma_rows[i][j]]
    let sigma_times = |t: &[Tensor<3>; 3]| -> [Tensor<3>; 3] {
        sigma_rows.map(|row| {
            s[row[0]].clone() * t[0].clone()
                + s[row[1]].clone() * t[1].clone()
                + s[row[2]].clone() * t[2].clone()
        })
    }; // [B, 1, N] each
    let dot = |p: &[Tensor<3>; 3], q: [Tensor<3>; 3]| {
        let [q0, q1, q2] = q;
        p[0].clone() * q0 + p[1].clone() * q1 + p[2].clone() * q2
    }; // [B, 1, N]
    let s_t1 = sigma_times(&t1);
    let a = dot(&t1, s_t1.clone()).add_scalar(LOW_PASS); // [B, 1, N]
    let b = dot(&t2, s_t1); // [B, 1, N]; t2ᵀΣt1 = t1ᵀΣt2 since Σ is symmetric
    let c = dot(&t2, sigma_times(&t2)).add_scalar(LOW_PASS); // [B, 1, N]
    let cov_2d = interleave(vec![a.clone(), b.clone(), c.clone()]); // [B, N, 3]

    // Invert through the trace-normalised matrix: a·c − b² itself overflows f32 (and its
    // square, in the backward pass, overflows much sooner) for big Gaussians near the camera.
    // trace ≥ 0.6 thanks to the low-pass, so the division is safe.
    let trace = a.clone() + c.clone(); // [B, 1, N]
    let inv_trace = trace.clone().recip(); // [B, 1, N]
    let an = a * inv_trace.clone(); // [B, 1, N]
    let bn = b * inv_trace.clone(); // [B, 1, N]
    let cn = c * inv_trace; // [B, 1, N]
    let det_n = an.clone() * cn.clone() - bn.clone().square(); // [B, 1, N], det / trace²
    let scale = (det_n.clamp_min(NORMALISED_DET_FLOOR) * trace).recip(); // [B, 1, N], 1/(det/trace)
    let conics = interleave(vec![cn * scale.clone(), -(bn * scale.clone()), an * scale]); // [B, N, 3]

    Projected {
        means_2d,
        depth: z.reshape([batch, n]),
        conics,
        cov_2d,
    }
}

/// Per-Gaussian rows `[B, 1, N]` each → `[B, N, K]`, one Gaussian's K values together (the
/// layout the compositing ops read).
fn interleave(rows: Vec<Tensor<3>>) -> Tensor<3> {
    Tensor::cat(rows, 1).swap_dims(1, 2)
}

/// Host-side cull data from a projection, without gradient: `(radii, visible)`, each `B·N`
/// long, index `b·N + i`.
///
/// visible = z > near ∧ det(Σ_2D) > 0, where the determinant test is det/tr² >
/// [`NORMALISED_DET_FLOOR`] (see there) computed in f64, and any non-finite value culls.
/// radius = ceil(3·sqrt(λ_max(Σ_2D))) in pixels; 0 where not visible.
pub fn radii_and_visibility(projected: &Projected, near: f64) -> (Vec<f32>, Vec<bool>) {
    let depth = to_f64(&projected.depth);
    let cov = to_f64(&projected.cov_2d);
    depth
        .iter()
        .zip(cov.chunks_exact(3))
        .map(|(&z, abc)| {
            let (visible, radius) = cull_and_radius(z, abc[0], abc[1], abc[2], near);
            (radius, visible)
        })
        .unzip()
}

/// (visible, radius) from camera depth z and Σ_2D = [[a, b], [b, c]] (low-pass included).
///
/// visible = z > near ∧ det/tr² > [`NORMALISED_DET_FLOOR`] with every value finite;
/// radius = ceil(3·sqrt(λ_max)) in pixels, 0 where not visible.
pub fn cull_and_radius(z: f64, a: f64, b: f64, c: f64, near: f64) -> (bool, f32) {
    let trace = a + c;
    let det = a * c - b * b;
    let ok = z > near
        && trace.is_finite()
        && b.is_finite()
        && trace > 0.0
        && det / (trace * trace) > NORMALISED_DET_FLOOR;
    if !ok {
        return (false, 0.0);
    }
    let mid = 0.5 * trace;
    let lambda_max = mid + (mid * mid - det).max(0.0).sqrt();
    (true, (3.0 * lambda_max.sqrt()).ceil() as f32)
}

/// Tensor values as f64 on the host (flattened, row-major).
fn to_f64<const D: usize>(t: &Tensor<D>) -> Vec<f64> {
    t.to_data()
        .try_to_vec_as::<f64>()
        .expect("float tensor converts to f64")
}
