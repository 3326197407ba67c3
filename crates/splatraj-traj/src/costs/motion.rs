//! Motion limits: keeps the camera's speed, acceleration, turning rate and orbit rate within
//! bounds, and optionally its speed even, along the densely sampled path.
//!
//! The path is played over `seconds` (the config's `[output] seconds`): normalised time t
//! becomes t·T seconds. On the path's evenly spaced poses (time step h, so Δt = h·T seconds)
//!
//! ```text
//! v_k = (c_{k+1} − c_k)/Δt,   a_k = (c_{k+1} − 2c_k + c_{k−1})/Δt²,
//! θ_k² ≈ ‖R_{k+1} − R_k‖²_F / 2                 (= 4 sin²(θ/2) ≈ θ² for the small turn θ)
//! u_k = (c_k − o)/‖c_k − o‖,   φ_k² ≈ ‖u_{k+1} − u_k‖²   (= 4 sin²(φ/2), φ the orbit angle)
//! L_motion = mean_k max(0, ‖v_k‖²/v_max² − 1) + mean_k max(0, ‖a_k‖²/a_max² − 1)
//!          + mean_k max(0, θ_k²/(ω_max Δt)² − 1) + mean_k max(0, φ_k²/(ψ_max Δt)² − 1)
//!          + w_even · mean_k (‖v_k‖²/mean‖v‖² − 1)²
//! ```
//!
//! with o the window's object centre ([`super::QueryContext::object_centre`]): the orbit rate
//! is how fast the camera circles its subject (docs/conventions.md, "Pacing"). ‖c_k − o‖ is
//! floored at 10⁻⁶ of the prior radius so a camera at o has a finite value and gradient.
//!
//! Each limit term is 0 within its bound and grows linearly with the relative excess of the
//! squared rate (no square root, so no NaN gradient at rest); a limit left out of the config
//! is not charged. Linear, not quadratic, on purpose: a quadratic penalty's pull vanishes at
//! the bound, so any competing cost (the prior pulling toward the next object) leaves the
//! rate above it, while a linear one is an exact penalty: with a large enough weight the
//! optimum keeps the bound (measured: a quadratic hinge of weight 50 left a 1 unit/s limit at
//! 1.5–1.6 units/s on `tests/clearance.rs`' two-object path). The even-speed term is the spread of the squared speed about its
//! mean over the window's stretch of path, scale-free. It is a path cost
//! ([`CostDomain::Path`]): with no path (single poses) it is 0. It batches windows: on a
//! joined path each term is the mean over each window's own rows (its own time step and
//! object centre, its own mean speed for the even-speed ratio), so the differences that
//! pair one window's last pose with the next window's first weigh nothing
//! ([`super::path`]).
//!
//! It reads nothing but the poses, so it is computed on the host in f64, value and gradient by
//! hand ([`super::motion_rates`]), from the poses a step reads back anyway, and joins the graph
//! by its first-order expansion about them ([`super::expansion`]): as burn ops its slices,
//! differences and Rodrigues were 139 of a first-try step's 349 GPU launches.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::expansion::per_stretch_on_host;
use super::motion_rates::{MIN_POSES, MotionLimits, Stretch, stretch_charge};
use super::{Cost, CostDomain, CostError, CostInputs, OrAuto, check_weight, invalid};

/// The motion-limit cost: table `[costs.motion]`, keys `weight` (default 1), `max_speed`
/// (scene units per second), `max_acceleration` (scene units per second²),
/// `max_angular_speed` and `max_orbit_speed` (degrees per second), each optional, and `even_speed` (weight of the
/// even-speed term, default 0). Needs `[output] seconds` when a limit is given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MotionCost {
    /// Weight (≥ 0).
    pub weight: f64,
    /// Largest camera speed, scene units per second (> 0), or `"auto"`: derived from the
    /// scene when the experiment is prepared ([`auto_max_speed`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_speed: Option<OrAuto>,
    /// Largest camera acceleration, scene units per second² (> 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_acceleration: Option<f64>,
    /// Largest turning rate of the view, degrees per second (> 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_angular_speed: Option<f64>,
    /// Largest orbit rate about the window's object centre, degrees per second (> 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_orbit_speed: Option<f64>,
    /// Weight of the even-speed term (≥ 0; 0 leaves the speed free).
    pub even_speed: f64,
}

impl Default for MotionCost {
    /// Weight 1, no limits, speed free.
    fn default() -> Self {
        Self {
            weight: 1.0,
            max_speed: None,
            max_acceleration: None,
            max_angular_speed: None,
            max_orbit_speed: None,
            even_speed: 0.0,
        }
    }
}

/// Turning-rate limit of a config without `[costs]`, degrees per second: 80 % of the rate a
/// viewer follows ([`crate::pacing::MAX_TURN_RATE`], the verdict's limit), since this linear
/// penalty lets the image costs push a rate past it and sees the path on the optimiser's
/// grid, coarser than the verdict's (measured on three first-try captures: at 40°/s the
/// peaks reached 46°/s; at 36°/s, with the pans of `optimise::pans`, 37°/s).
pub const FIRST_TRY_MAX_ANGULAR_SPEED: f64 = 36.0;

/// Orbit-rate limit of a config without `[costs]`, degrees per second: 80 % of
/// [`crate::pacing::MAX_ORBIT_RATE`], for the same reason (at 40°/s the peaks reached
/// 49°/s; at 36°/s, 37°/s).
pub const FIRST_TRY_MAX_ORBIT_SPEED: f64 = 36.0;

