//! INRIA 3DGS `cameras.json`, as the reference implementation writes it next to a trained model
//! (`utils/camera_utils.py::camera_to_JSON` of graphdeco-inria/gaussian-splatting) and as the
//! INRIA viewers and SuperSplat import it.
//!
//! A JSON array, one object per camera: `id`, `img_name`, `width`, `height` (pixels),
//! `position` (the camera centre, world coordinates), `rotation` (the **camera-to-world**
//! rotation R_wc as three rows; its columns are the camera axes in world coordinates, **OpenCV
//! axes**: x right, y down, z forward), `fx`, `fy` (pixels). The file has no principal point:
//! readers put it at the image centre, so an off-centre principal point reads back centred.
//! SuperSplat's camera-pose import takes `position` and the third column of `rotation` as the
//! viewing direction.
//!
//! The file lists views, not a timed path. A path with cuts gives each camera the key `shot`
//! (its shot's index, from 0; other readers ignore it), and a camera whose `shot` differs
//! from the one before begins a new shot when we read it back.

use serde::{Deserialize, Serialize};

use crate::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use crate::check_export;
use crate::colmap::frame_name;
use crate::error::{InterchangeError, Result, export_error, invalid, read_text};

const FORMAT: &str = "INRIA cameras.json";

#[derive(Debug, Serialize, Deserialize)]
struct Entry {
    id: i64,
    #[serde(default)]
    img_name: Option<String>,
    width: usize,
    height: usize,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
    /// splatraj's shot of the camera, on a path with cuts (module docs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    shot: Option<usize>,
}

/// `path` as `cameras.json` text; camera `i` is named like frame `i` of a run.
pub fn export(path: &CameraPath) -> Result<String> {
    let frames = check_export(path, FORMAT)?;
    path.check_cuts().map_err(|p| export_error(FORMAT, p))?;
    let entries: Vec<Entry> = frames
        .iter()
        .enumerate()
        .map(|(i, (pose, camera))| {
            let r = pose.rotation;
            let row = |k: usize| [r.x_axis[k], r.y_axis[k], r.z_axis[k]];
            Entry {
                id: i as i64,
                img_name: Some(frame_name(i).trim_end_matches(".png").to_string()),
                width: camera.width,
                height: camera.height,
                position: pose.centre.to_array(),
                rotation: [row(0), row(1), row(2)],
                fx: camera.fx,
                fy: camera.fy,
                shot: (!path.cuts.is_empty()).then(|| path.shot_of_frame(i)),
            }
        })
        .collect();
    serde_json::to_string_pretty(&entries)
        .map(|t| t + "\n")
        .map_err(|e| export_error(FORMAT, e.to_string()))
}

/// The path of `cameras.json` text (`file` names it in errors), in file order.
pub fn import(text: &str, file: &str) -> Result<CameraPath> {
    import_named(text, file).map(|(path, _)| path)
}

/// [`import`] with each camera's `img_name` (where the file has one).
pub fn import_named(text: &str, file: &str) -> Result<(CameraPath, Vec<Option<String>>)> {
    let entries: Vec<Entry> =
        serde_json::from_str(text).map_err(|error| InterchangeError::Json {
            file: file.to_string(),
            format: FORMAT,
            error,
        })?;
    if entries.is_empty() {
        return Err(invalid(file, "[]", "the file lists no cameras"));
    }
    let frames = entries
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let element = |key: &str| format!("[{i}] (id {}).{key}", e.id);
            let r = e.rotation;
            let rotation = glam::DMat3::from_cols(
                glam::DVec3::new(r[0][0], r[1][0], r[2][0]),
                glam::DVec3::new(r[0][1], r[1][1], r[2][1]),
                glam::DVec3::new(r[0][2], r[1][2], r[2][2]),
            );
            let pose = CameraPose::new(rotation, glam::DVec3::from_array(e.position))
                .map_err(|p| invalid(file, element("rotation/position"), p))?;
            let camera = Intrinsics {
                fx: e.fx,
                fy: e.fy,
                cx: e.width as f64 / 2.0,
                cy: e.height as f64 / 2.0,
                width: e.width,
                height: e.height,
            };
            camera
                .validate()
                .map_err(|p| invalid(file, element("width/height/fx/fy"), p))?;
            Ok(Frame {
                pose,
                camera: Some(camera),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let mut path = CameraPath::untimed(frames);
    path.cuts = (1..entries.len())
        .filter(|&i| entries[i].shot.is_some() && entries[i].shot != entries[i - 1].shot)
        .collect();
    let names = entries.into_iter().map(|e| e.img_name).collect();
    Ok((path, names))
}

/// Reads a `cameras.json`.
pub fn read(path: &std::path::Path) -> Result<CameraPath> {
    read_named(path).map(|(path, _)| path)
}

/// Reads a `cameras.json` with each camera's `img_name`.
pub fn read_named(path: &std::path::Path) -> Result<(CameraPath, Vec<Option<String>>)> {
    import_named(&read_text(path)?, &path.display().to_string())
}
