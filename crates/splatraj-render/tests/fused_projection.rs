//! The fused projection (one burn op with a hand-written backward) against the tensor
//! projection, its readable specification: in f64 the packed rows (u, v, conic, opacity, z) and
//! the pose gradient of any weighted sum of them agree to 1e-10, on Gaussians in view, off
//! screen beyond the Jacobian's clamp, behind the camera and degenerate ones, for rotations on
//! both of Rodrigues' branches (ω = 0 included); f32 stays within f32 rounding of f64; the
//! result does not depend on the thread count.

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{Rng, host, pose_tensor, projection_poses, projection_scene, row_weights};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::fused::projection::{
    PackedColumn, ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS, project_packed,
};
use splatraj_render::project::{NEAR_PLANE, SceneTensors, project_with_near};
use splatraj_render::rows::PoseRows;
use splatraj_scene::Scene;

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 160, 120).unwrap()
}

/// The tensor projection's outputs packed like the fused op's rows. `[B, U, 7]`
fn tensor_packed(
    geometry: &SceneTensors,
    poses: Tensor<2>,
    intrinsics: &Intrinsics,
    used: &[u32],
) -> Tensor<3> {
    let device = poses.device();
    let index = Tensor::<1, burn::tensor::Int>::from_data(
        TensorData::new(
            used.iter().map(|&g| g as i64).collect::<Vec<_>>(),
            [used.len()],
        ),
        &device,
    );
    let selected = geometry.select(index);
    let [batch, _] = poses.dims();
    let projected = project_with_near(&selected, poses, intrinsics, NEAR_PLANE);
    let opacity = selected
        .opacities
        .clone()
        .reshape([1, used.len(), 1])
        .repeat_dim(0, batch);
    let depth = projected.depth.unsqueeze_dim::<3>(2);
    Tensor::cat(
        vec![projected.means_2d, projected.conics, opacity, depth],
        2,
    )
}

/// Which projection a test runs.
#[derive(Clone, Copy)]
enum Projection {
    Fused,
    Tensor,
}

/// Rows and pose gradient of one projection, in `dtype` on Flex.
fn project(
    scene: &Scene,
    poses: &[Pose],
    used: &[u32],
    dtype: DType,
    projection: Projection,
) -> (Vec<f64>, Vec<f64>) {
    let device = Device::flex().autodiff();
    let geometry = SceneTensors::new(scene, None, &device, dtype);
    let intrinsics = intrinsics();
    let poses = pose_tensor(poses, &device, dtype).require_grad();
    let (batch, count) = (poses.dims()[0], used.len());
    let rows = match projection {
        Projection::Fused => {
            let camera = ProjectionCamera::new(&intrinsics, NEAR_PLANE);
            let plan = ProjectionPlan::dense(used, batch, camera);
            project_packed(&geometry, poses.clone(), plan) // [B·U, 7]
        }
        Projection::Tensor => tensor_packed(&geometry, poses.clone(), &intrinsics, used)
            .reshape([batch * count, SPLAT_COLUMNS]),
    };
    // burn 0.22 reads a 0 in a reshape's target as "keep that dimension": an empty pass is
    // summed as it is.
    let loss = if count == 0 {
        rows.clone().sum()
    } else {
        let weights =
            row_weights(batch, count, &device, dtype).reshape([batch * count, SPLAT_COLUMNS]);
        (rows.clone() * weights).sum()
    };
    let grads = loss.backward();
    let gradient = host(poses.grad(&grads).expect("the poses have a gradient"));
    (host(rows.detach()), gradient)
}

/// [`project`] with both projections: `[fused, tensor]`.
fn both(scene: &Scene, poses: &[Pose], used: &[u32], dtype: DType) -> [(Vec<f64>, Vec<f64>); 2] {
    [Projection::Fused, Projection::Tensor].map(|p| project(scene, poses, used, dtype, p))
}

