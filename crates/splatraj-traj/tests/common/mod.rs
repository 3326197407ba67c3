//! Helpers shared by the trajectory crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use splatraj_scene::Scene;
use splatraj_traj::metrics::{Framing, MotionMetrics, Occlusion, PathMetrics, WindowMetrics};

/// Opaque (0.99), axis-aligned, black Gaussians at `means` with `scales`.
pub fn scene_of(means: Vec<[f32; 3]>, scales: Vec<[f32; 3]>) -> Scene {
    let n = means.len();
    Scene {
        means,
        scales,
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![0.99; n],
        sh_degree: 0,
        sh: vec![0.0; n * 3],
        extras: Default::default(),
    }
}

/// The demo room of `gaussians` Gaussians (seed 7).
pub fn demo_room(gaussians: usize) -> Scene {
    splatraj_scene::demo::demo_scene(&splatraj_scene::demo::DemoConfig { seed: 7, gaussians })
        .unwrap()
}

/// The demo object called `name`.
pub fn demo_object(name: &str) -> splatraj_scene::demo::DemoObject {
    splatraj_scene::demo::demo_layout()
        .into_iter()
        .find(|o| o.name == name)
        .unwrap()
}

/// 1 for the Gaussians of `object` in the demo `scene`, 0 elsewhere.
pub fn demo_mask(scene: &Scene, object: &splatraj_scene::demo::DemoObject) -> Vec<f32> {
    let labels = scene.extras.labels.as_ref().unwrap();
    labels
        .ids
        .iter()
        .map(|&id| f32::from(u8::from(id == object.id)))
        .collect()
}

/// The query window of demo object `name` seen through `intrinsics`: its mask, centre, the
/// default prior radius at 15 % of the frame, the demo's up and `target_ratio`.
pub fn demo_window(
    scene: &Scene,
    name: &str,
    intrinsics: &splatraj_render::camera::Intrinsics,
    target_ratio: f64,
) -> splatraj_traj::optimise::WindowTarget {
    let (tx, ty) = intrinsics.tan_half_fov();
    let o = demo_object(name);
    splatraj_traj::optimise::WindowTarget {
        name: name.to_string(),
        mask: demo_mask(scene, &o),
        context: splatraj_traj::costs::QueryContext {
            object_centre: o.center.map(f64::from),
            prior_radius: splatraj_traj::costs::default_prior_radius(
                o.size.map(f64::from),
                2.0 * tx.atan(),
                2.0 * ty.atan(),
                0.15,
            )
            .unwrap(),
            world_up: splatraj_scene::demo::DEMO_UP.map(f64::from),
            target_ratio,
        },
    }
}

/// A window that passes every check but the ones the test sets: in view throughout, centred,
/// at the size asked for, unhidden, with the given framed share and rates.
pub fn passing_window(framed_share: f64, turning: f64, orbit: f64) -> WindowMetrics {
    WindowMetrics {
        window: 1,
        name: "jaw".into(),
        samples: 30,
        tce: Some(0.05),
        tre: 0.01,
        iou: 1.0,
        coverage: 0.15,
        target_ratio: 0.15,
        visible_fraction: 1.0,
        visible: true,
        tce_max: Some(0.1),
        tre_max: 0.02,
        occlusion: Occlusion::from_shares(&[Some(0.0); 30]),
        path: Some(PathMetrics {
            samples: 100,
            clearance: None,
            motion: MotionMetrics {
                seconds: Some(9.0),
                peak_speed: 0.1,
                peak_acceleration: 0.1,
                peak_angular_speed: turning,
                peak_orbit_speed: Some(orbit),
                speed_spread: 0.0,
            },
        }),
        shot: None,
        framing: Framing {
            tce_middle: Some(0.05),
            coverage_middle: Some(0.15),
            tce_in_view: Some(0.05),
            framed_share: Some(framed_share),
            inside_object: 0.0,
            wobble: None,
        },
        verdict: None,
        lens: None,
    }
}

/// Each window's samples as the host holds them (no path).
pub fn host_samples(
    windows: &[Vec<splatraj_render::camera::Pose>],
) -> Vec<splatraj_traj::costs::HostPoses> {
    windows
        .iter()
        .map(|w| splatraj_traj::costs::HostPoses {
            samples: w.iter().map(|p| p.0).collect(),
            path: None,
        })
        .collect()
}

/// Poses `[P, 6]` as an f64 tensor on `device`.
pub fn poses_tensor(poses: &[[f64; 6]], device: &burn::tensor::Device) -> burn::tensor::Tensor<2> {
    let flat: Vec<f64> = poses.iter().flatten().copied().collect();
    burn::tensor::Tensor::from_data(
        burn::tensor::TensorData::new(flat, [poses.len(), 6]),
        (device, burn::tensor::DType::F64),
    )
}

/// A tensor's values on the host, as f64.
pub fn host<const D: usize>(t: burn::tensor::Tensor<D>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()
}

/// `windows` square walls of `side`² opaque Gaussians, 0.7 units across, each a window's
/// object: wall w at `centre(w)` in the plane z = its centre's, facing −z, its window's
/// context `context(centre)`. A camera close in front of one sees no other.
pub fn walls(
    windows: usize,
    side: usize,
    centre: impl Fn(usize) -> glam::DVec3,
    context: impl Fn(glam::DVec3) -> splatraj_traj::costs::QueryContext,
) -> (Scene, Vec<splatraj_traj::optimise::WindowTarget>) {
    let mut scene = Scene::default();
    let mut targets = Vec::new();
    for w in 0..windows {
        let centre = centre(w);
        let first = scene.len();
        let step = 0.7 / side as f64;
        for i in 0..side * side {
            let (gx, gy) = ((i % side) as f64, (i / side) as f64);
            scene.means.push([
                (centre.x + (gx - side as f64 / 2.0) * step) as f32,
                (centre.y + (gy - side as f64 / 2.0) * step) as f32,
                centre.z as f32,
            ]);
            scene.scales.push([0.02, 0.02, 0.005]);
            scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
            scene.opacities.push(0.95);
            scene.sh.extend([0.5, 0.4, 0.3]);
        }
        let mut mask = vec![0.0; windows * side * side];
        mask[first..first + side * side].fill(1.0);
        targets.push(splatraj_traj::optimise::WindowTarget {
            name: format!("wall {w}"),
            mask,
            context: context(centre),
        });
    }
    (scene, targets)
}
