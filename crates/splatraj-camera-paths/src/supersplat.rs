//! SuperSplat viewer settings (`settings.json`, version 2) with one camera animation track, as
//! the SuperSplat editor's viewer export writes it and the SuperSplat viewer plays it.
//!
//! Schema (playcanvas/supersplat-viewer `docs/api.md`, "Settings Schema", and its
//! `src/animation/anim-state.ts`): `version: 2`, `tonemapping`, `highPrecisionRendering`,
//! `background`, `postEffectSettings`, `animTracks`, `cameras`, `annotations`, `startMode`.
//! A track has `name`, `duration` (seconds), `frameRate`, `loopMode`, `interpolation`,
//! `smoothness` and `keyframes: { times, values: { position, target, fov } }`, where `times`
//! are in **frames** (the player evaluates its spline at seconds × `frameRate`; read back
//! only when finite, from 0, increasing and below 10 hours at 30 fps), `position`
//! and `target` are flat `[x, y, z, x, y, z, …]` and `fov` is the PlayCanvas camera's
//! **vertical** field of view in **degrees**.
//!
//! Axes: the viewer rolls the splat 180° about z (`entity.setLocalEulerAngles(0, 0, 180)`), so
//! a scene point (x, y, z) of the file is at (−x, −y, z) in the viewer's world, where
//! positions and targets live; we write them so (SuperSplat's own cameras.json import does the
//! same). The camera looks from `position` at `target` with the viewer's +y as up (the scene's
//! −y: right for the usual y-down captures): **roll about the viewing axis is not kept**, nor
//! are the principal point and the horizontal focal length. `target` is `position` plus the
//! viewing direction times a focus distance ([`Focus`]); when the animation stops the viewer
//! orbits about it.
//!
//! Keyframes: the viewer plays a track through a cubic Hermite spline over the 7 numbers
//! (position, target, fov) of each key ([`Playback`], after supersplat-viewer's
//! `src/core/spline.ts` and `src/animation/anim-state.ts`), so a path needs keys only where the
//! spline would stray from it. The export places them greedily ([`Keyframes::Sparse`]: start
//! with the first and last frame, add the frame the playback misses most until every frame is
//! within a [`Tolerance`]), which leaves a track a person can edit; [`Keyframes::EveryFrame`]
//! keeps one key per frame. Reading plays the track back at every frame, so dense and sparse
//! files read alike.
//!
//! **Cuts.** A track is one spline: the format has no step. A path with cuts
//! ([`CameraPath::cuts`]) keys both frames of each cut (k − 1 and k, one frame apart), so
//! played at the track's frame rate, as we read it, no frame falls between them and the cut
//! is exact; a viewer that draws between frames flies the one frame (1/`frameRate` s) from
//! one shot to the next, the least the format can express. The cuts are also written in the
//! track as `cuts` (frames that begin a new shot), which the viewer ignores and we read back.

use serde::{Deserialize, Serialize};
use serde_json::json;

use glam::DVec3;

use crate::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use crate::error::{InterchangeError, Result, export_error, invalid, read_text};
use crate::{check_export, check_fps};

const FORMAT: &str = "SuperSplat settings.json";

/// More frames than any track a person would play (10 hours at 30 fps): a longer `duration`
/// is a broken file, not a reason to allocate without bound.
const MAX_FRAMES: f64 = 1.08e6;

/// The viewer's world from the scene's: 180° about z.
fn to_viewer(p: DVec3) -> [f64; 3] {
    [-p.x, -p.y, p.z]
}

fn from_viewer(p: [f64; 3]) -> DVec3 {
    DVec3::new(-p[0], -p[1], p[2])
}

/// Where each frame's `target` lies along its viewing direction.
#[derive(Debug, Clone, PartialEq)]
pub enum Focus {
    /// The same distance (scene units) for every frame.
    Distance(f64),
    /// One distance per frame (e.g. to the object the frame shows).
    PerFrame(Vec<f64>),
}

