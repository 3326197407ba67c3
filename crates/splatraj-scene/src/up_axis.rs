//! A guess of the scene's world-up direction, for scenes that do not say.
//!
//! **Axis.** Captured scenes with a floor or a table are dominated by flat splats on horizontal
//! surfaces (and some vertical ones: walls). The normal of a flat splat is its shortest axis.
//! We take the opacity- and area-weighted scatter matrix of these normals and pick its
//! principal direction. When no direction holds at least [`STRONG_NORMALS`] of that weight
//! (no dominant ground) and the scene's robust bounding box is [`TALL`] times longer along one
//! side than along its next longest, the scene is an object captured all around (a statue, a
//! rider, a guitar) and that longest side is up: standing things are taller than wide. (The
//! side along the weak normals' direction is no yardstick: a statue's plinth pulls them
//! sideways.) Few flat splats: the direction of least spread of the centres.
//!
//! **Sign**, from where the scene sits relative to the world origin, which trainers put at
//! one of three places. Where the origin lies near the scene's end along the axis (between
//! [`ORIGIN_AT_CENTRE`] and [`ORIGIN_ON_SCENE`] half-extents from its centre), it is a ground
//! point (Blender and SuperSplat scenes stand on the origin): up points from the origin into
//! the scene. Where it lies far outside ([`ORIGIN_AT_CAMERAS`] half-extents or more), it is
//! where the cameras were (COLMAP-style captures centre the world on their cameras, which look
//! down at a tabletop): up points toward it. Where it lies near the middle (an object filmed
//! all around, on a turntable or a plinth: the cameras' centre is the object's), the origin
//! says nothing; there, and between the bands, the densest slab of Gaussians along the axis
//! (the floor, the base, the turntable) is taken as the ground at the bottom of the scene.
//!
//! Judged on real captures whose up we know (see the scene crate's README): biker and guitar
//! (PlayCanvas, y-down, standing on y = 0: −y), donut (Blender synthetic, z-up, lying on
//! z = 0: +z), fruit_drops (a tabletop 2 units below its cameras at the origin: +z), narcissus
//! (a statue on a plinth, PlayCanvas y-down: −y; normals 0.38 toward −x, its height 1.96 × its
//! width) and the demo room (+z). The capture's cameras, where they exist, say better
//! ([`crate::cameras_up`]). The result is snapped to the nearest coordinate axis when within 25° of
//! one. It is a guess: configs can always state `up`.

use glam::{Mat3, Quat, Vec3};
use serde::Serialize;

use crate::cameras_up::CamerasUp;
use crate::scene::Scene;

/// The guessed up direction and how much to trust it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UpGuess {
    /// Unit up vector, snapped to ±x/±y/±z when within 25° of one.
    pub up: [f32; 3],
    /// The unsnapped estimate.
    pub raw: [f32; 3],
    /// Share of the normals' weight along the chosen direction, 1/3 (no preference) to 1.
    pub confidence: f32,
    /// Whether flat splats were found (`normals`) or the point spread was used (`spread`).
    pub method: UpMethod,
}

/// How [`UpGuess`] was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum UpMethod {
    /// From the normals of flat splats.
    Normals,
    /// From the direction of least spread of the centres (few flat splats).
    Spread,
    /// From the longest side of the bounding box (flat splats without a dominant direction).
    Extent,
}

impl UpMethod {
    /// What the method reads, in words: `the normals of flat splats (a floor, a table, a base)`.
    pub fn evidence(self) -> &'static str {
        match self {
            UpMethod::Normals => "the normals of flat splats (a floor, a table, a base)",
            UpMethod::Extent => "the longest side of an object captured all around",
            UpMethod::Spread => "the direction the centres spread least along",
        }
    }

    /// What a candidate's score means under this method ([`UpCandidates`]).
    pub fn score_meaning(self) -> &'static str {
        match self {
            UpMethod::Normals => "the share of the flat splats' normals along it",
            UpMethod::Extent => "its share of the box's sides",
            UpMethod::Spread => "1 minus the share of the centres' spread along it",
        }
    }
}

