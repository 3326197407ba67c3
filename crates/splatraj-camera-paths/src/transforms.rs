//! nerfstudio `transforms.json`, the training-data format (`ns-process-data` writes it beside
//! the images; Instant-NGP and the NeRF synthetic scenes use the same shape). Read only.
//!
//! Schema (nerfstudio `nerfstudio/data/dataparsers/nerfstudio_dataparser.py`):
//!
//! - `frames`: one entry per image, `file_path` (the image, relative to the file) and
//!   `transform_matrix` (4×4 as four rows, **camera-to-world**, **OpenGL camera axes**: x right,
//!   y up, z backward);
//! - intrinsics at the top level or per frame (a frame's own values win): `fl_x`, `fl_y`, `cx`,
//!   `cy` (pixels), `w`, `h` (image size); without `fl_x`, `camera_angle_x` (horizontal field
//!   of view, radians, as Instant-NGP and the synthetic scenes give it); a missing `fl_y` is
//!   `fl_x` (or from `camera_angle_y`), a missing principal point the image centre;
//! - `camera_model`: `OPENCV`, `PINHOLE`, `SIMPLE_PINHOLE` or absent; the distortion
//!   coefficients (`k1`…, `p1`, `p2`) are ignored, as for COLMAP's distorted models; fisheye and
//!   equirectangular cameras are refused.
//!
//! The poses are taken as the file holds them: nerfstudio's trainers move them again
//! (`dataparser_transforms.json`: orientation, centring, scale), and a scene exported from such
//! a model is in that moved frame.

use serde::Deserialize;
use serde_json::Value;

use crate::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use crate::error::{InterchangeError, Result, invalid, read_text};

const FORMAT: &str = "nerfstudio transforms.json";

/// Intrinsics keys, at the top level or in a frame.
#[derive(Debug, Default, Clone, Deserialize)]
struct CameraKeys {
    #[serde(default)]
    camera_model: Option<String>,
    #[serde(default)]
    fl_x: Option<f64>,
    #[serde(default)]
    fl_y: Option<f64>,
    #[serde(default)]
    cx: Option<f64>,
    #[serde(default)]
    cy: Option<f64>,
    #[serde(default)]
    w: Option<f64>,
    #[serde(default)]
    h: Option<f64>,
    #[serde(default)]
    camera_angle_x: Option<f64>,
    #[serde(default)]
    camera_angle_y: Option<f64>,
}

impl CameraKeys {
    /// These keys with `frame`'s own values in place of those it has.
    fn overridden_by(&self, frame: &CameraKeys) -> CameraKeys {
        CameraKeys {
            camera_model: frame
                .camera_model
                .clone()
                .or_else(|| self.camera_model.clone()),
            fl_x: frame.fl_x.or(self.fl_x),
            fl_y: frame.fl_y.or(self.fl_y),
            cx: frame.cx.or(self.cx),
            cy: frame.cy.or(self.cy),
            w: frame.w.or(self.w),
            h: frame.h.or(self.h),
            camera_angle_x: frame.camera_angle_x.or(self.camera_angle_x),
            camera_angle_y: frame.camera_angle_y.or(self.camera_angle_y),
        }
    }

