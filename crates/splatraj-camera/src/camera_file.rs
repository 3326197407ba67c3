//! The camera file: one pinhole camera and its pose as JSON (the `--camera` of `splatraj
//! render`).
//!
//! `{"fx", "fy", "cx", "cy", "width", "height"}` plus exactly one of `"pose"` (Φ = [ω, c], the
//! rotation vector of camera-to-world and the camera centre) or `"world_to_camera"` (4×4,
//! row-major, as four rows or 16 numbers). Unknown keys are refused by serde, naming the key.
//! This module holds the schema and its checks; the caller parses the JSON text (any serde
//! format works) and adds the file name to errors.

use glam::DMat4;
use serde::{Deserialize, Serialize};

use crate::error::CameraError;
use crate::intrinsics::Intrinsics;
use crate::pose::Pose;
pub use crate::pose::matrix_rows;

/// A checked camera: intrinsics and pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSpec {
    /// Intrinsics as written in the file.
    pub intrinsics: Intrinsics,
    /// Pose Φ.
    pub pose: Pose,
}

/// The camera file as written.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z]: rotation vector of camera-to-world, camera centre.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<[f64; 6]>,
    /// 4×4 world-to-camera matrix, row-major.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_to_camera: Option<Matrix4>,
}

/// A 4×4 matrix written as four rows or as 16 numbers, row-major.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Matrix4 {
    /// `[[r0], [r1], [r2], [r3]]`.
    Rows([[f64; 4]; 4]),
    /// 16 numbers, row by row.
    Flat([f64; 16]),
}

impl Matrix4 {
    /// The matrix as glam's (column-major) type.
    pub fn to_dmat4(&self) -> DMat4 {
        let rows = match self {
            Matrix4::Rows(rows) => *rows,
            Matrix4::Flat(flat) => {
                std::array::from_fn(|r| std::array::from_fn(|c| flat[r * 4 + c]))
            }
        };
        // glam is column-major: the rows read as columns give the transpose.
        DMat4::from_cols_array_2d(&rows).transpose()
    }
}

/// What is wrong with a camera file (the message names the key).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct CameraFileError(pub String);

impl CameraFile {
    /// The file of a camera (with `pose`).
    pub fn from_spec(spec: &CameraSpec) -> Self {
        let k = spec.intrinsics;
        CameraFile {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            pose: Some(spec.pose.0),
            world_to_camera: None,
        }
    }

    /// Checks the values and returns the camera.
    pub fn camera(&self) -> Result<CameraSpec, CameraFileError> {
        let bad = |m: String| Err(CameraFileError(m));
        let intrinsics =
            Intrinsics::new(self.fx, self.fy, self.cx, self.cy, self.width, self.height)
                .map_err(|e| CameraFileError(e.to_string()))?;
        let pose = match (&self.pose, &self.world_to_camera) {
            (Some(phi), None) => {
                if let Some(i) = phi.iter().position(|v| !v.is_finite()) {
                    return bad(format!("key `pose` holds a non-finite value at index {i}"));
                }
                check_pose_range(phi).map_err(|e| CameraFileError(format!("key `pose`: {e}")))?;
                Pose(*phi)
            }
            (None, Some(m)) => {
                let pose = Pose::from_world_to_camera(m.to_dmat4())
                    .map_err(|e| CameraFileError(format!("key `world_to_camera`: {e}")))?;
                check_pose_range(&pose.0)
                    .map_err(|e| CameraFileError(format!("key `world_to_camera`: {e}")))?;
                pose
            }
            (Some(_), Some(_)) => {
                return bad("give either key `pose` or key `world_to_camera`, not both".into());
            }
            (None, None) => {
                return bad(
                    "missing the camera pose: add key `pose` (rotation vector of \
                     camera-to-world, then camera centre) or key `world_to_camera` (4×4, \
                     row-major)"
                        .into(),
                );
            }
        };
        Ok(CameraSpec { intrinsics, pose })
    }
}

/// Largest rotation-vector angle accepted, radians: ω is axis × angle, so a real pose needs at
/// most π; far beyond, the renderer's sines and squares lose all precision or overflow.
pub const MAX_ROTATION_ANGLE: f64 = 1e4;
/// Largest camera-centre coordinate accepted: its square must stay finite in f32.
pub const MAX_COORDINATE: f64 = 1e15;

/// Refuses a pose Φ = [ω, c] whose rendering could not be finite: a non-finite value, a
/// rotation angle above [`MAX_ROTATION_ANGLE`] or a centre coordinate above
/// [`MAX_COORDINATE`] (in absolute value); the message names the component.
pub fn check_pose_range(phi: &[f64; 6]) -> Result<(), String> {
    const NAMES: [&str; 6] = ["ω_x", "ω_y", "ω_z", "c_x", "c_y", "c_z"];
    if let Some(i) = phi.iter().position(|v| !v.is_finite()) {
        return Err(format!(
            "{} (index {i}) = {} is not finite",
            NAMES[i], phi[i]
        ));
    }
    let largest = phi[..3].iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let angle = if largest > 0.0 {
        largest
            * phi[..3]
                .iter()
                .map(|v| (v / largest).powi(2))
                .sum::<f64>()
                .sqrt()
    } else {
        0.0
    };
    if angle > MAX_ROTATION_ANGLE {
        return Err(format!(
            "the rotation vector ω = {:?} turns by {angle:e} rad; ω is axis × angle in radians \
             (at most π is needed, {MAX_ROTATION_ANGLE:e} accepted)",
            &phi[..3]
        ));
    }
    if let Some(i) = (3..6).find(|&i| phi[i].abs() > MAX_COORDINATE) {
        return Err(format!(
            "{} (index {i}) = {:e} is beyond ±{MAX_COORDINATE:e} scene units, where the \
             renderer's squares overflow",
            NAMES[i], phi[i]
        ));
    }
    Ok(())
}

/// `k` at another resolution: both sides given, or one side alone keeping the aspect ratio,
/// or neither (unchanged).
pub fn resize(
    k: &Intrinsics,
    width: Option<usize>,
    height: Option<usize>,
) -> Result<Intrinsics, CameraError> {
    let aspect = k.height as f64 / k.width as f64;
    let (w, h) = match (width, height) {
        (None, None) => return Ok(*k),
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, ((w as f64 * aspect).round() as usize).max(1)),
        (None, Some(h)) => (((h as f64 / aspect).round() as usize).max(1), h),
    };
    if w == 0 || h == 0 {
        return Err(CameraError::Intrinsics(format!(
            "width and height must be at least 1 (got {w}×{h})"
        )));
    }
    k.rescaled(w, h)
}