/// A splat counts as flat when its shortest axis is this much shorter than its middle one.
const FLATNESS: f32 = 0.3;
/// Minimum number of flat splats for the normal-based estimate.
const MIN_FLAT: usize = 100;
/// Share of the normals' weight one direction needs to be taken as up (else: longest side).
pub const STRONG_NORMALS: f32 = 0.5;
/// Without a dominant normal, a scene this many times longer along one side than along its
/// next longest is a standing object, and that side is up.
pub const TALL: f32 = 1.5;
/// The origin is a ground point when within this many half-extents of the scene's centre
/// (and not within [`ORIGIN_AT_CENTRE`]).
pub const ORIGIN_ON_SCENE: f32 = 1.5;
/// The origin says nothing of the sign when within this many half-extents of the scene's
/// centre: it is the middle of an object captured all around. The known ground-standing
/// captures sit at about 1 (biker, guitar, donut).
pub const ORIGIN_AT_CENTRE: f32 = 0.5;
/// The origin is where the cameras were when this many half-extents or more away.
pub const ORIGIN_AT_CAMERAS: f32 = 3.0;

/// One direction up may be, as [`up_candidates`] ranks it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UpCandidate {
    /// Unit up vector, snapped to ±x/±y/±z when within 25° of one.
    pub up: [f32; 3],
    /// The unsnapped direction.
    pub raw: [f32; 3],
    /// How strongly the guess's method prefers this direction (see [`UpCandidates`]); for
    /// the first candidate, the guess's confidence.
    pub score: f32,
}

/// The guess and the two next candidates: three mutually orthogonal directions (unsnapped),
/// ranked by the score of the method that made the guess. `Normals`: the share of the flat
/// splats' normal weight along each (the three sum to 1). `Extent`: each coordinate axis's
/// share of the robust box's sides (they sum to 1). `Spread`: 1 − the share of the centres'
/// spread along each. A scene whose up the guess gets wrong usually has it among the other
/// two: a statue's long side against a plinth's normals, a tabletop's two flat directions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UpCandidates {
    /// How the directions and their scores were found.
    pub method: UpMethod,
    /// The guess first, then the others by falling score.
    pub ranked: [UpCandidate; 3],
}

impl UpCandidates {
    /// The first candidate as the guess [`guess_up_axis`] returns.
    pub fn guess(&self) -> UpGuess {
        let best = self.ranked[0];
        UpGuess {
            up: best.up,
            raw: best.raw,
            confidence: best.score,
            method: self.method,
        }
    }
}

/// Guesses the up direction; `None` for an empty scene.
pub fn guess_up_axis(scene: &Scene) -> Option<UpGuess> {
    up_candidates(scene).map(|c| c.guess())
}

