//! Helpers shared by the render crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::RefCamera;
use splatraj_scene::Scene;

/// The reference renderer's camera for a pose and intrinsics (near plane 0.01).
pub fn ref_camera(pose: &Pose, k: &Intrinsics) -> RefCamera {
    RefCamera::from_pose(pose, k, 0.01)
}

/// Poses as a `[B, 6]` tensor.
pub fn pose_tensor(poses: &[Pose], device: &Device, dtype: DType) -> Tensor<2> {
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    Tensor::from_data(TensorData::new(flat, [poses.len(), 6]), (device, dtype))
}

/// A tensor's values as f64 on the host, row-major.
pub fn host<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()
}

/// Small deterministic generator (xorshift), so the tests need no rand dependency.
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// `n` Gaussians drawn from `rng`: centre coordinates within ±`spread(i)`, scales and opacities
/// uniform in their ranges, rotations from four uniform values in [-1, 1) (the renderer
/// normalises them).
pub fn random_scene(
    rng: &mut Rng,
    n: usize,
    spread: impl Fn(usize) -> f64,
    scales: (f64, f64),
    opacities: (f64, f64),
) -> Scene {
    let mut scene = Scene::default();
    for i in 0..n {
        let spread = spread(i);
        scene
            .means
            .push(std::array::from_fn(|_| rng.range(-spread, spread) as f32));
        scene.scales.push(std::array::from_fn(|_| {
            rng.range(scales.0, scales.1) as f32
        }));
        scene
            .rotations
            .push(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
        scene
            .opacities
            .push(rng.range(opacities.0, opacities.1) as f32);
    }
    scene
}

/// 60 Gaussians around the origin, 15 of them far out (off screen, beyond the Jacobian's
/// clamp, behind the cameras), and a needle whose normalised determinant is floored.
pub fn projection_scene(seed: u64) -> Scene {
    let mut rng = Rng(seed);
    let mut scene = Scene::default();
    for i in 0..60 {
        let spread = if i < 45 { 1.5 } else { 9.0 };
        scene
            .means
            .push(std::array::from_fn(|_| rng.range(-spread, spread) as f32));
        let scales = if i == 59 {
            [1e-7, 1e-7, 2.0]
        } else {
            std::array::from_fn(|_| rng.range(0.02, 0.3) as f32)
        };
        scene.scales.push(scales);
        scene
            .rotations
            .push(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
        scene.opacities.push(rng.range(0.05, 1.0) as f32);
    }
    scene
}

/// Poses on both of Rodrigues' branches (ω = 0 included).
pub fn projection_poses() -> Vec<Pose> {
    let up = DVec3::new(0.0, -1.0, 0.0);
    vec![
        Pose::look_at(DVec3::new(4.0, -1.0, 5.0), DVec3::ZERO, up).unwrap(),
        Pose::look_at(DVec3::new(-5.5, -2.0, -1.0), DVec3::new(0.3, 0.2, 0.0), up).unwrap(),
        Pose([0.04, -0.05, 0.03, 0.2, -0.1, -6.0]),
        Pose([0.0, 0.0, 0.0, -0.3, 0.2, -5.0]),
    ]
}

/// Fixed pseudo-random weights `[B, U, 7]` for a scalar loss Σ w·rows of packed projection rows.
pub fn row_weights(batch: usize, rows: usize, device: &Device, dtype: DType) -> Tensor<3> {
    let mut rng = Rng(99);
    let w: Vec<f64> = (0..batch * rows * splatraj_render::fused::projection::SPLAT_COLUMNS)
        .map(|_| rng.range(-1.0, 1.0))
        .collect();
    Tensor::from_data(
        TensorData::new(
            w,
            [
                batch,
                rows,
                splatraj_render::fused::projection::SPLAT_COLUMNS,
            ],
        ),
        (device, dtype),
    )
}

/// A 40 m × 40 m floor of small clusters (SH degree 1; 12 Gaussians per square metre, a few
/// wide ones reaching far beyond their cluster), and each Gaussian's cluster centre (x, y).
pub fn floor_of_clusters() -> (Scene, Vec<[f64; 2]>) {
    let mut rng = Rng(0x5eed);
    let mut scene = Scene {
        sh_degree: 1,
        ..Default::default()
    };
    let mut clusters = Vec::new();
    for cx in -20..20 {
        for cy in -20..20 {
            let centre = DVec3::new(cx as f64 + 0.5, cy as f64 + 0.5, 0.0);
            for _ in 0..12 {
                let mean = centre
                    + DVec3::new(
                        rng.range(-0.3, 0.3),
                        rng.range(-0.3, 0.3),
                        rng.range(0.0, 0.6),
                    );
                scene.means.push(mean.to_array().map(|v| v as f32));
                let size = if rng.next() < 0.05 { 1.5 } else { 0.15 };
                scene
                    .scales
                    .push([0, 1, 2].map(|_| rng.range(0.01, size) as f32));
                let q = [0, 1, 2, 3].map(|_| rng.range(-1.0, 1.0));
                let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                scene.rotations.push(q.map(|v| (v / norm) as f32));
                scene.opacities.push(rng.range(0.2, 1.0) as f32);
                scene
                    .sh
                    .extend((0..12).map(|_| rng.range(-1.0, 1.0) as f32));
                clusters.push([centre.x, centre.y]);
            }
        }
    }
    (scene, clusters)
}

/// 1 for the Gaussians whose cluster lies within `radius` of `centre`, else 0.
pub fn mask_near(clusters: &[[f64; 2]], centre: [f64; 2], radius: f64) -> Vec<f32> {
    clusters
        .iter()
        .map(|c| {
            f32::from(u8::from(
                glam::DVec2::from(*c).distance(centre.into()) < radius,
            ))
        })
        .collect()
}

/// Asserts `got` has `want`'s length and lies within `relative` of `want`'s largest magnitude
/// (at least 1) everywhere, and that `want` holds something to compare (not all zeros).
pub fn assert_within(name: &str, got: &[f64], want: &[f64], relative: f64) {
    assert_eq!(got.len(), want.len(), "{name}: lengths");
    let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let error = got
        .iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(scale > 0.0, "{name}: something to compare");
    assert!(
        error <= relative * scale.max(1.0),
        "{name}: differs by {error} (largest value {scale})"
    );
}
