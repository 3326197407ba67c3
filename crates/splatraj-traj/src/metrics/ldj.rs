//! Log dimensionless jerk (LDJ, Hogan & Sternad 2009), reported as +ln: higher = jerkier.
//!
//! For a motion x(t), t ∈ [t₁, t₂] (docs/conventions.md "Metrics"):
//!
//! ```text
//! LDJ = ln( (t₂ − t₁)³ / v_peak² · ∫ ‖d³x/dt³‖² dt ),   v_peak = max ‖dx/dt‖
//! ```
//!
//! It is dimensionless: scaling the distance cancels between the jerk and v_peak², scaling the
//! duration between (t₂ − t₁)³, the jerk's t⁻⁶·t and v_peak's t⁻². A minimum-jerk
//! rest-to-rest movement scores ln(720/1.875²) ≈ 5.32.
//!
//! Discretisation (samples x₀ … x_{N−1} on a uniform grid of step h = (t₂ − t₁)/(N − 1), N ≥ 5),
//! every piece second-order accurate so a fine grid converges as h²:
//! - velocity: central difference (x_{i+1} − x_{i−1})/(2h) inside, one-sided
//!   (∓3x_i ± 4x_{i±1} ∓ x_{i±2})/(2h) at the two ends; v_peak is the largest norm on the grid;
//! - jerk: the central 5-point stencil (−x_{i−2} + 2x_{i−1} − 2x_{i+1} + x_{i+2})/(2h³) inside,
//!   the one-sided (−5, 18, −24, 14, −3)/(2h³) (mirrored at the end) at the first and last two
//!   points, where the central one would step outside the samples;
//! - the integral of ‖jerk‖²: trapezoid rule over all N points.
//!
//! A trajectory with jumps (the waypoint model) has no finite jerk: its sampled LDJ grows like
//! 3·ln N with the number of samples (each jump adds ~Δ²/h⁵ to the integral and makes v_peak
//! ~Δ/h). Compare LDJs at the same sampling; the run reports them at [`DEFAULT_LDJ_SAMPLES`].

use serde::{Deserialize, Serialize};

use crate::trajectory::{Pose, Trajectory, uniform_times};

/// Samples over [0, 1] at which a trajectory's LDJ is reported by default.
pub const DEFAULT_LDJ_SAMPLES: usize = 1001;

/// Fewest samples the stencils need.
pub const MIN_LDJ_SAMPLES: usize = 5;

/// Floor on the dimensionless jerk before the log, so a jerk-free motion (constant velocity)
/// gets a finite LDJ, ln(1e-12) ≈ −27.6, instead of −∞ or a value made of round-off.
pub const DIMENSIONLESS_JERK_FLOOR: f64 = 1e-12;

/// Relative peak-speed threshold below which a motion counts as standing still (no LDJ).
pub const STILL_TOLERANCE: f64 = 1e-12;

/// Positional and angular LDJ of a whole trajectory; `None` where that part does not move.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Smoothness {
    /// LDJ of the camera centre c(t).
    pub positional: Option<f64>,
    /// LDJ of the rotation vector ω(t).
    pub angular: Option<f64>,
}

