//! Sparse SuperSplat keyframes, judged by the viewer's own interpolation: the export keys a
//! few frames, and the track as supersplat-viewer plays it stays within the stated tolerance of
//! the path at every frame (position ≤ 1 % of the path's extent, view direction ≤ 1°, vertical
//! fov ≤ 0.1°).
//!
//! `viewer_play` below is a line-by-line transcription of playcanvas/supersplat-viewer
//! (commit f6378f066d803a7b9dd4b86e5eb78b03f8a37730) `src/animation/anim-state.ts`
//! (`AnimState.fromTrack`: points = position, target, fov per key; `extra`; the looping spline
//! of length (duration + extra) × frameRate; `update` evaluates at cursor seconds × frameRate)
//! and `src/core/spline.ts` (`CubicSpline.fromPointsLooping`, `calcKnots`, `evaluate`,
//! `evaluateSegment`), with its flat knot array (in-tangent, value, out-tangent per number), kept
//! apart from the library's `Playback` so that one checks the other.

use std::f64::consts::TAU;

use glam::DVec3;
use serde_json::Value;
use splatraj_camera_paths::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use splatraj_camera_paths::supersplat::{self, Focus, Keyframes, SupersplatOptions};

const FPS: f64 = 30.0;
const FOCUS: f64 = 2.0;

/// `CubicSpline.calcKnots` of spline.ts.
fn calc_knots(times: &[f64], points: &[f64], smoothness: f64) -> Vec<f64> {
    let n = times.len();
    let dim = points.len() / n;
    let mut knots = vec![0.0; n * dim * 3];
    for i in 0..n {
        let t = times[i];
        for j in 0..dim {
            let idx = i * dim + j;
            let p = points[idx];
            let tangent = if i == 0 {
                (points[idx + dim] - p) / (times[i + 1] - t)
            } else if i == n - 1 {
                (p - points[idx - dim]) / (t - times[i - 1])
            } else {
                (points[idx + dim] - points[idx - dim]) / (times[i + 1] - times[i - 1])
            };
            let in_scale = if i > 0 {
                times[i] - times[i - 1]
            } else {
                times[1] - times[0]
            };
            let out_scale = if i < n - 1 {
                times[i + 1] - times[i]
            } else {
                times[i] - times[i - 1]
            };
            knots[idx * 3] = tangent * in_scale * smoothness;
            knots[idx * 3 + 1] = p;
            knots[idx * 3 + 2] = tangent * out_scale * smoothness;
        }
    }
    knots
}

/// `CubicSpline.evaluate` (with `getKnot` and `evaluateSegment`) of spline.ts.
fn evaluate(times: &[f64], knots: &[f64], time: f64) -> Vec<f64> {
    let dim = knots.len() / times.len() / 3;
    let last = times.len() - 1;
    let knot = |index: usize| {
        (0..dim)
            .map(|i| knots[index * 3 * dim + i * 3 + 1])
            .collect()
    };
    if time <= times[0] {
        return knot(0);
    }
    if time >= times[last] {
        return knot(last);
    }
    let mut seg = 0;
    while time >= times[seg + 1] {
        seg += 1;
    }
    let t = (time - times[seg]) / (times[seg + 1] - times[seg]);
    let (t2, twot, omt) = (t * t, t + t, 1.0 - t);
    let omt2 = omt * omt;
    let mut idx = seg * dim * 3;
    (0..dim)
        .map(|_| {
            let p0 = knots[idx + 1];
            let m0 = knots[idx + 2];
            let m1 = knots[idx + dim * 3];
            let p1 = knots[idx + dim * 3 + 1];
            idx += 3;
            p0 * ((1.0 + twot) * omt2)
                + m0 * (t * omt2)
                + p1 * (t2 * (3.0 - twot))
                + m1 * (t2 * (t - 1.0))
        })
        .collect()
}

/// The first track of `settings` as the viewer shows it at frames 0, 1, … of `fps`, up to
/// its duration: [position, target, fov] in the viewer's axes.
fn viewer_play(settings: &Value, fps: f64) -> Vec<[f64; 7]> {
    let track = &settings["animTracks"][0];
    let num = |v: &Value| v.as_f64().unwrap();
    let list = |v: &Value| v.as_array().unwrap().iter().map(num).collect::<Vec<f64>>();
    let times = list(&track["keyframes"]["times"]);
    let (position, target, fov) = (
        list(&track["keyframes"]["values"]["position"]),
        list(&track["keyframes"]["values"]["target"]),
        list(&track["keyframes"]["values"]["fov"]),
    );
    let (duration, frame_rate, smoothness) = (
        num(&track["duration"]),
        num(&track["frameRate"]),
        num(&track["smoothness"]),
    );
    let mut points = Vec::new();
    for i in 0..times.len() {
        points.extend_from_slice(&position[i * 3..i * 3 + 3]);
        points.extend_from_slice(&target[i * 3..i * 3 + 3]);
        points.push(fov[i]);
    }
    let extra = if duration == times[times.len() - 1] / frame_rate {
        1.0
    } else {
        0.0
    };
    let length = (duration + extra) * frame_rate;
    // fromPointsLooping
    let (times, points) = if times.len() < 2 {
        (times, points)
    } else {
        let dim = points.len() / times.len();
        let mut new_times = vec![
            times[times.len() - 2] - length,
            times[times.len() - 1] - length,
        ];
        new_times.extend_from_slice(&times);
        new_times.extend([length + times[0], length + times[1]]);
        let mut new_points = points[points.len() - dim * 2..].to_vec();
        new_points.extend_from_slice(&points);
        new_points.extend_from_slice(&points[..dim * 2]);
        (new_times, new_points)
    };
    let knots = if times.len() < 2 {
        // One key: evaluate only ever returns its value.
        points.iter().flat_map(|&p| [0.0, p, 0.0]).collect()
    } else {
        calc_knots(&times, &points, smoothness)
    };
    let frames = (duration * fps + 1e-6).floor() as usize;
    (0..=frames)
        .map(|f| {
            // AnimCursor (loopMode none) holds at duration.
            let seconds = (f as f64 / fps).min(duration);
            let v = evaluate(&times, &knots, seconds * frame_rate);
            v.try_into().unwrap()
        })
        .collect()
}

