//! How a trajectory moves through the scene, per query window: clearance from the geometry
//! and peak speed, acceleration, turning and orbit rate (docs/conventions.md "Clearance and
//! motion").
//!
//! The trajectory is sampled on one even grid over [0, 1], made fine enough that consecutive
//! camera centres are at most a quarter of the clearance margin apart (so no surface can pass
//! between two samples unseen: a path that crosses a surface has a sample within an eighth of
//! the margin of it). Each window gets the samples inside it (its boundaries included).
//!
//! - Clearance: signed distance of each sample's centre to the nearest solid surface
//!   ([`crate::clearance`]), searched up to [`CLEARANCE_CAP_MARGINS`] margins away: a value
//!   at that cap means "at least this". `time_inside_margin` is the share of the window's
//!   samples (of its time: the grid is even) closer than the margin.
//! - Motion: finite differences on the grid, Δt = h·T with T the trajectory's duration in
//!   seconds (per unit of normalised time when none is given): speed ‖Δc‖/Δt between
//!   consecutive samples, acceleration ‖c_{k+1} − 2c_k + c_{k−1}‖/Δt² at inner samples,
//!   angular speed the exact angle of R_kᵀR_{k+1} over Δt, in degrees per second.
//! - Orbit rate, when the window's object centre o is given: the exact angle between the
//!   directions from o to consecutive camera centres, (c_k − o)/‖c_k − o‖, over Δt, in degrees
//!   per second: how fast the camera circles its subject, which a viewer reads as the subject
//!   turning. Computed here from the poses on the host, independently of the motion cost's
//!   tensor form (a chord, not an angle), so the verdict does not grade the cost by itself.
//!
//! A trajectory cut into shots ([`crate::trajectory::cuts`]) jumps at each cut: a difference
//! between samples of two shots is no motion and is left out of every rate, and a window's
//! clearance takes only the samples of its own shot (the sample on a window's end that is a
//! cut is the next shot's camera).

use glam::DVec3;
use serde::Serialize;
use splatraj_render::camera::rotation_vector_to_matrix;

use crate::clearance::Occupancy;
use crate::optimise::sampling::window_bounds;
use crate::trajectory::{Pose, ShotSpans, uniform_times};

/// Clearances are searched this many margins away; beyond it they read as the cap.
pub const CLEARANCE_CAP_MARGINS: f64 = 4.0;

/// Most grid points the metrics refine to (a path longer than this many quarter-margins is
/// checked more coarsely, and says so in `largest_gap`).
pub const MAX_PATH_SAMPLES: usize = 40_001;

/// Clearance of one window's stretch of path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClearanceMetrics {
    /// The margin the clearance cost keeps.
    pub margin: f64,
    /// Smallest clearance on the window's samples (capped at `CLEARANCE_CAP_MARGINS` × margin).
    pub min_clearance: f64,
    /// Share of the window's time closer to the geometry than the margin.
    pub time_inside_margin: f64,
    /// Largest distance between consecutive camera centres of the grid (whole path).
    pub largest_gap: f64,
}

/// Peak rates of one window's stretch of path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MotionMetrics {
    /// Duration of the whole trajectory in seconds the rates are per (None: per unit of
    /// normalised time).
    pub seconds: Option<f64>,
    /// Largest speed, scene units per second.
    pub peak_speed: f64,
    /// Largest acceleration, scene units per second².
    pub peak_acceleration: f64,
    /// Largest turning rate, degrees per second.
    pub peak_angular_speed: f64,
    /// Largest orbit rate about the window's object centre, degrees per second (None: no
    /// centre given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_orbit_speed: Option<f64>,
    /// Standard deviation of the speed over its mean (0: even speed).
    pub speed_spread: f64,
}

/// Clearance (when an occupancy is given) and motion of one window.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathMetrics {
    /// Grid samples inside the window.
    pub samples: usize,
    /// Clearance from the geometry, when an occupancy was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clearance: Option<ClearanceMetrics>,
    /// Peak rates.
    pub motion: MotionMetrics,
}

/// Per-window path metrics of the trajectory whose poses `pose_at` gives, sampled at least
/// `samples` times over [0, 1] (refined for the clearance, see the module docs);
/// `clearance` is the occupancy and margin, `seconds` the duration, `orbit_centres[i]` window
/// i's object centre for its orbit rate (a window beyond the list has none).
pub fn path_metrics(
    pose_at: &dyn Fn(&[f64]) -> Vec<Pose>,
    windows: usize,
    samples: usize,
    clearance: Option<(&Occupancy, f64)>,
    seconds: Option<f64>,
    orbit_centres: &[[f64; 3]],
) -> Vec<PathMetrics> {
    let shots = ShotSpans::single(windows);
    shot_path_metrics(pose_at, &shots, samples, clearance, seconds, orbit_centres)
}

