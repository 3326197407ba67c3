//! The fused projection on the GPU backend (`CubeBackend`: wgpu and any CubeCL runtime, under burn's fusion: [`crate::fused::fusion`]): the host
//! kernels' rules ([`super::cpu`]) as CubeCL kernels.
//!
//! - Forward: one unit per row (pose, Gaussian); each unit builds its pose's rotation from ω
//!   (Rodrigues, the same two branches) and writes the packed row. The launch grid is
//!   (chunks of 256 of a pose's rows, poses), so every cube serves one pose.
//! - Backward: each unit computes its rows' gradient with respect to the camera's axes,
//!   centre and zoom (13 values) and the cube sums them by a fixed tree in shared memory into one
//!   partial per cube; a second kernel, one cube per pose, sums the partials in order and takes
//!   them through Rodrigues' derivative. No atomics: the same numbers on every run.
//!
//! Two launches forward and backward together, whatever the batch; only the scene index of each
//! row's Gaussian (4 bytes a row) and each pose's first row travel from the host. f64 runs the
//! host kernels.

use std::sync::Arc;

use burn::backend::TensorMetadata;
use burn::backend::tensor::FloatTensor;
use burn::tensor::{DType, TensorData};
use burn_backend::cubecl::dtype_to_storage_type;
use burn_backend::ops::FloatTensorOps;
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;
use burn_cubecl::{CubeDevice, cubecl};

use super::{
    HostSaved, HostView, ProjectionKernels, ProjectionPlan, SPLAT_COLUMNS, host_backward,
    host_forward,
};
use crate::camera::SERIES_BELOW_THETA_SQ;
use crate::fused::cube::int_tensor;
use crate::fused::{host_pool, launch_grid};
use crate::project::{LOW_PASS, NORMALISED_DET_FLOOR};

/// Units per cube, and Gaussians per chunk of the launch grid (the fused colours' too).
pub(crate) const UNITS: usize = 256;
/// Values a row's gradient has before Rodrigues: the three axes (9), the centre (3) and the
/// zoom (1).
const PARTIAL: usize = 13;

/// One pose's camera as the kernels read it, in the pass's float type (as in [`super::cpu`]:
/// fx, fy zoomed by s; lim_x, lim_y the unzoomed clamp of s·x/z, s·y/z).
#[derive(CubeType)]
struct Lens<F: Float> {
    zoom: F,
    fx0: F,
    fy0: F,
    fx: F,
    fy: F,
    cx: F,
    cy: F,
    lim_x: F,
    lim_y: F,
    near: F,
}

/// Pose `pose`'s lens from the launch's `[fx, fy, cx, cy, lim_x, lim_y, near]` and zoom `[B]`.
#[cube]
fn lens<F: Float>(camera: &Tensor<F>, zoom: &Tensor<F>, pose: usize) -> Lens<F> {
    let s = zoom[pose];
    Lens::<F> {
        zoom: s,
        fx0: camera[0],
        fy0: camera[1],
        fx: camera[0] * s,
        fy: camera[1] * s,
        cx: camera[2],
        cy: camera[3],
        lim_x: camera[4],
        lim_y: camera[5],
        near: camera[6],
    }
}

/// R_wc of ω, row-major `m[i][j]` as nine scalars, and Rodrigues' coefficients.
#[derive(CubeType)]
struct Rodrigues<F: Float> {
    m00: F,
    m01: F,
    m02: F,
    m10: F,
    m11: F,
    m12: F,
    m20: F,
    m21: F,
    m22: F,
    /// sin θ/θ, (1 − cos θ)/θ² and their derivatives in θ².
    a: F,
    b: F,
    da: F,
    db: F,
}

