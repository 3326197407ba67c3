//! What the path-rendering tests share: a dolly past the demo room's objects.

use glam::DVec3;
use splatraj_experiment::outputs::camera_paths::PathFrames;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_scene::demo::DEMO_VIEWPOINT;

/// `count` frames of camera `k` at times spread evenly over [0, 1] (no cuts): frame i's eye is
/// `eye_step`·i along x from the demo's viewpoint, and it looks at (`target_step`·i, 0.3, 0.8),
/// z up.
pub fn dolly_frames(
    k: Intrinsics,
    count: usize,
    (eye_step, target_step): (f64, f64),
    fps: f64,
) -> PathFrames {
    let eye = DVec3::from_array(DEMO_VIEWPOINT.map(f64::from));
    PathFrames {
        cuts: Vec::new(),
        times: (0..count).map(|i| i as f64 / (count - 1) as f64).collect(),
        poses: (0..count)
            .map(|i| {
                let target = DVec3::new(target_step * i as f64, 0.3, 0.8);
                Pose::look_at(eye + DVec3::X * eye_step * i as f64, target, DVec3::Z)
                    .unwrap()
                    .0
            })
            .collect(),
        cameras: vec![k; count],
        fps,
    }
}
