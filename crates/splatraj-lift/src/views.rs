//! Which views to lift from: chosen from the scene's own geometry, or the capture's cameras.
//!
//! A semantic field needs every part of the content seen from a few sides, from where a person
//! would look at it: around an object capture, from inside a room looking out. Rather than
//! guessing which kind of scene this is, [`plan_views`] offers both kinds of candidate (rings
//! around the content at two distances, and outward-looking views from points inside it),
//! drops those that are buried in geometry or see nothing, and then picks views greedily by
//! how many Gaussians each newly shows, counting a Gaussian as covered once `sides` views show
//! it. What a view "shows" is measured with the lifting itself: the blending weight each
//! Gaussian gets in a small render (so an occluded Gaussian counts as not shown).

use glam::DVec3;
use serde::{Deserialize, Serialize};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::lift::lift_views;
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::Scene;

use crate::error::{LiftError, Result};
use crate::progress::{LiftStage, Progress};

/// How views are planned.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewOptions {
    /// How many views to pick.
    pub count: usize,
    /// Horizontal field of view of each (square) view, degrees.
    pub fov_degrees: f64,
    /// A Gaussian counts as covered once this many views show it.
    pub sides: usize,
    /// Side of the small renders that measure what each candidate shows, pixels.
    pub probe_size: usize,
}

impl Default for ViewOptions {
    fn default() -> Self {
        ViewOptions {
            count: 24,
            fov_degrees: 60.0,
            sides: 3,
            probe_size: 64,
        }
    }
}

impl ViewOptions {
    /// Checks the values; errors name the key under `prefix` (`targets.lifted.views`).
    pub fn check(&self, prefix: &str) -> Result<()> {
        if self.count == 0 || self.count > 512 {
            return Err(LiftError::option(
                format!("{prefix}.count"),
                format!("{} must be in 1..=512", self.count),
            ));
        }
        if !(self.fov_degrees >= 10.0 && self.fov_degrees <= 120.0) {
            return Err(LiftError::option(
                format!("{prefix}.fov_degrees"),
                format!("{} must be in [10, 120]", self.fov_degrees),
            ));
        }
        if self.sides == 0 || self.sides > 16 {
            return Err(LiftError::option(
                format!("{prefix}.sides"),
                format!("{} must be in 1..=16", self.sides),
            ));
        }
        if !(16..=256).contains(&self.probe_size) {
            return Err(LiftError::option(
                format!("{prefix}.probe_size"),
                format!("{} must be in 16..=256", self.probe_size),
            ));
        }
        Ok(())
    }
}

/// One view to render and lift from: a pose and its camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Camera pose Φ.
    pub pose: Pose,
    /// Intrinsics (any size; renders rescale them).
    pub intrinsics: Intrinsics,
}

/// Where a candidate view stands, for messages and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Placement {
    /// On a ring around the content, looking at its centre.
    Around,
    /// Inside the content's bounds, looking outward.
    Inside,
}

/// A candidate with what it shows.
#[derive(Debug, Clone)]
struct Candidate {
    pose: Pose,
    placement: Placement,
    /// Blending weight per Gaussian in the probe render. `[N]`
    shown: Vec<f32>,
}

/// The planned views and how they were chosen.
#[derive(Debug, Clone)]
pub struct ViewPlan {
    /// The chosen views, in the order picked.
    pub views: Vec<View>,
    /// Where each chosen view stands.
    pub placements: Vec<Placement>,
    /// Candidates offered, and those dropped as buried or empty.
    pub offered: usize,
    /// Candidates dropped.
    pub dropped: usize,
    /// Share of Gaussians shown by at least one chosen view.
    pub seen_share: f64,
}

