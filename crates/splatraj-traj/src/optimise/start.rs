//! Starting poses: seeded random cameras looking at the scene's centre, or cameras that
//! already look at each query's object.
//!
//! **Random** ([`random_start_poses`]). The distribution ([`StartDistribution`], config table `[start]`): with m the centre and h
//! the half-extent of the scene's robust bounding box,
//! - the camera centre is uniform in the box m ± `spread`·h (per axis);
//! - the camera looks at m, upright (image up toward world up); when the centre falls within
//!   1e-3·‖h‖ of m, or the view would be straight up or down, it looks along a uniformly random
//!   horizontal direction instead.
//!
//! The spread defaults to 0.5: inside a room (the demo) the cameras stay well inside the walls;
//! around an object capture they start inside the capture volume and the prior pulls them out
//! to their working distance. The same seed gives the same poses.
//!
//! **Objects** ([`object_start_poses`]): one pose per query, at the query's prior radius from
//! its object, looking at it from `elevation` degrees above the horizontal (default 30). All
//! objects are seen from the same horizontal direction: from the objects' mean centre toward
//! the scene's centre (inside a room, the open side), so consecutive windows differ by a
//! translation more than a turn, and the trajectory between them stays short; an object
//! capture's camera side is unknown, so there it is a guess. Restart k > 0 turns that common
//! azimuth by a seeded uniform angle in ±`jitter` degrees. It is the pose the prior pulls
//! toward, made explicit, so the image costs are in play from the first step. Its poses are
//! meant for a piecewise-constant fit per window (the caller fits the model).

use glam::{DMat3, DQuat, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use splatraj_render::camera::Pose;

use burn::tensor::{DType, Device};

use super::OptimiseError;
use super::route::{ROUTE_TRANSITION, Transition};
use super::sampling::{window_bounds, window_of};
use crate::shots::ShotPath;
use crate::trajectory::{Trajectory, TrajectoryModel, uniform_times};

/// How random starts are drawn (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StartDistribution {
    /// Fraction of the half-extent within which camera centres are drawn, in (0, 1]. Default 0.5.
    pub spread: f64,
}

impl Default for StartDistribution {
    /// Spread 0.5.
    fn default() -> Self {
        Self { spread: 0.5 }
    }
}

/// `count` random start poses in the box `centre ± half_extent` (see the module docs).
pub fn random_start_poses(
    centre: [f64; 3],
    half_extent: [f64; 3],
    world_up: [f64; 3],
    distribution: &StartDistribution,
    count: usize,
    seed: u64,
) -> Result<Vec<Pose>, OptimiseError> {
    let spread = distribution.spread;
    if !(spread > 0.0 && spread <= 1.0) {
        return Err(OptimiseError::InvalidOptions {
            field: "spread",
            reason: format!("= {spread} must be in (0, 1]"),
        });
    }
    let (m, h, up) = (
        DVec3::from(centre),
        DVec3::from(half_extent).abs(),
        DVec3::from(world_up).normalize_or_zero(),
    );
    if !(m.is_finite() && h.is_finite() && up != DVec3::ZERO && up.is_finite()) {
        return Err(OptimiseError::InvalidOptions {
            field: "scene bounds",
            reason: format!("centre {m}, half-extent {h} and up {up} must be finite, up non-zero"),
        });
    }
    // Two horizontal axes, for the fallback viewing direction.
    let side = up.any_orthonormal_vector();
    let front = up.cross(side);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut poses = Vec::with_capacity(count);
    for _ in 0..count {
        let offset = DVec3::new(
            rng.random_range(-1.0..=1.0),
            rng.random_range(-1.0..=1.0),
            rng.random_range(-1.0..=1.0),
        ) * h
            * spread;
        let eye = m + offset;
        let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
        let horizontal = side * azimuth.cos() + front * azimuth.sin();
        let towards_centre = Pose::look_at(eye, m, up).ok();
        let near_centre = offset.length() <= 1e-3 * h.length();
        let pose = match towards_centre {
            Some(p) if !near_centre => p,
            _ => Pose::look_at(eye, eye + horizontal, up).expect("horizontal view is not along up"),
        };
        poses.push(pose);
    }
    Ok(poses)
}

/// Default elevation of the object starts' viewing direction above the horizontal, degrees.
pub const OBJECT_START_ELEVATION_DEGREES: f64 = 30.0;

/// How object starts look at their objects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectView {
    /// Elevation of the viewing direction above the horizontal, degrees, in (−90, 90).
    pub elevation_degrees: f64,
    /// Azimuth jitter of restarts after the first, ± degrees (≥ 0).
    pub jitter_degrees: f64,
}

impl Default for ObjectView {
    /// 30° elevation, ±45° jitter.
    fn default() -> Self {
        Self {
            elevation_degrees: OBJECT_START_ELEVATION_DEGREES,
            jitter_degrees: 45.0,
        }
    }
}

