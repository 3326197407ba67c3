//! The decisions of a render pass, made on the host without gradient: which Gaussians each pose
//! culls, where they land on screen, their pixel radius and their depth (DESIGN.md: integer
//! data decided off the autodiff graph).
//!
//! The same formulas as the differentiable projection ([`crate::project`]), evaluated in f64
//! per Gaussian in parallel from a per-scene host copy of the means and world covariances
//! ([`HostGeometry`], built once). Only the cull test, the tile lists and the depth order come
//! from here; values and gradients come from the tensor projection of the Gaussians kept.

use rayon::prelude::*;
use splatraj_scene::Scene;

use crate::camera::{Intrinsics, Pose};
use crate::project::{FOV_CLAMP, LOW_PASS, NORMALISED_DET_FLOOR, world_covariance};

/// Pose-independent geometry on the host, for the decisions (computed once per scene).
#[derive(Debug, Clone, Default)]
pub struct HostGeometry {
    /// Means, world coordinates.
    pub means: Vec<[f32; 3]>,
    /// World covariances (xx, xy, xz, yy, yz, zz).
    pub covariances: Vec<[f32; 6]>,
    /// Largest eigenvalue of each world covariance (the squared largest scale).
    pub max_variance: Vec<f32>,
}

impl HostGeometry {
    /// From a scene's means, scales and rotations (Σ computed in f64, stored in f32).
    pub fn new(scene: &Scene) -> Self {
        let covariances = (0..scene.len())
            .into_par_iter()
            .map(|i| {
                let s = world_covariance(scene.scales[i], scene.rotations[i]);
                [s[0], s[1], s[2], s[4], s[5], s[8]].map(|v| v as f32)
            })
            .collect();
        let max_variance = scene
            .scales
            .iter()
            .map(|s| s.iter().fold(0.0f32, |m, &v| m.max(v * v)))
            .collect();
        HostGeometry {
            means: scene.means.clone(),
            covariances,
            max_variance,
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
}

/// Screen data of every Gaussian for every pose, flat `[B · N]` (means `[B · N · 2]`).
#[derive(Debug, Clone, Default)]
pub struct Decisions {
    /// Pixel coordinates (u, v) of the projected means.
    pub means_2d: Vec<f32>,
    /// Camera depths z.
    pub depth: Vec<f32>,
    /// Pixel radii ceil(3·sqrt(λ_max(Σ_2D))); 0 where culled.
    pub radii: Vec<f32>,
    /// In front of the near plane with an invertible 2D covariance.
    pub visible: Vec<bool>,
}

/// Projects every Gaussian for every pose and decides its cull, radius and depth.
pub fn decide(
    geometry: &HostGeometry,
    poses: &[Pose],
    intrinsics: &Intrinsics,
    near: f64,
) -> Decisions {
    let n = geometry.len();
    let total = n * poses.len();
    let mut decisions = Decisions {
        means_2d: vec![0.0; 2 * total],
        depth: vec![0.0; total],
        radii: vec![0.0; total],
        visible: vec![false; total],
    };
    let Intrinsics { fx, fy, cx, cy, .. } = *intrinsics;
    // The tile grid's extent (whole tiles): a square that reaches into the last partial tile
    // is listed there, as the binning rule says.
    let grid = crate::tiles::TileGrid::new(intrinsics.width, intrinsics.height);
    let (width, height) = (
        (grid.tiles_x * crate::tiles::TILE_SIZE) as f64,
        (grid.tiles_y * crate::tiles::TILE_SIZE) as f64,
    );
    let (tan_x, tan_y) = intrinsics.tan_half_fov();
    let (lim_x, lim_y) = (FOV_CLAMP * tan_x, FOV_CLAMP * tan_y);
    const BLOCK: usize = 4096;
    for (b, pose) in poses.iter().enumerate() {
        let r = pose.rotation_wc();
        let (r0, r1, r2) = (r.x_axis, r.y_axis, r.z_axis); // camera axes in world
        let centre = pose.centre();
        let range = b * n..(b + 1) * n;
        decisions.means_2d[2 * range.start..2 * range.end]
            .par_chunks_mut(2 * BLOCK)
            .zip(decisions.depth[range.clone()].par_chunks_mut(BLOCK))
            .zip(decisions.radii[range.clone()].par_chunks_mut(BLOCK))
            .zip(decisions.visible[range].par_chunks_mut(BLOCK))
            .enumerate()
            .for_each(|(block, (((means_2d, depth), radii), visible))| {
                for j in 0..depth.len() {
                    let g = block * BLOCK + j;
                    let m = geometry.means[g].map(f64::from);
                    let d = glam::DVec3::from(m) - centre;
                    let (x, y, z) = (d.dot(r0), d.dot(r1), d.dot(r2));
                    let z_safe = z.max(near);
                    let (xz, yz) = (x / z_safe, y / z_safe);
                    means_2d[2 * j] = (fx * xz + cx) as f32;
                    means_2d[2 * j + 1] = (fy * yz + cy) as f32;
                    depth[j] = z as f32;
                    let (tx, ty) = (xz.clamp(-lim_x, lim_x), yz.clamp(-lim_y, lim_y));
                    // A bound on the radius from ‖J‖²_F·λ_max(Σ): a Gaussian whose bounding
                    // square surely misses the tile grid touches no tile, so its covariance is
                    // not needed (it is marked not visible, which changes no tile list).
                    let j_norm2 =
                        (fx * fx * (1.0 + tx * tx) + fy * fy * (1.0 + ty * ty)) / (z_safe * z_safe);
                    let bound = 3.0
                        * (j_norm2 * f64::from(geometry.max_variance[g]) + LOW_PASS).sqrt()
                        + 1.0;
                    let (u, v) = (fx * xz + cx, fy * yz + cy);
                    if z <= near
                        || u + bound < 0.0
                        || v + bound < 0.0
                        || u - bound > width
                        || v - bound > height
                    {
                        visible[j] = false;
                        radii[j] = 0.0;
                        continue;
                    }
                    let t1 = r0 * (fx / z_safe) + r2 * (-fx * tx / z_safe);
                    let t2 = r1 * (fy / z_safe) + r2 * (-fy * ty / z_safe);
                    let [sxx, sxy, sxz, syy, syz, szz] = geometry.covariances[g].map(f64::from);
                    let sigma = |t: glam::DVec3| {
                        glam::DVec3::new(
                            sxx * t.x + sxy * t.y + sxz * t.z,
                            sxy * t.x + syy * t.y + syz * t.z,
                            sxz * t.x + syz * t.y + szz * t.z,
                        )
                    };
                    let s_t2 = sigma(t2);
                    let a = t1.dot(sigma(t1)) + LOW_PASS;
                    let bb = t1.dot(s_t2);
                    let c = t2.dot(s_t2) + LOW_PASS;
                    let (ok, radius) = cull_and_radius(z, a, bb, c, near);
                    visible[j] = ok;
                    radii[j] = radius;
                }
            });
    }
    decisions
}

/// (visible, radius) from camera depth z and Σ_2D = [[a, b], [b, c]] (low-pass included).
///
/// visible = z > near ∧ det/tr² > [`NORMALISED_DET_FLOOR`] with every value finite;
/// radius = ceil(3·sqrt(λ_max)) in pixels, 0 where not visible.
pub fn cull_and_radius(z: f64, a: f64, b: f64, c: f64, near: f64) -> (bool, f32) {
    let trace = a + c;
    let det = a * c - b * b;
    let ok = z > near
        && trace.is_finite()
        && b.is_finite()
        && trace > 0.0
        && det / (trace * trace) > NORMALISED_DET_FLOOR;
    if !ok {
        return (false, 0.0);
    }
    let mid = 0.5 * trace;
    let lambda_max = mid + (mid * mid - det).max(0.0).sqrt();
    (true, (3.0 * lambda_max.sqrt()).ceil() as f32)
}
