//! How long the start's pan at each join of windows lasts: long enough to keep the pacing
//! limits, short enough to leave the windows' middles framed.
//!
//! The start turns from one window's view to the next, and moves its camera centre, along
//! the smoothstep 3x² − 2x³ of time over a share s of each window on both sides of the join
//! ([`crate::optimise::start::routed_start_trajectory`]). The smoothstep's peak rate is
//! [`SMOOTHSTEP_PEAK`] = 1.5 times its mean, so a pan through an angle θ over 2·s·W seconds
//! (W a window's duration) peaks at 1.5·θ/(2·s·W). The angles a join asks for are the turn
//! of the view between the two views, and the orbits of the camera about each window's
//! object centre as it moves from one view's centre to the other; the share that keeps each
//! within its limit is
//!
//! ```text
//! s = clamp(1.5 · max(θ_turn/ω_turn, θ_orbit,k/ω_orbit, θ_orbit,k+1/ω_orbit) / (2W),
//!           ROUTE_TRANSITION, MAX_PAN_SHARE)
//! ```
//!
//! At least [`ROUTE_TRANSITION`] (a quarter window, what every pan had before), at most
//! [`MAX_PAN_SHARE`]: beyond a third the smoothstep's first eighth of the turn (about 8° of a
//! 60° pan) reaches the window's middle 60 %, which the verdict's `framed_share` judges; a
//! join that needs longer breaks a limit or a framing either way, and is a place to cut.

use glam::DVec3;
use splatraj_render::camera::Pose;

use super::route::ROUTE_TRANSITION;
use super::start::WindowStart;
use crate::costs::motion::SMOOTHSTEP_PEAK;

/// Largest share of a window on each side of a join over which the start pans (module docs).
pub const MAX_PAN_SHARE: f64 = 1.0 / 3.0;

/// The limits a start's pans keep, degrees per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PanLimits {
    /// Turning rate of the view (`costs.motion.max_angular_speed`).
    pub turn: Option<f64>,
    /// Orbit rate about a window's object centre (`costs.motion.max_orbit_speed`).
    pub orbit: Option<f64>,
    /// Duration of one window, seconds.
    pub window_seconds: f64,
}

/// The share of each window on both sides of each join (one per join of `per_window`) over
/// which the start pans (module docs); `centres[i]` is window i's object centre.
pub fn pan_shares(per_window: &[WindowStart], centres: &[[f64; 3]], limits: PanLimits) -> Vec<f64> {
    (0..per_window.len().saturating_sub(1))
        .map(|k| {
            let (a, b) = (per_window[k].pose_at(1.0), per_window[k + 1].pose_at(0.0));
            let turn = rotation_angle(&a, &b).to_degrees();
            let orbit = |i: usize| {
                centres.get(i).map_or(0.0, |&o| {
                    let o = DVec3::from(o);
                    let (u, v) = (a.centre() - o, b.centre() - o);
                    u.cross(v).length().atan2(u.dot(v)).to_degrees()
                })
            };
            // Seconds each angle needs at its limit (none without a limit).
            let needs = |angle: f64, limit: Option<f64>| limit.map_or(0.0, |l| angle / l);
            let seconds = needs(turn, limits.turn)
                .max(needs(orbit(k), limits.orbit))
                .max(needs(orbit(k + 1), limits.orbit));
            let share = SMOOTHSTEP_PEAK * seconds / (2.0 * limits.window_seconds.max(1e-9));
            share.clamp(ROUTE_TRANSITION, MAX_PAN_SHARE)
        })
        .collect()
}

/// The angle (radians) of the rotation between two poses' orientations.
pub(crate) fn rotation_angle(a: &Pose, b: &Pose) -> f64 {
    let relative = a.rotation_wc().transpose() * b.rotation_wc();
    let trace = relative.x_axis.x + relative.y_axis.y + relative.z_axis.z;
    ((trace - 1.0) * 0.5).clamp(-1.0, 1.0).acos()
}