/// How far the viewer's playback of sparse keyframes may stray from the path, at each frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    /// Camera position, as a fraction of the path's extent (the diagonal of its centres'
    /// bounding box).
    pub position: f64,
    /// Viewing direction (from position to target), degrees.
    pub direction_degrees: f64,
    /// Vertical field of view, degrees.
    pub fov_degrees: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Self {
            position: 0.01,
            direction_degrees: 1.0,
            fov_degrees: 0.1,
        }
    }
}

/// Which frames become keyframes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Keyframes {
    /// Every frame (exact at each frame, but hundreds of keys to edit).
    EveryFrame,
    /// As few as keep the viewer's playback within the tolerance of every frame.
    Sparse(Tolerance),
}

/// Options of the SuperSplat export.
#[derive(Debug, Clone, PartialEq)]
pub struct SupersplatOptions {
    /// Frames per second (`frameRate`; `duration` = (frames − 1) / fps).
    pub fps: f64,
    /// Focus distance of the targets.
    pub focus: Focus,
    /// Which frames become keyframes.
    pub keyframes: Keyframes,
}

impl Default for SupersplatOptions {
    fn default() -> Self {
        Self {
            fps: 30.0,
            focus: Focus::Distance(1.0),
            keyframes: Keyframes::Sparse(Tolerance::default()),
        }
    }
}

/// One key's values in the order the viewer's spline holds them: position, target (viewer
/// axes), vertical fov (degrees).
type Key = [f64; 7];

/// A track as the SuperSplat viewer plays it: `CubicSpline.fromPointsLooping` of
/// supersplat-viewer `src/core/spline.ts`, built as `AnimState.fromTrack`
/// (`src/animation/anim-state.ts`) builds it, evaluated at frame = seconds × frameRate.
///
/// The viewer builds the looping spline whatever the `loopMode` (which only stops the cursor
/// at `duration`), so the first and last keys' tangents come from the keys across the wrap:
/// the last two keys are repeated `length` frames before the first, the first two `length`
/// after the last, `length` = (`duration` + 1 s if the last key is at `duration`, else 0) ×
/// frameRate. Tangents are Catmull-Rom (central differences over the neighbours' times) times
/// `smoothness`, scaled to each segment's length.
#[derive(Debug, Clone)]
pub struct Playback {
    times: Vec<f64>,
    points: Vec<Key>,
    /// Incoming and outgoing tangent of each point, per unit of the segment's parameter.
    tangents: Vec<(Key, Key)>,
}

impl Playback {
    /// The spline of keys at `times` (frames, increasing) for a track of `duration` seconds.
    pub fn new(
        times: &[f64],
        keys: &[Key],
        duration: f64,
        frame_rate: f64,
        smoothness: f64,
    ) -> Self {
        let n = times.len();
        let (times, points) = if n < 2 {
            (times.to_vec(), keys.to_vec())
        } else {
            // Same floating-point operations as anim-state.ts, so the wrap length is the
            // viewer's to the last bit.
            let extra = if duration == times[n - 1] / frame_rate {
                1.0
            } else {
                0.0
            };
            let length = (duration + extra) * frame_rate;
            let mut t = vec![times[n - 2] - length, times[n - 1] - length];
            t.extend_from_slice(times);
            t.extend([length + times[0], length + times[1]]);
            let mut p = vec![keys[n - 2], keys[n - 1]];
            p.extend_from_slice(keys);
            p.extend([keys[0], keys[1]]);
            (t, p)
        };
        let m = times.len();
        let tangents = (0..m)
            .map(|i| {
                if m < 2 {
                    return ([0.0; 7], [0.0; 7]);
                }
                let (before, after) = (i.saturating_sub(1), (i + 1).min(m - 1));
                let span = times[after] - times[before];
                let in_scale = if i > 0 {
                    times[i] - times[i - 1]
                } else {
                    times[1] - times[0]
                };
                let out_scale = if i < m - 1 {
                    times[i + 1] - times[i]
                } else {
                    times[i] - times[i - 1]
                };
                let mut incoming = [0.0; 7];
                let mut outgoing = [0.0; 7];
                for k in 0..7 {
                    let slope = (points[after][k] - points[before][k]) / span;
                    incoming[k] = slope * in_scale * smoothness;
                    outgoing[k] = slope * out_scale * smoothness;
                }
                (incoming, outgoing)
            })
            .collect();
        Self {
            times,
            points,
            tangents,
        }
    }

