//! Transitions between consecutive windows: a pan (the camera moves on from one part to the
//! next) or a cut (a hard switch to the next shot, [`crate::trajectory::cuts`]).
//!
//! `[output] transitions = "pan" | "cut" | "auto"` (auto the default). `"auto"` judges each
//! join of windows k and k + 1 on the start's plan, before any optimisation: the pose that
//! ends window k's start (a), the pose that begins window k + 1's (b), both parts' centres
//! and boxes, and the route the start would take between them ([`crate::optimise::route`]).
//! It cuts when the pan
//!
//! 1. **breaks the pacing limits**: the start pans along the smoothstep over at most
//!    [`MAX_PAN_SHARE`] of each window ([`crate::optimise::pans`]: beyond a third it eats into
//!    the middle 60 % the verdict's framing check judges), so a join has at most
//!    2·W/3 seconds (W a window's duration), and the eased pan peaks at
//!    [`SMOOTHSTEP_PEAK`] = 1.5 times its mean rate. The angles it must cover are the turn of
//!    the view from a to b and the orbit of the camera about the subject, the two parts'
//!    common centre, when both views look at it (within [`SUBJECT_CONE_DEGREES`] of their
//!    axes: two sides of one object); between two parts seen side by side the directions
//!    from each part to the camera sweep too, but the viewer sees a truck from one to the
//!    next, which the verdict's orbit check passes (the demo's pans: 133° about the mug by
//!    that measure, at most 37°/s as optimised). A pan needs
//!    1.5·max(θ_turn/ω, θ_orbit/ψ) seconds with ω, ψ the verdict's limits
//!    ([`crate::pacing::MAX_TURN_RATE`], [`crate::pacing::MAX_ORBIT_RATE`], 45°/s: the rates a
//!    viewer follows). More than 2·W/3 is a cut. At the first-try 3 s windows that is any
//!    turn or orbit beyond 60°: two sides of a part 120° apart need 4 s;
//! 2. **leaves a part hidden**: the camera's way from a to b (the route, or the straight
//!    segment) passes through either part's box, from where the part is not seen (the two
//!    sides of a small object: the straight way runs through it);
//! 3. **needs a long route**: no route keeps the clearance margin (the straight way goes
//!    through the geometry), or the route is longer than the speed limit covers in those
//!    2·W/3 seconds at the eased pan's peak (1.5·L/v_max), or, without a speed limit, more
//!    than [`MAX_DETOUR`] times the straight distance (a tour around the scene between two
//!    neighbours).
//!
//! and pans elsewhere. Each cut's reason is kept ([`CutReason`]) and printed with its figures.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use splatraj_render::camera::Pose;

use crate::costs::motion::SMOOTHSTEP_PEAK;
use crate::optimise::pans::{MAX_PAN_SHARE, rotation_angle};
use crate::optimise::route::Route;
use crate::trajectory::{ShotSpans, TrajectoryError};

/// Longest route, as a multiple of the straight distance, a pan takes without a speed limit.
pub const MAX_DETOUR: f64 = 2.0;

/// How far off a view's axis (degrees) the parts' common centre may lie for the move between
/// two views to read as circling it: about half a 60° lens's width.
pub const SUBJECT_CONE_DEGREES: f64 = 30.0;

/// How consecutive windows are joined (`[output] transitions`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TransitionMode {
    /// Every join pans (the camera moves on to the next part).
    Pan,
    /// Every join cuts (each window is its own shot).
    Cut,
    /// Cut where a pan would break the pacing limits, hide a part or need a long route
    /// (module docs); pan elsewhere.
    #[default]
    Auto,
}