/// A probe weight (in pixels of the probe) from which a view counts as showing the Gaussian:
/// small enough that a Gaussian far smaller than a probe pixel but in plain sight counts, large
/// enough that one behind others (T ≈ 0) does not. Counting shown/not shown rather than the
/// weight itself keeps the choice from favouring views that show large splats large.
const SHOWN_WEIGHT: f32 = 0.01;
/// A candidate whose median shown depth is below this share of the content's radius is
/// inside geometry (a camera in a wall, inside an object).
const BURIED_DEPTH: f64 = 0.12;
/// A candidate whose weights sum to less than this share of its pixels sees (almost) nothing.
const EMPTY_COVERAGE: f64 = 0.05;

/// Plans views of `scene` (uploaded as `device_scene`) with world `up`; see the module docs.
/// The views' intrinsics are at `size`×`size` pixels.
pub fn plan_views(
    scene: &Scene,
    device_scene: &DeviceScene,
    up: [f64; 3],
    options: &ViewOptions,
    size: usize,
    progress: &Progress,
) -> Result<ViewPlan> {
    options.check("views")?;
    let bounds = scene
        .robust_bounds(0.01)
        .ok_or_else(|| LiftError::Scene("the scene has no Gaussians to lift onto".into()))?;
    let centre = DVec3::from(bounds.center().map(f64::from));
    let half = DVec3::from(bounds.size().map(|s| 0.5 * f64::from(s)));
    // A scene of coinciding centres (one splat, a tiny object) still has the splats' extent.
    let largest_scale = scene.scales.iter().flatten().fold(0f32, |a, &b| a.max(b));
    let radius = half.length().max(3.0 * f64::from(largest_scale)).max(1e-6);
    let up = DVec3::from(up).normalize_or(DVec3::Z);
    let (east, north) = horizontal_axes(up);
    let fov = options.fov_degrees.to_radians();

    let mut offered: Vec<(Pose, Placement)> = Vec::new();
    let mut around = |distance: f64, elevations: &[(f64, usize)]| -> Result<()> {
        for &(elevation, azimuths) in elevations {
            let e = elevation.to_radians();
            for a in 0..azimuths {
                // Rings above 30° are offset by half a step, so neighbouring rings of one
                // distance do not share a meridian.
                let az = (a as f64 + 0.5 * (elevation > 30.0) as u8 as f64) * std::f64::consts::TAU
                    / azimuths as f64;
                let dir = e.cos() * (az.cos() * east + az.sin() * north) + e.sin() * up;
                offered.push((
                    Pose::look_at(centre + distance * dir, centre, up)?,
                    Placement::Around,
                ));
            }
        }
        Ok(())
    };
    // Far enough that the content's bounding sphere fits the view, then close up.
    let far = radius / (0.5 * fov).sin();
    around(far, &[(10.0, 12), (35.0, 12), (65.0, 6)])?;
    around(radius, &[(20.0, 12), (50.0, 6)])?;
    // From points inside the bounds, looking out and a little down, as one stands in a room.
    let pitch = (-20f64).to_radians();
    for (dx, dy) in [(0.0, 0.0), (0.4, 0.0), (-0.4, 0.0), (0.0, 0.4), (0.0, -0.4)] {
        let eye = centre
            + dx * half.dot(east).abs().max(half.length() * 0.3) * east
            + dy * half.dot(north).abs().max(half.length() * 0.3) * north;
        for a in 0..8 {
            let az = a as f64 * std::f64::consts::TAU / 8.0;
            let dir = pitch.cos() * (az.cos() * east + az.sin() * north) + pitch.sin() * up;
            offered.push((Pose::look_at(eye, eye + dir, up)?, Placement::Inside));
        }
    }

    let probe =
        Intrinsics::from_fov_x(options.fov_degrees, options.probe_size, options.probe_size)?;
    let ones = vec![1.0f32; options.probe_size * options.probe_size];
    let pixels = (options.probe_size * options.probe_size) as f64;
    let mut candidates = Vec::new();
    let offered_count = offered.len();
    for (c, (pose, placement)) in offered.into_iter().enumerate() {
        progress(LiftStage::Plan, c, offered_count);
        let sums = lift_views(device_scene, &[pose], &probe, &ones, 1, Rasterizer::Fused)?;
        let shown: Vec<f32> = sums.weights.iter().map(|&w| w as f32).collect();
        let total: f64 = sums.weights.iter().sum();
        if total < EMPTY_COVERAGE * pixels {
            continue;
        }
        if median_depth(scene, &pose, &shown) < BURIED_DEPTH * radius {
            continue;
        }
        candidates.push(Candidate {
            pose,
            placement,
            shown,
        });
    }
    if candidates.is_empty() {
        return Err(LiftError::Scene(format!(
            "none of {offered_count} candidate views sees the scene's content (all were inside \
             geometry or empty; the content's radius is {radius:.3e}, and a scene much smaller \
             than the near plane at {near} cannot be seen at all: scale it up); give the \
             capture's cameras instead",
            near = splatraj_render::project::NEAR_PLANE
        )));
    }
    let dropped = offered_count - candidates.len();
    let chosen = greedy_cover(&candidates, options.count, options.sides as f32);
    let n = scene.len();
    let mut seen = vec![false; n];
    for &c in &chosen {
        for (i, &w) in candidates[c].shown.iter().enumerate() {
            seen[i] |= w >= SHOWN_WEIGHT;
        }
    }
    let intrinsics = Intrinsics::from_fov_x(options.fov_degrees, size, size)?;
    Ok(ViewPlan {
        views: chosen
            .iter()
            .map(|&c| View {
                pose: candidates[c].pose,
                intrinsics,
            })
            .collect(),
        placements: chosen.iter().map(|&c| candidates[c].placement).collect(),
        offered: offered_count,
        dropped,
        seen_share: seen.iter().filter(|&&s| s).count() as f64 / n.max(1) as f64,
    })
}

