//! Shot presets: camera paths a query window can ask for instead of a free framing.
//!
//! A shot is a per-query option (`[[queries]] shot = { kind = "orbit", … }`). It is not a
//! separate optimiser: it becomes (1) a start for the window, the shot's ideal path fitted into
//! the trajectory model like any other start, and (2) a cost ([`crate::costs::ShotCost`]) that
//! keeps the optimised camera on that path while the usual costs (TCE, TRE, upright,
//! clearance, motion) shape the rest.
//!
//! The window's normalised time s ∈ [0, 1] runs from the window's start to its end. With o the
//! object's centre, u world up, h₀ the start's horizontal direction from the object to the
//! camera (the side object starts look from, turned by `azimuth` about u) and h(φ) = h₀
//! turned by φ about u (right-handed: counter-clockwise seen from above):
//!
//! ```text
//! orbit:  c*(s) = o + r·(cos ε·h(±s·sweep) + sin ε·u)          (+ ccw, − cw)
//! dolly:  c*(s) = o + ((1 − s)·r₀ + s·r₁)·(cos ε·h₀ + sin ε·u)
//! ```
//!
//! with ε the elevation. The camera looks at o throughout, upright; the elevation is kept in
//! (−90°, 90°) so that the view never points straight down, where "upright" has no meaning
//! and the orientation would twist.

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use splatraj_render::camera::Pose;

/// Default elevation of a shot's viewing direction above the horizontal, degrees.
pub const DEFAULT_SHOT_ELEVATION: f64 = 30.0;
/// Default sweep of an orbit, degrees.
pub const DEFAULT_ORBIT_SWEEP: f64 = 90.0;
/// Default weight of a shot's cost.
pub const DEFAULT_SHOT_WEIGHT: f64 = 10.0;
/// Default start radius of a dolly as a multiple of the window's working radius (an approach).
pub const DEFAULT_DOLLY_FROM: f64 = 1.5;

/// Which way an orbit turns about world up, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Direction {
    /// Counter-clockwise (right-handed about world up).
    #[default]
    Ccw,
    /// Clockwise.
    Cw,
}

/// A shot as the config gives it (`[[queries]] shot = { kind = "…", … }`); distances in
/// scene units, angles in degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum ShotSpec {
    /// Circle the object at a fixed elevation and radius.
    Orbit(OrbitSpec),
    /// Approach (or retreat from) the object along one view line.
    Dolly(DollySpec),
}

/// `kind = "orbit"`: elevation, radius, sweep, direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OrbitSpec {
    /// Elevation of the view above the horizontal, degrees, in (−90, 90). Default 30.
    pub elevation: f64,
    /// Distance from the object's centre, scene units (> 0). Default: the window's working
    /// radius, the distance at which the object fills the query's `target_ratio`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Angle swept over the window, degrees (> 0, at most 3600). Default 90.
    pub sweep: f64,
    /// `ccw` (default) or `cw`, seen from above.
    pub direction: Direction,
    /// Start azimuth, degrees counter-clockwise about world up from the side object starts
    /// look from. Default 0.
    pub azimuth: f64,
    /// Weight of the shot's cost (≥ 0). Default 10.
    pub weight: f64,
}

impl Default for OrbitSpec {
    /// 30° elevation, working radius, 90° counter-clockwise from azimuth 0, weight 10.
    fn default() -> Self {
        Self {
            elevation: DEFAULT_SHOT_ELEVATION,
            radius: None,
            sweep: DEFAULT_ORBIT_SWEEP,
            direction: Direction::Ccw,
            azimuth: 0.0,
            weight: DEFAULT_SHOT_WEIGHT,
        }
    }
}

/// `kind = "dolly"`: along one view line from radius `from` to radius `to`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DollySpec {
    /// Elevation of the view line above the horizontal, degrees, in (−90, 90). Default 30.
    pub elevation: f64,
    /// Distance at the window's start, scene units (> 0). Default 1.5 × the working radius.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<f64>,
    /// Distance at the window's end, scene units (> 0). Default: the working radius.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub to: Option<f64>,
    /// Azimuth of the view line, degrees, as for an orbit. Default 0.
    pub azimuth: f64,
    /// Weight of the shot's cost (≥ 0). Default 10.
    pub weight: f64,
}

impl Default for DollySpec {
    /// 30° elevation, from 1.5 × to 1 × the working radius, azimuth 0, weight 10.
    fn default() -> Self {
        Self {
            elevation: DEFAULT_SHOT_ELEVATION,
            from: None,
            to: None,
            azimuth: 0.0,
            weight: DEFAULT_SHOT_WEIGHT,
        }
    }
}

/// Why a shot cannot be placed; `field` is its key in the shot table.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("shot `{field}` {reason}")]
pub struct ShotError {
    /// Key in the shot table (`elevation`, `radius`, …) or `world_up`/`side`.
    pub field: &'static str,
    /// What is wrong and what is allowed.
    pub reason: String,
}

/// Where a window's object is and which side it is seen from: what places a shot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotFrame {
    /// The object's centre o.
    pub object_centre: [f64; 3],
    /// The window's working radius (from its target ratio; the default radius).
    pub working_radius: f64,
    /// World up (any length > 0).
    pub world_up: [f64; 3],
    /// Horizontal direction from the object toward the camera at azimuth 0 (any length > 0,
    /// not along up; its vertical part is dropped).
    pub side: [f64; 3],
}

