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
//! dolly-zoom: the dolly's c*(s), with the zoom z*(s) = r(s)/r_w (r_w the working radius)
//! reveal: c*(s) = o + r·(cos ε·h₀ + sin ε·u),   view turned by ∓pan·(1 − smooth(s/f)) about u
//! group:  c*(s) = o + r·(cos ε·h₀ + sin ε·u),   o and r those of the objects' union
//! ```
//!
//! with ε the elevation. The camera looks at its aim point a(s), upright; for orbit, dolly and
//! group a(s) = o. The elevation is kept in (−90°, 90°) so that the view never points
//! straight down, where "upright" has no meaning and the orientation would twist.
//!
//! **Reveal** is a pan from a standing camera: at s = 0 the view is the view of o turned by
//! `pan` about world up (so the object is out of frame: hidden by the frame's edge, not by
//! an occluder, which works in any scene), and it turns toward o along the smoothstep
//! 3x² − 2x³ of x = s/`framed_from` (no jolt at either end), framing o from s = `framed_from`
//! to the window's end: a(s) = c* + R(u, θ(s))·(o − c*), θ(0) = ∓pan, θ = 0 from
//! `framed_from` on. `direction` is the way the view turns toward the object.
//!
//! **Dolly zoom** moves the camera along the dolly's view line while the lens zooms so that the
//! object keeps its projected size: a size on the image is ∝ f·z/r, and at the working
//! radius r_w the object fills its target ratio at z = 1, so z*(s) = r(s)/r_w keeps it there
//! while the background's perspective changes (it grows as the camera backs away and zooms
//! in). It needs `[camera] lens = "zoom"` with z*(s) inside `zoom_range`; the start's zoom is
//! z*(s) fitted into the trajectory's basis, and TRE (rendered through the zoom) holds the size
//! while the shot's cost moves the camera; after the optimisation a run locks the window's zoom
//! to the camera's actual distance, s = d/r_w (`splatraj-experiment`, `prepare/shot_lens.rs`). Defaults: from 0.6·r_w to 1.8·r_w, so the zoom goes
//! from 0.6 to 1.8 (3×) and a 60° horizontal field of view from 88° to 36° (2.5×).
//!
//! **Group** frames several queries' objects together: the caller grounds each of the
//! `objects` and passes their union's centre and working radius in the [`ShotFrame`]; the
//! window's target (TCE, TRE, metrics) is the union's mask. The camera holds one framing.

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
/// Default start radius of a dolly zoom as a multiple of the working radius (zoom 0.6).
pub const DEFAULT_DOLLY_ZOOM_FROM: f64 = 0.6;
/// Default end radius of a dolly zoom as a multiple of the working radius (zoom 1.8).
pub const DEFAULT_DOLLY_ZOOM_TO: f64 = 1.8;
/// Default angle a reveal's view starts turned away from its object, degrees: out of frame
/// for any horizontal field of view below 180° minus the object's width.
pub const DEFAULT_REVEAL_PAN: f64 = 90.0;
/// Default share of a reveal's window after which its object is framed.
pub const DEFAULT_REVEAL_FRAMED_FROM: f64 = 0.6;

/// Which way an orbit (or a reveal's view) turns about world up, seen from above.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Direction {
    /// Counter-clockwise (right-handed about world up).
    #[default]
    Ccw,
    /// Clockwise.
    Cw,
}

impl Direction {
    /// +1 counter-clockwise, −1 clockwise (the sign of a turn about world up).
    pub fn sign(self) -> f64 {
        match self {
            Direction::Ccw => 1.0,
            Direction::Cw => -1.0,
        }
    }
}

/// Angle `hold = "orbit"` sweeps over its window, degrees: 15° over a 3 s window is 5°/s, a
/// slow orbit well inside the pacing limits (the orbit's default 90° is 30°/s).
pub const HOLD_ORBIT_SWEEP: f64 = 15.0;

/// What the camera does while it holds on a part (`[[queries]] hold`): the short name of a
/// shot preset, for the common case of a hold that breathes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Hold {
    /// No shot: the image costs hold one framing.
    #[default]
    Still,
    /// A slow orbit: `shot = { kind = "orbit", sweep = 15 }` ([`HOLD_ORBIT_SWEEP`]).
    Orbit,
    /// A slow push-in: `shot = { kind = "dolly" }`, from 1.5 to 1 working distance.
    Push,
}

impl Hold {
    /// Its name in the config (`still`, `orbit`, `push`).
    pub fn name(self) -> &'static str {
        match self {
            Hold::Still => "still",
            Hold::Orbit => "orbit",
            Hold::Push => "push",
        }
    }

    /// The shot it stands for (None for `still`).
    pub fn shot(self) -> Option<ShotSpec> {
        match self {
            Hold::Still => None,
            Hold::Orbit => Some(ShotSpec::Orbit(OrbitSpec {
                sweep: HOLD_ORBIT_SWEEP,
                ..OrbitSpec::default()
            })),
            Hold::Push => Some(ShotSpec::Dolly(DollySpec::default())),
        }
    }
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
    /// A dolly whose zoom keeps the object's projected size (the "Vertigo" effect); the
    /// dolly's keys, other default radii.
    DollyZoom(DollySpec),
    /// Start with the object out of frame, pan to frame it.
    Reveal(RevealSpec),
    /// Frame several queries' objects together.
    Group(GroupSpec),
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