/// Two unit vectors spanning the plane perpendicular to `up`.
fn horizontal_axes(up: DVec3) -> (DVec3, DVec3) {
    let helper = if up.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let east = (helper - up * helper.dot(up)).normalize();
    (east, up.cross(east))
}

/// Weighted median camera depth of what a pose shows (∞ when it shows nothing).
fn median_depth(scene: &Scene, pose: &Pose, shown: &[f32]) -> f64 {
    let centre = pose.centre();
    let forward = pose.rotation_wc() * DVec3::Z;
    let mut depths: Vec<(f64, f64)> = shown
        .iter()
        .enumerate()
        .filter(|&(_, &w)| w > 0.0)
        .map(|(i, &w)| {
            let m = DVec3::from(scene.means[i].map(f64::from));
            ((m - centre).dot(forward), f64::from(w))
        })
        .collect();
    let total: f64 = depths.iter().map(|d| d.1).sum();
    if total <= 0.0 {
        return f64::INFINITY;
    }
    depths.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    for (depth, w) in depths {
        acc += w;
        if acc >= 0.5 * total {
            return depth;
        }
    }
    f64::INFINITY
}

/// Greedy maximum coverage: repeatedly the candidate that adds the most coverage, where a
/// Gaussian's coverage is the number of chosen views showing it, capped at `sides`.
fn greedy_cover(candidates: &[Candidate], count: usize, sides: f32) -> Vec<usize> {
    let n = candidates[0].shown.len();
    let mut covered = vec![0.0f32; n];
    let mut chosen: Vec<usize> = Vec::new();
    let soft = |w: f32| f32::from(u8::from(w >= SHOWN_WEIGHT));
    while chosen.len() < count.min(candidates.len()) {
        let best = candidates
            .iter()
            .enumerate()
            .filter(|(c, _)| !chosen.contains(c))
            .map(|(c, cand)| {
                let gain: f64 = cand
                    .shown
                    .iter()
                    .zip(&covered)
                    .map(|(&w, &have)| f64::from((have + soft(w)).min(sides) - have.min(sides)))
                    .sum();
                (c, gain)
            })
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)));
        let Some((c, gain)) = best else { break };
        if gain <= 0.0 && !chosen.is_empty() {
            break;
        }
        for (have, &w) in covered.iter_mut().zip(&candidates[c].shown) {
            *have += soft(w);
        }
        chosen.push(c);
    }
    chosen
}