fn assert_close(what: &str, fused: &[f64], tensor: &[f64], tolerance: f64) {
    assert_eq!(fused.len(), tensor.len(), "{what}: lengths");
    let scale = tensor.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    for (i, (f, t)) in fused.iter().zip(tensor).enumerate() {
        assert!(
            f.is_finite() && (f - t).abs() <= tolerance * (1.0 + t.abs()).min(scale),
            "{what}[{i}] (row {}, column {}): fused {f} vs tensor {t}",
            i / SPLAT_COLUMNS,
            i % SPLAT_COLUMNS
        );
    }
}

#[test]
fn rows_and_pose_gradients_match_the_tensor_projection_in_f64() {
    let scene = projection_scene(7);
    let all: Vec<u32> = (0..scene.len() as u32).collect();
    let [(rows, grad), (rows_t, grad_t)] = both(&scene, &projection_poses(), &all, DType::F64);
    assert_close("rows", &rows, &rows_t, 1e-10);
    let norm = grad_t.iter().map(|g| g * g).sum::<f64>().sqrt();
    assert!(norm > 1.0, "a loss over 60 Gaussians moves with the pose");
    for (i, (f, t)) in grad.iter().zip(&grad_t).enumerate() {
        assert!(
            (f - t).abs() <= 1e-10 * norm,
            "d loss/dΦ[{}][{}]: fused {f} vs tensor {t} (norm {norm})",
            i / 6,
            i % 6
        );
    }
    // The cases the rows had to cover did occur: behind the near plane, beyond the clamp,
    // a floored determinant (the needle is the last Gaussian).
    let depth = PackedColumn::Depth as usize;
    let behind = rows_t
        .chunks_exact(SPLAT_COLUMNS)
        .filter(|r| r[depth] <= NEAR_PLANE)
        .count();
    assert!(behind > 0, "some Gaussian lies behind a camera");
    let (lim_x, _) = ProjectionCamera::new(&intrinsics(), NEAR_PLANE).limits();
    let beyond = rows_t.chunks_exact(SPLAT_COLUMNS).any(|r| {
        let fx = intrinsics().fx;
        let x_over_z = (r[0] - intrinsics().cx) / fx;
        r[depth] > NEAR_PLANE && x_over_z.abs() > lim_x
    });
    assert!(beyond, "some Gaussian lies beyond the Jacobian's clamp");
}

#[test]
fn a_subset_in_any_order_projects_the_rows_it_names() {
    let scene = projection_scene(11);
    // Out of order, with a repeat: the rows follow `used`, not the scene.
    let used = [41u32, 3, 17, 59, 3, 0];
    let [(rows, grad), (rows_t, grad_t)] =
        both(&scene, &projection_poses()[..2], &used, DType::F64);
    assert_close("rows", &rows, &rows_t, 1e-10);
    assert_close("gradient", &grad, &grad_t, 1e-9);
    let (empty, grad_empty) = project(
        &scene,
        &projection_poses()[..2],
        &[],
        DType::F64,
        Projection::Fused,
    );
    assert!(empty.is_empty());
    assert_eq!(
        grad_empty,
        vec![0.0; 12],
        "nothing projected, nothing moves"
    );
}

#[test]
fn f32_stays_within_rounding_of_f64() {
    let scene = projection_scene(5);
    // In view only: behind the camera or beyond the clamp, f32 and f64 garbage may differ more.
    let used: Vec<u32> = (0..45).collect();
    let (rows32, grad32) = project(
        &scene,
        &projection_poses()[..1],
        &used,
        DType::F32,
        Projection::Fused,
    );
    let (rows64, grad64) = project(
        &scene,
        &projection_poses()[..1],
        &used,
        DType::F64,
        Projection::Fused,
    );
    for (i, (a, b)) in rows32.iter().zip(&rows64).enumerate() {
        assert!(
            (a - b).abs() <= 2e-4 * (1.0 + b.abs()),
            "row value {i}: f32 {a} vs f64 {b}"
        );
    }
    let norm = grad64.iter().map(|g| g * g).sum::<f64>().sqrt();
    for (a, b) in grad32.iter().zip(&grad64) {
        assert!((a - b).abs() <= 1e-3 * norm, "gradient: f32 {a} vs f64 {b}");
    }
}