/// How far `played` (viewer axes) strays from `frame` of the path: position (scene units),
/// viewing direction (degrees), vertical fov (degrees).
fn misses(played: &[f64; 7], frame: &Frame) -> (f64, f64, f64) {
    // The viewer's world is the scene turned 180° about z.
    let scene = |x: f64, y: f64, z: f64| DVec3::new(-x, -y, z);
    let position = scene(played[0], played[1], played[2]);
    let target = scene(played[3], played[4], played[5]);
    let direction = (target - position).normalize();
    let angle = direction
        .dot(frame.pose.forward())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees();
    let fov = (played[6] - frame.camera.unwrap().vertical_fov_degrees()).abs();
    (position.distance(frame.pose.centre), angle, fov)
}

/// Diagonal of the bounding box of the path's centres.
fn extent(path: &CameraPath) -> f64 {
    let centres = path.frames.iter().map(|f| f.pose.centre);
    let lo = centres.clone().fold(DVec3::INFINITY, DVec3::min);
    let hi = centres.fold(DVec3::NEG_INFINITY, DVec3::max);
    (hi - lo).length()
}

/// A path of `seconds` at 30 fps: centre, what it looks at and the vertical fov at time t (s).
fn path_of(
    seconds: f64,
    centre: impl Fn(f64) -> DVec3,
    look: impl Fn(f64) -> DVec3,
    fov: impl Fn(f64) -> f64,
) -> CameraPath {
    // Scene y down, as in the usual captures.
    let up = DVec3::new(0.0, -1.0, 0.0);
    let frames = (0..=(seconds * FPS).round() as usize)
        .map(|i| {
            let t = i as f64 / FPS;
            let c = centre(t);
            Frame {
                pose: CameraPose::look_at(c, c + look(t), up).unwrap(),
                camera: Some(Intrinsics::centred(
                    Intrinsics::focal_from_vertical_fov(fov(t), 480),
                    640,
                    480,
                )),
            }
        })
        .collect();
    CameraPath {
        cuts: Vec::new(),
        frames,
        fps: Some(FPS),
        seconds: None,
    }
}

/// Exports `path` with sparse keys and checks the viewer's playback against it; returns the
/// key count and prints what it found.
fn sparse_export_plays_within_tolerance(path: &CameraPath, what: &str) -> usize {
    let text = supersplat::export(
        path,
        &SupersplatOptions {
            fps: FPS,
            focus: Focus::Distance(FOCUS),
            ..SupersplatOptions::default()
        },
    )
    .unwrap();
    let settings: Value = serde_json::from_str(&text).unwrap();
    let keys = settings["animTracks"][0]["keyframes"]["times"]
        .as_array()
        .unwrap()
        .len();
    let played = viewer_play(&settings, FPS);
    assert_eq!(played.len(), path.frames.len(), "{what}: frames played");
    let limit = 0.01 * extent(path);
    let (mut position, mut angle, mut fov) = (0.0f64, 0.0f64, 0.0f64);
    for (f, (p, frame)) in played.iter().zip(&path.frames).enumerate() {
        let (dp, da, df) = misses(p, frame);
        assert!(
            dp <= limit * (1.0 + 1e-9) && da <= 1.0 + 1e-9 && df <= 0.1 + 1e-9,
            "{what}: frame {f}: position off by {dp} (limit {limit}), direction {da}°, fov {df}°"
        );
        (position, angle, fov) = (position.max(dp), angle.max(da), fov.max(df));
    }
    // Our reader plays the file as the viewer does: same poses at every frame.
    let back = supersplat::import(&text, "settings.json", 480, 640.0 / 480.0).unwrap();
    assert_eq!(back.frames.len(), path.frames.len(), "{what}: frames read");
    for (f, (p, frame)) in played.iter().zip(&back.frames).enumerate() {
        let (dp, da, df) = misses(p, frame);
        assert!(
            dp < 1e-9 && da < 1e-5 && df < 1e-9,
            "{what}: frame {f} read {dp}, {da}°, {df}° from the viewer's playback"
        );
    }
    println!(
        "{what}: {} frames, {keys} keys ({:.2} per second); largest misses: position {:.3} % of \
         extent, direction {angle:.3}°, fov {fov:.4}°",
        path.frames.len(),
        keys as f64 / (path.frames.len() as f64 / FPS),
        100.0 * position / extent(path),
    );
    keys
}

