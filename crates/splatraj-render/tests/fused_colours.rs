//! The fused colours (one burn op with a hand-written backward) against the tensor SH colours,
//! their readable specification: in f64 the RGB of each row and the pose gradient of any
//! weighted sum of them agree to 1e-10 for SH degrees 0 to 3, rows laid out per pose, channels
//! that the clamp at 0 stops and a camera on a Gaussian's mean; f32 stays within f32 rounding
//! of f64; the result does not depend on the thread count.

mod common;

use std::sync::Arc;

use burn::tensor::{DType, Device, Int, Tensor, TensorData};
use common::{Rng, host, pose_tensor, projection_poses, projection_scene};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::fused::colours::colours_of_rows;
use splatraj_render::fused::projection::{ProjectionCamera, ProjectionPlan};
use splatraj_render::project::{NEAR_PLANE, SceneTensors};
use splatraj_render::rows::PoseRows;
use splatraj_render::sh::{ShTensors, sh_colours_of_rows};
use splatraj_scene::Scene;

/// [`projection_scene`] with SH coefficients of `degree`, large enough that the clamp at 0
/// stops some channels, and Gaussian 0 on the first pose's camera centre.
fn sh_scene(seed: u64, degree: u8) -> Scene {
    let mut scene = projection_scene(seed);
    let mut rng = Rng(seed + 100);
    scene.sh_degree = degree;
    scene.sh = (0..scene.len() * scene.sh_coeffs() * 3)
        .map(|_| rng.range(-3.0, 3.0) as f32)
        .collect();
    let centre = projection_poses()[0].0;
    scene.means[0] = [centre[3] as f32, centre[4] as f32, centre[5] as f32];
    scene
}

/// Which colours a test runs.
#[derive(Clone, Copy)]
enum Colours {
    Fused,
    Tensor,
}

/// The rows each pose reads: a different subset each, out of order, with repeats.
fn plan(scene: &Scene, batch: usize) -> ProjectionPlan {
    let n = scene.len() as u32;
    let own: Vec<Vec<u32>> = (0..batch as u32)
        .map(|b| (0..n).filter(|g| (g + b) % 3 != 0).chain([0, 5]).collect())
        .collect();
    ProjectionPlan::new(
        own.concat(),
        PoseRows::from_counts(own.iter().map(Vec::len)),
        ProjectionCamera::new(&Intrinsics::from_fov_x(60.0, 160, 120).unwrap(), NEAR_PLANE),
    )
}

/// Colours `[R, 3]` and the pose gradient of Σ w·colours, in `dtype` on Flex.
fn colours(scene: &Scene, poses: &[Pose], dtype: DType, which: Colours) -> (Vec<f64>, Vec<f64>) {
    let device = Device::flex().autodiff();
    let geometry = SceneTensors::new(scene, None, &device, dtype);
    let sh = ShTensors::new(scene, None, &device, dtype);
    let poses = pose_tensor(poses, &device, dtype).require_grad();
    let plan = Arc::new(plan(scene, poses.dims()[0]));
    let rows = plan.rows.total();
    let rgb = match which {
        Colours::Fused => colours_of_rows(&geometry, &sh, poses.clone(), plan.clone()),
        Colours::Tensor => {
            let index = |values: Vec<i64>| {
                let len = values.len();
                Tensor::<1, Int>::from_data(TensorData::new(values, [len]), &device)
            };
            let gaussians = index(plan.gaussians.iter().map(|&g| g as i64).collect());
            let pose_of_row = index(
                (0..plan.rows.batch())
                    .flat_map(|b| std::iter::repeat_n(b as i64, plan.rows.count(b)))
                    .collect(),
            );
            let rows_sh = ShTensors {
                degree: sh.degree,
                coeffs: sh.coeffs.clone().select(0, gaussians.clone()),
            };
            let means = geometry.means.clone().select(0, gaussians);
            let centres = poses.clone().narrow(1, 3, 3).select(0, pose_of_row);
            sh_colours_of_rows(&rows_sh, means, centres)
        }
    };
    let mut rng = Rng(99);
    let weights: Vec<f64> = (0..rows * 3).map(|_| rng.range(-1.0, 1.0)).collect();
    let weights = Tensor::<2>::from_data(TensorData::new(weights, [rows, 3]), (&device, dtype));
    // At degree 0 the tensor path's colours are constants, off the graph: the zero term keeps
    // a gradient (of zeros) to compare.
    let zero = poses.clone().sum().mul_scalar(0.0);
    let grads = ((rgb.clone() * weights).sum() + zero).backward();
    let gradient = host(poses.grad(&grads).expect("the poses have a gradient"));
    (host(rgb.detach()), gradient)
}

