//! The ups the views page's "Which way is up?" strip offers
//! ([`splatraj_report::views_page::up_strip`]), each with a picture of the scene stood upright
//! for it.
//!
//! The first is the up the page's views use ([`ResolvedUp`]: `--up`, the capture's cameras,
//! or the geometry's guess); then the geometry's candidates ([`up_candidates`]) that are not
//! along one already shown, up to [`CHOICES`]. A guess that is wrong is usually one of the
//! other two (a statue's long side against its plinth's normals), so three pictures side by
//! side settle up in one look. Each picture is taken from a little above the scene's horizon
//! for its up: the first looking at the scene's broadest side, the others looking across the
//! first's up, so that it runs left to right in their pictures (a floor then stands as a wall,
//! never seen face on as a map, which looks right any way up).

use anyhow::Result;
use glam::DVec3;
use splatraj_lift::{Progress, View};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::DeviceScene;
use splatraj_report::views_page::up_strip::{InUse, UpChoice};
use splatraj_scene::up_axis::{ResolvedUp, UpCandidates, UpMethod, up_candidates};
use splatraj_scene::{Scene, UpSource};

use super::view_render::render_view;

/// Ups the strip shows: the one in use and the geometry's next candidates.
pub const CHOICES: usize = 3;
/// A candidate within this angle of a shown up, either way along it, is that picture again
/// (or upside down, which its "opposite" line already offers): left out.
pub const SAME_AXIS_DEGREES: f64 = 20.0;
/// The strip's cameras look at the scene from this far above its horizon: a floor or a base
/// then shows as ground, not as a line.
const ELEVATION_DEGREES: f64 = 20.0;
/// A candidate's camera looks across the first up, turned this far toward it.
const TOWARD_SIDEWAYS_DEGREES: f64 = 30.0;
/// Horizontal directions tried for the scene's broadest side.
const SIDES_TRIED: usize = 36;

/// One up to offer, before its picture is taken.
#[derive(Debug, Clone, PartialEq)]
pub struct UpOption {
    /// Unit direction.
    pub up: [f64; 3],
    /// Where it comes from, in words.
    pub why: String,
    /// Whether the page's views use it.
    pub in_use: InUse,
}

/// The ups to offer: `resolved` first, then `candidates` not along an up already taken, up to
/// [`CHOICES`].
pub fn up_options(resolved: &ResolvedUp, candidates: Option<&UpCandidates>) -> Vec<UpOption> {
    let mut options = vec![UpOption {
        up: resolved.up,
        why: in_use_why(resolved, candidates),
        in_use: InUse::Yes,
    }];
    let Some(candidates) = candidates else {
        return options;
    };
    for (rank, candidate) in candidates.ranked.iter().enumerate() {
        if options.len() == CHOICES {
            break;
        }
        let up = candidate.up.map(f64::from);
        if options.iter().any(|o| same_axis(o.up, up)) {
            continue;
        }
        options.push(UpOption {
            up,
            why: candidate_why(candidates.method, rank, candidate.score),
            in_use: InUse::No,
        });
    }
    options
}

/// Whether `a` and `b` lie within [`SAME_AXIS_DEGREES`] of one line.
fn same_axis(a: [f64; 3], b: [f64; 3]) -> bool {
    let (a, b) = (DVec3::from(a), DVec3::from(b));
    a.normalize_or_zero().dot(b.normalize_or_zero()).abs() >= SAME_AXIS_DEGREES.to_radians().cos()
}

/// Where the up in use came from, and for the capture's cameras, how well they agree and
/// whether the geometry agrees with them.
fn in_use_why(resolved: &ResolvedUp, candidates: Option<&UpCandidates>) -> String {
    let geometry = candidates.map(|c| {
        let best = c.ranked[0].up.map(f64::from);
        let along = DVec3::from(best).dot(DVec3::from(resolved.up));
        if along >= SAME_AXIS_DEGREES.to_radians().cos() {
            "; the geometry's guess agrees".to_string()
        } else {
            format!("; the geometry guesses {}", vector(best))
        }
    });
    match resolved.source {
        UpSource::Guess => match (resolved.guess, candidates) {
            (Some(_), Some(c)) => candidate_why(c.method, 0, c.ranked[0].score),
            _ => "the geometry's guess".to_string(),
        },
        UpSource::Cameras => match &resolved.cameras {
            Some(c) => format!(
                "from the capture's {} cameras in {}: 90 % of their horizons within {:.1}° of \
                 level{}",
                c.cameras,
                c.file,
                c.spread_degrees,
                geometry.unwrap_or_default()
            ),
            None => "from the capture's cameras".to_string(),
        },
        UpSource::Config => format!("given (--up){}", geometry.unwrap_or_default()),
        UpSource::Demo => "the demo room's known up".to_string(),
        UpSource::Default => "nothing to go on: +z".to_string(),
    }
}

