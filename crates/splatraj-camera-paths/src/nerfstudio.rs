//! nerfstudio `camera_path.json`, as `ns-render camera-path` reads it and the nerfstudio viewer
//! (viser) writes and loads it.
//!
//! Schema (nerfstudio `nerfstudio/cameras/camera_paths.py::get_path_from_json` and
//! `nerfstudio/viewer/render_panel.py`):
//!
//! - `camera_type`: `"perspective"` (we write and read only this), `render_width`,
//!   `render_height` (pixels), `fps`, `seconds` (finite and > 0 where given);
//! - `camera_path`: one entry per rendered frame, `camera_to_world` (16 numbers, a 4×4 matrix
//!   row-major, **OpenGL camera axes**: x right, y up, z backward), `fov` (**vertical**, in
//!   **degrees**, 0 < fov < 180) and `aspect` (width / height, finite and > 0);
//! - `keyframes` (for the viewer's "Load Path"): `matrix` (the same kind of matrix), `fov`,
//!   `aspect`, `override_transition_enabled`, `override_transition_sec`; with
//!   `default_fov`, `default_transition_sec`, `is_cycle`, `smoothness_value`.
//!
//! ns-render builds the intrinsics from `fov` and `render_height` alone: fx = fy =
//! (height / 2) / tan(fov / 2), principal point at the image centre. A camera with fx ≠ fy or an
//! off-centre principal point is written with its vertical field of view and reads back
//! centred. World coordinates are the scene file's own (for a splatfacto model exported with
//! `ns-export gaussian-splat`, nerfstudio's world frame, in which ns-render also renders).
//!
//! Keyframes are a subset of the frames (`keyframes_per_second`, always the first and the last
//! frame); each transition's length is written as an override so the viewer's spline passes the
//! keyframes at the same times as the frames.
//!
//! **Cuts.** nerfstudio has no cut: `ns-render` plays `camera_path` frame by frame (so a
//! switch between two consecutive entries is a cut as rendered), and the viewer's spline
//! flies through keyframes. We write a path with cuts ([`CameraPath::cuts`]) as its frames,
//! both frames of each cut as keyframes (the viewer's flight between them lasts one frame,
//! `1/fps` s, the least its editor can express), and the cuts themselves under the top-level
//! key `cuts` (frame indices that begin a new shot), which nerfstudio ignores and we read
//! back.

use serde::{Deserialize, Serialize};

use crate::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use crate::error::{InterchangeError, Result, invalid};
use crate::{check_export, check_fps};

const FORMAT: &str = "nerfstudio camera_path.json";

/// The file as written and read (unknown keys, such as `crop`, are ignored on reading).
#[derive(Debug, Serialize, Deserialize)]
struct CameraPathFile {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    default_fov: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    default_transition_sec: Option<f64>,
    #[serde(default)]
    keyframes: Vec<serde_json::Value>,
    #[serde(default = "perspective")]
    camera_type: String,
    render_height: usize,
    render_width: usize,
    #[serde(default)]
    fps: Option<f64>,
    #[serde(default)]
    seconds: Option<f64>,
    #[serde(default)]
    is_cycle: bool,
    #[serde(default)]
    smoothness_value: f64,
    camera_path: Vec<PathEntry>,
    /// splatraj's cuts: the frames that begin a new shot (module docs).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    cuts: Vec<usize>,
}

fn perspective() -> String {
    "perspective".into()
}

#[derive(Debug, Serialize, Deserialize)]
struct PathEntry {
    camera_to_world: Vec<f64>,
    #[serde(default)]
    fov: Option<f64>,
    #[serde(default)]
    aspect: Option<f64>,
}

#[derive(Debug, Serialize)]
struct Keyframe {
    matrix: Vec<f64>,
    fov: f64,
    aspect: f64,
    override_transition_enabled: bool,
    override_transition_sec: Option<f64>,
}

/// Options of the nerfstudio export.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NerfstudioOptions {
    /// Frames per second (`fps`; `seconds` = frames / fps).
    pub fps: f64,
    /// Keyframes written per second of path for the viewer (at least the first and last frame).
    pub keyframes_per_second: f64,
}

impl Default for NerfstudioOptions {
    fn default() -> Self {
        Self {
            fps: 30.0,
            keyframes_per_second: 2.0,
        }
    }
}

fn flat(rows: [[f64; 4]; 4]) -> Vec<f64> {
    rows.iter().flatten().copied().collect()
}