/// R = I + A·K + B·(ωωᵀ − θ²I) with K = [ω]ₓ (K² = ωωᵀ − θ²I), the tensor path's branches.
#[cube]
// The kernel language assigns branch values to variables declared before the branch.
#[allow(unused_assignments)]
fn rodrigues<F: Float>(w0: F, w1: F, w2: F) -> Rodrigues<F> {
    let s = w0 * w0 + w1 * w1 + w2 * w2;
    let mut a = F::new(0.0);
    let mut b = F::new(0.0);
    let mut da = F::new(0.0);
    let mut db = F::new(0.0);
    if s < F::new(SERIES_BELOW_THETA_SQ as f32) {
        a = F::new(1.0) - s / F::new(6.0) + s * s / F::new(120.0) - s * s * s / F::new(5040.0);
        b = F::new(0.5) - s / F::new(24.0) + s * s / F::new(720.0) - s * s * s / F::new(40320.0);
        da = F::new(-1.0 / 6.0) + s / F::new(60.0) - s * s / F::new(1680.0);
        db = F::new(-1.0 / 24.0) + s / F::new(360.0) - s * s / F::new(13440.0);
    } else {
        let theta = F::sqrt(s);
        let sin = F::sin(theta);
        let cos = F::cos(theta);
        let dtheta = F::new(0.5) / theta;
        a = sin / theta;
        b = (F::new(1.0) - cos) / s;
        da = (cos / theta - sin / s) * dtheta;
        db = sin * dtheta / s - (F::new(1.0) - cos) / (s * s);
    }
    Rodrigues::<F> {
        m00: F::new(1.0) + b * (w0 * w0 - s),
        m01: F::new(0.0) - a * w2 + b * w0 * w1,
        m02: a * w1 + b * w0 * w2,
        m10: a * w2 + b * w0 * w1,
        m11: F::new(1.0) + b * (w1 * w1 - s),
        m12: F::new(0.0) - a * w0 + b * w1 * w2,
        m20: F::new(0.0) - a * w1 + b * w0 * w2,
        m21: a * w0 + b * w1 * w2,
        m22: F::new(1.0) + b * (w2 * w2 - s),
        a,
        b,
        da,
        db,
    }
}

/// One row's projection: the packed outputs and every intermediate its backward reads
/// (names as in [`super::cpu`]).
#[derive(CubeType)]
struct Row<F: Float> {
    d0: F,
    d1: F,
    d2: F,
    x: F,
    y: F,
    z: F,
    inv_z: F,
    x_over_z: F,
    y_over_z: F,
    tx: F,
    ty: F,
    j00: F,
    j11: F,
    j02: F,
    j12: F,
    st1_0: F,
    st1_1: F,
    st1_2: F,
    st2_0: F,
    st2_1: F,
    st2_2: F,
    a: F,
    b: F,
    c: F,
    inv_trace: F,
    trace: F,
    an: F,
    bn: F,
    cn: F,
    det_n: F,
    det_kept: F,
    scale: F,
    u: F,
    v: F,
}

