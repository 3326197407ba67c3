//! What a shared optimisation step launches on the GPU with the first-try costs (TCE, TRE,
//! visibility from the images; upright, prior, clearance and motion, the costs of the poses
//! alone, computed on the host and joined by their first-order expansion): the same kernels
//! whatever the number of windows (one render call, the costs run once on the whole batch and
//! on every window's stretch of path joined), one read for the gradient, and only a handful
//! for each cost of the poses alone (docs/gpu.md, "Costs on the host": as tensor ops the motion
//! cost alone launched 139 kernels a step).
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
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_traj::clearance::{Occupancy, OccupancySpec};
use splatraj_traj::costs::{
    ClearanceCost, CostsConfig, HostPoses, MotionCost, QueryContext, UprightCost, UprightMode,
    VisibilityCost,
};
use splatraj_traj::optimise::{
    Problem, StepPasses, WindowPath, WindowSamples, WindowTarget, backward,
};

/// Gaussians along a wall's side, samples and path poses a window.
const SIDE: usize = 12;
const SAMPLES: usize = 3;
const PATH: usize = 6;

/// Where wall `w` stands: 10 units apart.
fn wall_centre(w: usize) -> DVec3 {
    DVec3::new(10.0 * w as f64, 0.0, 3.0)
}

/// `windows` walls of opaque Gaussians, each a window's object.
fn walls(windows: usize) -> (Scene, Vec<WindowTarget>) {
    common::walls(windows, SIDE, wall_centre, |centre| QueryContext {
        object_centre: centre.to_array(),
        prior_radius: 0.8,
        world_up: [0.0, -1.0, 0.0],
        target_ratio: 0.3,
    })
}

/// `count` poses of window `w`, in front of its wall, sweeping sideways and turning.
fn poses(w: usize, count: usize) -> Vec<Pose> {
    let centre = wall_centre(w);
    (0..count)
        .map(|k| {
            let shift = DVec3::new(0.08 * k as f64, 0.02 * k as f64, 0.0);
            Pose::look_at(
                centre + shift - DVec3::new(0.0, 0.0, 0.9),
                centre,
                DVec3::new(0.0, -1.0, 0.0),
            )
            .unwrap()
        })
        .collect()
}

/// The costs of the first try with numbers for what a run derives from the scene, the costs of
/// the poses alone left out when `pose_costs` is off.
fn costs(pose_costs: bool) -> CostsConfig {
    let mut costs = CostsConfig {
        upright: None,
        prior: None,
        visibility: Some(VisibilityCost::default()),
        ..CostsConfig::default()
    };
    if pose_costs {
        costs.upright = Some(UprightCost {
            mode: UprightMode::Roll,
            ..UprightCost::default()
        });
        costs.prior = CostsConfig::default().prior;
        costs.clearance = Some(ClearanceCost::with_margin(0.3));
        costs.motion = Some(MotionCost {
            max_speed: Some(0.5.into()),
            max_angular_speed: Some(36.0),
            max_orbit_speed: Some(36.0),
            ..MotionCost::default()
        });
    }
    costs
}

/// (launches, reads) of one shared step of `windows` windows: the evaluation, its backward and
/// the read of the gradient; and the step's loss.
fn step(windows: usize, pose_costs: bool) -> (u64, u64, f64) {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let (scene, targets) = walls(windows);
    let intrinsics = Intrinsics::from_fov_x(60.0, 16, 16).unwrap();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let occupancy = Occupancy::new(
        &scene,
        OccupancySpec {
            sigma: 2.0,
            min_opacity: 0.2,
        },
    );
    let built = costs(pose_costs).build().unwrap();
    let problem = Problem::new(&on_device, &targets, &built, intrinsics)
        .with_occupancy(Some(&occupancy))
        .with_seconds(Some(6.0))
        .with_step_passes(StepPasses::Shared);
    // The step's rows as the optimiser lays them out: every window's samples, then every
    // window's path. The host values are the f32 values the device holds.
    let samples: Vec<Vec<Pose>> = (0..windows).map(|w| poses(w, SAMPLES)).collect();
    let paths: Vec<Vec<Pose>> = (0..windows).map(|w| poses(w, PATH)).collect();
    let rows: Vec<Pose> = samples.iter().chain(&paths).flatten().copied().collect();
    let held = |p: &[Pose]| -> Vec<[f64; 6]> {
        p.iter().map(|p| p.0.map(|v| f64::from(v as f32))).collect()
    };
    let hosts: Vec<HostPoses> = (0..windows)
        .map(|w| HostPoses {
            samples: held(&samples[w]),
            path: Some(held(&paths[w])),
        })
        .collect();
    let tensor = on_device.poses(&rows).require_grad();
    // Untimed and uncounted first: CubeCL compiles and tunes kernels on their first use.
    for counted in [false, true] {
        let before = counters::snapshot();
        let windows_samples = (0..windows)
            .map(|w| WindowSamples {
                window: w,
                count: SAMPLES,
                times: None,
                // As the optimiser gives it: rows after the samples.
                path: Some(WindowPath::Rows(PATH, 1.0 / (windows * PATH) as f64)),
                host: Some(&hosts[w]),
                zoom: None,
            })
            .collect();
        let evaluated = problem
            .evaluate_windows(tensor.clone(), windows_samples, 0, None)
            .expect("the step evaluates");
        let grads = backward(&evaluated.loss).expect("the step's backward");
        let gradient = tensor.grad(&grads).unwrap();
        let loss = to_host(evaluated.loss.without_autodiff()).unwrap()[0];
        let values = to_host(gradient).unwrap();
        assert!(values.iter().all(|v| v.is_finite()));
        let spent = counters::snapshot().since(&before);
        if counted {
            return (spent.launches, spent.reads, loss);
        }
    }
    unreachable!("the second, counted step returns")
}

#[test]
fn a_first_try_step_launches_the_same_whatever_the_windows_and_pose_costs_add_a_handful() {
    let (two, reads, loss_two) = step(2, true);
    let (six, _, loss_six) = step(6, true);
    let (images_only, _, _) = step(2, false);
    eprintln!(
        "launches: 2 windows {two}, 6 windows {six}, 2 windows without the pose costs \
         {images_only}"
    );
    assert!(loss_two > 0.0 && loss_six > 0.0);
    // The loss and the gradient, read one after the other here.
    assert_eq!(reads, 2, "the step itself reads nothing");
    // One render call and one evaluation of each cost whatever the windows: anything done per
    // window would add at least four launches here. Fusion merges chains of elementwise ops
    // by their shapes, so the counts may differ by a few.
    assert!(
        six.abs_diff(two) <= 3,
        "2 windows launch {two} kernels, 6 windows {six}"
    );
    // Each cost of the poses alone: the expansion's difference, product and sum forward and
    // its product backward, and its term's share of the loss and the window means; burn's
    // fusion search splits the chains differently as the rest of the step changes (lavapipe,
    // burn 0.22.1: 82 against 50 without them, 81 against 47 once the images dropped alpha).
    let pose_costs = 4;
    assert!(
        two <= images_only + 10 * pose_costs,
        "the costs of the poses alone added {} launches to {images_only}",
        two.saturating_sub(images_only)
    );
}