/// The guess of [`guess_up_axis`] and the two next candidates ([`UpCandidates`]); `None` for
/// an empty scene. Each is signed and snapped as the guess is.
pub fn up_candidates(scene: &Scene) -> Option<UpCandidates> {
    let bounds = scene.robust_bounds(0.02)?;
    let mut scatter = Mat3::ZERO;
    let mut flat = 0usize;
    let mut total = 0.0f32;
    for i in 0..scene.len() {
        let s = scene.scales[i];
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| s[a].total_cmp(&s[b]));
        let (short, mid, long) = (s[order[0]], s[order[1]], s[order[2]]);
        if short >= FLATNESS * mid || short.is_nan() {
            continue;
        }
        let [w, x, y, z] = scene.rotations[i];
        let normal = Quat::from_xyzw(x, y, z, w) * Vec3::AXES[order[0]];
        let weight = scene.opacities[i] * mid * long;
        if !weight.is_finite() || !normal.is_finite() {
            continue;
        }
        scatter +=
            Mat3::from_cols(normal * normal.x, normal * normal.y, normal * normal.z) * weight;
        total += weight;
        flat += 1;
    }

    // Three orthogonal directions with their scores, best first.
    let (ranked, method): ([(Vec3, f32); 3], UpMethod) = if flat >= MIN_FLAT && total > 0.0 {
        let normals = scatter / total;
        let (axis, value) = principal_direction(normals, Largest);
        let size = Vec3::from(bounds.max) - Vec3::from(bounds.min);
        let k = (0..3)
            .max_by(|&a, &b| size[a].total_cmp(&size[b]))
            .unwrap_or(2);
        // The box's next longest side. Not its side along the normals' axis: normals that
        // prefer no direction point anywhere (a plinth's four sides pull them sideways, and
        // the statue on it is twice as tall as the plinth is wide).
        let mut sides = size.to_array();
        sides.sort_by(f32::total_cmp);
        if value >= STRONG_NORMALS || size[k] < TALL * sides[1] {
            let [second, third] = rest_of_spectrum(normals, axis, Largest);
            let score = |v: Vec3| v.dot(normals * v);
            (
                [
                    (axis, value),
                    (second, score(second)),
                    (third, score(third)),
                ],
                UpMethod::Normals,
            )
        } else {
            // Score: each side's share of the box, how much longer the longest is than the
            // others.
            let sum = (size.x + size.y + size.z).max(f32::MIN_POSITIVE);
            let mut axes = [0usize, 1, 2];
            axes.sort_by(|&a, &b| size[b].total_cmp(&size[a]));
            axes.sort_by_key(|&a| a != k);
            let share = |a: usize| size[a] / sum;
            (
                [
                    (Vec3::AXES[k], share(k).clamp(1.0 / 3.0, 1.0)),
                    (Vec3::AXES[axes[1]], share(axes[1])),
                    (Vec3::AXES[axes[2]], share(axes[2])),
                ],
                UpMethod::Extent,
            )
        }
    } else {
        let centre = Vec3::from(bounds.center());
        let mut spread = Mat3::ZERO;
        for m in &scene.means {
            let d = Vec3::from(*m) - centre;
            spread += Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        }
        let trace = spread.x_axis.x + spread.y_axis.y + spread.z_axis.z;
        let (axis, value) = principal_direction(spread, Smallest);
        let score = |value: f32| {
            if trace > 0.0 {
                1.0 - value / trace
            } else {
                1.0 / 3.0
            }
        };
        let [second, third] = rest_of_spectrum(spread, axis, Smallest);
        (
            [
                (axis, score(value).clamp(1.0 / 3.0, 1.0)),
                (second, score(second.dot(spread * second))),
                (third, score(third.dot(spread * third))),
            ],
            UpMethod::Spread,
        )
    };

    let ranked = ranked.map(|(axis, score)| {
        let raw = orient_by_origin(axis, &bounds)
            .unwrap_or_else(|| orient_away_from_ground(scene, axis, &bounds));
        UpCandidate {
            up: snap_to_axis(raw, 25f32.to_radians()).to_array(),
            raw: raw.to_array(),
            score,
        }
    });
    Some(UpCandidates { method, ranked })
}

/// The two eigenvectors of the symmetric `m` orthogonal to its eigenvector `first`, from the
/// same end of the spectrum as `first` inwards: the 2×2 problem in the plane orthogonal to
/// `first`, solved in closed form.
fn rest_of_spectrum(m: Mat3, first: Vec3, which: Extreme) -> [Vec3; 2] {
    let first = first.normalize_or(Vec3::Z);
    let a = first.any_orthonormal_vector();
    let b = first.cross(a);
    let (aa, bb, ab) = (a.dot(m * a), b.dot(m * b), a.dot(m * b));
    // The larger eigenvalue's direction lies at θ from a.
    let theta = 0.5 * (2.0 * ab).atan2(aa - bb);
    let larger = theta.cos() * a + theta.sin() * b;
    let smaller = first.cross(larger);
    match which {
        Largest => [larger, smaller],
        Smallest => [smaller, larger],
    }
}