/// Why a join cuts.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "reason")]
pub enum CutReason {
    /// `transitions = "cut"` asks for it.
    Asked,
    /// The start trajectory (`[start] trajectory`, a file) cuts there.
    Start,
    /// The pan would turn or orbit faster than the pacing limits.
    TooFast {
        /// Turn of the view from one window's view to the next, degrees.
        turn_degrees: f64,
        /// Orbit of the camera about the parts' common centre, degrees (0 unless both views
        /// look at it).
        orbit_degrees: f64,
        /// Seconds the pan needs at the limits.
        needed_seconds: f64,
        /// Seconds the join has.
        available_seconds: f64,
    },
    /// The camera's way passes through a part (window `window`'s), which hides it.
    ThroughPart {
        /// The window whose part is in the way.
        window: usize,
    },
    /// No route keeps the clearance margin between the views.
    NoRoute,
    /// The route is too long for the join.
    LongRoute {
        /// Length of the route, scene units.
        length: f64,
        /// Straight distance between the views, scene units.
        straight: f64,
        /// Seconds it needs at the speed limit (None: no speed limit; judged by the detour).
        needed_seconds: Option<f64>,
        /// Seconds the join has.
        available_seconds: f64,
    },
}

impl CutReason {
    /// The reason in words, with its figures.
    pub fn describe(&self) -> String {
        match self {
            Self::Asked => "`output.transitions` = \"cut\"".into(),
            Self::Start => "the start trajectory (`start.trajectory`) cuts there".into(),
            Self::TooFast {
                turn_degrees,
                orbit_degrees,
                needed_seconds,
                available_seconds,
            } => format!(
                "a pan turning {turn_degrees:.0}° and orbiting {orbit_degrees:.0}° needs \
                 {needed_seconds:.1} s at the pacing limits, the join has {available_seconds:.1} s"
            ),
            Self::ThroughPart { window } => {
                format!("the way between the views passes through window {window}'s part")
            }
            Self::NoRoute => "no route between the views keeps the clearance margin".into(),
            Self::LongRoute {
                length,
                straight,
                needed_seconds,
                available_seconds,
            } => match needed_seconds {
                Some(needed) => format!(
                    "the route is {length:.3} long (straight {straight:.3}) and needs \
                     {needed:.1} s at the speed limit, the join has {available_seconds:.1} s"
                ),
                None => format!(
                    "the route is {length:.3} long, more than {MAX_DETOUR}× the straight \
                     {straight:.3}"
                ),
            },
        }
    }
}

/// What a join becomes.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum JoinKind {
    /// The camera pans on.
    Pan,
    /// A hard switch to the next shot.
    Cut(CutReason),
}

impl JoinKind {
    /// Whether the join cuts.
    pub fn is_cut(&self) -> bool {
        matches!(self, Self::Cut(_))
    }
}

/// One part of a join: its centre and its box (centre, half extent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoinPart {
    /// The part's centre.
    pub centre: [f64; 3],
    /// Its box: centre and half extent.
    pub bounds: ([f64; 3], [f64; 3]),
}

/// What the start plans for one join of windows k and k + 1.
#[derive(Debug, Clone, PartialEq)]
pub struct Join {
    /// Window k's last start pose.
    pub from: Pose,
    /// Window k + 1's first start pose.
    pub to: Pose,
    /// Window k's and window k + 1's parts.
    pub parts: [JoinPart; 2],
    /// The route between the two camera centres, when the start plans one.
    pub route: Option<Route>,
}

/// The limits a join is judged against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JoinLimits {
    /// Turning rate, degrees per second.
    pub turn: f64,
    /// Orbit rate, degrees per second.
    pub orbit: f64,
    /// Speed limit, scene units per second, when there is one.
    pub speed: Option<f64>,
    /// Duration of a window, seconds.
    pub window_seconds: f64,
}

impl JoinLimits {
    /// Seconds a join has: [`MAX_PAN_SHARE`] of each window.
    pub fn available_seconds(&self) -> f64 {
        2.0 * MAX_PAN_SHARE * self.window_seconds
    }
}

/// What `mode` makes of each join (module docs).
pub fn plan_joins(mode: TransitionMode, joins: &[Join], limits: &JoinLimits) -> Vec<JoinKind> {
    joins
        .iter()
        .map(|join| match mode {
            TransitionMode::Pan => JoinKind::Pan,
            TransitionMode::Cut => JoinKind::Cut(CutReason::Asked),
            TransitionMode::Auto => judge_join(join, limits),
        })
        .collect()
}