/// The projection of scene Gaussian `g` from pose `pose`, step by step as the host kernel does.
#[cube]
#[allow(clippy::too_many_arguments)]
fn project_row<F: Float>(
    poses: &Tensor<F>,
    components: &Tensor<F>,
    rot: &Rodrigues<F>,
    pose: usize,
    g: usize,
    n: usize,
    lens: &Lens<F>,
) -> Row<F> {
    let d0 = components[g] - poses[pose * 6 + 3];
    let d1 = components[n + g] - poses[pose * 6 + 4];
    let d2 = components[2 * n + g] - poses[pose * 6 + 5];
    // Camera axis k is column k of R.
    let x = rot.m00 * d0 + rot.m10 * d1 + rot.m20 * d2;
    let y = rot.m01 * d0 + rot.m11 * d1 + rot.m21 * d2;
    let z = rot.m02 * d0 + rot.m12 * d1 + rot.m22 * d2;
    let inv_z = F::new(1.0) / max(z, lens.near);
    let x_over_z = x * inv_z;
    let y_over_z = y * inv_z;
    let fx = lens.fx;
    let fy = lens.fy;
    let lim_x = lens.lim_x;
    let lim_y = lens.lim_y;
    // clamp(x/z, ±lim/s) as clamp(s·x/z, ±lim)/s, as the host kernel.
    let tx = max(min(x_over_z * lens.zoom, lim_x), F::new(0.0) - lim_x) / lens.zoom;
    let ty = max(min(y_over_z * lens.zoom, lim_y), F::new(0.0) - lim_y) / lens.zoom;
    let j00 = inv_z * fx;
    let j11 = inv_z * fy;
    let j02 = tx * inv_z * (F::new(0.0) - fx);
    let j12 = ty * inv_z * (F::new(0.0) - fy);
    let t1_0 = j00 * rot.m00 + j02 * rot.m02;
    let t1_1 = j00 * rot.m10 + j02 * rot.m12;
    let t1_2 = j00 * rot.m20 + j02 * rot.m22;
    let t2_0 = j11 * rot.m01 + j12 * rot.m02;
    let t2_1 = j11 * rot.m11 + j12 * rot.m12;
    let t2_2 = j11 * rot.m21 + j12 * rot.m22;
    let sxx = components[3 * n + g];
    let sxy = components[4 * n + g];
    let sxz = components[5 * n + g];
    let syy = components[6 * n + g];
    let syz = components[7 * n + g];
    let szz = components[8 * n + g];
    let st1_0 = sxx * t1_0 + sxy * t1_1 + sxz * t1_2;
    let st1_1 = sxy * t1_0 + syy * t1_1 + syz * t1_2;
    let st1_2 = sxz * t1_0 + syz * t1_1 + szz * t1_2;
    let st2_0 = sxx * t2_0 + sxy * t2_1 + sxz * t2_2;
    let st2_1 = sxy * t2_0 + syy * t2_1 + syz * t2_2;
    let st2_2 = sxz * t2_0 + syz * t2_1 + szz * t2_2;
    let low_pass = F::new(LOW_PASS as f32);
    let a = t1_0 * st1_0 + t1_1 * st1_1 + t1_2 * st1_2 + low_pass;
    let b = t2_0 * st1_0 + t2_1 * st1_1 + t2_2 * st1_2;
    let c = t2_0 * st2_0 + t2_1 * st2_1 + t2_2 * st2_2 + low_pass;
    let trace = a + c;
    let inv_trace = F::new(1.0) / trace;
    let an = a * inv_trace;
    let bn = b * inv_trace;
    let cn = c * inv_trace;
    let det_n = an * cn - bn * bn;
    let det_kept = max(det_n, F::new(NORMALISED_DET_FLOOR as f32));
    let scale = F::new(1.0) / (det_kept * trace);
    Row::<F> {
        d0,
        d1,
        d2,
        x,
        y,
        z,
        inv_z,
        x_over_z,
        y_over_z,
        tx,
        ty,
        j00,
        j11,
        j02,
        j12,
        st1_0,
        st1_1,
        st1_2,
        st2_0,
        st2_1,
        st2_2,
        a,
        b,
        c,
        inv_trace,
        trace,
        an,
        bn,
        cn,
        det_n,
        det_kept,
        scale,
        u: x_over_z * fx + lens.cx,
        v: y_over_z * fy + lens.cy,
    }
}

#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn forward_kernel<F: Float, I: Int>(
    poses: &Tensor<F>,      // [B, 6]
    zoom: &Tensor<F>,       // [B]
    components: &Tensor<F>, // [9, N]
    opacities: &Tensor<F>,  // [N]
    gaussians: &Tensor<I>,  // [R]: scene index of each row's Gaussian
    starts: &Tensor<I>,     // [B + 1]: first row of each pose, then R
    rows: &mut Tensor<F>,   // [R, 7]
    camera: &Tensor<F>,     // [7]: fx, fy, cx, cy, lim_x, lim_y, near
    n: u32,
    chunks: u32,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let pose = CUBE_POS_Y as usize;
    let lens = lens::<F>(camera, zoom, pose);
    let rot = rodrigues::<F>(poses[pose * 6], poses[pose * 6 + 1], poses[pose * 6 + 2]);
    let first = u32::cast_from(starts[pose]) as usize;
    let count = u32::cast_from(starts[pose + 1]) as usize - first;
    let mut chunk = CUBE_POS_X;
    while chunk < chunks {
        let k = chunk as usize * 256 + UNIT_POS as usize;
        if k < count {
            let r = first + k;
            let g = u32::cast_from(gaussians[r]) as usize;
            let row = project_row::<F>(poses, components, &rot, pose, g, n as usize, &lens);
            let at = r * 7;
            rows[at] = row.u;
            rows[at + 1] = row.v;
            rows[at + 2] = row.cn * row.scale;
            rows[at + 3] = F::new(0.0) - row.bn * row.scale;
            rows[at + 4] = row.an * row.scale;
            rows[at + 5] = opacities[g];
            rows[at + 6] = row.z;
        }
        chunk += CUBE_COUNT_X;
    }
}