/// One start pose per object `(centre, prior radius)` (see the module docs); restart `restart`
/// (0: no jitter).
pub fn object_start_poses(
    objects: &[([f64; 3], f64)],
    scene_centre: [f64; 3],
    world_up: [f64; 3],
    view: ObjectView,
    restart: usize,
    seed: u64,
) -> Result<Vec<Pose>, OptimiseError> {
    if !(view.elevation_degrees.abs() < 90.0 && view.jitter_degrees.is_finite()) {
        return Err(OptimiseError::InvalidOptions {
            field: "elevation",
            reason: format!(
                "= {}° must be in (−90°, 90°) (a view along up has no horizon)",
                view.elevation_degrees
            ),
        });
    }
    let jitter_degrees = view.jitter_degrees.abs();
    let up = DVec3::from(world_up).normalize_or_zero();
    if up == DVec3::ZERO || !up.is_finite() {
        return Err(OptimiseError::InvalidOptions {
            field: "world_up",
            reason: format!("{world_up:?} must be finite and non-zero"),
        });
    }
    if objects.is_empty() {
        return Ok(Vec::new());
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (restart as u64).wrapping_mul(0x9E37_79B9));
    let elevation = view.elevation_degrees.to_radians();
    let centres: Vec<[f64; 3]> = objects.iter().map(|(c, _)| *c).collect();
    let horizontal = DVec3::from(object_side(&centres, scene_centre, up.to_array()));
    let turn = if restart == 0 {
        0.0
    } else {
        rng.random_range(-jitter_degrees..=jitter_degrees)
            .to_radians()
    };
    let side = up.cross(horizontal);
    let direction = horizontal * turn.cos() + side * turn.sin();
    objects
        .iter()
        .map(|&(centre, radius)| {
            let o = DVec3::from(centre);
            let eye = o + (direction * elevation.cos() + up * elevation.sin()) * radius;
            Pose::look_at(eye, o, up).map_err(|e| OptimiseError::InvalidOptions {
                field: "objects",
                reason: format!("no start pose for the object at {centre:?}: {e}"),
            })
        })
        .collect()
}

/// The horizontal direction object starts (and shots, at azimuth 0) see the objects from:
/// from the objects' mean centre toward the scene's centre (module docs), unit length; any
/// horizontal direction when the objects surround the middle. `world_up` must be non-zero.
pub fn object_side(objects: &[[f64; 3]], scene_centre: [f64; 3], world_up: [f64; 3]) -> [f64; 3] {
    let up = DVec3::from(world_up).normalize_or_zero();
    let mean = objects.iter().map(|c| DVec3::from(*c)).sum::<DVec3>() / objects.len().max(1) as f64;
    let to_middle = DVec3::from(scene_centre) - mean;
    let horizontal = (to_middle - up * to_middle.dot(up)).normalize_or_zero();
    // Objects around the middle have no preferred side: any horizontal direction will do.
    if horizontal == DVec3::ZERO || !horizontal.is_finite() {
        up.any_orthonormal_vector().to_array()
    } else {
        horizontal.to_array()
    }
}

/// ω rewritten as the equivalent rotation vector nearest `previous` (ω and ω·(1 − 2π/|ω|)
/// are the same rotation), so that fitting a model through consecutive poses does not swing
/// through a full turn.
pub fn unwrap_rotation(previous: [f64; 3], omega: [f64; 3]) -> [f64; 3] {
    let w = DVec3::from(omega);
    let theta = w.length();
    if theta < 1e-9 {
        return omega;
    }
    let p = DVec3::from(previous);
    let candidates = [-1.0, 0.0, 1.0].map(|k: f64| w * (1.0 + k * std::f64::consts::TAU / theta));
    candidates
        .into_iter()
        .min_by(|a, b| a.distance_squared(p).total_cmp(&b.distance_squared(p)))
        .expect("three candidates")
        .to_array()
}

/// Samples of [0, 1] used to fit a start trajectory (enough for the finest model, 100 waypoint
/// segments, to get several samples per segment).
pub const START_FIT_SAMPLES: usize = 401;

/// What a start asks of one window: hold one pose, or follow a shot's ideal path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WindowStart {
    /// The same pose throughout the window.
    Hold(Pose),
    /// The shot's pose at each time of the window ([`ShotPath::pose_at`]).
    Shot(ShotPath),
}

impl WindowStart {
    /// The pose asked for at s ∈ [0, 1] within the window.
    pub fn pose_at(&self, s: f64) -> Pose {
        match self {
            WindowStart::Hold(p) => *p,
            WindowStart::Shot(shot) => shot.pose_at(s),
        }
    }
}

/// The trajectory of `model` closest (least squares) to holding `per_window[i]` throughout
/// window i; rotation vectors are unwrapped along the sequence first ([`unwrap_rotation`]).
pub fn window_start_trajectory(
    model: TrajectoryModel,
    per_window: &[Pose],
    device: &Device,
    dtype: DType,
) -> Result<Trajectory, OptimiseError> {
    let starts: Vec<WindowStart> = per_window.iter().map(|p| WindowStart::Hold(*p)).collect();
    start_trajectory(model, &starts, device, dtype)
}

