//! SuperSplat viewer settings (`settings.json`, version 2) with one camera animation track, as
//! the SuperSplat editor's viewer export writes it and the SuperSplat viewer plays it.
//!
//! Schema (playcanvas/supersplat-viewer `docs/api.md`, "Settings Schema", and its
//! `src/animation/anim-state.ts`): `version: 2`, `tonemapping`, `highPrecisionRendering`,
//! `background`, `postEffectSettings`, `animTracks`, `cameras`, `annotations`, `startMode`.
//! A track has `name`, `duration` (seconds), `frameRate`, `loopMode`, `interpolation`,
//! `smoothness` and `keyframes: { times, values: { position, target, fov } }`, where `times`
//! are in **frames** (the player evaluates its spline at seconds × `frameRate`), `position`
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

use serde::{Deserialize, Serialize};
use serde_json::json;

use glam::DVec3;

use crate::camera::{CameraPath, CameraPose, Frame, Pinhole};
use crate::error::{InterchangeError, Result, export_error, invalid, read_text};
use crate::{check_export, check_fps};

const FORMAT: &str = "SuperSplat settings.json";

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

/// Options of the SuperSplat export.
#[derive(Debug, Clone, PartialEq)]
pub struct SupersplatOptions {
    /// Frames per second (`frameRate`; `duration` = (frames − 1) / fps).
    pub fps: f64,
    /// Focus distance of the targets.
    pub focus: Focus,
}

impl Default for SupersplatOptions {
    fn default() -> Self {
        Self {
            fps: 30.0,
            focus: Focus::Distance(1.0),
        }
    }
}

/// `path` as SuperSplat `settings.json` text: every frame a keyframe of one track
/// (`cameraAnim`, spline, played once), the first frame also the initial camera, and the
/// viewer set to start with the track.
pub fn export(path: &CameraPath, options: &SupersplatOptions) -> Result<String> {
    let frames = check_export(path, FORMAT)?;
    check_fps(options.fps, FORMAT)?;
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
    let mut times = Vec::with_capacity(frames.len());
    let mut positions = Vec::with_capacity(3 * frames.len());
    let mut targets = Vec::with_capacity(3 * frames.len());
    let mut fovs = Vec::with_capacity(frames.len());
    for (i, ((pose, camera), d)) in frames.iter().zip(&distances).enumerate() {
        times.push(i as f64);
        positions.extend(to_viewer(pose.centre));
        targets.extend(to_viewer(pose.centre + pose.forward() * *d));
        fovs.push(camera.vertical_fov_degrees());
    }
    let duration = (frames.len() - 1) as f64 / options.fps;
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
    frame_rate: f64,
    keyframes: Keys,
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

/// The keyframes of the first animation track of `settings.json` text, one frame per keyframe
/// (poses by look-at with the viewer's up; with a `fov`, a centred square-pixel camera of
/// `height` pixels and width `height` × `aspect`, since the file has no image size).
pub fn import(text: &str, file: &str, height: usize, aspect: f64) -> Result<CameraPath> {
    let settings: Settings =
        serde_json::from_str(text).map_err(|source| InterchangeError::Json {
            file: file.to_string(),
            format: FORMAT,
            source,
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
    let width = ((height as f64) * aspect).round().max(1.0) as usize;
    let up = from_viewer([0.0, 1.0, 0.0]);
    let frames = (0..n)
        .map(|i| {
            let p = &keys.values.position[3 * i..3 * i + 3];
            let t = &keys.values.target[3 * i..3 * i + 3];
            let pose = CameraPose::look_at(
                from_viewer([p[0], p[1], p[2]]),
                from_viewer([t[0], t[1], t[2]]),
                up,
            )
            .map_err(|problem| invalid(file, format!("keyframe {i}"), problem))?;
            let camera = match keys.values.fov.get(i) {
                Some(&fov) if fov.is_finite() && fov > 0.0 && fov < 180.0 => Some(
                    Pinhole::centred(Pinhole::focal_from_vertical_fov(fov, height), width, height),
                ),
                Some(fov) => {
                    return Err(invalid(
                        file,
                        element(&format!("values.fov[{i}]")),
                        format!("{fov} is not a field of view in degrees"),
                    ));
                }
                None => None,
            };
            Ok(Frame { pose, camera })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(CameraPath {
        frames,
        fps: Some(track.frame_rate),
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