    /// The values at `frame`, and the segment they came from (a hint for the next, later
    /// frame: playback is evaluated in order).
    fn at_from(&self, frame: f64, hint: usize) -> (Key, usize) {
        let times = &self.times;
        let last = times.len() - 1;
        if frame <= times[0] {
            return (self.points[0], 0);
        }
        if frame >= times[last] {
            return (self.points[last], hint);
        }
        let mut seg = if times[hint] <= frame { hint } else { 0 };
        while frame >= times[seg + 1] {
            seg += 1;
        }
        let t = (frame - times[seg]) / (times[seg + 1] - times[seg]);
        let (t2, twot, omt) = (t * t, t + t, 1.0 - t);
        let omt2 = omt * omt;
        let (p0, m0) = (self.points[seg], self.tangents[seg].1);
        let (p1, m1) = (self.points[seg + 1], self.tangents[seg + 1].0);
        let mut out = [0.0; 7];
        for k in 0..7 {
            out[k] = p0[k] * ((1.0 + twot) * omt2)
                + m0[k] * (t * omt2)
                + p1[k] * (t2 * (3.0 - twot))
                + m1[k] * (t2 * (t - 1.0));
        }
        (out, seg)
    }

    /// The values at `frame` (position, target, fov).
    pub fn at(&self, frame: f64) -> [f64; 7] {
        self.at_from(frame, 0).0
    }

    /// The values at frames 0, 1, …, `last`.
    pub fn frames(&self, last: usize) -> Vec<[f64; 7]> {
        let mut hint = 0;
        (0..=last)
            .map(|f| {
                let (v, seg) = self.at_from(f as f64, hint);
                hint = seg;
                v
            })
            .collect()
    }
}

/// How far played values are from the wanted ones, in units of the tolerance (≤ 1 is within):
/// position against `position_tolerance` (scene units), the viewing direction and the fov.
fn miss(played: &Key, wanted: &Key, position_tolerance: f64, tolerance: &Tolerance) -> f64 {
    let p = |v: &Key| DVec3::new(v[0], v[1], v[2]);
    let direction = |v: &Key| (DVec3::new(v[3], v[4], v[5]) - p(v)).normalize_or_zero();
    let position = p(played).distance(p(wanted)) / position_tolerance;
    let cos = direction(played).dot(direction(wanted)).clamp(-1.0, 1.0);
    let angle = cos.acos().to_degrees() / tolerance.direction_degrees;
    let fov = (played[6] - wanted[6]).abs() / tolerance.fov_degrees;
    position.max(angle).max(fov)
}

/// The frames to key so the viewer's playback of `values` (one per frame) stays within
/// `tolerance`: greedy insertion of the worst-played frame, from the first and last frames,
/// then removal of each key the others make unnecessary.
fn sparse_keys(
    values: &[Key],
    cuts: &[usize],
    duration: f64,
    fps: f64,
    tolerance: &Tolerance,
) -> Vec<usize> {
    let n = values.len();
    if n <= 2 {
        return (0..n).collect();
    }
    // Both frames of a cut are keys, whatever the tolerance, and stay keys.
    let forced: Vec<usize> = cuts.iter().flat_map(|&c| [c - 1, c]).collect();
    let (lo, hi) = values.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), v| {
            let c = DVec3::new(v[0], v[1], v[2]);
            (lo.min(c), hi.max(c))
        },
    );
    // A floor for paths that only turn on the spot: rounding, not a tolerance.
    let position_tolerance = (tolerance.position * (hi - lo).length())
        .max(1e-9 * (1.0 + hi.abs().max(lo.abs()).max_element()));
    let worst = |keys: &[usize]| {
        let times: Vec<f64> = keys.iter().map(|&k| k as f64).collect();
        let points: Vec<Key> = keys.iter().map(|&k| values[k]).collect();
        let played = Playback::new(&times, &points, duration, fps, 1.0).frames(n - 1);
        played
            .iter()
            .zip(values)
            .map(|(p, v)| miss(p, v, position_tolerance, tolerance))
            .enumerate()
            .fold(
                (0, 0.0),
                |best, (i, m)| if m > best.1 { (i, m) } else { best },
            )
    };
    let mut keys = vec![0, n - 1];
    keys.extend(&forced);
    keys.sort_unstable();
    keys.dedup();
    loop {
        let (frame, score) = worst(&keys);
        // A key plays exactly, so the worst frame is never one already keyed.
        if score <= 1.0 || keys.len() == n {
            break;
        }
        let at = keys.partition_point(|&k| k < frame);
        keys.insert(at, frame);
    }
    // Insertion at the worst frame closes in on a bad stretch from afar (a key at each halving
    // of it); keys that the ones placed later made redundant are dropped again.
    let mut i = 1;
    while i + 1 < keys.len() {
        if forced.contains(&keys[i]) {
            i += 1;
            continue;
        }
        let without: Vec<usize> = keys[..i].iter().chain(&keys[i + 1..]).copied().collect();
        if worst(&without).1 <= 1.0 {
            keys = without;
        } else {
            i += 1;
        }
    }
    keys
}

