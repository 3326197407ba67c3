//! The fused colours on the GPU backend (`CubeBackend`: wgpu and any CubeCL runtime, under
//! burn's fusion: [`crate::fused::fusion`]): the host kernels' rules ([`super::cpu`]) as
//! CubeCL kernels, with the projection's launch grid.
//!
//! - Forward: one unit per row (pose, Gaussian) writes the row's RGB. The SH degree is a
//!   compile-time argument, so a degree-0 scene runs no basis arithmetic.
//! - Backward: each unit sums its rows' camera-centre gradients, the cube sums them by the
//!   projection's fixed tree into one partial per cube, and a second kernel, one cube per pose,
//!   sums the partials in order. No atomics: the same numbers on every run.
//!
//! One launch forward, two backward; the scene index of each row's Gaussian (4 bytes a row)
//! and each pose's first row travel from the host. f64 runs the host kernels.

use std::sync::Arc;

use burn::backend::TensorMetadata;
use burn::backend::tensor::FloatTensor;
use burn::tensor::DType;
use burn_backend::cubecl::dtype_to_storage_type;
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;

use super::{ColourKernels, HostSaved, host_backward, host_forward};
use crate::fused::host_pool;
use crate::fused::projection::ProjectionPlan;
use crate::fused::projection::cube::{CubeSaved, UNITS, empty, grid, tree_sum, upload_rows};
use crate::sh::{C0, C1, C2, C3};

/// The tensor path's floor of the view direction's squared length.
const SQUARED_LENGTH_FLOOR: f32 = 1e-24;

/// A Gaussian seen from a camera centre: the unit direction, the length it was divided by,
/// and 1 where that length is the true one (0 where floored: no gradient through it).
#[derive(CubeType)]
struct View<F: Float> {
    x: F,
    y: F,
    z: F,
    length: F,
    through_length: F,
}

#[cube]
fn view_of<F: Float>(
    poses: &Tensor<F>,
    components: &Tensor<F>,
    pose: usize,
    g: usize,
    n: usize,
) -> View<F> {
    let rx = components[g] - poses[pose * 6 + 3];
    let ry = components[n + g] - poses[pose * 6 + 4];
    let rz = components[2 * n + g] - poses[pose * 6 + 5];
    let squared = rx * rx + ry * ry + rz * rz;
    let floor = F::new(SQUARED_LENGTH_FLOOR);
    let mut length = F::sqrt(squared);
    let mut through_length = F::new(1.0);
    if squared < floor {
        length = F::sqrt(floor);
        through_length = F::new(0.0);
    }
    View::<F> {
        x: rx / length,
        y: ry / length,
        z: rz / length,
        length,
        through_length,
    }
}

/// The first `basis` SH basis functions at (x, y, z) into `b`, in the tensor path's order.
#[cube]
fn basis_at<F: Float>(x: F, y: F, z: F, b: &mut Array<F>, #[comptime] basis: usize) {
    b[0] = F::new(C0 as f32);
    if comptime!(basis > 1) {
        b[1] = y * F::new(-C1 as f32);
        b[2] = z * F::new(C1 as f32);
        b[3] = x * F::new(-C1 as f32);
    }
    if comptime!(basis > 4) {
        let xx = x * x;
        let yy = y * y;
        let zz = z * z;
        b[4] = x * y * F::new(C2[0] as f32);
        b[5] = y * z * F::new(C2[1] as f32);
        b[6] = (zz * F::new(2.0) - xx - yy) * F::new(C2[2] as f32);
        b[7] = x * z * F::new(C2[3] as f32);
        b[8] = (xx - yy) * F::new(C2[4] as f32);
        if comptime!(basis > 9) {
            b[9] = y * (xx * F::new(3.0) - yy) * F::new(C3[0] as f32);
            b[10] = x * y * z * F::new(C3[1] as f32);
            b[11] = y * (zz * F::new(4.0) - xx - yy) * F::new(C3[2] as f32);
            b[12] =
                z * (zz * F::new(2.0) - xx * F::new(3.0) - yy * F::new(3.0)) * F::new(C3[3] as f32);
            b[13] = x * (zz * F::new(4.0) - xx - yy) * F::new(C3[4] as f32);
            b[14] = z * (xx - yy) * F::new(C3[5] as f32);
            b[15] = x * (xx - yy * F::new(3.0)) * F::new(C3[6] as f32);
        }
    }
}

