//! The occlusion check of the window metrics against geometry: a camera passing behind a
//! square occluder while it looks at an object hides the object for the share of the window
//! during which the line of sight crosses the occluder.

mod common;

use burn::tensor::{DType, Device};
use common::scene_of;
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::Scene;
use splatraj_traj::metrics::{Occlusion, WindowObject, window_metrics};

/// A small object at the origin (5 Gaussians within 0.03), and when `occluder` is set a
/// square of small opaque Gaussians in the plane x = 1 over |y|, |z| ≤ 0.3 (0.03 apart).
fn scene(occluder: bool) -> Scene {
    let mut means: Vec<[f32; 3]> = vec![
        [0.0, 0.0, 0.0],
        [0.0, 0.03, 0.0],
        [0.0, -0.03, 0.0],
        [0.0, 0.0, 0.03],
        [0.0, 0.0, -0.03],
    ];
    let mut scales = vec![[0.03f32; 3]; 5];
    if occluder {
        for j in -10..=10 {
            for k in -10..=10 {
                means.push([1.0, 0.03 * j as f32, 0.03 * k as f32]);
                scales.push([0.005, 0.02, 0.02]);
            }
        }
    }
    scene_of(means, scales)
}

fn occlusion(occluder: bool) -> Occlusion {
    let host = scene(occluder);
    let device = Device::flex();
    let on_device = DeviceScene::new(&host, &device, DType::F64);
    let mut mask = vec![0.0f32; host.len()];
    mask[..5].fill(1.0);
    let alone = DeviceScene::new(&scene(false), &device, DType::F64);
    let object = WindowObject {
        name: "object",
        mask: &mask,
        alone: &alone,
        target_ratio: 0.05,
        rasterizer: Rasterizer::default(),
        bounds: None,
    };
    // The camera slides from y = −1 to y = 1 at x = 2, looking at the object.
    let pose_at = |times: &[f64]| -> Vec<[f64; 6]> {
        times
            .iter()
            .map(|&t| {
                let eye = DVec3::new(2.0, -1.0 + 2.0 * t, 0.0);
                Pose::look_at(eye, DVec3::ZERO, DVec3::Z).unwrap().0
            })
            .collect()
    };
    let k = Intrinsics::from_fov_x(60.0, 64, 48).unwrap();
    let metrics = window_metrics(&on_device, &object, 0, 1, 16, &k, &pose_at).unwrap();
    println!("occluder {occluder}: {:?}", metrics.occlusion);
    metrics.occlusion
}

#[test]
fn a_camera_behind_an_occluder_counts_the_hidden_stretch() {
    // The line of sight from (2, y, 0) to the origin crosses x = 1 at y/2: inside the square
    // for |y| < 0.6. The 16 samples sit at y = −0.9375 + 0.125·k; ten of them have |y| < 0.6
    // (the nearest outside, 0.6875, sees the object's middle 0.04 beyond the square's edge).
    let hidden = occlusion(true);
    assert_eq!(hidden.hidden_fraction, 10.0 / 16.0);
    assert_eq!(hidden.longest_hidden, 10.0 / 16.0);
    assert!(hidden.mean_occluded > 0.55, "{hidden:?}");
    assert_eq!(
        hidden.with_window_seconds(8.0).longest_hidden_seconds,
        Some(5.0)
    );
    let clear = occlusion(false);
    assert_eq!((clear.hidden_fraction, clear.longest_hidden), (0.0, 0.0));
    assert!(clear.mean_occluded < 1e-9, "{clear:?}");
}

#[test]
fn the_longest_hidden_stretch_is_the_longest_run() {
    let h = Some(0.9);
    let seen = Some(0.1);
    let o = Occlusion::from_shares(&[h, h, seen, None, h, h, h, seen]);
    assert_eq!(o.longest_hidden, 3.0 / 8.0);
    assert_eq!(o.hidden_fraction, 5.0 / 8.0);
    // Out of frame (None) does not count toward the mean occluded share.
    assert!((o.mean_occluded - (0.9 * 5.0 + 0.1 * 2.0) / 7.0).abs() < 1e-12);
}