/// `path` as `camera_path.json` text. The render size is the first frame's; every frame must
/// have intrinsics of that size.
pub fn export(path: &CameraPath, options: &NerfstudioOptions) -> Result<String> {
    let frames = check_export(path, FORMAT)?;
    check_fps(options.fps, FORMAT)?;
    let first = frames[0].1;
    if let Some((i, c)) = frames
        .iter()
        .enumerate()
        .find(|(_, (_, c))| (c.width, c.height) != (first.width, first.height))
    {
        return Err(crate::error::export_error(
            FORMAT,
            format!(
                "frame {i} is {}×{} but frame 0 is {}×{} (ns-render renders one size)",
                c.1.width, c.1.height, first.width, first.height
            ),
        ));
    }
    let n = frames.len();
    let seconds = n as f64 / options.fps;
    let camera_path = frames
        .iter()
        .map(|(pose, camera)| PathEntry {
            camera_to_world: flat(pose.camera_to_world_opengl()),
            fov: Some(camera.vertical_fov_degrees()),
            aspect: Some(camera.aspect()),
        })
        .collect();

    path.check_cuts()
        .map_err(|p| crate::error::export_error(FORMAT, p))?;
    let mut indices = keyframe_indices(n, options.fps, options.keyframes_per_second);
    // Both frames of every cut are keyframes, so the viewer's spline switches in one frame.
    indices.extend(path.cuts.iter().flat_map(|&c| [c - 1, c]));
    indices.sort_unstable();
    indices.dedup();
    let mut previous = None;
    let keyframes = indices
        .iter()
        .map(|&i| {
            let (pose, camera) = frames[i];
            let transition = previous.map(|p: usize| (i - p) as f64 / options.fps);
            previous = Some(i);
            serde_json::to_value(Keyframe {
                matrix: flat(pose.camera_to_world_opengl()),
                fov: camera.vertical_fov_degrees(),
                aspect: camera.aspect(),
                override_transition_enabled: transition.is_some(),
                override_transition_sec: transition,
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| crate::error::export_error(FORMAT, e.to_string()))?;
    let default_transition = if indices.len() > 1 {
        seconds / (indices.len() - 1) as f64
    } else {
        seconds
    };
    let file = CameraPathFile {
        default_fov: Some(first.vertical_fov_degrees()),
        default_transition_sec: Some(default_transition),
        keyframes,
        camera_type: perspective(),
        render_height: first.height,
        render_width: first.width,
        fps: Some(options.fps),
        seconds: Some(seconds),
        is_cycle: false,
        smoothness_value: 0.0,
        camera_path,
        cuts: path.cuts.clone(),
    };
    serde_json::to_string_pretty(&file)
        .map(|t| t + "\n")
        .map_err(|e| crate::error::export_error(FORMAT, e.to_string()))
}

/// Frame indices of the keyframes: evenly spread at `per_second`, first and last included.
fn keyframe_indices(n: usize, fps: f64, per_second: f64) -> Vec<usize> {
    if n == 1 {
        return vec![0];
    }
    let seconds = (n - 1) as f64 / fps;
    let intervals = if per_second.is_finite() && per_second > 0.0 {
        ((seconds * per_second).round() as usize).clamp(1, n - 1)
    } else {
        1
    };
    let mut indices: Vec<usize> = (0..=intervals)
        .map(|k| ((k as f64 * (n - 1) as f64 / intervals as f64).round() as usize).min(n - 1))
        .collect();
    indices.dedup();
    indices
}

/// The path of `camera_path.json` text (`file` names it in errors).
pub fn import(text: &str, file: &str) -> Result<CameraPath> {
    let parsed: CameraPathFile =
        serde_json::from_str(text).map_err(|error| InterchangeError::Json {
            file: file.to_string(),
            format: FORMAT,
            error,
        })?;
    if parsed.camera_type != "perspective" {
        return Err(invalid(
            file,
            "camera_type",
            format!(
                "{:?} is not supported (only \"perspective\" cameras are)",
                parsed.camera_type
            ),
        ));
    }
    if parsed.render_width == 0 || parsed.render_height == 0 {
        return Err(invalid(
            file,
            "render_width/render_height",
            format!(
                "{}×{} is not an image size",
                parsed.render_width, parsed.render_height
            ),
        ));
    }
    if parsed.camera_path.is_empty() {
        return Err(invalid(file, "camera_path", "holds no cameras"));
    }
    let fps = match parsed.fps {
        Some(f) if !(f.is_finite() && f > 0.0) => {
            return Err(invalid(
                file,
                "fps",
                format!("{f} is not a positive number"),
            ));
        }
        other => other,
    };
    if let Some(s) = parsed.seconds
        && !(s.is_finite() && s > 0.0)
    {
        return Err(invalid(
            file,
            "seconds",
            format!("{s} is not a length in seconds (must be finite and > 0)"),
        ));
    }
    let frames = parsed
        .camera_path
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            let element = |key: &str| format!("camera_path[{i}].{key}");
            let rows = matrix_rows(&entry.camera_to_world)
                .map_err(|p| invalid(file, element("camera_to_world"), p))?;
            let pose = CameraPose::from_camera_to_world_opengl(&rows)
                .map_err(|p| invalid(file, element("camera_to_world"), p))?;
            let fov = entry
                .fov
                .ok_or_else(|| invalid(file, element("fov"), "missing"))?;
            if !(fov.is_finite() && fov > 0.0 && fov < 180.0) {
                return Err(invalid(
                    file,
                    element("fov"),
                    format!("{fov} is not a field of view in degrees (0 < fov < 180)"),
                ));
            }
            // ns-render sizes the image by render_width/height, but a broken aspect is a
            // broken file all the same.
            if let Some(aspect) = entry.aspect
                && !(aspect.is_finite() && aspect > 0.0)
            {
                return Err(invalid(
                    file,
                    element("aspect"),
                    format!("{aspect} is not a width / height ratio (must be finite and > 0)"),
                ));
            }
            let focal = Intrinsics::focal_from_vertical_fov(fov, parsed.render_height);
            Ok(Frame {
                pose,
                camera: Some(Intrinsics::centred(
                    focal,
                    parsed.render_width,
                    parsed.render_height,
                )),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    crate::camera::check_cuts(&parsed.cuts, frames.len()).map_err(|p| invalid(file, "cuts", p))?;
    Ok(CameraPath {
        frames,
        fps,
        seconds: parsed.seconds,
        cuts: parsed.cuts,
    })
}

/// Reads a `camera_path.json`.
pub fn read(path: &std::path::Path) -> Result<CameraPath> {
    import(&crate::error::read_text(path)?, &path.display().to_string())
}

fn matrix_rows(values: &[f64]) -> Result<[[f64; 4]; 4], String> {
    if values.len() != 16 {
        return Err(format!(
            "{} numbers, expected 16 (a 4×4 matrix, row-major)",
            values.len()
        ));
    }
    let mut rows = [[0.0; 4]; 4];
    for (k, v) in values.iter().enumerate() {
        rows[k / 4][k % 4] = *v;
    }
    Ok(rows)
}