#[test]
fn the_same_numbers_on_one_and_three_threads() {
    // 5000 Gaussians: several of the kernels' fixed chunks per pose.
    let mut rng = Rng(3);
    let mut big = Scene::default();
    for _ in 0..5000 {
        big.means
            .push(std::array::from_fn(|_| rng.range(-2.0, 2.0) as f32));
        big.scales
            .push(std::array::from_fn(|_| rng.range(0.01, 0.1) as f32));
        big.rotations
            .push(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
        big.opacities.push(rng.range(0.1, 1.0) as f32);
    }
    let used: Vec<u32> = (0..5000).collect();
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                project(
                    &big,
                    &projection_poses()[..2],
                    &used,
                    DType::F32,
                    Projection::Fused,
                )
            })
    };
    let (one, three) = (on(1), on(3));
    assert_eq!(one.0, three.0, "rows");
    assert_eq!(one.1, three.1, "pose gradient");
}

/// Rows laid out per pose (each pose only its own Gaussians, one pose none, as a render lays
/// out a pass of several windows) are the tensor projection's rows of those (pose, Gaussian)
/// pairs, and the pose gradient of a weighted sum of them is the tensor path's gradient of the
/// same sum (weights on those pairs, zero elsewhere).
#[test]
fn rows_laid_out_per_pose_are_the_tensor_rows_they_name() {
    let scene = projection_scene(11);
    let poses = &projection_poses()[..3];
    let own: [&[u32]; 3] = [&[3, 17, 41], &[], &[0, 3, 17, 59]];
    let pairs: Vec<(usize, u32)> = (0..3)
        .flat_map(|b| own[b].iter().map(move |&g| (b, g)))
        .collect();
    let mut rng = Rng(7);
    let weights: Vec<f64> = (0..pairs.len() * SPLAT_COLUMNS)
        .map(|_| rng.range(-1.0, 1.0))
        .collect();
    let device = Device::flex().autodiff();
    let dtype = DType::F64;
    let geometry = SceneTensors::new(&scene, None, &device, dtype);
    let intrinsics = intrinsics();

    let pose_rows = pose_tensor(poses, &device, dtype).require_grad();
    let plan = ProjectionPlan::new(
        own.concat(),
        PoseRows::from_counts(own.map(<[u32]>::len)),
        ProjectionCamera::new(&intrinsics, NEAR_PLANE),
    );
    let rows = project_packed(&geometry, pose_rows.clone(), plan); // [R, 7]
    let w = Tensor::<2>::from_data(
        TensorData::new(weights.clone(), [pairs.len(), SPLAT_COLUMNS]),
        (&device, dtype),
    );
    let grads = (rows.clone() * w).sum().backward();
    let gradient = host(pose_rows.grad(&grads).unwrap());
    let rows = host(rows.detach());

    // The tensor path: every Gaussian from every pose, the weights placed on the named pairs.
    let n = scene.len();
    let all: Vec<u32> = (0..n as u32).collect();
    let pose_dense = pose_tensor(poses, &device, dtype).require_grad();
    let dense = tensor_packed(&geometry, pose_dense.clone(), &intrinsics, &all); // [B, N, 7]
    let mut placed = vec![0.0; 3 * n * SPLAT_COLUMNS];
    let mut expected = Vec::new();
    let dense_host = host(dense.clone().detach());
    for (i, &(b, g)) in pairs.iter().enumerate() {
        let at = (b * n + g as usize) * SPLAT_COLUMNS;
        placed[at..at + SPLAT_COLUMNS]
            .copy_from_slice(&weights[i * SPLAT_COLUMNS..(i + 1) * SPLAT_COLUMNS]);
        expected.extend_from_slice(&dense_host[at..at + SPLAT_COLUMNS]);
    }
    let w = Tensor::<3>::from_data(
        TensorData::new(placed, [3, n, SPLAT_COLUMNS]),
        (&device, dtype),
    );
    let grads = (dense * w).sum().backward();
    let expected_gradient = host(pose_dense.grad(&grads).unwrap());
    assert_close("rows", &rows, &expected, 1e-10);
    assert_close("gradient", &gradient, &expected_gradient, 1e-9);
    assert!(
        gradient[6..12].iter().all(|&v| v == 0.0),
        "the pose without rows has no gradient: {:?}",
        &gradient[6..12]
    );
}