#[test]
fn a_smooth_path_with_pans_needs_a_few_keys_a_second() {
    // 9 s: a dolly along a gentle S-curve that rises, the view panning left and right twice
    // (±35°) and tilting, a zoom from 55° to 40° in the middle.
    let smooth = |x: f64| x * x * (3.0 - 2.0 * x);
    let path = path_of(
        9.0,
        |t| DVec3::new(3.0 * (TAU * t / 18.0).sin(), -0.5 * t / 9.0, -6.0 + t * 0.8),
        |t| {
            let yaw = 0.6 * (TAU * t / 4.5).sin();
            let pitch = 0.15 * (TAU * t / 9.0).cos();
            DVec3::new(
                yaw.sin() * pitch.cos(),
                pitch.sin(),
                yaw.cos() * pitch.cos(),
            )
        },
        |t| 55.0 - 15.0 * smooth(((t - 3.0) / 3.0).clamp(0.0, 1.0)),
    );
    let keys = sparse_export_plays_within_tolerance(&path, "smooth path with pans");
    assert!(keys <= 4 * 9, "{keys} keys for 9 s");
}

#[test]
fn an_orbit_with_a_stop_needs_keys_only_at_the_turns() {
    // 6 s: a half orbit about the origin at radius 4, a 1-s stop, then back a quarter; always
    // looking at the origin, fov fixed. The turning points are where keys must go.
    let angle = |t: f64| {
        if t < 3.0 {
            std::f64::consts::PI * (t / 3.0)
        } else if t < 4.0 {
            std::f64::consts::PI
        } else {
            std::f64::consts::PI * (1.0 - 0.5 * (t - 4.0) / 2.0)
        }
    };
    let centre = move |t: f64| DVec3::new(4.0 * angle(t).sin(), -1.0, -4.0 * angle(t).cos());
    let path = path_of(6.0, centre, move |t| -centre(t), |_| 50.0);
    let keys = sparse_export_plays_within_tolerance(&path, "orbit with a stop");
    assert!(keys <= 4 * 6, "{keys} keys for 6 s");
}

#[test]
fn an_eased_straight_line_is_two_keys() {
    // A dolly from rest to rest along a line is what the viewer plays between two keys: it
    // builds the looping spline, whose end tangents (across the wrap, from a key to itself) are
    // zero, so two keys play position = A + (B − A)·smoothstep(t / T).
    let smooth = |x: f64| x * x * (3.0 - 2.0 * x);
    let (a, b) = (DVec3::new(-2.0, -1.0, -5.0), DVec3::new(3.0, -0.5, 1.0));
    let path = path_of(
        4.0,
        |t| a + (b - a) * smooth(t / 4.0),
        |_| DVec3::new(0.3, 0.1, 1.0),
        |_| 50.0,
    );
    assert_eq!(sparse_export_plays_within_tolerance(&path, "eased line"), 2);
}

#[test]
fn a_constant_speed_line_needs_keys_near_its_ends() {
    // At constant speed the wrap-around tangents of the first and last keys are wrong (they
    // point from the far end), so the export keys the frames next to each end; Catmull-Rom
    // tangents between those are exact on a line, so the middle needs none.
    let (a, b) = (DVec3::new(-2.0, -1.0, -5.0), DVec3::new(3.0, -0.5, 1.0));
    let path = path_of(
        4.0,
        |t| a + (b - a) * (t / 4.0),
        |_| DVec3::new(0.3, 0.1, 1.0),
        |_| 50.0,
    );
    assert_eq!(
        sparse_export_plays_within_tolerance(&path, "constant-speed line"),
        4
    );
}

#[test]
fn every_frame_keys_are_still_written_and_read_exactly() {
    let path = path_of(
        1.0,
        |t| DVec3::new(t, 0.0, -3.0),
        |t| DVec3::new(t.sin(), 0.0, t.cos()),
        |t| 50.0 + t,
    );
    let text = supersplat::export(
        &path,
        &SupersplatOptions {
            fps: FPS,
            focus: Focus::Distance(FOCUS),
            keyframes: Keyframes::EveryFrame,
        },
    )
    .unwrap();
    let settings: Value = serde_json::from_str(&text).unwrap();
    let times = settings["animTracks"][0]["keyframes"]["times"]
        .as_array()
        .unwrap()
        .len();
    assert_eq!(times, path.frames.len());
    let back = supersplat::import(&text, "settings.json", 480, 640.0 / 480.0).unwrap();
    for (f, (a, b)) in path.frames.iter().zip(&back.frames).enumerate() {
        let (r, c) = a.pose.max_difference(&b.pose);
        assert!(r < 1e-9 && c < 1e-9, "frame {f}: {r:e}, {c:e}");
    }
}