/// Sums `values[k·256 + p]` over the cube's 256 units into `values[k·256]`, for k < `count`,
/// by a fixed tree (the same sum on every run).
#[cube]
pub(crate) fn tree_sum<F: Float>(values: &mut Shared<[F]>, p: usize, #[comptime] count: usize) {
    let mut half = 128usize;
    while half > 0 {
        if p < half {
            for k in 0..count {
                let other = values[k * 256 + p + half];
                values[k * 256 + p] += other;
            }
        }
        sync_cube();
        half /= 2;
    }
}

#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn backward_kernel<F: Float, I: Int>(
    poses: &Tensor<F>,       // [B, 6]
    zoom: &Tensor<F>,        // [B]
    components: &Tensor<F>,  // [9, N]
    gaussians: &Tensor<I>,   // [R]
    starts: &Tensor<I>,      // [B + 1]
    v_rows: &Tensor<F>,      // [R, 7]
    partial: &mut Tensor<F>, // [B, cubes per pose, 13]
    camera: &Tensor<F>,      // [7]
    n: u32,
    chunks: u32,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let pose = CUBE_POS_Y as usize;
    let p = UNIT_POS as usize;
    let rot = rodrigues::<F>(poses[pose * 6], poses[pose * 6 + 1], poses[pose * 6 + 2]);
    let lens = lens::<F>(camera, zoom, pose);
    let s = lens.zoom;
    let fx = lens.fx;
    let fy = lens.fy;
    let lim_x = lens.lim_x;
    let lim_y = lens.lim_y;
    let floor = F::new(NORMALISED_DET_FLOOR as f32);
    let near = lens.near;
    let two = F::new(2.0);
    let zero = F::new(0.0);
    // d L/d axes (r0, r1, r2: columns of R), d L/d centre and d L/ds, summed over this unit's
    // rows.
    let mut acc = Array::<F>::new(13usize);
    for k in 0..13usize {
        acc[k] = zero;
    }
    let first = u32::cast_from(starts[pose]) as usize;
    let count = u32::cast_from(starts[pose + 1]) as usize - first;
    let mut chunk = CUBE_POS_X;
    while chunk < chunks {
        let k = chunk as usize * 256 + p;
        if k < count {
            let r = first + k;
            let g = u32::cast_from(gaussians[r]) as usize;
            let row = project_row::<F>(poses, components, &rot, pose, g, n as usize, &lens);
            let at = r * 7;
            let vu = v_rows[at];
            let vv = v_rows[at + 1];
            let va_out = v_rows[at + 2];
            let vb_out = v_rows[at + 3];
            let vc_out = v_rows[at + 4];
            let v_depth = v_rows[at + 6];

            let v_scale = va_out * row.cn - vb_out * row.bn + vc_out * row.an;
            let mut v_cn = va_out * row.scale;
            let mut v_bn = zero - vb_out * row.scale;
            let mut v_an = vc_out * row.scale;
            let q = row.det_kept * row.trace;
            let v_q = zero - v_scale / (q * q);
            let v_det_kept = v_q * row.trace;
            let mut v_trace = v_q * row.det_kept;
            let mut v_det = v_det_kept;
            if row.det_n < floor {
                v_det = zero;
            }
            v_an += v_det * row.cn;
            v_cn += v_det * row.an;
            v_bn += zero - two * row.bn * v_det;
            let v_inv_trace = v_an * row.a + v_bn * row.b + v_cn * row.c;
            v_trace += zero - v_inv_trace * row.inv_trace * row.inv_trace;
            let v_a = v_an * row.inv_trace + v_trace;
            let v_b = v_bn * row.inv_trace;
            let v_c = v_cn * row.inv_trace + v_trace;

            let v_t1_0 = two * v_a * row.st1_0 + v_b * row.st2_0;
            let v_t1_1 = two * v_a * row.st1_1 + v_b * row.st2_1;
            let v_t1_2 = two * v_a * row.st1_2 + v_b * row.st2_2;
            let v_t2_0 = v_b * row.st1_0 + two * v_c * row.st2_0;
            let v_t2_1 = v_b * row.st1_1 + two * v_c * row.st2_1;
            let v_t2_2 = v_b * row.st1_2 + two * v_c * row.st2_2;

            // r0 = (m00, m10, m20), r1 = (m01, m11, m21), r2 = (m02, m12, m22)
            let v_j00 = v_t1_0 * rot.m00 + v_t1_1 * rot.m10 + v_t1_2 * rot.m20;
            let v_j02 = v_t1_0 * rot.m02 + v_t1_1 * rot.m12 + v_t1_2 * rot.m22;
            let v_j11 = v_t2_0 * rot.m01 + v_t2_1 * rot.m11 + v_t2_2 * rot.m21;
            let v_j12 = v_t2_0 * rot.m02 + v_t2_1 * rot.m12 + v_t2_2 * rot.m22;

            let mut v_inv_z = fx * v_j00 + fy * v_j11 - fx * row.tx * v_j02 - fy * row.ty * v_j12;
            let v_tx = zero - fx * row.inv_z * v_j02;
            let v_ty = zero - fy * row.inv_z * v_j12;
            // d L/d(fx·s), d L/d(fy·s), then tx = clamp(s·x/z)/s (the host kernel's steps).
            let v_fx = vu * row.x_over_z + v_j00 * row.inv_z - v_j02 * row.tx * row.inv_z;
            let v_fy = vv * row.y_over_z + v_j11 * row.inv_z - v_j12 * row.ty * row.inv_z;
            let mut v_zoom = v_fx * lens.fx0 + v_fy * lens.fy0;
            let v_kx = v_tx / s;
            let v_ky = v_ty / s;
            v_zoom += zero - v_tx * row.tx / s - v_ty * row.ty / s;
            let mut v_x_over_z = fx * vu;
            let x_zoomed = row.x_over_z * s;
            if x_zoomed <= lim_x && x_zoomed >= zero - lim_x {
                v_x_over_z += v_kx * s;
                v_zoom += v_kx * row.x_over_z;
            }
            let mut v_y_over_z = fy * vv;
            let y_zoomed = row.y_over_z * s;
            if y_zoomed <= lim_y && y_zoomed >= zero - lim_y {
                v_y_over_z += v_ky * s;
                v_zoom += v_ky * row.y_over_z;
            }
            acc[12] += v_zoom;
            let v_x = v_x_over_z * row.inv_z;
            let v_y = v_y_over_z * row.inv_z;
            v_inv_z += v_x_over_z * row.x + v_y_over_z * row.y;
            let mut v_z = v_depth;
            if row.z >= near {
                v_z += zero - v_inv_z * row.inv_z * row.inv_z;
            }

            // axes[k][e]: axis 0 from t1 (j00) and x; axis 1 from t2 (j11) and y; axis 2 from
            // both (j02, j12) and z.
            acc[0] += row.j00 * v_t1_0 + v_x * row.d0;
            acc[1] += row.j00 * v_t1_1 + v_x * row.d1;
            acc[2] += row.j00 * v_t1_2 + v_x * row.d2;
            acc[3] += row.j11 * v_t2_0 + v_y * row.d0;
            acc[4] += row.j11 * v_t2_1 + v_y * row.d1;
            acc[5] += row.j11 * v_t2_2 + v_y * row.d2;
            acc[6] += row.j02 * v_t1_0 + row.j12 * v_t2_0 + v_z * row.d0;
            acc[7] += row.j02 * v_t1_1 + row.j12 * v_t2_1 + v_z * row.d1;
            acc[8] += row.j02 * v_t1_2 + row.j12 * v_t2_2 + v_z * row.d2;
            acc[9] += zero - (v_x * rot.m00 + v_y * rot.m01 + v_z * rot.m02);
            acc[10] += zero - (v_x * rot.m10 + v_y * rot.m11 + v_z * rot.m12);
            acc[11] += zero - (v_x * rot.m20 + v_y * rot.m21 + v_z * rot.m22);
        }
        chunk += CUBE_COUNT_X;
    }
    let mut shared = Shared::<[F]>::new_slice(3328usize);
    for k in 0..13usize {
        shared[k * 256 + p] = acc[k];
    }
    sync_cube();
    tree_sum::<F>(&mut shared, p, PARTIAL);
    if p < 13 {
        partial[(pose * CUBE_COUNT_X as usize + CUBE_POS_X as usize) * 13 + p] = shared[p * 256];
    }
}