/// A shot placed in the scene: the camera centre it asks for at each s ∈ [0, 1] of its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotPath {
    /// Object centre o (the camera looks at it).
    pub object_centre: DVec3,
    /// Unit world up u.
    pub up: DVec3,
    /// Unit horizontal direction h₀ from o to the camera at s = 0.
    pub start_side: DVec3,
    /// Elevation ε, radians.
    pub elevation: f64,
    /// Radius at s = 0 and at s = 1.
    pub radius: (f64, f64),
    /// Signed angle turned about u over the window, radians (positive: counter-clockwise).
    pub turn: f64,
    /// Weight of the shot's cost.
    pub weight: f64,
}

fn check(ok: bool, field: &'static str, reason: impl FnOnce() -> String) -> Result<(), ShotError> {
    if ok {
        Ok(())
    } else {
        Err(ShotError {
            field,
            reason: reason(),
        })
    }
}

fn positive(field: &'static str, value: f64) -> Result<f64, ShotError> {
    check(value.is_finite() && value > 0.0, field, || {
        format!("= {value} must be finite and > 0")
    })?;
    Ok(value)
}

impl ShotSpec {
    /// The shot's kind as the config names it.
    pub fn kind(&self) -> &'static str {
        match self {
            ShotSpec::Orbit(_) => "orbit",
            ShotSpec::Dolly(_) => "dolly",
        }
    }

    /// Checks the values that do not depend on the scene; errors name the key.
    pub fn validate(&self) -> Result<(), ShotError> {
        let (elevation, azimuth, weight) = match self {
            ShotSpec::Orbit(o) => (o.elevation, o.azimuth, o.weight),
            ShotSpec::Dolly(d) => (d.elevation, d.azimuth, d.weight),
        };
        check(elevation.abs() < 90.0, "elevation", || {
            format!("= {elevation}° must be in (−90°, 90°) (a view along up has no horizon)")
        })?;
        check(azimuth.is_finite(), "azimuth", || {
            format!("= {azimuth} must be finite")
        })?;
        check(weight.is_finite() && weight >= 0.0, "weight", || {
            format!("= {weight} must be finite and ≥ 0")
        })?;
        match self {
            ShotSpec::Orbit(o) => {
                if let Some(r) = o.radius {
                    positive("radius", r)?;
                }
                check(o.sweep > 0.0 && o.sweep <= 3600.0, "sweep", || {
                    format!("= {}° must be in (0°, 3600°]", o.sweep)
                })
            }
            ShotSpec::Dolly(d) => {
                if let Some(r) = d.from {
                    positive("from", r)?;
                }
                if let Some(r) = d.to {
                    positive("to", r)?;
                }
                Ok(())
            }
        }
    }

    /// The shot placed around the window's object.
    pub fn place(&self, frame: &ShotFrame) -> Result<ShotPath, ShotError> {
        self.validate()?;
        let up = DVec3::from(frame.world_up).normalize_or_zero();
        check(up != DVec3::ZERO && up.is_finite(), "world_up", || {
            format!("{:?} must be finite and non-zero", frame.world_up)
        })?;
        let side = DVec3::from(frame.side);
        let side = (side - up * side.dot(up)).normalize_or_zero();
        check(side != DVec3::ZERO && side.is_finite(), "side", || {
            format!("{:?} must be finite and not along world up", frame.side)
        })?;
        let o = DVec3::from(frame.object_centre);
        check(o.is_finite(), "object_centre", || {
            format!("{o} must be finite")
        })?;
        let working = positive("radius", frame.working_radius)?;
        let (elevation, azimuth, weight, radius, turn) = match self {
            ShotSpec::Orbit(s) => {
                let r = s.radius.unwrap_or(working);
                let sign = match s.direction {
                    Direction::Ccw => 1.0,
                    Direction::Cw => -1.0,
                };
                (
                    s.elevation,
                    s.azimuth,
                    s.weight,
                    (r, r),
                    sign * s.sweep.to_radians(),
                )
            }
            ShotSpec::Dolly(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                (
                    s.from.unwrap_or(DEFAULT_DOLLY_FROM * working),
                    s.to.unwrap_or(working),
                ),
                0.0,
            ),
        };
        Ok(ShotPath {
            object_centre: o,
            up,
            start_side: DQuat::from_axis_angle(up, azimuth.to_radians()) * side,
            elevation: elevation.to_radians(),
            radius,
            turn,
            weight,
        })
    }
}

impl ShotPath {
    /// Radius asked for at s.
    pub fn radius_at(&self, s: f64) -> f64 {
        (1.0 - s) * self.radius.0 + s * self.radius.1
    }

    /// Unit direction from the object to the camera at s.
    pub fn direction_at(&self, s: f64) -> DVec3 {
        let side = DQuat::from_axis_angle(self.up, s * self.turn) * self.start_side;
        side * self.elevation.cos() + self.up * self.elevation.sin()
    }

    /// Camera centre c*(s) asked for at s ∈ [0, 1] (module docs).
    pub fn centre_at(&self, s: f64) -> DVec3 {
        self.object_centre + self.direction_at(s) * self.radius_at(s)
    }

    /// The ideal pose at s: at c*(s), looking at the object, upright.
    pub fn pose_at(&self, s: f64) -> Pose {
        Pose::look_at(self.centre_at(s), self.object_centre, self.up)
            .expect("a shot's elevation is within (−90°, 90°), so the view is not along up")
    }

    /// Mean of the radii at the ends (the cost's length scale).
    pub fn mean_radius(&self) -> f64 {
        0.5 * (self.radius.0 + self.radius.1)
    }
}