/// [`path_metrics`] of a trajectory cut into `shots` (one shot: the same): no rate is taken
/// across a cut (module docs).
pub fn shot_path_metrics(
    pose_at: &dyn Fn(&[f64]) -> Vec<Pose>,
    shots: &ShotSpans,
    samples: usize,
    clearance: Option<(&Occupancy, f64)>,
    seconds: Option<f64>,
    orbit_centres: &[[f64; 3]],
) -> Vec<PathMetrics> {
    let windows = shots.windows;
    let mut times = uniform_times(samples.max(3));
    let mut poses = pose_at(&times);
    // The largest step between consecutive samples of one shot (a cut is no step).
    let gap = |poses: &[Pose], times: &[f64]| {
        (0..poses.len().saturating_sub(1))
            .filter(|&k| shots.same_shot(times[k], times[k + 1]))
            .map(|k| centre(&poses[k]).distance(centre(&poses[k + 1])))
            .fold(0.0, f64::max)
    };
    if let Some((_, margin)) = clearance {
        let factor = (gap(&poses, &times) / (0.25 * margin)).ceil().max(1.0) as usize;
        let refined = ((times.len() - 1) * factor + 1).min(MAX_PATH_SAMPLES);
        if refined > times.len() {
            times = uniform_times(refined);
            poses = pose_at(&times);
        }
    }
    let largest_gap = gap(&poses, &times);
    let clearances = clearance.map(|(occupancy, margin)| {
        let cap = CLEARANCE_CAP_MARGINS * margin;
        let centres: Vec<DVec3> = poses.iter().map(centre).collect();
        use rayon::prelude::*;
        centres
            .par_iter()
            .map(|&c| {
                occupancy
                    .nearest_up_to(c, margin, cap)
                    .map_or(cap, |contact| contact.surface.distance.min(cap))
            })
            .collect::<Vec<f64>>()
    });
    let duration = seconds.unwrap_or(1.0);
    let dt = duration / (times.len() - 1) as f64;
    let n = windows.max(1);
    (0..n)
        .map(|i| {
            let (start, end) = window_bounds(i, n);
            let shot = shots.shot_of_window(i);
            let inside: Vec<usize> = (0..times.len())
                .filter(|&k| times[k] >= start - 1e-12 && times[k] <= end + 1e-12)
                .filter(|&k| shots.shot_of(times[k]) == shot)
                .collect();
            let (first, last) = (inside[0], *inside.last().expect("a window holds samples"));
            // Steps k → k + 1 within the window's shot (none across a cut).
            let steps = || (first..last).filter(|&k| shots.same_shot(times[k], times[k + 1]));
            let speeds: Vec<f64> = steps()
                .map(|k| centre(&poses[k]).distance(centre(&poses[k + 1])) / dt)
                .collect();
            let peak_acceleration = (first.max(1)..last.min(times.len() - 2) + 1)
                .filter(|&k| shots.same_shot(times[k - 1], times[k + 1]))
                .map(|k| {
                    let second =
                        centre(&poses[k + 1]) - 2.0 * centre(&poses[k]) + centre(&poses[k - 1]);
                    second.length() / (dt * dt)
                })
                .fold(0.0, f64::max);
            let peak_angular_speed = steps()
                .map(|k| turn_angle(&poses[k], &poses[k + 1]).to_degrees() / dt)
                .fold(0.0, f64::max);
            let peak_orbit_speed = orbit_centres.get(i).map(|&o| {
                let o = DVec3::from(o);
                steps()
                    .map(|k| {
                        let angle = angle_between(centre(&poses[k]) - o, centre(&poses[k + 1]) - o);
                        angle.to_degrees() / dt
                    })
                    .fold(0.0, f64::max)
            });
            let mean = speeds.iter().sum::<f64>() / speeds.len().max(1) as f64;
            let variance =
                speeds.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / speeds.len().max(1) as f64;
            let motion = MotionMetrics {
                seconds,
                peak_speed: speeds.iter().copied().fold(0.0, f64::max),
                peak_acceleration,
                peak_angular_speed,
                peak_orbit_speed,
                speed_spread: if mean > 0.0 {
                    variance.sqrt() / mean
                } else {
                    0.0
                },
            };
            let clearance = clearance
                .zip(clearances.as_ref())
                .map(|((_, margin), all)| {
                    let here: Vec<f64> = inside.iter().map(|&k| all[k]).collect();
                    ClearanceMetrics {
                        margin,
                        min_clearance: here.iter().copied().fold(f64::INFINITY, f64::min),
                        time_inside_margin: here.iter().filter(|&&d| d < margin).count() as f64
                            / here.len() as f64,
                        largest_gap,
                    }
                });
            PathMetrics {
                samples: inside.len(),
                clearance,
                motion,
            }
        })
        .collect()
}

fn centre(pose: &Pose) -> DVec3 {
    DVec3::new(pose[3], pose[4], pose[5])
}

/// The angle (radians) between `a` and `b`, 0 when either is zero: atan2 of the cross and dot
/// products, accurate for the small angles between consecutive grid samples (acos of a dot
/// product near 1 loses half the digits).
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// The angle (radians) of the rotation from `a`'s camera orientation to `b`'s.
fn turn_angle(a: &Pose, b: &Pose) -> f64 {
    let ra = rotation_vector_to_matrix(DVec3::new(a[0], a[1], a[2]));
    let rb = rotation_vector_to_matrix(DVec3::new(b[0], b[1], b[2]));
    let relative = ra.transpose() * rb;
    let trace = relative.x_axis.x + relative.y_axis.y + relative.z_axis.z;
    ((trace - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
}