#[cube(launch)]
fn reduce_kernel<F: Float>(
    poses: &Tensor<F>,       // [B, 6]
    partial: &Tensor<F>,     // [B, cubes, 13]
    v_poses: &mut Tensor<F>, // [B, 6]
    v_zoom: &mut Tensor<F>,  // [B]
    cubes: u32,
    #[define(F)] _dtype: ElemType,
) {
    let pose = CUBE_POS_X as usize;
    let p = UNIT_POS as usize;
    let mut shared = Shared::<[F]>::new_slice(3328usize);
    for k in 0..13usize {
        let mut sum = F::new(0.0);
        let mut i = p;
        while i < cubes as usize {
            sum += partial[(pose * cubes as usize + i) * 13 + k];
            i += 256;
        }
        shared[k * 256 + p] = sum;
    }
    sync_cube();
    tree_sum::<F>(&mut shared, p, PARTIAL);
    if p == 0 {
        let w0 = poses[pose * 6];
        let w1 = poses[pose * 6 + 1];
        let w2 = poses[pose * 6 + 2];
        let rot = rodrigues::<F>(w0, w1, w2);
        // d L/dR[e][k] = d L/d axes[k][e] = shared[(3k + e)·256].
        let v00 = shared[0];
        let v10 = shared[256];
        let v20 = shared[512];
        let v01 = shared[768];
        let v11 = shared[1024];
        let v21 = shared[1280];
        let v02 = shared[1536];
        let v12 = shared[1792];
        let v22 = shared[2048];
        // ∂R/∂ω_m = 2ω_m (A'·K + B'·(ωωᵀ − sI)) + A·E_m + B·(e_m ωᵀ + ω e_mᵀ − 2ω_m I), so
        // d L/dω_m = 2ω_m (A'⟨V,K⟩ + B'(ωᵀVω − s·tr V) − B·tr V) + A⟨V,E_m⟩
        //            + B((Vω)_m + (Vᵀω)_m).
        let s = w0 * w0 + w1 * w1 + w2 * w2;
        let g0 = v21 - v12;
        let g1 = v02 - v20;
        let g2 = v10 - v01;
        let vk = w0 * g0 + w1 * g1 + w2 * g2;
        let vw0 = v00 * w0 + v01 * w1 + v02 * w2;
        let vw1 = v10 * w0 + v11 * w1 + v12 * w2;
        let vw2 = v20 * w0 + v21 * w1 + v22 * w2;
        let vtw0 = v00 * w0 + v10 * w1 + v20 * w2;
        let vtw1 = v01 * w0 + v11 * w1 + v21 * w2;
        let vtw2 = v02 * w0 + v12 * w1 + v22 * w2;
        let trace = v00 + v11 + v22;
        let wvw = w0 * vw0 + w1 * vw1 + w2 * vw2;
        let common = F::new(2.0) * (rot.da * vk + rot.db * (wvw - s * trace) - rot.b * trace);
        v_poses[pose * 6] = w0 * common + rot.a * g0 + rot.b * (vw0 + vtw0);
        v_poses[pose * 6 + 1] = w1 * common + rot.a * g1 + rot.b * (vw1 + vtw1);
        v_poses[pose * 6 + 2] = w2 * common + rot.a * g2 + rot.b * (vw2 + vtw2);
        v_poses[pose * 6 + 3] = shared[2304];
        v_poses[pose * 6 + 4] = shared[2560];
        v_poses[pose * 6 + 5] = shared[2816];
        v_zoom[pose] = shared[3072];
    }
}