/// `path` as SuperSplat `settings.json` text: one track (`cameraAnim`, spline, played once)
/// keyed as `options.keyframes` says, the first frame also the initial camera, and the viewer
/// set to start with the track.
pub fn export(path: &CameraPath, options: &SupersplatOptions) -> Result<String> {
    let frames = check_export(path, FORMAT)?;
    check_fps(options.fps, FORMAT)?;
    path.check_cuts().map_err(|p| export_error(FORMAT, p))?;
    if let Keyframes::Sparse(t) = &options.keyframes {
        let bad = [
            ("position", t.position),
            ("direction", t.direction_degrees),
            ("fov", t.fov_degrees),
        ]
        .into_iter()
        .find(|(_, v)| !(v.is_finite() && *v > 0.0));
        if let Some((what, v)) = bad {
            return Err(export_error(
                FORMAT,
                format!("{what} tolerance {v} is not a positive number"),
            ));
        }
    }
    let distances: Vec<f64> = match &options.focus {
        Focus::Distance(d) => vec![*d; frames.len()],
        Focus::PerFrame(d) if d.len() == frames.len() => d.clone(),
        Focus::PerFrame(d) => {
            return Err(export_error(
                FORMAT,
                format!("{} focus distances for {} frames", d.len(), frames.len()),
            ));
        }
    };
    if let Some((i, d)) = distances
        .iter()
        .enumerate()
        .find(|(_, d)| !(d.is_finite() && **d > 0.0))
    {
        return Err(export_error(
            FORMAT,
            format!("focus distance {d} of frame {i} is not a positive number"),
        ));
    }
    let values: Vec<Key> = frames
        .iter()
        .zip(&distances)
        .map(|((pose, camera), d)| {
            let [px, py, pz] = to_viewer(pose.centre);
            let [tx, ty, tz] = to_viewer(pose.centre + pose.forward() * *d);
            [px, py, pz, tx, ty, tz, camera.vertical_fov_degrees()]
        })
        .collect();
    let duration = (frames.len() - 1) as f64 / options.fps;
    let keys = match &options.keyframes {
        Keyframes::EveryFrame => (0..values.len()).collect(),
        Keyframes::Sparse(tolerance) => {
            sparse_keys(&values, &path.cuts, duration, options.fps, tolerance)
        }
    };
    let times: Vec<f64> = keys.iter().map(|&k| k as f64).collect();
    let positions: Vec<f64> = keys
        .iter()
        .flat_map(|&k| values[k][0..3].to_vec())
        .collect();
    let targets: Vec<f64> = keys
        .iter()
        .flat_map(|&k| values[k][3..6].to_vec())
        .collect();
    let fovs: Vec<f64> = keys.iter().map(|&k| values[k][6]).collect();
    let settings = json!({
        "version": 2,
        "tonemapping": "none",
        "highPrecisionRendering": false,
        "background": { "color": [0, 0, 0] },
        "postEffectSettings": {
            "sharpness": { "enabled": false, "amount": 0 },
            "bloom": { "enabled": false, "intensity": 0.1, "blurLevel": 2 },
            "grading": { "enabled": false, "brightness": 1, "contrast": 1, "saturation": 1,
                         "tint": [1, 1, 1] },
            "vignette": { "enabled": false, "intensity": 0.5, "inner": 0.3, "outer": 0.75,
                          "curvature": 1 },
            "fringing": { "enabled": false, "intensity": 0.5 }
        },
        "animTracks": [{
            "name": "cameraAnim",
            "duration": duration,
            "frameRate": options.fps,
            "loopMode": "none",
            "interpolation": "spline",
            "smoothness": 1,
            "keyframes": {
                "times": times,
                "values": { "position": positions, "target": targets, "fov": fovs }
            }
        }],
        "cameras": [{
            "initial": {
                "position": &positions[0..3],
                "target": &targets[0..3],
                "fov": fovs[0]
            }
        }],
        "annotations": [],
        "startMode": "animTrack"
    });
    let mut settings = settings;
    if !path.cuts.is_empty() {
        settings["animTracks"][0]["cuts"] = json!(path.cuts);
    }
    serde_json::to_string_pretty(&settings)
        .map(|t| t + "\n")
        .map_err(|e| export_error(FORMAT, e.to_string()))
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(rename_all = "camelCase")]
struct Settings {
    anim_tracks: Vec<Track>,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(rename_all = "camelCase")]