/// Pan or cut for one join under `"auto"` (module docs), the first reason found.
pub fn judge_join(join: &Join, limits: &JoinLimits) -> JoinKind {
    let available = limits.available_seconds();
    let (a, b) = (join.from.centre(), join.to.centre());
    let turn = rotation_angle(&join.from, &join.to).to_degrees();
    let orbit = subject_orbit(join).to_degrees();
    let needed = SMOOTHSTEP_PEAK * (turn / limits.turn).max(orbit / limits.orbit);
    if needed > available {
        return JoinKind::Cut(CutReason::TooFast {
            turn_degrees: turn,
            orbit_degrees: orbit,
            needed_seconds: needed,
            available_seconds: available,
        });
    }
    let way = match &join.route {
        Some(Route::Unreachable) => return JoinKind::Cut(CutReason::NoRoute),
        Some(Route::Around(points)) => points.clone(),
        Some(Route::Straight) | None => vec![a, b],
    };
    for (k, part) in join.parts.iter().enumerate() {
        let (centre, half) = (DVec3::from(part.bounds.0), DVec3::from(part.bounds.1));
        if way
            .windows(2)
            .any(|s| segment_hits_box(s[0], s[1], centre, half))
        {
            return JoinKind::Cut(CutReason::ThroughPart { window: k });
        }
    }
    let length: f64 = way.windows(2).map(|s| s[0].distance(s[1])).sum();
    let straight = a.distance(b);
    let needed = limits.speed.map(|v| SMOOTHSTEP_PEAK * length / v);
    let too_long = match needed {
        Some(needed) => needed > available,
        None => length > MAX_DETOUR * straight,
    };
    if too_long {
        return JoinKind::Cut(CutReason::LongRoute {
            length,
            straight,
            needed_seconds: needed,
            available_seconds: available,
        });
    }
    JoinKind::Pan
}

/// The angle (radians) the camera circles the two parts' common centre by from one view to
/// the other, when both views look at it (within [`SUBJECT_CONE_DEGREES`] of both axes); 0
/// when either does not: the camera then moves from one part to the next beside it, which
/// the viewer sees as a truck, not as the subject turning (module docs).
fn subject_orbit(join: &Join) -> f64 {
    let subject = 0.5 * (DVec3::from(join.parts[0].centre) + DVec3::from(join.parts[1].centre));
    let looks_at = |pose: &Pose| {
        let to = subject - pose.centre();
        let axis = pose.rotation_wc().z_axis;
        angle_between(axis, to).to_degrees() <= SUBJECT_CONE_DEGREES
    };
    if !(looks_at(&join.from) && looks_at(&join.to)) {
        return 0.0;
    }
    angle_between(join.from.centre() - subject, join.to.centre() - subject)
}

/// The shots of `windows` windows joined as `kinds` say (one per join).
pub fn shot_spans(windows: usize, kinds: &[JoinKind]) -> Result<ShotSpans, TrajectoryError> {
    let cuts = kinds
        .iter()
        .enumerate()
        .filter(|(_, k)| k.is_cut())
        .map(|(k, _)| k + 1)
        .collect();
    ShotSpans::new(windows, cuts)
}

/// Whether the segment p–q meets the box `centre ± half` (slab test).
fn segment_hits_box(p: DVec3, q: DVec3, centre: DVec3, half: DVec3) -> bool {
    let (lo, hi) = (centre - half.abs(), centre + half.abs());
    let d = q - p;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        if d[k].abs() < 1e-15 {
            if p[k] < lo[k] || p[k] > hi[k] {
                return false;
            }
            continue;
        }
        let (mut a, mut b) = ((lo[k] - p[k]) / d[k], (hi[k] - p[k]) / d[k]);
        if a > b {
            std::mem::swap(&mut a, &mut b);
        }
        t0 = t0.max(a);
        t1 = t1.min(b);
        if t0 > t1 {
            return false;
        }
    }
    true
}

/// The angle (radians) between `a` and `b`, 0 when either is zero.
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}