/// What the GPU forward pass keeps for its backward.
#[derive(Debug, Clone)]
pub struct DeviceSaved {
    poses: CubeTensor,
    zoom: CubeTensor,
    components: CubeTensor,
    gaussians: CubeTensor,
    starts: CubeTensor,
    camera: CubeTensor,
    plan: Arc<ProjectionPlan>,
}

/// A fused op's backward state on the GPU backend: on the device (`D`), or the host kernels'
/// state (`H`) for f64 passes. The projection's and the colours' ops keep one each.
#[derive(Debug, Clone)]
pub enum CubeSaved<D, H> {
    /// f32 passes: everything on the device.
    Device(Box<D>),
    /// f64 passes: the host kernels' state.
    Host(Box<H>),
}

/// The row table a plan's kernels read: each row's Gaussian `[R]` and each pose's first row,
/// then R, `[B + 1]` (4 bytes a row and a pose), uploaded by the first op of the plan that
/// reads it on `device` and shared by the others.
pub(crate) fn upload_rows(plan: &ProjectionPlan, device: &CubeDevice) -> (CubeTensor, CubeTensor) {
    let upload = || {
        let gaussians = int_tensor(host_pool::i32s(&plan.gaussians), device);
        let starts = int_tensor(
            plan.rows.starts().iter().map(|&s| s as i32).collect(),
            device,
        );
        (gaussians, starts)
    };
    let uploaded = plan.device_rows.uploaded.get_or_init(upload);
    // A plan is one pass's, on one device; another device gets its own copy.
    if uploaded.0.device == *device {
        uploaded.clone()
    } else {
        upload()
    }
}