/// `kind = "dolly"` (and `"dolly-zoom"`): along one view line from radius `from` to radius
/// `to`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DollySpec {
    /// Elevation of the view line above the horizontal, degrees, in (−90, 90). Default 30.
    pub elevation: f64,
    /// Distance at the window's start, scene units (> 0). Default 1.5 × the working radius
    /// (dolly-zoom: 0.6 ×).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<f64>,
    /// Distance at the window's end, scene units (> 0). Default: the working radius
    /// (dolly-zoom: 1.8 ×).
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

/// `kind = "reveal"`: a standing camera pans from off the object onto it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RevealSpec {
    /// Elevation of the camera seen from the object, degrees, in (−90, 90). Default 30.
    pub elevation: f64,
    /// Distance from the object's centre, scene units (> 0). Default: the working radius.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Azimuth of the camera, degrees, as for an orbit. Default 0.
    pub azimuth: f64,
    /// Angle the view starts turned away from the object, degrees, in (0, 180]. Default 90.
    pub pan: f64,
    /// Way the view turns toward the object, seen from above: `ccw` (default) or `cw`.
    pub direction: Direction,
    /// Share of the window after which the object is framed, in (0, 1]. Default 0.6.
    pub framed_from: f64,
    /// Weight of the shot's cost (≥ 0). Default 10.
    pub weight: f64,
}

impl Default for RevealSpec {
    /// 30° elevation, working radius, azimuth 0, a 90° counter-clockwise pan framed from 0.6.
    fn default() -> Self {
        Self {
            elevation: DEFAULT_SHOT_ELEVATION,
            radius: None,
            azimuth: 0.0,
            pan: DEFAULT_REVEAL_PAN,
            direction: Direction::Ccw,
            framed_from: DEFAULT_REVEAL_FRAMED_FROM,
            weight: DEFAULT_SHOT_WEIGHT,
        }
    }
}

/// `kind = "group"`: the union of `objects` (each grounded like a query's text) held in one
/// framing; the window's query text only names the group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroupSpec {
    /// The objects framed together (at least two), each a query text of the target source.
    pub objects: Vec<String>,
    /// Elevation of the view above the horizontal, degrees, in (−90, 90). Default 30.
    pub elevation: f64,
    /// Distance from the union's centre, scene units (> 0). Default: the union's working
    /// radius.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Azimuth of the camera, degrees, as for an orbit. Default 0.
    pub azimuth: f64,
    /// Weight of the shot's cost (≥ 0; 0 leaves the framing to TCE and TRE). Default 10.
    pub weight: f64,
}

impl Default for GroupSpec {
    /// No objects (a config must name them), 30° elevation, working radius, azimuth 0.
    fn default() -> Self {
        Self {
            objects: Vec::new(),
            elevation: DEFAULT_SHOT_ELEVATION,
            radius: None,
            azimuth: 0.0,
            weight: DEFAULT_SHOT_WEIGHT,
        }
    }
}