/// LDJ of a motion sampled at `samples.len()` evenly spaced times spanning `duration`.
///
/// `None` when it cannot be defined: fewer than [`MIN_LDJ_SAMPLES`] samples, a duration that is
/// not finite and positive, a non-finite sample, or no motion (peak speed × duration at most
/// [`STILL_TOLERANCE`] × (1 + the largest coordinate magnitude): v_peak = 0 would divide by 0).
pub fn ldj<const D: usize>(samples: &[[f64; D]], duration: f64) -> Option<f64> {
    let n = samples.len();
    if n < MIN_LDJ_SAMPLES
        || !(duration.is_finite() && duration > 0.0)
        || samples.iter().flatten().any(|v| !v.is_finite())
    {
        return None;
    }
    let h = duration / (n - 1) as f64;
    let x = |i: usize, d: usize| samples[i][d];

    let v_peak = (0..n)
        .map(|i| {
            let speed2: f64 = (0..D)
                .map(|d| {
                    let v = if i == 0 {
                        -3.0 * x(0, d) + 4.0 * x(1, d) - x(2, d)
                    } else if i == n - 1 {
                        3.0 * x(i, d) - 4.0 * x(i - 1, d) + x(i - 2, d)
                    } else {
                        x(i + 1, d) - x(i - 1, d)
                    } / (2.0 * h);
                    v * v
                })
                .sum();
            speed2.sqrt()
        })
        .fold(0.0, f64::max);
    let extent = samples.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    if v_peak * duration <= STILL_TOLERANCE * (1.0 + extent) {
        return None;
    }

    let h3 = 2.0 * h * h * h;
    let jerk2 = |i: usize| -> f64 {
        (0..D)
            .map(|d| {
                let j = if i < 2 {
                    -5.0 * x(i, d) + 18.0 * x(i + 1, d) - 24.0 * x(i + 2, d) + 14.0 * x(i + 3, d)
                        - 3.0 * x(i + 4, d)
                } else if i + 2 >= n {
                    5.0 * x(i, d) - 18.0 * x(i - 1, d) + 24.0 * x(i - 2, d) - 14.0 * x(i - 3, d)
                        + 3.0 * x(i - 4, d)
                } else {
                    -x(i - 2, d) + 2.0 * x(i - 1, d) - 2.0 * x(i + 1, d) + x(i + 2, d)
                } / h3;
                j * j
            })
            .sum()
    };
    // Trapezoid rule: interior points weigh h, the two end points h/2.
    let integral = h * ((1..n - 1).map(jerk2).sum::<f64>() + 0.5 * (jerk2(0) + jerk2(n - 1)));

    let dimensionless = duration.powi(3) / (v_peak * v_peak) * integral;
    Some(dimensionless.max(DIMENSIONLESS_JERK_FLOOR).ln())
}

/// Positional LDJ (camera centres, components 3..6) and angular LDJ (rotation vectors,
/// components 0..3) of poses sampled evenly over `duration`.
pub fn pose_ldj(poses: &[Pose], duration: f64) -> Smoothness {
    let rotation: Vec<[f64; 3]> = poses.iter().map(|p| [p[0], p[1], p[2]]).collect();
    let centre: Vec<[f64; 3]> = poses.iter().map(|p| [p[3], p[4], p[5]]).collect();
    Smoothness {
        positional: ldj(&centre, duration),
        angular: ldj(&rotation, duration),
    }
}

/// LDJ of a trajectory over its normalised time [0, 1], from `samples` evenly spaced poses.
///
/// The duration is 1; any other would give the same values (LDJ is dimensionless). A
/// trajectory cut into shots has no jerk at a cut (the switch is no motion): each shot's LDJ
/// is taken over its own span, from its share of the samples, and the shots' values are
/// averaged weighted by their durations.
pub fn trajectory_ldj(trajectory: &Trajectory, samples: usize) -> Smoothness {
    let shots = trajectory.model().shots(1);
    if shots.is_empty() {
        return pose_ldj(&trajectory.poses_at(&uniform_times(samples)), 1.0);
    }
    let spans: Vec<(f64, f64)> = (0..shots.len()).map(|j| shots.span(j)).collect();
    let per_shot: Vec<(f64, Smoothness)> = spans
        .iter()
        .map(|&(a, b)| {
            let count = ((samples as f64 * (b - a)).round() as usize).max(MIN_LDJ_SAMPLES);
            // Inside the shot: its end is the next shot's first time.
            let times: Vec<f64> = uniform_times(count)
                .iter()
                .map(|u| a + u * (b - a) * (1.0 - 1e-9))
                .collect();
            (b - a, pose_ldj(&trajectory.poses_at(&times), b - a))
        })
        .collect();
    let mean = |value: fn(&Smoothness) -> Option<f64>| {
        let kept: Vec<(f64, f64)> = per_shot
            .iter()
            .filter_map(|(w, s)| value(s).map(|v| (*w, v)))
            .collect();
        let total: f64 = kept.iter().map(|k| k.0).sum();
        (total > 0.0).then(|| kept.iter().map(|(w, v)| w * v).sum::<f64>() / total)
    };
    Smoothness {
        positional: mean(|s| s.positional),
        angular: mean(|s| s.angular),
    }
}
