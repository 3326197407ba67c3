//! The decisions of a render pass, made on the host without gradient: which Gaussians each pose
//! culls, where they land on screen, their pixel radius and their depth (docs/conventions.md:
//! integer data decided off the autodiff graph).
//!
//! The same formulas as the differentiable projection ([`crate::project`]), evaluated in f64
//! per Gaussian in parallel (four at a time in lanes where the processor has AVX, the same
//! bits: `decide/lanes.rs`) from a per-scene host copy of the means and world covariances
//! ([`HostGeometry`], built once). Only the cull test, the tile lists and the depth order come
//! from here; values and gradients come from the tensor projection of the Gaussians kept.

use rayon::prelude::*;
use splatraj_scene::Scene;

#[cfg(target_arch = "x86_64")]
mod lanes;

use crate::alpha_reach::{AlphaReach, SquaredReach};
use crate::camera::{Intrinsics, Pose, zoomed_intrinsics};
use glam::DVec3;

use crate::focus::{FocusCache, ObjectFocus, PoseFocus, Surroundings};

use crate::project::{FOV_CLAMP, LOW_PASS, cull_and_radius, world_covariance};
use crate::tile_grid::{TILE_SIZE, TileGrid};

/// A kept Gaussian's pixel radius and screen covariance (xx, xy, yy, low-pass included).
type ScreenSize = (f32, [f64; 3]);

/// Pose-independent geometry on the host, for the decisions (computed once per scene).
///
/// Means, covariances and largest variances are stored **sorted**: in the Morton order of the
/// means, so block b's members are the positions `b · BLOCK_MEMBERS ..` and a pass reads them
/// sequentially. In scene order, a block's members are scattered over the arrays and each read
/// was a cache miss (a perf profile put half of the deciding time on those two loads).
#[derive(Debug, Clone, Default)]
pub struct HostGeometry {
    /// Means, world coordinates, sorted. `[N]`
    pub means: Vec<[f32; 3]>,
    /// World covariances (xx, xy, xz, yy, yz, zz), sorted. `[N]`
    pub covariances: Vec<[f32; 6]>,
    /// Largest eigenvalue of each world covariance (the squared largest scale), sorted. `[N]`
    pub max_variance: Vec<f32>,
    /// Opacities in scene order (for the `min_opacity` approximation). `[N]`
    pub opacities: Vec<f32>,
    /// Each Gaussian's [`SquaredReach`], sorted: read beside its covariance, where the scene
    /// order's opacity was a scattered read and a logarithm per pose. `[N]`
    pub squared_reach: Vec<SquaredReach>,
    /// Gaussians grouped by place, so a pose can skip the groups it cannot see.
    pub blocks: Vec<Block>,
    /// Scene index of the Gaussian at each sorted position. `[N]`
    pub scene_from_sorted: Vec<u32>,
    /// The objects of the mask passes rendered lately (derived once per mask).
    pub focus: FocusCache,
}

/// Neighbouring Gaussians (consecutive in Morton order of their means), bounded as a whole.
///
/// A pass visits only what a pose can see; on scenes of millions of Gaussians most of them are
/// off-screen, behind the camera or outside a mask pass's tiles, and testing one bound per block
/// instead of projecting each Gaussian is what keeps the decisions from growing with N.
#[derive(Debug, Clone, Copy, Default)]
pub struct Block {
    /// Centre of the members' means (middle of their bounding box), world coordinates.
    pub centre: DVec3,
    /// Largest distance of a member's mean from `centre` (rounded up).
    pub radius: f64,
    /// Largest eigenvalue of a member's world covariance.
    pub max_variance: f64,
}

/// Gaussians per [`Block`]: small enough to bound tightly, large enough that the block tests
/// cost nothing next to the Gaussians they skip.
const BLOCK_MEMBERS: usize = 256;