/// The launch grid: (cubes per pose, poses), and the chunks of 256 rows the pose with the
/// most rows has. A pose's cubes take its chunks in turn when there are more chunks than the
/// axis cap ([`launch_grid`]); a cube past a pose's rows only writes its zero partial.
pub(crate) fn grid(batch: usize, largest: usize) -> (CubeCount, u32, usize) {
    let chunks = largest.div_ceil(UNITS).max(1);
    let per_pose = chunks.min(launch_grid::axis_cap());
    (
        CubeCount::Static(per_pose as u32, batch as u32, 1),
        chunks as u32,
        per_pose,
    )
}

/// A float device tensor of `shape` whose values the kernels will write (no fill launch).
pub(crate) fn empty(shape: Vec<usize>, device: &CubeDevice, dtype: DType) -> CubeTensor {
    CubeBackend::float_empty(shape.into(), device, dtype.into())
}

/// The camera's constants as a device tensor `[7]` in `dtype` (seven floats up with the indices).
fn camera_tensor(plan: &ProjectionPlan, device: &CubeDevice, dtype: DType) -> CubeTensor {
    let c = &plan.camera;
    let (lim_x, lim_y) = c.limits();
    let values = vec![c.fx, c.fy, c.cx, c.cy, lim_x, lim_y, c.near];
    crate::counters::upload(values.len() * dtype.size());
    CubeBackend::float_from_data(TensorData::new(values, [7]).convert_dtype(dtype), device)
}