/// 0.5 + Σ_k b_k · coeff[g, k, channel], before the clamp at 0.
#[cube]
fn unclamped<F: Float>(
    coeffs: &Tensor<F>,
    b: &Array<F>,
    g: usize,
    channel: usize,
    #[comptime] basis: usize,
) -> F {
    let mut sum = F::new(0.0);
    #[unroll]
    for k in 0..basis {
        sum += b[k] * coeffs[(g * basis + k) * 3 + channel];
    }
    sum + F::new(0.5)
}

/// Σ_k w_k ∇b_k(x, y, z) into `v` (3 values): the host kernels' `basis_gradient`.
#[cube]
fn basis_gradient<F: Float>(
    x: F,
    y: F,
    z: F,
    w: &Array<F>,
    v: &mut Array<F>,
    #[comptime] basis: usize,
) {
    let mut vx = F::new(0.0);
    let mut vy = F::new(0.0);
    let mut vz = F::new(0.0);
    if comptime!(basis > 1) {
        vy += w[1] * F::new(-C1 as f32);
        vz += w[2] * F::new(C1 as f32);
        vx += w[3] * F::new(-C1 as f32);
    }
    if comptime!(basis > 4) {
        let xx = x * x;
        let yy = y * y;
        let zz = z * z;
        let w4 = w[4] * F::new(C2[0] as f32);
        vx += w4 * y;
        vy += w4 * x;
        let w5 = w[5] * F::new(C2[1] as f32);
        vy += w5 * z;
        vz += w5 * y;
        let w6 = w[6] * F::new(C2[2] as f32);
        vx += w6 * x * F::new(-2.0);
        vy += w6 * y * F::new(-2.0);
        vz += w6 * z * F::new(4.0);
        let w7 = w[7] * F::new(C2[3] as f32);
        vx += w7 * z;
        vz += w7 * x;
        let w8 = w[8] * F::new(C2[4] as f32);
        vx += w8 * x * F::new(2.0);
        vy += w8 * y * F::new(-2.0);
        if comptime!(basis > 9) {
            let w9 = w[9] * F::new(C3[0] as f32);
            vx += w9 * x * y * F::new(6.0);
            vy += w9 * (xx - yy) * F::new(3.0);
            let w10 = w[10] * F::new(C3[1] as f32);
            vx += w10 * y * z;
            vy += w10 * x * z;
            vz += w10 * x * y;
            let w11 = w[11] * F::new(C3[2] as f32);
            vx += w11 * x * y * F::new(-2.0);
            vy += w11 * (zz * F::new(4.0) - xx - yy * F::new(3.0));
            vz += w11 * y * z * F::new(8.0);
            let w12 = w[12] * F::new(C3[3] as f32);
            vx += w12 * x * z * F::new(-6.0);
            vy += w12 * y * z * F::new(-6.0);
            vz += w12 * (zz * F::new(6.0) - (xx + yy) * F::new(3.0));
            let w13 = w[13] * F::new(C3[4] as f32);
            vx += w13 * (zz * F::new(4.0) - xx * F::new(3.0) - yy);
            vy += w13 * x * y * F::new(-2.0);
            vz += w13 * x * z * F::new(8.0);
            let w14 = w[14] * F::new(C3[5] as f32);
            vx += w14 * x * z * F::new(2.0);
            vy += w14 * y * z * F::new(-2.0);
            vz += w14 * (xx - yy);
            let w15 = w[15] * F::new(C3[6] as f32);
            vx += w15 * (xx - yy) * F::new(3.0);
            vy += w15 * x * y * F::new(-6.0);
        }
    }
    v[0] = vx;
    v[1] = vy;
    v[2] = vz;
}

#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn forward_kernel<F: Float, I: Int>(
    poses: &Tensor<F>,       // [B, 6]
    components: &Tensor<F>,  // [9, N]
    coeffs: &Tensor<F>,      // [N, K, 3]
    gaussians: &Tensor<I>,   // [R]: scene index of each row's Gaussian
    starts: &Tensor<I>,      // [B + 1]: first row of each pose, then R
    colours: &mut Tensor<F>, // [R, 3]
    n: u32,
    chunks: u32,
    #[comptime] basis: usize,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let pose = CUBE_POS_Y as usize;
    let first = u32::cast_from(starts[pose]) as usize;
    let count = u32::cast_from(starts[pose + 1]) as usize - first;
    let mut b = Array::<F>::new(16usize);
    let mut chunk = CUBE_POS_X;
    while chunk < chunks {
        let k = chunk as usize * UNITS + UNIT_POS as usize;
        if k < count {
            let r = first + k;
            let g = u32::cast_from(gaussians[r]) as usize;
            let view = view_of::<F>(poses, components, pose, g, n as usize);
            basis_at::<F>(view.x, view.y, view.z, &mut b, basis);
            #[unroll]
            for channel in 0..3usize {
                let mut value = unclamped::<F>(coeffs, &b, g, channel, basis);
                if value < F::new(0.0) {
                    value = F::new(0.0);
                }
                colours[r * 3 + channel] = value;
            }
        }
        chunk += CUBE_COUNT_X;
    }
}