/// Smallest and largest coordinates of `points` (NaN coordinates are skipped by min/max).
fn bounding_box(points: impl Iterator<Item = DVec3>) -> (DVec3, DVec3) {
    points.fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    )
}

/// Groups the Gaussians into [`Block`]s: sorted by a 30-bit Morton code of their means (10 bits
/// per axis over the scene's bounding box), then cut into runs of [`BLOCK_MEMBERS`].
/// Returns the blocks and the Gaussian indices in block order.
fn spatial_blocks(means: &[[f32; 3]], max_variance: &[f32]) -> (Vec<Block>, Vec<u32>) {
    let finite = means.iter().filter(|m| m.iter().all(|v| v.is_finite()));
    let (lo, hi) = bounding_box(finite.map(|m| DVec3::from(m.map(f64::from))));
    let cells = 1023.0;
    let extent = (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
    let morton = |m: &[f32; 3]| -> u32 {
        let q = (DVec3::from(m.map(f64::from)) - lo) / extent * cells;
        // NaN and out-of-range values land in a corner cell; the block bounds stay exact.
        let cell = |v: f64| v.clamp(0.0, cells) as u32;
        let spread = |mut v: u32| {
            v = (v | (v << 16)) & 0x0300_00ff;
            v = (v | (v << 8)) & 0x0300_f00f;
            v = (v | (v << 4)) & 0x030c_30c3;
            (v | (v << 2)) & 0x0924_9249
        };
        spread(cell(q.x)) | (spread(cell(q.y)) << 1) | (spread(cell(q.z)) << 2)
    };
    let mut order: Vec<(u32, u32)> = means
        .par_iter()
        .enumerate()
        .map(|(g, m)| (morton(m), g as u32))
        .collect();
    order.par_sort_unstable();
    let blocks = order
        .par_chunks(BLOCK_MEMBERS)
        .map(|members| {
            let point = |g: u32| DVec3::from(means[g as usize].map(f64::from));
            let (lo, hi) = bounding_box(members.iter().map(|&(_, g)| point(g)));
            let centre = 0.5 * (lo + hi);
            let mut block = Block {
                centre,
                radius: 0.0,
                max_variance: 0.0,
            };
            for &(_, g) in members {
                // f64::max skips NaN: a non-finite member makes the radius infinite below.
                let distance = (point(g) - centre).length();
                block.radius = if distance.is_finite() {
                    block.radius.max(distance)
                } else {
                    f64::INFINITY
                };
                block.max_variance = block.max_variance.max(f64::from(max_variance[g as usize]));
            }
            // Rounding of the distances must not let a member poke out of the bound.
            block.radius = block.radius * (1.0 + 1e-9) + 1e-9;
            block
        })
        .collect();
    (blocks, order.into_iter().map(|(_, g)| g).collect())
}

impl HostGeometry {
    /// From a scene's means, scales and rotations (Σ computed in f64, stored in f32).
    pub fn new(scene: &Scene) -> Self {
        let max_variance: Vec<f32> = scene
            .scales
            .iter()
            .map(|s| s.iter().fold(0.0f32, |m, &v| m.max(v * v)))
            .collect();
        let (blocks, scene_from_sorted) = spatial_blocks(&scene.means, &max_variance);
        let covariances = scene_from_sorted
            .par_iter()
            .map(|&g| {
                let g = g as usize;
                let s = world_covariance(scene.scales[g], scene.rotations[g]);
                [s[0], s[1], s[2], s[4], s[5], s[8]].map(|v| v as f32)
            })
            .collect();
        HostGeometry {
            means: scene_from_sorted
                .iter()
                .map(|&g| scene.means[g as usize])
                .collect(),
            covariances,
            max_variance: scene_from_sorted
                .iter()
                .map(|&g| max_variance[g as usize])
                .collect(),
            opacities: scene.opacities.clone(),
            squared_reach: scene_from_sorted
                .par_iter()
                .map(|&g| SquaredReach::of_opacity(f64::from(scene.opacities[g as usize])))
                .collect(),
            blocks,
            scene_from_sorted,
            focus: FocusCache::default(),
        }
    }

    /// The same geometry with every block's bound made infinite, so that a pass decides each
    /// Gaussian one by one: the full scan the block tests must agree with (for tests and
    /// checks; the decisions, tile lists and renders are the same, only slower).
    pub fn with_unbounded_blocks(mut self) -> Self {
        for block in &mut self.blocks {
            block.radius = f64::INFINITY;
        }
        self
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

/// What one pose decided about one Gaussian it keeps (in front of the near plane, with an
/// invertible 2D covariance, and able to reach the pass's tiles).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decided {
    /// Index of the Gaussian in the scene.
    pub gaussian: u32,
    /// Pixel coordinates (u, v) of the projected mean.
    pub means_2d: [f32; 2],
    /// Camera depth z.
    pub depth: f32,
    /// Pixel radius ceil(3·sqrt(λ_max(Σ_2D))), positive.
    pub radius: f32,
    /// Where its α can reach 1/255 (the binning keeps only the tiles of the square it meets).
    pub reach: AlphaReach,
}

/// The Gaussians each pose keeps, `[B][kept]` in no particular order.
///
/// Sparse on purpose: a pass visits only the spatial blocks a pose can see (or, in a mask pass,
/// the object and what can cover it), and nothing in it allocates or scans `[B · N]`; on large
/// scenes that fixed cost was most of a pruned pass.
#[derive(Debug, Clone, Default)]
pub struct Decisions {
    /// Per pose, the Gaussians it keeps.
    pub kept: Vec<Vec<Decided>>,
}

impl Decisions {
    /// Pose `b`'s decision for each of the scene's `n` Gaussians (`None` where culled or
    /// skipped): a dense view for tests and diagnostics.
    pub fn dense(&self, b: usize, n: usize) -> Vec<Option<Decided>> {
        let mut dense = vec![None; n];
        for decided in &self.kept[b] {
            dense[decided.gaussian as usize] = Some(*decided);
        }
        dense
    }
}

/// Projects the Gaussians each pose can see and decides their cull, radius and depth.
///
/// With `focus` (a mask pass's object), the object's Gaussians are
/// decided first; the others are then decided only where their bounded square reaches the box
/// of tiles the object touches in that pose and they are no deeper than the object's deepest
/// Gaussian there, and are left out elsewhere. That changes no tile list the pass uses:
/// binning keeps only the object's tiles, and cuts each list after the object's last Gaussian,
/// which a deeper one always follows.
pub fn decide(
    geometry: &HostGeometry,
    poses: &[Pose],
    intrinsics: &Intrinsics,
    near: f64,
    focus: Option<&ObjectFocus>,
) -> Decisions {
    let focus: Vec<Option<PoseFocus>> = vec![
        focus.map(|object| PoseFocus {
            object,
            surroundings: Surroundings::Scene,
        });
        poses.len()
    ];
    decide_zoomed(geometry, poses, None, intrinsics, near, &focus)
}

/// [`decide`] with pose b seen through `intrinsics` zoomed by `zoom[b]` (fx·s, fy·s; `None`:
/// s = 1), as the zoomed projection draws it, and each pose with its own focus `focus[b]`
/// (`None`: the whole frame; [`Surroundings::Nothing`]: the object's Gaussians only). Panics
/// if `zoom` or `focus` is not one per pose.
pub fn decide_zoomed(
    geometry: &HostGeometry,
    poses: &[Pose],
    zoom: Option<&[f64]>,
    intrinsics: &Intrinsics,
    near: f64,
    focus: &[Option<PoseFocus>],
) -> Decisions {
    if let Some(zoom) = zoom {
        assert_eq!(zoom.len(), poses.len(), "one zoom per pose");
    }
    assert_eq!(focus.len(), poses.len(), "one focus per pose");
    let grid = TileGrid::new(intrinsics.width, intrinsics.height);
    // The tile grid's extent in whole tiles: a square that reaches into the last partial tile
    // is listed there, as the binning rule says.
    let whole_grid = [
        0.0,
        0.0,
        (grid.tiles_x * TILE_SIZE) as f64,
        (grid.tiles_y * TILE_SIZE) as f64,
    ];
    // Poses in parallel too: a mask pass's pose decides an object of a few thousand
    // Gaussians, too little work to keep every core busy within one pose (first-try guitar
    // on 2 cores, `bench step`: 140.9 → 137.3 ms a step per window, 143.5 → 141.7 shared;
    // more cores, more to gain). Each pose's decisions are its own: the same lists.
    let kept = poses
        .par_iter()
        .enumerate()
        .map(|(b, pose)| {
            let intrinsics = match zoom {
                Some(zoom) => zoomed_intrinsics(intrinsics, zoom[b]),
                None => *intrinsics,
            };
            let camera = Camera::new(pose, &intrinsics, near);
            let Some(focus) = focus[b] else {
                return camera.decide_blocks(geometry, &|_| true, Reach::everywhere(whole_grid));
            };
            // The object's sorted positions come listed (an object is a small part of a
            // scene, and its positions are close together); membership is read by sorted
            // position, so the members of a block are tested one after the other.
            let object = focus.object;
            let mut kept: Vec<Decided> = object
                .sorted_list
                .par_chunks(CHUNK)
                .flat_map_iter(|chunk| {
                    let positions = chunk.iter().map(|&k| k as usize);
                    camera.kept_of(geometry, positions, Reach::everywhere(whole_grid))
                })
                .collect();
            if focus.surroundings == Surroundings::Nothing {
                return kept;
            }
            // The box of tiles the object touches (in pixels), then everything else against it.
            let mut tiles = [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ];
            let mut deepest = f32::NEG_INFINITY;
            for decided in &kept {
                let [u, v] = decided.means_2d.map(f64::from);
                let (xs, ys) = grid.touched(u, v, f64::from(decided.radius));
                if xs.is_empty() || ys.is_empty() {
                    continue;
                }
                deepest = deepest.max(decided.depth);
                let size = TILE_SIZE as f64;
                tiles[0] = tiles[0].min(xs.start as f64 * size);
                tiles[1] = tiles[1].min(ys.start as f64 * size);
                tiles[2] = tiles[2].max(xs.end as f64 * size);
                tiles[3] = tiles[3].max(ys.end as f64 * size);
            }
            if tiles[0] < tiles[2] {
                let reach = Reach {
                    bounds: tiles,
                    max_depth: deepest,
                };
                let outside = |k: usize| !object.sorted.contains(k);
                kept.extend(camera.decide_blocks(geometry, &outside, reach));
            }
            kept
        })
        .collect();
    Decisions { kept }
}

/// Where a pass's Gaussians must land to matter.
#[derive(Debug, Clone, Copy)]
struct Reach {
    /// Pixel box [x0, y0, x1, y1] a Gaussian's bounded square must touch.
    bounds: [f64; 4],
    /// Largest stored (f32) depth that can matter: binning orders by the f32 depth, so the
    /// comparison is made on the same value.
    max_depth: f32,
}

impl Reach {
    /// Anything touching `bounds`, at any depth.
    fn everywhere(bounds: [f64; 4]) -> Self {
        Reach {
            bounds,
            max_depth: f32::INFINITY,
        }
    }
}

/// Gaussians per parallel task when deciding a list of them.
const CHUNK: usize = 1024;

/// One pose's camera, set up for deciding Gaussians.
struct Camera {
    r: [DVec3; 3],
    centre: DVec3,
    intrinsics: Intrinsics,
    limits: (f64, f64),
    near: f64,
}

impl Camera {
    /// The Gaussians `select` picks (by sorted position) that this pose keeps, from the blocks
    /// that may reach `reach` (in parallel over blocks).
    fn decide_blocks(
        &self,
        geometry: &HostGeometry,
        select: &(dyn Fn(usize) -> bool + Sync),
        reach: Reach,
    ) -> Vec<Decided> {
        let n = geometry.len();
        geometry
            .blocks
            .par_iter()
            .enumerate()
            .filter(|(_, block)| self.may_reach(block, reach))
            .flat_map_iter(|(b, _)| {
                let members = b * BLOCK_MEMBERS..((b + 1) * BLOCK_MEMBERS).min(n);
                self.kept_of(geometry, members.filter(|&k| select(k)), reach)
            })
            .collect()
    }

    /// The decisions on the Gaussians at sorted positions `positions` that this pose keeps,
    /// in their order: four at a time in lanes where the processor can ([`lanes`]), the same
    /// bits as one by one.
    fn kept_of(
        &self,
        geometry: &HostGeometry,
        positions: impl Iterator<Item = usize>,
        reach: Reach,
    ) -> Vec<Decided> {
        let mut kept = Vec::new();
        #[cfg(target_arch = "x86_64")]
        if let Some(lanes) = lanes::Lanes::new() {
            lanes.decide(self, geometry, positions, reach, &mut kept);
            return kept;
        }
        kept.extend(positions.filter_map(|k| self.kept(geometry, k as u32, reach)));
        kept
    }

    /// The decision on the Gaussian at sorted position `k`, if this pose keeps it
    /// ([`Camera::decide`]).
    fn kept(&self, geometry: &HostGeometry, k: u32, reach: Reach) -> Option<Decided> {
        let (uv, z, screen) = self.decide(geometry, k as usize, reach);
        let (radius, covariance) = screen?;
        Some(Decided {
            gaussian: geometry.scene_from_sorted[k as usize],
            means_2d: uv.map(|c| c as f32),
            depth: z as f32,
            radius,
            reach: AlphaReach::scaled(covariance, geometry.squared_reach[k as usize]),
        })
    }

    fn new(pose: &Pose, intrinsics: &Intrinsics, near: f64) -> Self {
        let r = pose.rotation_wc();
        let (tan_x, tan_y) = intrinsics.tan_half_fov();
        Camera {
            r: [r.x_axis, r.y_axis, r.z_axis], // camera axes in world
            centre: pose.centre(),
            intrinsics: *intrinsics,
            limits: (FOV_CLAMP * tan_x, FOV_CLAMP * tan_y),
            near,
        }
    }

    /// False only when no member of `block` can matter in this pose: each is behind the near
    /// plane, deeper than `reach.max_depth` or, by [`Camera::decide`]'s own bound, lands
    /// outside `reach.bounds`.
    fn may_reach(&self, block: &Block, reach: Reach) -> bool {
        let bounds = reach.bounds;
        let Intrinsics { fx, fy, cx, cy, .. } = self.intrinsics;
        let [r0, r1, r2] = self.r;
        let d = block.centre - self.centre;
        let (x, y, z, r) = (d.dot(r0), d.dot(r1), d.dot(r2), block.radius);
        if !(x.is_finite() && y.is_finite() && z.is_finite() && r.is_finite()) {
            return true;
        }
        if z + r <= self.near {
            return false;
        }
        let z_min = z - r;
        // Rounding to f32 is monotone: every member's stored depth is at least this one.
        if (z_min as f32) > reach.max_depth {
            return false;
        }
        if z_min <= self.near {
            return true; // straddles the near plane: decide each member
        }
        // A member's camera coordinates lie in the box [x ± r] × [y ± r] × [z ± r] with z > 0,
        // where x'/z' is extreme at the corners.
        let ratio_range = |a: f64| {
            let ratios = [
                (a - r) / z_min,
                (a - r) / (z + r),
                (a + r) / z_min,
                (a + r) / (z + r),
            ];
            ratios
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &q| {
                    (lo.min(q), hi.max(q))
                })
        };
        let ((x_lo, x_hi), (y_lo, y_hi)) = (ratio_range(x), ratio_range(y));
        let (u_lo, u_hi) = (fx * x_lo + cx, fx * x_hi + cx);
        let (v_lo, v_hi) = (fy * y_lo + cy, fy * y_hi + cy);
        // The largest footprint bound of a member: |x̂|, |ŷ| are clamped, and z ≥ z_min.
        let (lx, ly) = self.limits;
        let j_norm2 = (fx * fx * (1.0 + lx * lx) + fy * fy * (1.0 + ly * ly)) / (z_min * z_min);
        let bound = 3.0 * (j_norm2 * block.max_variance + LOW_PASS).sqrt() + 1.0;
        !(u_hi + bound < bounds[0]
            || v_hi + bound < bounds[1]
            || u_lo - bound > bounds[2]
            || v_lo - bound > bounds[3])
    }

    /// Pixel position, depth, and radius with screen covariance (xx, xy, yy; `None` if culled)
    /// of the Gaussian at sorted position `k`. A Gaussian whose bounded square misses
    /// `reach.bounds` ([x0, y0, x1, y1], pixels), or whose stored depth is beyond
    /// `reach.max_depth`, gets `None` without its covariance being projected: it would be in
    /// no tile list there.
    fn decide(
        &self,
        geometry: &HostGeometry,
        k: usize,
        reach: Reach,
    ) -> ([f64; 2], f64, Option<ScreenSize>) {
        let bounds = reach.bounds;
        let Intrinsics { fx, fy, cx, cy, .. } = self.intrinsics;
        let [r0, r1, r2] = self.r;
        let d = DVec3::from(geometry.means[k].map(f64::from)) - self.centre;
        let (x, y, z) = (d.dot(r0), d.dot(r1), d.dot(r2));
        let z_safe = z.max(self.near);
        let (xz, yz) = (x / z_safe, y / z_safe);
        let (u, v) = (fx * xz + cx, fy * yz + cy);
        let (tx, ty) = (
            xz.clamp(-self.limits.0, self.limits.0),
            yz.clamp(-self.limits.1, self.limits.1),
        );
        // λ_max(Σ_2D) ≤ ‖J‖²_F·λ_max(Σ) + 0.3 bounds the radius.
        let j_norm2 = (fx * fx * (1.0 + tx * tx) + fy * fy * (1.0 + ty * ty)) / (z_safe * z_safe);
        let bound = 3.0 * (j_norm2 * f64::from(geometry.max_variance[k]) + LOW_PASS).sqrt() + 1.0;
        if z <= self.near
            || (z as f32) > reach.max_depth
            || u + bound < bounds[0]
            || v + bound < bounds[1]
            || u - bound > bounds[2]
            || v - bound > bounds[3]
        {
            return ([u, v], z, None);
        }
        let t1 = r0 * (fx / z_safe) + r2 * (-fx * tx / z_safe);
        let t2 = r1 * (fy / z_safe) + r2 * (-fy * ty / z_safe);
        let [sxx, sxy, sxz, syy, syz, szz] = geometry.covariances[k].map(f64::from);
        let sigma = |t: DVec3| {
            DVec3::new(
                sxx * t.x + sxy * t.y + sxz * t.z,
                sxy * t.x + syy * t.y + syz * t.z,
                sxz * t.x + syz * t.y + szz * t.z,
            )
        };
        let s_t2 = sigma(t2);
        let a = t1.dot(sigma(t1)) + LOW_PASS;
        let b = t1.dot(s_t2);
        let c = t2.dot(s_t2) + LOW_PASS;
        let (ok, radius) = cull_and_radius(z, a, b, c, self.near);
        ([u, v], z, ok.then_some((radius, [a, b, c])))
    }
}
