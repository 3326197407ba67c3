//! The GPU kernels give the same images, pose gradient and packed levels when their launch
//! grids are two-dimensional. Real captures need 2D grids (a step of a 6 M capture has more
//! than 65 535 × 256 rows to gather) and no lavapipe-sized input reaches them, so this test
//! lowers the per-axis cap (`fused::launch_grid::set_axis_cap`) until a small pass does.
//!
//! Its own test binary: the cap is the whole process's.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::{DType, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::fused::launch_grid::{MAX_PER_AXIS, set_axis_cap};
use splatraj_render::images::packed_rgb8;
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, render};
use splatraj_scene::Scene;

/// Gaussians in a 3 m cube at the origin, all in view of [`poses`]: 1 500 rows a pose, so six
/// chunks of 256 for the projection and 18 cubes for the gather over three poses.
const GAUSSIANS: usize = 1_500;

/// Below every count the pass launches (pixels / 256 = 36, work tiles ≥ 36, gather 18,
/// projection chunks 6 a pose) and dividing none of them, so every grid is 2D with spare cubes
/// in its last row, and the projection's cubes each take a second chunk.
const LOW_CAP: usize = 5;

fn scene() -> Scene {
    let mut rng = common::Rng(0x9a1d);
    let mut scene = Scene::default();
    for _ in 0..GAUSSIANS {
        scene
            .means
            .push(std::array::from_fn(|_| rng.range(-1.5, 1.5) as f32));
        scene
            .scales
            .push(std::array::from_fn(|_| rng.range(0.03, 0.2) as f32));
        scene
            .rotations
            .push(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
        scene.opacities.push(rng.range(0.05, 0.6) as f32);
        // Degree 1: the colours depend on the view, so the fused colours' kernels run too.
        scene.sh.extend(std::array::from_fn::<f32, 12, _>(|_| {
            rng.range(-0.6, 0.6) as f32
        }));
    }
    scene.sh_degree = 1;
    scene
}

fn poses() -> Vec<Pose> {
    let up = DVec3::new(0.0, -1.0, 0.0);
    [
        DVec3::new(0.3, -0.3, -4.0),
        DVec3::new(-3.5, -0.5, 1.0),
        DVec3::new(2.0, 1.0, 3.0),
    ]
    .map(|eye| Pose::look_at(eye, DVec3::ZERO, up).unwrap())
    .to_vec()
}

/// What one pass gives: its images `[B, H, W, 4]`, the pose gradient of a weighted sum of them
/// and the images' packed levels.
struct Pass {
    images: Vec<f64>,
    gradient: Vec<f64>,
    levels: Vec<i32>,
}

/// An RGB and mask pass with its pose gradient on wgpu (f32), under the cap in force.
fn pass() -> Pass {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let scene = scene();
    let mask: Vec<f32> = (0..GAUSSIANS).map(|i| f32::from(i % 4 == 0)).collect();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let poses = poses();
    let request = RenderRequest::new(
        Intrinsics::from_fov_x(70.0, 64, 48).unwrap(),
        vec![Channel::Rgb, Channel::Mask(mask)],
    );
    let tensor = common::pose_tensor(&poses, &device, DType::F32).require_grad();
    let out = render(&on_device, tensor.clone(), &request).unwrap();
    let dims = out.images.dims();
    // Weights of both signs, so the gradient does not hinge on one large sum.
    let mut rng = common::Rng(7);
    let weights: Vec<f32> = (0..dims.iter().product::<usize>())
        .map(|_| rng.range(-1.0, 1.0) as f32)
        .collect();
    let weights = Tensor::<4>::from_data(TensorData::new(weights, dims), (&device, DType::F32));
    let grads = (out.images.clone() * weights).sum().backward();
    let gradient = common::host(tensor.grad(&grads).expect("the poses have a gradient"));
    let levels = packed_rgb8(out.images.clone())
        .into_data()
        .convert::<i32>()
        .try_into_vec::<i32>()
        .unwrap();
    Pass {
        images: common::host(out.images),
        gradient,
        levels,
    }
}

/// Equal values, or how many differ and the first of them (the whole list would be pages).
fn assert_same<T: PartialEq + std::fmt::Debug>(name: &str, got: &[T], want: &[T]) {
    assert_eq!(got.len(), want.len(), "{name}: lengths");
    let apart: Vec<usize> = (0..got.len()).filter(|&i| got[i] != want[i]).collect();
    if let Some(&first) = apart.first() {
        panic!(
            "{name}: {} of {} values differ, the first at {first}: {:?} against {:?}",
            apart.len(),
            got.len(),
            got[first],
            want[first]
        );
    }
}

#[test]
fn two_dimensional_launch_grids_give_the_same_pass() {
    set_axis_cap(MAX_PER_AXIS);
    let linear = pass();
    let covered = linear.images.iter().filter(|v| **v > 0.05).count();
    assert!(
        covered > linear.images.len() / 2,
        "the scene covers the frames: {covered} of {} values",
        linear.images.len()
    );
    set_axis_cap(LOW_CAP);
    let folded = pass();
    set_axis_cap(MAX_PER_AXIS);
    // Per pixel and per row the kernels do the same sums in the same order whatever the grid.
    assert_same("images", &folded.images, &linear.images);
    assert_same("packed levels", &folded.levels, &linear.levels);
    // The pose gradient's partial sums are per cube, and the cubes take other chunks.
    common::assert_within("pose gradient", &folded.gradient, &linear.gradient, 1e-5);
}
