//! The host decision pass against the tensor projection's own cull and radius: same visible
//! set and radii wherever a Gaussian's square reaches the tile grid (elsewhere the host pass
//! may skip it, which changes no tile list), and the same screen positions.

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::decide::{HostGeometry, decide};
use splatraj_render::project::{NEAR_PLANE, SceneTensors, project, radii_and_visibility};
use splatraj_render::tiles::TileGrid;
use splatraj_scene::Scene;

/// 3000 Gaussians of many sizes around the origin, some far off-screen, some behind the camera.
fn scene() -> Scene {
    let mut state = 0x1234_5678_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut scene = Scene::default();
    for i in 0..3000 {
        let spread = if i % 5 == 0 { 30.0 } else { 3.0 };
        scene
            .means
            .push([0, 1, 2].map(|_| ((next() - 0.5) * spread) as f32));
        let size = 0.005 * 200f64.powf(next());
        scene
            .scales
            .push([0, 1, 2].map(|_| (size * (0.2 + next())) as f32));
        scene
            .rotations
            .push([0, 1, 2, 3].map(|_| (next() - 0.5) as f32));
        scene.opacities.push(next() as f32);
    }
    scene
}

#[test]
fn host_decisions_match_the_tensor_projection() {
    let scene = scene();
    // Image sizes that are not multiples of 16: the last tile column/row is partial.
    let k = Intrinsics::from_fov_x(70.0, 100, 70).unwrap();
    let grid = TileGrid::new(k.width, k.height);
    let poses = [
        Pose::look_at(DVec3::new(0.0, -1.0, 6.0), DVec3::ZERO, DVec3::Y).unwrap(),
        Pose::look_at(
            DVec3::new(4.0, 0.5, -1.0),
            DVec3::new(0.0, 0.2, 0.0),
            DVec3::Y,
        )
        .unwrap(),
    ];
    let device = Device::flex();
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    let pose_tensor = Tensor::<2>::from_data(
        TensorData::new(flat, [poses.len(), 6]),
        (&device, DType::F64),
    );
    let tensors = SceneTensors::new(&scene, None, &device, DType::F64);
    let projected = project(&tensors, pose_tensor, &k);
    let (radii, visible) = radii_and_visibility(&projected, NEAR_PLANE);
    let means: Vec<f64> = projected
        .means_2d
        .into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .unwrap();

    let host = decide(&HostGeometry::new(&scene), &poses, &k, NEAR_PLANE, None);
    let (mut on_grid, mut skipped) = (0, 0);
    for i in 0..visible.len() {
        let (u, v, r) = (means[2 * i], means[2 * i + 1], radii[i] as f64);
        let (xs, ys) = grid.touched(u, v, r);
        let reaches_grid = visible[i] && !xs.is_empty() && !ys.is_empty();
        if reaches_grid {
            on_grid += 1;
            assert!(
                host.visible[i],
                "Gaussian {i}: visible on the grid, culled by the host"
            );
            assert_eq!(host.radii[i], radii[i], "Gaussian {i}: radius");
            let du = (host.means_2d[2 * i] as f64 - u).abs();
            let dv = (host.means_2d[2 * i + 1] as f64 - v).abs();
            assert!(
                du.max(dv) < 1e-3 * (1.0 + u.abs().max(v.abs())),
                "Gaussian {i}: position"
            );
        } else if !visible[i] {
            assert!(
                !host.visible[i],
                "Gaussian {i}: culled by the tensor path, not by the host"
            );
        } else {
            skipped += usize::from(!host.visible[i]);
        }
    }
    assert!(on_grid > 1000, "enough Gaussians on screen ({on_grid})");
    assert!(
        skipped > 100,
        "the host skips off-screen Gaussians ({skipped})"
    );
}