fn device_forward(
    poses: CubeTensor,
    zoom: CubeTensor,
    components: CubeTensor,
    opacities: CubeTensor,
    plan: Arc<ProjectionPlan>,
) -> (CubeTensor, DeviceSaved) {
    let [poses, zoom, components, opacities] =
        [poses, zoom, components, opacities].map(into_contiguous);
    let device = poses.device.clone();
    let client = poses.client.clone();
    let dtype = poses.dtype;
    let batch = poses.shape().dims::<2>()[0];
    let n = components.shape().dims::<2>()[1];
    let largest = plan.rows.largest();
    let (gaussians, starts) = upload_rows(&plan, &device);
    let camera = camera_tensor(&plan, &device, dtype);
    let rows = empty(vec![plan.rows.total(), SPLAT_COLUMNS], &device, dtype);
    let (cubes, chunks, _) = grid(batch, largest);
    if batch > 0 && largest > 0 {
        forward_kernel::launch(
            &client,
            cubes,
            CubeDim::new_1d(UNITS as u32),
            poses.clone().into_tensor_arg(),
            zoom.clone().into_tensor_arg(),
            components.clone().into_tensor_arg(),
            opacities.into_tensor_arg(),
            gaussians.clone().into_tensor_arg(),
            starts.clone().into_tensor_arg(),
            rows.clone().into_tensor_arg(),
            camera.clone().into_tensor_arg(),
            n as u32,
            chunks,
            [
                dtype_to_storage_type(dtype),
                dtype_to_storage_type(gaussians.dtype),
            ],
        );
    }
    let saved = DeviceSaved {
        poses,
        zoom,
        components,
        gaussians,
        starts,
        camera,
        plan,
    };
    (rows, saved)
}

fn device_backward(saved: DeviceSaved, v_rows: CubeTensor) -> (CubeTensor, CubeTensor) {
    let v_rows = into_contiguous(v_rows);
    let DeviceSaved {
        poses,
        zoom,
        components,
        gaussians,
        starts,
        camera,
        plan,
    } = saved;
    let device = poses.device.clone();
    let client = poses.client.clone();
    let dtype = poses.dtype;
    let batch = poses.shape().dims::<2>()[0];
    let n = components.shape().dims::<2>()[1];
    let (cubes, chunks, per_pose) = grid(batch, plan.rows.largest());
    let partial = empty(vec![batch, per_pose, PARTIAL], &device, dtype);
    let v_poses = empty(vec![batch, 6], &device, dtype);
    let v_zoom = empty(vec![batch], &device, dtype);
    if batch == 0 {
        return (v_poses, v_zoom);
    }
    let int_dtype = dtype_to_storage_type(gaussians.dtype);
    // With nothing projected every cube still writes its (zero) partial.
    backward_kernel::launch(
        &client,
        cubes,
        CubeDim::new_1d(UNITS as u32),
        poses.clone().into_tensor_arg(),
        zoom.into_tensor_arg(),
        components.into_tensor_arg(),
        gaussians.into_tensor_arg(),
        starts.into_tensor_arg(),
        v_rows.into_tensor_arg(),
        partial.clone().into_tensor_arg(),
        camera.into_tensor_arg(),
        n as u32,
        chunks,
        [dtype_to_storage_type(dtype), int_dtype],
    );
    reduce_kernel::launch(
        &client,
        CubeCount::Static(batch as u32, 1, 1),
        CubeDim::new_1d(UNITS as u32),
        poses.into_tensor_arg(),
        partial.into_tensor_arg(),
        v_poses.clone().into_tensor_arg(),
        v_zoom.clone().into_tensor_arg(),
        per_pose as u32,
        dtype_to_storage_type(dtype),
    );
    (v_poses, v_zoom)
}

/// f64 passes read the scene's rows back (a copy) and run the host kernels.
impl HostView for CubeBackend {}

impl ProjectionKernels for CubeBackend {
    type Saved = CubeSaved<DeviceSaved, HostSaved<CubeBackend>>;

    fn projection_forward(
        poses: FloatTensor<Self>,
        zoom: FloatTensor<Self>,
        components: FloatTensor<Self>,
        opacities: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved) {
        if components.dtype() == DType::F64 {
            // The host kernels run on every core: on the pool that never waits on the device.
            let (rows, saved) =
                host_pool::run(|| host_forward::<Self>(poses, zoom, components, opacities, plan));
            return (rows, CubeSaved::Host(Box::new(saved)));
        }
        let (rows, saved) = device_forward(poses, zoom, components, opacities, plan);
        (rows, CubeSaved::Device(Box::new(saved)))
    }

    fn projection_backward(
        saved: Self::Saved,
        v_rows: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        match saved {
            CubeSaved::Host(saved) => host_pool::run(|| host_backward::<Self>(*saved, v_rows)),
            CubeSaved::Device(saved) => device_backward(*saved, v_rows),
        }
    }
}
