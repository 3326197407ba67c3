//! A shared optimisation step (`StepPasses::Shared`: every window in one render call) holds
//! every window's packed rows in one buffer (each pose its own Gaussians), the largest buffer
//! of a run. On a device too small for it (lavapipe's largest buffer is 128 MiB) the render
//! refuses the call by name, and the step renders a call per window instead, whose buffers
//! are a window's share: the same evaluation as `StepPasses::PerWindow`.
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
use splatraj_render::pass_size::max_buffer_bytes;
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_traj::costs::{CostsConfig, QueryContext};
use splatraj_traj::optimise::{Problem, StepPasses, WindowSamples, WindowTarget};

/// Gaussians a wall, walls (one a window), samples a window.
const WALL: usize = 150;
const WINDOWS: usize = 6;
const SAMPLES: usize = 64;

/// Where wall `w` stands: 10 units apart, so a camera facing one sees no other.
fn wall_centre(w: usize) -> DVec3 {
    DVec3::new(10.0 * w as f64 - 10.0, 0.0, 3.0)
}

/// WINDOWS walls of WALL² large opaque Gaussians, each a window's object: a camera 0.5 in front
/// of its wall sees only that wall, wall to wall, so every pixel is covered after a few
/// entries and the passes stay quick on lavapipe whatever their lists' lengths.
fn walls() -> (Scene, Vec<WindowTarget>) {
    common::walls(WINDOWS, WALL, wall_centre, |centre| QueryContext {
        object_centre: centre.to_array(),
        prior_radius: 0.5,
        world_up: [0.0, -1.0, 0.0],
        target_ratio: 0.5,
    })
}

/// Window `w`'s samples: 0.5 in front of its wall, shifted a little sample to sample.
fn samples(w: usize) -> Vec<Pose> {
    let centre = wall_centre(w);
    (0..SAMPLES)
        .map(|k| {
            let shift = DVec3::new(0.002 * k as f64, -0.001 * k as f64, 0.0);
            Pose::look_at(
                centre + shift - DVec3::new(0.0, 0.0, 0.5),
                centre + shift,
                DVec3::new(0.0, -1.0, 0.0),
            )
            .unwrap()
        })
        .collect()
}

#[test]
fn a_shared_step_too_large_for_the_device_renders_a_call_per_window() {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let rows_bytes = |rows: u64| rows * 7 * 4;
    let max = max_buffer_bytes(&device).expect("a wgpu device reports its largest buffer");
    // Each pose uses at most its own wall.
    if rows_bytes((WINDOWS * SAMPLES * WALL * WALL) as u64) <= max {
        return; // a device large enough for a shared step of these walls
    }

    let (scene, targets) = walls();
    let intrinsics = Intrinsics::from_fov_x(60.0, 16, 16).unwrap();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let costs = CostsConfig::default().build().unwrap();
    let problem = Problem::new(&on_device, &targets, &costs, intrinsics);
    let rows: Vec<Vec<Pose>> = (0..WINDOWS).map(samples).collect();
    let hosts = common::host_samples(&rows);
    let all: Vec<Pose> = rows.iter().flatten().copied().collect();

    let evaluate = |passes: StepPasses| {
        let poses = on_device.poses(&all).require_grad();
        let windows = (0..WINDOWS)
            .map(|w| WindowSamples {
                window: w,
                count: SAMPLES,
                times: None,
                path: None,
                host: Some(&hosts[w]),
                zoom: None,
            })
            .collect();
        let before = counters::snapshot();
        let step = problem
            .with_step_passes(passes)
            .evaluate_windows(poses.clone(), windows, 0, None)
            .expect("the step evaluates");
        let counted = counters::snapshot().since(&before);
        // The loss and every window's term means; not the gradient: lavapipe takes tens of
        // seconds for the projection's backward over these rows, and the step is the same
        // code as a step per window from the render on.
        let passes = step.passes;
        let loss = to_host(step.loss).unwrap();
        let means = to_host(step.means).unwrap();
        (counted, passes, loss, means)
    };
    let (per_window, _, loss, means) = evaluate(StepPasses::PerWindow);
    // The premise, from the rows the calls per window projected (the shared call's are the
    // same rows in one buffer): together too large for the device, a window's share not.
    assert!(
        rows_bytes(per_window.rows) > max && rows_bytes(per_window.rows) / (WINDOWS as u64) < max,
        "{} rows of {} bytes against a largest buffer of {max} bytes",
        per_window.rows,
        7 * 4
    );
    let (shared, shared_passes, shared_loss, shared_means) = evaluate(StepPasses::Shared);
    assert_eq!(
        shared_passes,
        StepPasses::PerWindow,
        "the step says it rendered a call per window, so a run's later steps keep to it"
    );
    assert_eq!(per_window.renders, WINDOWS as u64);
    assert_eq!(
        shared.renders,
        WINDOWS as u64 + 1,
        "the shared call is tried, refused, and each window rendered"
    );
    assert!(loss[0].is_finite() && means.iter().any(|m| *m != 0.0));
    assert_eq!(shared_loss, loss);
    assert_eq!(shared_means, means);
}