/// Each value within `tolerance` relative to its own size: the camera on a mean makes its
/// pose's centre gradient ~1e12 (divided by the floored length), which would hide the others'.
fn assert_close(what: &str, fused: &[f64], tensor: &[f64], tolerance: f64) {
    assert_eq!(fused.len(), tensor.len(), "{what}: lengths");
    for (i, (f, t)) in fused.iter().zip(tensor).enumerate() {
        assert!(
            f.is_finite() && (f - t).abs() <= tolerance * (1.0 + t.abs()),
            "{what}[{i}]: fused {f} vs tensor {t}"
        );
    }
}

#[test]
fn colours_and_pose_gradients_match_the_tensor_path_in_f64_for_every_degree() {
    for degree in 0..=3u8 {
        let scene = sh_scene(7 + u64::from(degree), degree);
        let poses = projection_poses();
        let (rgb, grad) = colours(&scene, &poses, DType::F64, Colours::Fused);
        let (rgb_t, grad_t) = colours(&scene, &poses, DType::F64, Colours::Tensor);
        assert_close(&format!("degree {degree}: rgb"), &rgb, &rgb_t, 1e-12);
        assert_close(&format!("degree {degree}: gradient"), &grad, &grad_t, 1e-10);
        // The cases the rows had to cover did occur: channels stopped by the clamp, others
        // passed; view-dependent colours move with the centre, and nothing moves the rotation.
        let stopped = rgb_t.iter().filter(|&&v| v == 0.0).count();
        assert!(
            stopped > 0 && stopped < rgb_t.len(),
            "degree {degree}: {stopped} of {} channels at 0",
            rgb_t.len()
        );
        let floored = grad_t[3..6].iter().map(|g| g.abs()).fold(0.0, f64::max);
        assert!(
            degree == 0 || floored > 1e9,
            "degree {degree}: the camera on a mean divides by the floored length ({floored})"
        );
        for pose in grad.chunks_exact(6) {
            assert_eq!(
                &pose[..3],
                &[0.0; 3],
                "degree {degree}: a rotation moved a colour"
            );
        }
        let moved = grad.iter().map(|g| g.abs()).sum::<f64>();
        if degree == 0 {
            assert_eq!(moved, 0.0, "degree 0 does not depend on the view");
        } else {
            assert!(
                moved > 1e-3,
                "degree {degree}: the centre moves the colours ({moved})"
            );
        }
    }
}

#[test]
fn f32_stays_within_rounding_of_f64() {
    let scene = sh_scene(5, 3);
    let poses = &projection_poses()[1..];
    let (rgb32, grad32) = colours(&scene, poses, DType::F32, Colours::Fused);
    let (rgb64, grad64) = colours(&scene, poses, DType::F64, Colours::Fused);
    for (i, (a, b)) in rgb32.iter().zip(&rgb64).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
            "rgb {i}: f32 {a} vs f64 {b}"
        );
    }
    let norm = grad64.iter().map(|g| g * g).sum::<f64>().sqrt();
    for (a, b) in grad32.iter().zip(&grad64) {
        assert!((a - b).abs() <= 1e-4 * norm, "gradient: f32 {a} vs f64 {b}");
    }
}

#[test]
fn the_same_numbers_on_one_and_three_threads() {
    // 9 000 more Gaussians: several of the kernels' fixed chunks a pose.
    let mut scene = sh_scene(3, 3);
    let mut rng = Rng(4);
    let base = scene.clone();
    for _ in 0..9000 {
        let g = (rng.next() * base.len() as f64) as usize % base.len();
        scene
            .means
            .push(base.means[g].map(|m| m + rng.range(-0.5, 0.5) as f32));
        scene.scales.push(base.scales[g]);
        scene.rotations.push(base.rotations[g]);
        scene.opacities.push(base.opacities[g]);
        scene.sh.extend_from_slice(base.sh_of(g));
    }
    let poses = projection_poses();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| colours(&scene, &poses, DType::F32, Colours::Fused))
    };
    assert_eq!(run(1), run(3));
}