#[cube(launch)]
#[allow(clippy::too_many_arguments)]
fn backward_kernel<F: Float, I: Int>(
    poses: &Tensor<F>,       // [B, 6]
    components: &Tensor<F>,  // [9, N]
    coeffs: &Tensor<F>,      // [N, K, 3]
    gaussians: &Tensor<I>,   // [R]
    starts: &Tensor<I>,      // [B + 1]
    v_colours: &Tensor<F>,   // [R, 3]
    partial: &mut Tensor<F>, // [B, cubes per pose, 3]
    n: u32,
    chunks: u32,
    #[comptime] basis: usize,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let pose = CUBE_POS_Y as usize;
    let p = UNIT_POS as usize;
    let zero = F::new(0.0);
    let mut acc = Array::<F>::new(3usize);
    for e in 0..3usize {
        acc[e] = zero;
    }
    let mut b = Array::<F>::new(16usize);
    let mut w = Array::<F>::new(16usize);
    let mut v_d = Array::<F>::new(3usize);
    let first = u32::cast_from(starts[pose]) as usize;
    let count = u32::cast_from(starts[pose + 1]) as usize - first;
    let mut chunk = CUBE_POS_X;
    while chunk < chunks {
        let k = chunk as usize * UNITS + p;
        if k < count {
            let r = first + k;
            let g = u32::cast_from(gaussians[r]) as usize;
            let view = view_of::<F>(poses, components, pose, g, n as usize);
            basis_at::<F>(view.x, view.y, view.z, &mut b, basis);
            #[unroll]
            for i in 0..basis {
                w[i] = zero;
            }
            // w_k = Σ_c v_c · coeff[k, c] over the channels the clamp passes.
            #[unroll]
            for channel in 0..3usize {
                let v = v_colours[r * 3 + channel];
                if unclamped::<F>(coeffs, &b, g, channel, basis) >= zero {
                    #[unroll]
                    for i in 0..basis {
                        w[i] += v * coeffs[(g * basis + i) * 3 + channel];
                    }
                }
            }
            basis_gradient::<F>(view.x, view.y, view.z, &w, &mut v_d, basis);
            let along = (view.x * v_d[0] + view.y * v_d[1] + view.z * v_d[2]) * view.through_length;
            // raw = mean − centre: the centre takes minus the raw direction's gradient.
            acc[0] += zero - (v_d[0] - view.x * along) / view.length;
            acc[1] += zero - (v_d[1] - view.y * along) / view.length;
            acc[2] += zero - (v_d[2] - view.z * along) / view.length;
        }
        chunk += CUBE_COUNT_X;
    }
    let mut shared = Shared::<[F]>::new_slice(comptime!(3 * UNITS));
    for e in 0..3usize {
        shared[e * UNITS + p] = acc[e];
    }
    sync_cube();
    tree_sum::<F>(&mut shared, p, 3usize);
    if p < 3 {
        partial[(pose * CUBE_COUNT_X as usize + CUBE_POS_X as usize) * 3 + p] = shared[p * UNITS];
    }
}

#[cube(launch)]
fn reduce_kernel<F: Float>(
    partial: &Tensor<F>,     // [B, cubes, 3]
    v_poses: &mut Tensor<F>, // [B, 6]
    cubes: u32,
    #[define(F)] _dtype: ElemType,
) {
    let pose = CUBE_POS_X as usize;
    let p = UNIT_POS as usize;
    let mut shared = Shared::<[F]>::new_slice(comptime!(3 * UNITS));
    for e in 0..3usize {
        let mut sum = F::new(0.0);
        let mut i = p;
        while i < cubes as usize {
            sum += partial[(pose * cubes as usize + i) * 3 + e];
            i += UNITS;
        }
        shared[e * UNITS + p] = sum;
    }
    sync_cube();
    tree_sum::<F>(&mut shared, p, 3usize);
    if p < 3 {
        v_poses[pose * 6 + p] = F::new(0.0);
        v_poses[pose * 6 + 3 + p] = shared[p * UNITS];
    }
}