struct Track {
    #[serde(default)]
    name: String,
    /// Seconds; when absent, the last key's time.
    #[serde(default)]
    duration: Option<f64>,
    frame_rate: f64,
    /// The viewer's default (a JavaScript default parameter) when absent.
    #[serde(default)]
    smoothness: Option<f64>,
    keyframes: Keys,
    /// splatraj's cuts: frames that begin a new shot (module docs).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    cuts: Vec<usize>,
}

#[derive(Debug, Deserialize, Serialize)]
struct Keys {
    times: Vec<f64>,
    values: Values,
}

#[derive(Debug, Deserialize, Serialize)]
struct Values {
    position: Vec<f64>,
    target: Vec<f64>,
    #[serde(default)]
    fov: Vec<f64>,
}

/// The first animation track of `settings.json` text as the viewer plays it ([`Playback`]),
/// one frame per 1/frameRate s from 0 to `duration` (a dense file's keys are those frames;
/// a sparse one's frames between keys are the spline's). Poses by look-at with the viewer's
/// up; with a `fov`, a centred square-pixel camera of `height` pixels and width
/// `height` × `aspect`, since the file has no image size.
pub fn import(text: &str, file: &str, height: usize, aspect: f64) -> Result<CameraPath> {
    let settings: Settings =
        serde_json::from_str(text).map_err(|error| InterchangeError::Json {
            file: file.to_string(),
            format: FORMAT,
            error,
        })?;
    let track = settings
        .anim_tracks
        .first()
        .ok_or_else(|| invalid(file, "animTracks", "holds no track"))?;
    let keys = &track.keyframes;
    let n = keys.times.len();
    let element = |key: &str| format!("animTracks[0].keyframes.{key}");
    if n == 0 {
        return Err(invalid(file, element("times"), "holds no keyframes"));
    }
    for (key, values, per) in [
        ("values.position", &keys.values.position, 3),
        ("values.target", &keys.values.target, 3),
    ] {
        if values.len() != per * n {
            return Err(invalid(
                file,
                element(key),
                format!(
                    "{} numbers for {n} keyframes, expected {}",
                    values.len(),
                    per * n
                ),
            ));
        }
    }
    if !keys.values.fov.is_empty() && keys.values.fov.len() != n {
        return Err(invalid(
            file,
            element("values.fov"),
            format!("{} numbers for {n} keyframes", keys.values.fov.len()),
        ));
    }
    if !(track.frame_rate.is_finite() && track.frame_rate > 0.0) {
        return Err(invalid(
            file,
            "animTracks[0].frameRate",
            format!("{} is not a positive number", track.frame_rate),
        ));
    }
    if let Some((i, time)) = keys
        .times
        .iter()
        .enumerate()
        .find(|(_, t)| !(t.is_finite() && (0.0..MAX_FRAMES).contains(*t)))
    {
        return Err(invalid(
            file,
            element(&format!("times[{i}]")),
            format!(
                "{time} is not a keyframe time: times are frames from 0, below {MAX_FRAMES} \
                 (the longest track played)"
            ),
        ));
    }
    if let Some(i) = (1..n).find(|&i| {
        keys.times[i].partial_cmp(&keys.times[i - 1]) != Some(std::cmp::Ordering::Greater)
    }) {
        return Err(invalid(
            file,
            element(&format!("times[{i}]")),
            format!(
                "{} does not follow {} (times must increase)",
                keys.times[i],
                keys.times[i - 1]
            ),
        ));
    }
    let fovs = keys
        .values
        .fov
        .iter()
        .enumerate()
        .map(|(i, &fov)| {
            if fov.is_finite() && fov > 0.0 && fov < 180.0 {
                Ok(fov)
            } else {
                Err(invalid(
                    file,
                    element(&format!("values.fov[{i}]")),
                    format!("{fov} is not a field of view in degrees"),
                ))
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let last_time = keys.times[n - 1];
    let duration = track.duration.unwrap_or(last_time / track.frame_rate);
    // The viewer plays from 0 s to `duration`: one frame per 1/frameRate s; a few frames of
    // slack against rounding in duration × frameRate.
    let played = duration * track.frame_rate + 1e-6;
    if !(0.0..MAX_FRAMES).contains(&played) {
        return Err(invalid(
            file,
            "animTracks[0].duration",
            format!(
                "{duration} s at {} fps is not a playable length",
                track.frame_rate
            ),
        ));
    }
    let points: Vec<Key> = (0..n)
        .map(|i| {
            let p = &keys.values.position[3 * i..3 * i + 3];
            let t = &keys.values.target[3 * i..3 * i + 3];
            [
                p[0],
                p[1],
                p[2],
                t[0],
                t[1],
                t[2],
                fovs.get(i).copied().unwrap_or(0.0),
            ]
        })
        .collect();
    let playback = Playback::new(
        &keys.times,
        &points,
        duration,
        track.frame_rate,
        track.smoothness.unwrap_or(1.0),
    );
    let width = ((height as f64) * aspect).round().max(1.0) as usize;
    let up = from_viewer([0.0, 1.0, 0.0]);
    let frames = playback
        .frames(played.floor() as usize)
        .into_iter()
        .enumerate()
        .map(|(f, v)| {
            let pose = CameraPose::look_at(
                from_viewer([v[0], v[1], v[2]]),
                from_viewer([v[3], v[4], v[5]]),
                up,
            )
            .map_err(|problem| {
                let at = match keys.times.iter().position(|&t| t == f as f64) {
                    Some(i) => format!("frame {f} (keyframe {i})"),
                    None => format!("frame {f} (between keyframes)"),
                };
                invalid(file, at, problem.to_string())
            })?;
            // The file has no image size: a centred camera of the chosen size.
            let camera = (!fovs.is_empty()).then(|| {
                Intrinsics::centred(
                    Intrinsics::focal_from_vertical_fov(v[6], height),
                    width,
                    height,
                )
            });
            Ok(Frame { pose, camera })
        })
        .collect::<Result<Vec<_>>>()?;
    crate::camera::check_cuts(&track.cuts, frames.len())
        .map_err(|p| invalid(file, "animTracks[0].cuts", p))?;
    Ok(CameraPath {
        frames,
        fps: Some(track.frame_rate),
        seconds: Some(duration),
        cuts: track.cuts.clone(),
    })
}

/// Reads a SuperSplat `settings.json` (see [`import`]).
pub fn read(path: &std::path::Path, height: usize, aspect: f64) -> Result<CameraPath> {
    import(
        &read_text(path)?,
        &path.display().to_string(),
        height,
        aspect,
    )
}