/// A geometry candidate's origin: `the geometry's guess, from the normals of flat splats …:
/// score 0.64 (…)`, or its rank.
fn candidate_why(method: UpMethod, rank: usize, score: f32) -> String {
    let which = match rank {
        0 => format!("the geometry's guess, from {}", method.evidence()),
        1 => "the geometry's second candidate".to_string(),
        _ => "the geometry's third candidate".to_string(),
    };
    format!("{which}: score {score:.2} ({})", method.score_meaning())
}

/// `[0, -1, 0]`, `[0.1234, 0.9876, 0]`: whole numbers without decimals, others to 4.
pub fn vector(up: [f64; 3]) -> String {
    let values: Vec<String> = up
        .iter()
        .map(|&v| {
            if (v - v.round()).abs() < 1e-9 {
                // `+ 0.0` turns −0 into 0.
                format!("{}", v.round() + 0.0)
            } else {
                format!("{v:.4}")
            }
        })
        .collect();
    format!("[{}]", values.join(", "))
}

/// The `[scene]` line that sets `up`: `up = [0, 0, 1]`.
pub fn up_line(up: [f64; 3]) -> String {
    format!("up = {}", vector(up))
}

/// A square camera of `size` pixels that sees `scene`'s robust box whole, upright for `up`:
/// from `ELEVATION_DEGREES` above the horizon, looking across `sideways` (a direction the
/// picture shows running left to right) or, without one or along `up`, at the box's broadest
/// face; from the side nearer the world origin (where capture cameras stand or look from).
pub fn upright_view(
    scene: &Scene,
    up: [f64; 3],
    sideways: Option<[f64; 3]>,
    fov_degrees: f64,
    size: usize,
) -> Result<View> {
    let bounds = scene
        .robust_bounds(0.02)
        .ok_or_else(|| anyhow::anyhow!("the scene holds no Gaussian"))?;
    let centre = DVec3::from(bounds.center().map(f64::from));
    let sides = DVec3::from(bounds.size().map(f64::from));
    let up = DVec3::from(up).normalize_or(DVec3::Z);
    let (east, north) = up.any_orthonormal_pair();
    // The box is thinnest, seen along this horizontal direction: its broadest face shows.
    let width = |d: DVec3| d.abs().dot(sides);
    let toward_origin = |d: DVec3| if d.dot(-centre) < 0.0 { -d } else { d };
    let across = sideways.map(DVec3::from).and_then(|s| {
        let level = (s - up * s.dot(up)).normalize_or_zero();
        let w = up.cross(level);
        (w != DVec3::ZERO).then_some((w, level))
    });
    let side = match across {
        // Turned a little toward `sideways`, so that the ground it stands for shows from its
        // upper side (a tabletop seen exactly edge on is a line).
        Some((w, level)) => {
            let a = TOWARD_SIDEWAYS_DEGREES.to_radians();
            a.cos() * toward_origin(w) + a.sin() * level
        }
        None => toward_origin(
            (0..SIDES_TRIED)
                .map(|k| {
                    let a = std::f64::consts::PI * k as f64 / SIDES_TRIED as f64;
                    a.cos() * east + a.sin() * north
                })
                .min_by(|a, b| width(*a).total_cmp(&width(*b)))
                .unwrap_or(east),
        ),
    };
    let e = ELEVATION_DEGREES.to_radians();
    let direction = e.cos() * side + e.sin() * up;
    let radius = (0.5 * sides.length()).max(1e-6);
    let distance = radius / (0.5 * fov_degrees.to_radians()).sin();
    Ok(View {
        pose: Pose::look_at(centre + distance * direction, centre, up)?,
        intrinsics: Intrinsics::from_fov_x(fov_degrees, size, size)?,
    })
}

/// The strip's choices for `scene` (uploaded as `uploaded`) whose views use `resolved`: see
/// the module docs. Pictures of `size` pixels square, `fov_degrees` wide.
pub fn up_choices(
    scene: &Scene,
    uploaded: &DeviceScene,
    resolved: &ResolvedUp,
    fov_degrees: f64,
    size: usize,
    progress: &Progress,
) -> Result<Vec<UpChoice>> {
    let options = up_options(resolved, up_candidates(scene).as_ref());
    let total = options.len();
    let first = resolved.up;
    let mut choices = Vec::with_capacity(total);
    for (done, option) in options.into_iter().enumerate() {
        progress(splatraj_lift::LiftStage::Render, done, total);
        let sideways = (option.in_use == InUse::No).then_some(first);
        let view = upright_view(scene, option.up, sideways, fov_degrees, size)?;
        choices.push(UpChoice {
            line: up_line(option.up),
            opposite: up_line(option.up.map(|v| -v)),
            png: render_view(uploaded, &view, String::new())?.png,
            size: (size, size),
            up: option.up,
            why: option.why,
            in_use: option.in_use,
        });
    }
    Ok(choices)
}