/// What the GPU forward pass keeps for its backward.
#[derive(Debug, Clone)]
pub struct DeviceSaved {
    poses: CubeTensor,
    components: CubeTensor,
    coeffs: CubeTensor,
    gaussians: CubeTensor,
    starts: CubeTensor,
    plan: Arc<ProjectionPlan>,
}

fn device_forward(
    poses: CubeTensor,
    components: CubeTensor,
    coeffs: CubeTensor,
    plan: Arc<ProjectionPlan>,
) -> (CubeTensor, DeviceSaved) {
    let [poses, components, coeffs] = [poses, components, coeffs].map(into_contiguous);
    let client = poses.client.clone();
    let dtype = poses.dtype;
    let batch = poses.shape().dims::<2>()[0];
    let n = components.shape().dims::<2>()[1];
    let basis = coeffs.shape().dims::<3>()[1];
    let largest = plan.rows.largest();
    let (gaussians, starts) = upload_rows(&plan, &poses.device);
    let colours = empty(vec![plan.rows.total(), 3], &poses.device, dtype);
    let (cubes, chunks, _) = grid(batch, largest);
    if batch > 0 && largest > 0 {
        forward_kernel::launch(
            &client,
            cubes,
            CubeDim::new_1d(UNITS as u32),
            poses.clone().into_tensor_arg(),
            components.clone().into_tensor_arg(),
            coeffs.clone().into_tensor_arg(),
            gaussians.clone().into_tensor_arg(),
            starts.clone().into_tensor_arg(),
            colours.clone().into_tensor_arg(),
            n as u32,
            chunks,
            basis,
            [
                dtype_to_storage_type(dtype),
                dtype_to_storage_type(gaussians.dtype),
            ],
        );
    }
    let saved = DeviceSaved {
        poses,
        components,
        coeffs,
        gaussians,
        starts,
        plan,
    };
    (colours, saved)
}

fn device_backward(saved: DeviceSaved, v_colours: CubeTensor) -> CubeTensor {
    let v_colours = into_contiguous(v_colours);
    let DeviceSaved {
        poses,
        components,
        coeffs,
        gaussians,
        starts,
        plan,
    } = saved;
    let client = poses.client.clone();
    let dtype = poses.dtype;
    let batch = poses.shape().dims::<2>()[0];
    let n = components.shape().dims::<2>()[1];
    let basis = coeffs.shape().dims::<3>()[1];
    let (cubes, chunks, per_pose) = grid(batch, plan.rows.largest());
    let partial = empty(vec![batch, per_pose, 3], &poses.device, dtype);
    let v_poses = empty(vec![batch, 6], &poses.device, dtype);
    if batch == 0 {
        return v_poses;
    }
    let int_dtype = dtype_to_storage_type(gaussians.dtype);
    // With no rows every cube still writes its (zero) partial.
    backward_kernel::launch(
        &client,
        cubes,
        CubeDim::new_1d(UNITS as u32),
        poses.into_tensor_arg(),
        components.into_tensor_arg(),
        coeffs.into_tensor_arg(),
        gaussians.into_tensor_arg(),
        starts.into_tensor_arg(),
        v_colours.into_tensor_arg(),
        partial.clone().into_tensor_arg(),
        n as u32,
        chunks,
        basis,
        [dtype_to_storage_type(dtype), int_dtype],
    );
    reduce_kernel::launch(
        &client,
        CubeCount::Static(batch as u32, 1, 1),
        CubeDim::new_1d(UNITS as u32),
        partial.into_tensor_arg(),
        v_poses.clone().into_tensor_arg(),
        per_pose as u32,
        dtype_to_storage_type(dtype),
    );
    v_poses
}

impl ColourKernels for CubeBackend {
    type Saved = CubeSaved<DeviceSaved, HostSaved<CubeBackend>>;

    fn colours_forward(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved) {
        if components.dtype() == DType::F64 {
            // The host kernels run on every core: on the pool that never waits on the device.
            let (colours, saved) =
                host_pool::run(|| host_forward::<Self>(poses, components, coeffs, plan));
            return (colours, CubeSaved::Host(Box::new(saved)));
        }
        let (colours, saved) = device_forward(poses, components, coeffs, plan);
        (colours, CubeSaved::Device(Box::new(saved)))
    }

    fn colours_backward(saved: Self::Saved, v_colours: FloatTensor<Self>) -> FloatTensor<Self> {
        match saved {
            CubeSaved::Host(saved) => host_pool::run(|| host_backward::<Self>(*saved, v_colours)),
            CubeSaved::Device(saved) => device_backward(*saved, v_colours),
        }
    }
}
