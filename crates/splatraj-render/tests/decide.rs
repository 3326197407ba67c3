//! The host decision pass against the tensor projection's own cull and radius: same visible
//! set and radii wherever a Gaussian's square reaches the tile grid (elsewhere the host pass
//! may skip it, which changes no tile list), and the same screen positions.

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::decide::{HostGeometry, decide};
use splatraj_render::focus::ObjectFocus;
use splatraj_render::project::{NEAR_PLANE, SceneTensors, project, radii_and_visibility};
use splatraj_render::tiles::TileGrid;
use splatraj_scene::Scene;

/// `count` Gaussians from a seeded uniform stream: `place(i, next)` gives the i-th centre and
/// size; rotations and opacities are random.
fn random_scene(
    seed: u64,
    count: usize,
    place: impl Fn(usize, &mut dyn FnMut() -> f64) -> ([f64; 3], f64),
) -> Scene {
    let mut state = seed;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut scene = Scene::default();
    for i in 0..count {
        let (mean, size) = place(i, &mut next);
        scene.means.push(mean.map(|v| v as f32));
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

/// 3000 Gaussians of many sizes around the origin, some far off-screen, some behind the camera.
fn scene() -> Scene {
    random_scene(0x1234_5678, 3000, |i, next| {
        let spread = if i % 5 == 0 { 30.0 } else { 3.0 };
        let mean = [0, 1, 2].map(|_| (next() - 0.5) * spread);
        (mean, 0.005 * 200f64.powf(next()))
    })
}

/// The tensor projection of `scene` for `poses` in f64: radii, visibility, depths, means 2D
/// (flat, as the host decisions are).
fn tensor_projection(
    scene: &Scene,
    poses: &[Pose],
    k: &Intrinsics,
) -> (Vec<f32>, Vec<bool>, Vec<f64>, Vec<f64>) {
    let device = Device::flex();
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    let pose_tensor = Tensor::<2>::from_data(
        TensorData::new(flat, [poses.len(), 6]),
        (&device, DType::F64),
    );
    let tensors = SceneTensors::new(scene, None, &device, DType::F64);
    let projected = project(&tensors, pose_tensor, k);
    let (radii, visible) = radii_and_visibility(&projected, NEAR_PLANE);
    let values = |t: Tensor<2>| t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap();
    let depth = values(projected.depth);
    let [batch, n, _] = projected.means_2d.dims();
    let means = values(projected.means_2d.reshape([batch, 2 * n]));
    (radii, visible, depth, means)
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
    let (radii, visible, _, means) = tensor_projection(&scene, &poses, &k);

    let decisions = decide(&HostGeometry::new(&scene), &poses, &k, NEAR_PLANE, None);
    let n = scene.len();
    let host: Vec<_> = (0..poses.len())
        .flat_map(|b| decisions.dense(b, n))
        .collect();
    let (mut on_grid, mut skipped) = (0, 0);
    for i in 0..visible.len() {
        let (u, v, r) = (means[2 * i], means[2 * i + 1], radii[i] as f64);
        let (xs, ys) = grid.touched(u, v, r);
        let reaches_grid = visible[i] && !xs.is_empty() && !ys.is_empty();
        if reaches_grid {
            on_grid += 1;
            let Some(kept) = host[i] else {
                panic!("Gaussian {i}: visible on the grid, culled by the host");
            };
            assert_eq!(kept.radius, radii[i], "Gaussian {i}: radius");
            let du = (kept.means_2d[0] as f64 - u).abs();
            let dv = (kept.means_2d[1] as f64 - v).abs();
            assert!(
                du.max(dv) < 1e-3 * (1.0 + u.abs().max(v.abs())),
                "Gaussian {i}: position"
            );
        } else if !visible[i] {
            assert!(
                host[i].is_none(),
                "Gaussian {i}: culled by the tensor path, not by the host"
            );
        } else {
            skipped += usize::from(host[i].is_none());
        }
    }
    assert!(on_grid > 1000, "enough Gaussians on screen ({on_grid})");
    assert!(
        skipped > 100,
        "the host skips off-screen Gaussians ({skipped})"
    );
}

/// 144 clusters of 256 Gaussians (about one block each) 0.8 apart on a floor, so whole
/// neighbourhoods fall outside a view or a mask pass's tiles; a tenth are large enough to reach
/// the next cluster.
fn clustered_scene() -> Scene {
    random_scene(0x9e37_79b9, 144 * 256, |i, next| {
        let cluster = i / 256;
        let centre = [
            0.8 * ((cluster % 12) as f64 - 5.5),
            0.8 * ((cluster / 12) as f64 - 5.5),
            0.0,
        ];
        let mean = centre.map(|c| c + 0.3 * (next() - 0.5));
        let size = if i % 10 == 0 { 0.25 } else { 0.01 } * (0.5 + next());
        (mean, size)
    })
}

#[test]
fn focused_decisions_keep_every_gaussian_in_front_of_the_object_on_its_tiles() {
    let scene = clustered_scene();
    // The "object": Gaussians near (0.4, 0.4, 0); the camera sees much more than its tiles.
    let focus: Vec<bool> = scene
        .means
        .iter()
        .map(|m| DVec3::from(m.map(f64::from)).distance(DVec3::new(0.4, 0.4, 0.0)) < 0.25)
        .collect();
    let k = Intrinsics::from_fov_x(70.0, 200, 140).unwrap();
    let grid = TileGrid::new(k.width, k.height);
    let object = DVec3::new(0.4, 0.4, 0.0);
    let poses = [
        // From above, and grazing along the floor through its clusters (near-plane cases).
        Pose::look_at(DVec3::new(0.4, -0.6, 4.0), object, DVec3::Y).unwrap(),
        Pose::look_at(DVec3::new(-2.0, -1.5, 0.3), object, DVec3::Z).unwrap(),
    ];
    let (radii, visible, depth, means) = tensor_projection(&scene, &poses, &k);
    let geometry = HostGeometry::new(&scene);
    let decisions = decide(
        &geometry,
        &poses,
        &k,
        NEAR_PLANE,
        Some(&ObjectFocus::from_flags(
            &geometry.scene_from_sorted,
            &focus,
        )),
    );

    let n = scene.len();
    let host: Vec<_> = (0..poses.len())
        .flat_map(|b| decisions.dense(b, n))
        .collect();
    let tiles = |i: usize| grid.touched(means[2 * i], means[2 * i + 1], radii[i] as f64);
    let (mut needed, mut skipped, mut behind) = (0, 0, 0);
    for b in 0..poses.len() {
        // The object's tile box in this pose, from the tensor projection.
        // [x0, x1) × [y0, y1) in tiles, grown from empty.
        let (mut xs, mut ys) = ((usize::MAX, 0), (usize::MAX, 0));
        // Binning cuts each list after the object's last Gaussian: nothing deeper than its
        // deepest one is ever composited.
        let mut deepest = f64::NEG_INFINITY;
        for g in (0..n).filter(|&g| focus[g] && visible[b * n + g]) {
            let (gx, gy) = tiles(b * n + g);
            if gx.is_empty() || gy.is_empty() {
                continue;
            }
            deepest = deepest.max(depth[b * n + g]);
            xs = (xs.0.min(gx.start), xs.1.max(gx.end));
            ys = (ys.0.min(gy.start), ys.1.max(gy.end));
        }
        assert!(xs.0 < xs.1, "pose {b} sees the object");
        for (g, &in_object) in focus.iter().enumerate() {
            let i = b * n + g;
            let (gx, gy) = tiles(i);
            let overlaps = gx.start < xs.1 && xs.0 < gx.end && gy.start < ys.1 && ys.0 < gy.end;
            // A relative margin keeps the f32 rounding of stored depths out of the comparison.
            let in_front = depth[i] < deepest * (1.0 - 1e-6);
            if visible[i] && overlaps && !in_front && !in_object {
                behind += usize::from(depth[i] > deepest * (1.0 + 1e-6) && host[i].is_none());
            } else if visible[i] && overlaps {
                needed += 1;
                let Some(kept) = host[i] else {
                    panic!(
                        "pose {b}, Gaussian {g}: reaches the object's tiles, culled by the host"
                    );
                };
                assert_eq!(kept.radius, radii[i], "pose {b}, Gaussian {g}: radius");
            } else if !visible[i] {
                assert!(
                    host[i].is_none(),
                    "pose {b}, Gaussian {g}: culled by the tensor path, not by the host"
                );
            } else {
                skipped += usize::from(host[i].is_none());
            }
        }
    }
    assert!(
        needed > 300,
        "enough Gaussians reach the object's tiles ({needed})"
    );
    assert!(
        skipped > 500,
        "the host skips what cannot reach them ({skipped})"
    );
    assert!(
        behind > 100,
        "the host skips what lies behind the object ({behind})"
    );
}
