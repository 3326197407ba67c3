//! What one mask pass with its pose gradient launches on the GPU (TCE and TRE of one pose,
//! `Problem::loss_at`, the pass `bench render` times): a few dozen kernels, not the 50–70 of a
//! pass whose costs' elementwise chains burn-fusion left unfused (docs/gpu.md, "Three moments,
//! three tensors"). A count, not a time: it is the same on every machine with the same burn.
//!
//! Runs on the wgpu backend (lavapipe in CI); its own test binary, as the render counters are
//! process-wide.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::DType;
use glam::DVec3;
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::counters;
use splatraj_render::render::DeviceScene;
use splatraj_traj::costs::{CostsConfig, QueryContext};
use splatraj_traj::optimise::Problem;

#[test]
fn a_mask_pass_with_its_gradient_launches_few_kernels() {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let centre = DVec3::new(0.0, 0.0, 3.0);
    let (scene, targets) = common::walls(
        1,
        12,
        |_| centre,
        |c| QueryContext {
            object_centre: c.to_array(),
            prior_radius: 0.8,
            world_up: [0.0, -1.0, 0.0],
            target_ratio: 0.3,
        },
    );
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let costs = CostsConfig {
        upright: None,
        prior: None,
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let intrinsics = Intrinsics::from_fov_x(60.0, 32, 32).unwrap();
    let problem = Problem::new(&on_device, &targets, &costs, intrinsics);
    let eye = centre + DVec3::new(0.1, 0.05, -0.9);
    let pose = Pose::look_at(eye, centre, DVec3::new(0.0, -1.0, 0.0)).unwrap();
    // Uncounted first: CubeCL compiles and tunes kernels on their first use.
    problem.loss_at(0, &pose, true).expect("the pass runs");
    let before = counters::snapshot();
    let loss = problem.loss_at(0, &pose, true).expect("the pass runs");
    let spent = counters::snapshot().since(&before);
    eprintln!("a mask pass with its gradient: {spent:?}");
    let gradient = loss.grad_pose.expect("a gradient");
    assert!(gradient.iter().all(|g| g.is_finite()) && gradient.iter().any(|&g| g != 0.0));
    assert_eq!(
        spent.reads, 1,
        "the terms, coverage and gradient in one read"
    );
    // 29 on lavapipe with burn 0.22.1: the projection and compositing forward and backward (7),
    // the moments (three reductions and two products), the costs' fused chains and the mask
    // slices' backward. 32 while the pass also made alpha, which nothing reads; unfused cost
    // chains make it 50 or more.
    assert!(
        spent.launches <= 34,
        "a mask pass launched {} kernels",
        spent.launches
    );
}