/// A group's box: the smallest axis-aligned box holding every object's box (`(centre,
/// extent)`, each extent a full side length); its centre and extent. Empty input: a point at
/// the origin.
pub fn union_box(boxes: &[([f64; 3], [f64; 3])]) -> ([f64; 3], [f64; 3]) {
    let (lo, hi) = boxes.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), (centre, extent)| {
            let (c, half) = (DVec3::from(*centre), 0.5 * DVec3::from(*extent).abs());
            (lo.min(c - half), hi.max(c + half))
        },
    );
    if boxes.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    ((0.5 * (lo + hi)).to_array(), (hi - lo).to_array())
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
    /// The shot's kind as the config names it (`orbit`, `dolly`, `reveal`, `group`).
    pub kind: &'static str,
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
    /// Signed angle the view is turned about u away from the object at s = 0, radians (0:
    /// it looks at the object throughout).
    pub pan: f64,
    /// Share of the window from which the view is back on the object (reveal), in (0, 1].
    pub framed_from: f64,
    /// Weight of the shot's cost.
    pub weight: f64,
    /// The radius at which the zoom is 1 when the shot zooms (dolly zoom: the working radius;
    /// [`ShotPath::zoom_at`]); None: the shot leaves the lens alone.
    pub zoom_radius: Option<f64>,
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
            ShotSpec::DollyZoom(_) => "dolly-zoom",
            ShotSpec::Reveal(_) => "reveal",
            ShotSpec::Group(_) => "group",
        }
    }

    /// The objects a group frames together (empty for the other kinds).
    pub fn group_objects(&self) -> &[String] {
        match self {
            ShotSpec::Group(g) => &g.objects,
            _ => &[],
        }
    }

    /// Checks the values that do not depend on the scene; errors name the key.
    pub fn validate(&self) -> Result<(), ShotError> {
        let (elevation, azimuth, weight) = match self {
            ShotSpec::Orbit(o) => (o.elevation, o.azimuth, o.weight),
            ShotSpec::Dolly(d) | ShotSpec::DollyZoom(d) => (d.elevation, d.azimuth, d.weight),
            ShotSpec::Reveal(r) => (r.elevation, r.azimuth, r.weight),
            ShotSpec::Group(g) => (g.elevation, g.azimuth, g.weight),
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
            ShotSpec::Dolly(d) | ShotSpec::DollyZoom(d) => {
                if let Some(r) = d.from {
                    positive("from", r)?;
                }
                if let Some(r) = d.to {
                    positive("to", r)?;
                }
                Ok(())
            }
            ShotSpec::Reveal(r) => {
                if let Some(radius) = r.radius {
                    positive("radius", radius)?;
                }
                check(r.pan > 0.0 && r.pan <= 180.0, "pan", || {
                    format!("= {}° must be in (0°, 180°]", r.pan)
                })?;
                check(
                    r.framed_from > 0.0 && r.framed_from <= 1.0,
                    "framed_from",
                    || {
                        format!(
                            "= {} must be in (0, 1] (a share of the window)",
                            r.framed_from
                        )
                    },
                )
            }
            ShotSpec::Group(g) => {
                if let Some(radius) = g.radius {
                    positive("radius", radius)?;
                }
                check(g.objects.len() >= 2, "objects", || {
                    format!(
                        "names {} object(s): a group frames at least two (for one, use a plain \
                         query)",
                        g.objects.len()
                    )
                })?;
                match g.objects.iter().find(|o| o.trim().is_empty()) {
                    Some(_) => check(false, "objects", || "holds an empty name".into()),
                    None => Ok(()),
                }
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
        let still = |r: Option<f64>| {
            let r = r.unwrap_or(working);
            (r, r)
        };
        // (elevation, azimuth, weight, radius at both ends, turn, pan, framed_from)
        let (elevation, azimuth, weight, radius, turn, pan, framed_from) = match self {
            ShotSpec::Orbit(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                still(s.radius),
                s.direction.sign() * s.sweep.to_radians(),
                0.0,
                1.0,
            ),
            ShotSpec::Dolly(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                (
                    s.from.unwrap_or(DEFAULT_DOLLY_FROM * working),
                    s.to.unwrap_or(working),
                ),
                0.0,
                0.0,
                1.0,
            ),
            ShotSpec::DollyZoom(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                (
                    s.from.unwrap_or(DEFAULT_DOLLY_ZOOM_FROM * working),
                    s.to.unwrap_or(DEFAULT_DOLLY_ZOOM_TO * working),
                ),
                0.0,
                0.0,
                1.0,
            ),
            // The view turns toward the object in `direction`, so it starts turned the
            // other way.
            ShotSpec::Reveal(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                still(s.radius),
                0.0,
                -s.direction.sign() * s.pan.to_radians(),
                s.framed_from,
            ),
            ShotSpec::Group(s) => (
                s.elevation,
                s.azimuth,
                s.weight,
                still(s.radius),
                0.0,
                0.0,
                1.0,
            ),
        };
        Ok(ShotPath {
            kind: self.kind(),
            object_centre: o,
            up,
            start_side: DQuat::from_axis_angle(up, azimuth.to_radians()) * side,
            elevation: elevation.to_radians(),
            radius,
            turn,
            pan,
            framed_from,
            weight,
            zoom_radius: matches!(self, ShotSpec::DollyZoom(_)).then_some(working),
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

    /// Angle θ(s) the view is turned about up away from the object at s (reveal; else 0).
    pub fn pan_at(&self, s: f64) -> f64 {
        let x = (s / self.framed_from).clamp(0.0, 1.0);
        self.pan * (1.0 - x * x * (3.0 - 2.0 * x))
    }

    /// The point a(s) the camera looks at: the object, or for a reveal the object turned
    /// about the camera by θ(s) (module docs).
    pub fn aim_at(&self, s: f64) -> DVec3 {
        let c = self.centre_at(s);
        c + DQuat::from_axis_angle(self.up, self.pan_at(s)) * (self.object_centre - c)
    }

    /// The ideal pose at s: at c*(s), looking at a(s), upright.
    pub fn pose_at(&self, s: f64) -> Pose {
        Pose::look_at(self.centre_at(s), self.aim_at(s), self.up)
            .expect("a shot's elevation is within (−90°, 90°), so the view is not along up")
    }

    /// The zoom z*(s) = r(s)/r_w the shot asks for at s (dolly zoom; module docs), None for a
    /// shot that leaves the lens alone.
    pub fn zoom_at(&self, s: f64) -> Option<f64> {
        self.zoom_radius.map(|r| self.radius_at(s) / r)
    }

    /// Mean of the radii at the ends (the cost's length scale).
    pub fn mean_radius(&self) -> f64 {
        0.5 * (self.radius.0 + self.radius.1)
    }
}