/// Which end of the spectrum [`principal_direction`] returns.
#[derive(Clone, Copy)]
enum Extreme {
    Largest,
    Smallest,
}
use Extreme::{Largest, Smallest};

/// Eigenvector (and eigenvalue) of a symmetric positive semi-definite 3×3 matrix at one end of
/// its spectrum, by power iteration (on trace·I − m for the smallest one).
fn principal_direction(m: Mat3, which: Extreme) -> (Vec3, f32) {
    let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    let iterated = match which {
        Largest => m,
        Smallest => Mat3::from_diagonal(Vec3::splat(trace)) - m,
    };
    // Start from the largest column: never orthogonal to the wanted eigenvector unless the
    // matrix is zero. Three starts guard against an unlucky one.
    let mut v = [iterated.x_axis, iterated.y_axis, iterated.z_axis]
        .into_iter()
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
        .unwrap_or(Vec3::Z)
        .normalize_or(Vec3::Z);
    for _ in 0..200 {
        v = (iterated * v).normalize_or(v);
    }
    (v, v.dot(m * v))
}

/// `axis` or `-axis` by where the world origin lies along it (see the module docs); `None`
/// when that says nothing.
fn orient_by_origin(axis: Vec3, bounds: &crate::scene::Bounds) -> Option<Vec3> {
    let centre = axis.dot(Vec3::from(bounds.center()));
    let corners = [bounds.min, bounds.max];
    let half = (0..8)
        .map(|c| {
            let corner = Vec3::new(
                corners[c & 1][0],
                corners[(c >> 1) & 1][1],
                corners[c >> 2][2],
            );
            (axis.dot(corner) - centre).abs()
        })
        .fold(0.0f32, f32::max);
    if !(half > 0.0 && centre.is_finite()) {
        return None;
    }
    let offset = centre / half; // where the scene's centre is, in half-extents from the origin
    if offset.abs() < ORIGIN_AT_CENTRE {
        // The origin is the object's middle (a turntable's or a plinth's capture).
        None
    } else if offset.abs() <= ORIGIN_ON_SCENE {
        // The origin is a ground point: up points from it into the scene.
        Some(if centre >= 0.0 { axis } else { -axis })
    } else if offset.abs() >= ORIGIN_AT_CAMERAS {
        // The origin is where the cameras were, above the scene.
        Some(if centre >= 0.0 { -axis } else { axis })
    } else {
        None
    }
}

/// Flips `axis` so that it points from the densest slab (the ground) into the scene.
fn orient_away_from_ground(scene: &Scene, axis: Vec3, bounds: &crate::scene::Bounds) -> Vec3 {
    const BINS: usize = 32;
    let corners = [bounds.min, bounds.max];
    let heights: Vec<f32> = (0..8)
        .map(|c| {
            axis.dot(Vec3::new(
                corners[c & 1][0],
                corners[(c >> 1) & 1][1],
                corners[c >> 2][2],
            ))
        })
        .collect();
    let lo = heights.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = heights.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return axis;
    }
    let mut histogram = [0.0f32; BINS];
    for (m, o) in scene.means.iter().zip(&scene.opacities) {
        let t = (axis.dot(Vec3::from(*m)) - lo) / (hi - lo);
        if (0.0..1.0).contains(&t) {
            histogram[(t * BINS as f32) as usize] += o;
        }
    }
    let densest = (0..BINS)
        .max_by(|&a, &b| histogram[a].total_cmp(&histogram[b]))
        .unwrap_or(0);
    if densest as f32 + 0.5 > BINS as f32 / 2.0 {
        -axis
    } else {
        axis
    }
}

/// The nearest signed coordinate axis if within `max_angle` of `v`, else `v`.
fn snap_to_axis(v: Vec3, max_angle: f32) -> Vec3 {
    let k = (0..3)
        .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
        .unwrap_or(2);
    let mut axis = Vec3::ZERO;
    axis[k] = v[k].signum();
    if v.angle_between(axis) <= max_angle {
        axis
    } else {
        v
    }
}