    /// The pinhole these keys give, or which key is missing or wrong (`element` prefixes it).
    fn pinhole(&self, file: &str, element: &str) -> Result<Intrinsics> {
        if let Some(model) = &self.camera_model
            && !matches!(model.as_str(), "OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE")
        {
            return Err(invalid(
                file,
                format!("{element}camera_model"),
                format!(
                    "{model} is not supported (OPENCV, PINHOLE or SIMPLE_PINHOLE; distortion \
                     is ignored)"
                ),
            ));
        }
        let size = |value: Option<f64>, key: &str| -> Result<usize> {
            let v = value.ok_or_else(|| {
                invalid(
                    file,
                    format!("{element}{key}"),
                    "missing (the image size is needed at the top level or in the frame)",
                )
            })?;
            if !(v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= 1e6) {
                return Err(invalid(
                    file,
                    format!("{element}{key}"),
                    format!("{v} is not an image size in pixels"),
                ));
            }
            Ok(v as usize)
        };
        let (width, height) = (size(self.w, "w")?, size(self.h, "h")?);
        // A field of view in radians: in (0, π), else the focal length it gives is negative
        // or infinite; named as written, not as the focal length it would have made.
        let from_angle = |angle: Option<f64>, pixels: usize, key: &str| -> Result<Option<f64>> {
            match angle {
                None => Ok(None),
                Some(a) if a.is_finite() && a > 0.0 && a < std::f64::consts::PI => {
                    Ok(Some(0.5 * pixels as f64 / (0.5 * a).tan()))
                }
                Some(a) => Err(invalid(
                    file,
                    format!("{element}{key}"),
                    format!("{a:?} is not a field of view in radians (between 0 and π)"),
                )),
            }
        };
        let fx = match self.fl_x {
            Some(fx) => fx,
            None => from_angle(self.camera_angle_x, width, "camera_angle_x")?.ok_or_else(|| {
                invalid(
                    file,
                    format!("{element}fl_x"),
                    "missing (or camera_angle_x)",
                )
            })?,
        };
        let fy = match self.fl_y {
            Some(fy) => fy,
            None => from_angle(self.camera_angle_y, height, "camera_angle_y")?.unwrap_or(fx),
        };
        let camera = Intrinsics {
            fx,
            fy,
            cx: self.cx.unwrap_or(width as f64 / 2.0),
            cy: self.cy.unwrap_or(height as f64 / 2.0),
            width,
            height,
        };
        camera
            .validate()
            .map_err(|p| invalid(file, format!("{element}fl_x/fl_y/cx/cy/w/h"), p))?;
        Ok(camera)
    }
}

#[derive(Debug, Deserialize)]
struct TransformsFile {
    #[serde(flatten)]
    camera: CameraKeys,
    frames: Vec<Value>,
}

#[derive(Debug, Deserialize)]
struct FrameEntry {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    camera: CameraKeys,
}

/// The path of `transforms.json` text (`file` names it in errors), in file order, with each
/// frame's `file_path`.
pub fn import_named(text: &str, file: &str) -> Result<(CameraPath, Vec<String>)> {
    let parsed: TransformsFile =
        serde_json::from_str(text).map_err(|error| InterchangeError::Json {
            file: file.to_string(),
            format: FORMAT,
            error,
        })?;
    if parsed.frames.is_empty() {
        return Err(invalid(file, "frames", "holds no frames"));
    }
    let mut frames = Vec::with_capacity(parsed.frames.len());
    let mut names = Vec::with_capacity(parsed.frames.len());
    for (i, value) in parsed.frames.iter().enumerate() {
        let element = format!("frames[{i}].");
        // Each frame on its own, so that an error says which frame it is in.
        let entry: FrameEntry = serde_json::from_value(value.clone())
            .map_err(|e| invalid(file, format!("frames[{i}]"), e.to_string()))?;
        let key = |k: &str| format!("frames[{i}] ({}).{k}", entry.file_path);
        let rows = matrix_rows(&entry.transform_matrix)
            .map_err(|p| invalid(file, key("transform_matrix"), p))?;
        let pose = CameraPose::from_camera_to_world_opengl(&rows)
            .map_err(|p| invalid(file, key("transform_matrix"), p))?;
        let camera = parsed
            .camera
            .overridden_by(&entry.camera)
            .pinhole(file, &element)?;
        frames.push(Frame {
            pose,
            camera: Some(camera),
        });
        names.push(entry.file_path);
    }
    Ok((CameraPath::untimed(frames), names))
}

/// The path of `transforms.json` text, without the image names.
pub fn import(text: &str, file: &str) -> Result<CameraPath> {
    import_named(text, file).map(|(path, _)| path)
}

/// Reads a `transforms.json` with each frame's `file_path`.
pub fn read_named(path: &std::path::Path) -> Result<(CameraPath, Vec<String>)> {
    import_named(&read_text(path)?, &path.display().to_string())
}

/// Four rows of four numbers (a 3×4 matrix gets the row `[0, 0, 0, 1]`, as some writers leave
/// it out).
fn matrix_rows(rows: &[Vec<f64>]) -> Result<[[f64; 4]; 4], String> {
    if !(rows.len() == 4 || rows.len() == 3) || rows.iter().any(|r| r.len() != 4) {
        return Err(format!(
            "expected 4 rows of 4 numbers, got {} rows of {:?}",
            rows.len(),
            rows.iter().map(Vec::len).collect::<Vec<_>>()
        ));
    }
    let mut out = [[0.0, 0.0, 0.0, 1.0]; 4];
    for (o, r) in out.iter_mut().zip(rows) {
        o.copy_from_slice(r);
    }
    Ok(out)
}