/// The trajectory of `model` closest (least squares) to what `per_window[i]` asks of window
/// i (a held pose or a shot's path), sampled at [`START_FIT_SAMPLES`] times; rotation vectors
/// are unwrapped along the samples in time order first ([`unwrap_rotation`]).
pub fn start_trajectory(
    model: TrajectoryModel,
    per_window: &[WindowStart],
    device: &Device,
    dtype: DType,
) -> Result<Trajectory, OptimiseError> {
    routed_start_trajectory(model, per_window, &[], &[], device, dtype)
}

/// Each window's end and the next window's start camera centre, per join (what
/// [`crate::optimise::route::plan_transitions`] routes between).
pub fn window_joins(per_window: &[WindowStart]) -> Vec<(DVec3, DVec3)> {
    per_window
        .windows(2)
        .map(|w| (w[0].pose_at(1.0).centre(), w[1].pose_at(0.0).centre()))
        .collect()
}

/// [`start_trajectory`] whose camera centres follow `transitions` (planned routes around the
/// geometry, [`crate::optimise::route`]) over their times, with the pan at join k over
/// `shares[k]` of each window ([`crate::optimise::pans::pan_shares`]; a join beyond the list
/// pans over [`ROUTE_TRANSITION`]).
///
/// **Joins.** Around each join of two windows the start does not jump from one window's pose
/// to the next: over the last share of the earlier window and the first of the later one
/// (not inside a window with a shot, whose path is the shot's), the orientation
/// turns from the one to the other (slerp) and the centre moves along the join's route, or
/// straight, both by the smoothstep 3x² − 2x³ of time, at rest at both ends: a pan from one
/// framed object to the next. A step is what no smooth model can hold: fitted by 3 RBF
/// centres per window, a jump rang through the whole window (the first-try donut's windows
/// started at TCE 0.24 before any step); a blend is a smooth target the model fits. The
/// path's first and last windows hold their poses to t = 0 and t = 1: it starts and ends at
/// rest.
pub fn routed_start_trajectory(
    model: TrajectoryModel,
    per_window: &[WindowStart],
    transitions: &[Transition],
    shares: &[f64],
    device: &Device,
    dtype: DType,
) -> Result<Trajectory, OptimiseError> {
    let n = per_window.len();
    let times = uniform_times(START_FIT_SAMPLES);
    let joins = join_spans(per_window, shares);
    let mut poses: Vec<[f64; 6]> = Vec::with_capacity(times.len());
    for &t in &times {
        let i = window_of(t, n);
        let (start, end) = window_bounds(i, n);
        let mut pose = per_window[i]
            .pose_at(((t - start) / (end - start)).clamp(0.0, 1.0))
            .0;
        if let Some(&(k, from, to)) = joins.iter().find(|(_, a, b)| t > *a && t < *b) {
            let s = smoothstep((t - from) / (to - from));
            let (a, b) = (per_window[k].pose_at(1.0), per_window[k + 1].pose_at(0.0));
            let turn =
                DQuat::from_mat3(&a.rotation_wc()).slerp(DQuat::from_mat3(&b.rotation_wc()), s);
            let centre = a.centre().lerp(b.centre(), s);
            pose = Pose::from_rotation_and_centre(DMat3::from_quat(turn), centre).0;
        }
        if let Some(route) = transitions
            .iter()
            .find(|r| t >= r.times.0 && t <= r.times.1)
        {
            pose[3..].copy_from_slice(&route.centre_at(t).to_array());
        }
        if let Some(prev) = poses.last() {
            let w = unwrap_rotation([prev[0], prev[1], prev[2]], [pose[0], pose[1], pose[2]]);
            pose[..3].copy_from_slice(&w);
        }
        poses.push(pose);
    }
    Ok(Trajectory::fit(model, &times, &poses, device, dtype)?)
}

/// (join k, from, to): the time span over which the start turns from window k's end pose to
/// window k + 1's start pose, `shares[k]` of each window (see [`routed_start_trajectory`]);
/// none beside a shot's window.
fn join_spans(per_window: &[WindowStart], shares: &[f64]) -> Vec<(usize, f64, f64)> {
    let n = per_window.len().max(1) as f64;
    let held = |w: &WindowStart| matches!(w, WindowStart::Hold(_));
    (0..per_window.len().saturating_sub(1))
        .filter_map(|k| {
            let join = (k + 1) as f64 / n;
            let share = shares.get(k).copied().unwrap_or(ROUTE_TRANSITION);
            let before = if held(&per_window[k]) { share / n } else { 0.0 };
            let after = if held(&per_window[k + 1]) {
                share / n
            } else {
                0.0
            };
            (before + after > 0.0).then_some((k, join - before, join + after))
        })
        .collect()
}

/// 3x² − 2x³ on [0, 1]: 0 to 1 at rest at both ends.
fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}