/// How many working distances (prior radii) per second the automatic speed limit allows.
pub const AUTO_SPEED_RADII_PER_SECOND: f64 = 1.5;

/// Share of a window's duration the automatic speed limit allows for the move from one
/// object to the next: the start pans over at least the last and first quarter of the windows
/// at a join (`optimise::route::ROUTE_TRANSITION`; more where the pacing limits ask for it,
/// `optimise::pans`), half a window in all: the speed that shortest pan needs bounds them all.
pub const AUTO_SPEED_JOIN_SHARE: f64 = 0.5;

/// Peak over mean speed of the start's eased pans (the smoothstep 3x² − 2x³).
pub const SMOOTHSTEP_PEAK: f64 = 1.5;

/// The speed `"auto"` stands for: [`AUTO_SPEED_RADII_PER_SECOND`] mean working distances per
/// second, raised to what the start's longest pan needs: `largest_travel` (a bound on the
/// camera's way from one window's view to the next: the objects' distance plus both working
/// distances) in [`AUTO_SPEED_JOIN_SHARE`] of a window of `window_seconds`, at the eased pan's
/// peak ([`SMOOTHSTEP_PEAK`]). A limit below that would fight the start from the first step.
pub fn auto_max_speed(mean_radius: f64, largest_travel: f64, window_seconds: f64) -> f64 {
    let steady = AUTO_SPEED_RADII_PER_SECOND * mean_radius;
    let travel =
        SMOOTHSTEP_PEAK * largest_travel / (AUTO_SPEED_JOIN_SHARE * window_seconds).max(1e-9);
    steady.max(travel)
}

impl MotionCost {
    /// The motion limits of a config without `[costs]`: speed `"auto"`, turning at most
    /// [`FIRST_TRY_MAX_ANGULAR_SPEED`], orbiting at most [`FIRST_TRY_MAX_ORBIT_SPEED`], weight 1: a preference the image costs can overrule
    /// (at 10 the limits won against framing on the first-try tray: the camera backed away
    /// from its objects to turn less).
    pub fn first_try() -> Self {
        Self {
            weight: 1.0,
            max_speed: Some(OrAuto::Auto),
            max_acceleration: None,
            max_angular_speed: Some(FIRST_TRY_MAX_ANGULAR_SPEED),
            max_orbit_speed: Some(FIRST_TRY_MAX_ORBIT_SPEED),
            even_speed: 0.0,
        }
    }

    /// The limits in per-second units and radians, or why `max_speed` has no number yet.
    fn limits(&self) -> Result<MotionLimits, CostError> {
        let speed = match self.max_speed {
            Some(OrAuto::Value(limit)) => Some(limit),
            Some(OrAuto::Auto) => {
                return Err(invalid(
                    self.name(),
                    "max_speed",
                    "is \"auto\" but was never derived from a scene (prepare the experiment \
                     first, or give a number)"
                        .into(),
                ));
            }
            None => None,
        };
        Ok(MotionLimits {
            speed,
            acceleration: self.max_acceleration,
            turn: self.max_angular_speed.map(f64::to_radians),
            orbit: self.max_orbit_speed.map(f64::to_radians),
            even_speed: self.even_speed,
        })
    }

    /// Whether any limit needs the path's duration.
    pub fn needs_duration(&self) -> bool {
        self.max_speed.is_some()
            || self.max_acceleration.is_some()
            || self.max_angular_speed.is_some()
            || self.max_orbit_speed.is_some()
    }
}

impl Cost for MotionCost {
    fn name(&self) -> &'static str {
        "motion"
    }
    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }
    fn domain(&self) -> CostDomain {
        CostDomain::Path
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "weight", self.weight)?;
        check_weight(self.name(), "even_speed", self.even_speed)?;
        for (field, value) in [
            ("max_speed", self.max_speed.and_then(OrAuto::value)),
            ("max_acceleration", self.max_acceleration),
            ("max_angular_speed", self.max_angular_speed),
            ("max_orbit_speed", self.max_orbit_speed),
        ] {
            if let Some(v) = value
                && !(v.is_finite() && v > 0.0)
            {
                return Err(invalid(
                    self.name(),
                    field,
                    format!("= {v} must be finite and > 0"),
                ));
            }
        }
        Ok(())
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let Some(path) = inputs.path() else {
            return Ok(inputs
                .poses()
                .clone()
                .narrow(1, 0, 1)
                .reshape([inputs.batch()])
                * 0.0);
        };
        if path.rows() < MIN_POSES {
            // Nothing to charge (and nothing the duration or the limits are needed for).
            let zero = path.poses.clone().narrow(1, 0, 1).sum().mul_scalar(0.0); // [1]
            return Ok(zero.expand([path.stretches().len()]));
        }
        let seconds = match (path.seconds, self.needs_duration()) {
            (Some(s), _) => s,
            (None, false) => 1.0,
            (None, true) => {
                return Err(CostError::InvalidContext {
                    field: "seconds",
                    reason: "motion limits need the path's duration: set `[output] seconds`".into(),
                });
            }
        };
        let limits = self.limits()?;
        // On the host, each stretch on its own (docs/gpu.md, "Costs on the host").
        per_stretch_on_host(inputs, self.name(), |stretch, poses| {
            let floor = 1e-6 * stretch.context.prior_radius;
            stretch_charge(
                &limits,
                &Stretch {
                    poses,
                    dt: stretch.time_step * seconds,
                    pivot: stretch.context.object_centre,
                    floor_sq: floor * floor,
                },
            )
        })
    }
}
