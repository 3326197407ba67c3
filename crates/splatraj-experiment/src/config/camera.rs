//! `[camera]`: the optimisation camera.

use serde::{Deserialize, Serialize};
use splatraj_config::ConfigError;
use splatraj_render::camera::Intrinsics;
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;
use splatraj_traj::trajectory::{
    DEFAULT_ZOOM_MAX, DEFAULT_ZOOM_MIN, Lens, TrajectoryError, ZoomRange,
};

/// `[camera]`: the optimisation camera (pinhole, principal point at the centre unless given).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Horizontal field of view, degrees (used unless `fx` is given).
    pub fov_x: f64,
    /// Focal lengths and principal point in pixels (all four, or none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fx: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fy: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cx: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cy: Option<f64>,
    /// Default target ratio r_t of every query.
    pub target_ratio: f64,
    /// How each query's working distance (the prior radius, the distance at which its object
    /// covers r_t) is found: `measured` (default) or `box`.
    pub working_distance: WorkingDistance,
    /// The lens over the trajectory: `fixed` (default: the focal length above throughout) or
    /// `zoom` (a zoom s(t) optimised with the pose, `splatraj_traj::trajectory::lens`).
    pub lens: LensKind,
    /// Bounds `[min, max]` of the zoom s of `lens = "zoom"` (focal lengths fx·s, fy·s);
    /// default `[0.5, 2]`.
    pub zoom_range: [f64; 2],
}

/// What the lens does over the trajectory (`[camera] lens`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LensKind {
    /// The configured focal length throughout.
    #[default]
    Fixed,
    /// A zoom in `zoom_range`, optimised with the pose.
    Zoom,
}

/// How a query's working distance is found (`[camera] working_distance`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorkingDistance {
    /// Estimated from the object's box, then measured on renders of the object alone from ten
    /// directions and corrected (`splatraj_traj::optimise::calibrated_radius`); a prior
    /// `radius` in `[costs.prior]` is kept as given.
    #[default]
    Measured,
    /// Estimated from the object's box alone (Cauchy's mean silhouette): what runs did before
    /// measuring, and what the tuned demo configs keep.
    Box,
}

/// Width of the default optimisation camera, pixels: enough to resolve an object covering
/// 2 % of the frame (about 11 × 11 pixels), few enough for a step in well under a second on
/// 2 cores.
pub const DEFAULT_CAMERA_WIDTH: usize = 96;
/// Height of the default optimisation camera: the default output's 16:9.
pub const DEFAULT_CAMERA_HEIGHT: usize = 54;

impl Default for CameraConfig {
    /// [`DEFAULT_CAMERA_WIDTH`] × [`DEFAULT_CAMERA_HEIGHT`] (the output's 16:9), 60°
    /// horizontal, r_t = 0.15.
    fn default() -> Self {
        Self {
            width: DEFAULT_CAMERA_WIDTH,
            height: DEFAULT_CAMERA_HEIGHT,
            fov_x: 60.0,
            fx: None,
            fy: None,
            cx: None,
            cy: None,
            target_ratio: DEFAULT_TARGET_RATIO,
            working_distance: WorkingDistance::Measured,
            lens: LensKind::Fixed,
            zoom_range: [DEFAULT_ZOOM_MIN, DEFAULT_ZOOM_MAX],
        }
    }
}

impl CameraConfig {
    /// The lens of `lens` and `zoom_range`; errors name `camera.zoom_range`.
    pub fn lens(&self) -> Result<Lens, ConfigError> {
        let [min, max] = self.zoom_range;
        let range = ZoomRange { min, max };
        range.validate().map_err(|e| {
            let reason = match e {
                TrajectoryError::InvalidModel { reason, .. } => reason,
                other => other.to_string(),
            };
            ConfigError::new("camera.zoom_range", reason)
        })?;
        Ok(match self.lens {
            LensKind::Fixed => Lens::Fixed,
            LensKind::Zoom => Lens::Zoom(range),
        })
    }

    /// The intrinsics at the configured size; errors name the key.
    pub fn intrinsics(&self) -> Result<Intrinsics, ConfigError> {
        if self.width == 0 || self.height == 0 {
            return Err(ConfigError::new(
                "camera.width",
                format!(
                    "and `camera.height` must be ≥ 1, got {}×{}",
                    self.width, self.height
                ),
            ));
        }
        if !(self.target_ratio > 0.0 && self.target_ratio <= 1.0) {
            return Err(ConfigError::new(
                "camera.target_ratio",
                format!("= {} must be in (0, 1]", self.target_ratio),
            ));
        }
        match (self.fx, self.fy, self.cx, self.cy) {
            (Some(fx), Some(fy), Some(cx), Some(cy)) => {
                Intrinsics::new(fx, fy, cx, cy, self.width, self.height)
                    .map_err(|e| ConfigError::new("camera.fx", format!("(with fy, cx, cy): {e}")))
            }
            (None, None, None, None) => {
                if !(self.fov_x > 0.0 && self.fov_x < 180.0) {
                    return Err(ConfigError::new(
                        "camera.fov_x",
                        format!("= {} must be in (0, 180) degrees", self.fov_x),
                    ));
                }
                Intrinsics::from_fov_x(self.fov_x, self.width, self.height)
                    .map_err(|e| ConfigError::new("camera.fov_x", e.to_string()))
            }
            _ => Err(ConfigError::new(
                "camera",
                "needs all of fx, fy, cx, cy, or none of them (then fov_x)",
            )),
        }
    }
}