/// Where a resolved world up came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UpSource {
    /// Given by the user (a config's `scene.up`).
    Config,
    /// The built-in demo room's known up ([`crate::demo::DEMO_UP`]).
    Demo,
    /// The capture's cameras ([`crate::cameras_up`]).
    Cameras,
    /// Guessed from the scene ([`guess_up_axis`]).
    Guess,
    /// Nothing to go on: +z.
    Default,
}

impl UpSource {
    /// The name used in logs: `config`, `demo`, `cameras`, `guess` or `default`.
    pub fn name(self) -> &'static str {
        match self {
            UpSource::Config => "config",
            UpSource::Demo => "demo",
            UpSource::Cameras => "cameras",
            UpSource::Guess => "guess",
            UpSource::Default => "default",
        }
    }
}

/// World up (unit length, f64) and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedUp {
    /// Unit world up.
    pub up: [f64; 3],
    /// Its origin.
    pub source: UpSource,
    /// The guess, when up was guessed (its confidence and method).
    pub guess: Option<UpGuess>,
    /// The cameras, when up came from them (their count, file and spread).
    pub cameras: Option<CamerasUp>,
}

/// Below this confidence a guessed up is worth a warning: the normals or the extent hardly
/// prefer one axis.
pub const DOUBTFUL_UP: f32 = 0.5;

impl ResolvedUp {
    /// Whether up was guessed with a confidence below [`DOUBTFUL_UP`].
    pub fn doubtful(&self) -> bool {
        self.guess.is_some_and(|g| g.confidence < DOUBTFUL_UP)
    }

    /// One line saying where up came from and how sure the guess is, with how to override it:
    /// `up [0, -1, 0] (guessed from the normals of flat splats, confidence 0.44 …)`.
    pub fn describe(&self) -> String {
        let [x, y, z] = self.up;
        let up = format!("up [{x:.3}, {y:.3}, {z:.3}]");
        match (self.source, self.guess) {
            (UpSource::Guess, Some(g)) => {
                let how = g.method.evidence();
                let doubt = if self.doubtful() {
                    ", low: check the frames"
                } else {
                    ""
                };
                format!(
                    "{up} (guessed from {how}, confidence {:.2} of 1{doubt}; set `scene.up = [x, \
                     y, z]` to override)",
                    g.confidence
                )
            }
            (UpSource::Cameras, _) if let Some(c) = &self.cameras => {
                format!("{up} ({}; `scene.up` overrides)", c.describe())
            }
            (source, _) => format!("{up} ({})", source.name()),
        }
    }
}

/// The one rule for world up: an explicit `given` (any non-zero length) wins, then the demo
/// room's known up when `is_demo`, then [`guess_up_axis`], then +z (with a warning).
pub fn resolve_up(given: Option<[f64; 3]>, is_demo: bool, scene: &Scene) -> ResolvedUp {
    let (up, source, guess) = match given {
        Some(up) => (up, UpSource::Config, None),
        None if is_demo => (crate::demo::DEMO_UP.map(f64::from), UpSource::Demo, None),
        None => match guess_up_axis(scene) {
            Some(g) => (g.up.map(f64::from), UpSource::Guess, Some(g)),
            None => {
                tracing::warn!("could not guess world up; using +z (set scene.up)");
                ([0.0, 0.0, 1.0], UpSource::Default, None)
            }
        },
    };
    let norm = up.iter().map(|v| v * v).sum::<f64>().sqrt();
    let up = if norm > 0.0 && norm.is_finite() {
        up.map(|v| v / norm)
    } else {
        [0.0, 0.0, 1.0]
    };
    ResolvedUp {
        up,
        source,
        guess,
        cameras: None,
    }
}

impl From<CamerasUp> for ResolvedUp {
    fn from(cameras: CamerasUp) -> Self {
        ResolvedUp {
            up: cameras.up,
            source: UpSource::Cameras,
            guess: None,
            cameras: Some(cameras),
        }
    }
}
