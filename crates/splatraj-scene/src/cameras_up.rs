//! World up from the capture's own cameras: people hold cameras level, so the cameras of a
//! capture say where up is far better than the splats can.
//!
//! **Convention.** The input is each camera's camera-to-world rotation R_wc in OpenCV camera
//! axes (x right, y down, z forward), as every reader of `splatraj-report` returns it: the
//! camera's up in world coordinates is −R_wc·[0, 1, 0]. Files in OpenGL axes (nerfstudio's
//! `transforms.json`, y up and z backward) are converted by their readers, where that camera's
//! up is +y of the file's own matrix; COLMAP's `images.txt` stores R_cw = R_wcᵀ, so its up is
//! −R_cwᵀ·[0, 1, 0].
//!
//! **Estimate.** nerfstudio's `auto_orient_and_center_poses` (method `"vertical"`): the mean
//! of the cameras' up vectors is right for cameras all around a subject but tilts toward the
//! subject when the cameras all look down at it from one side (a tabletop filmed from above).
//! The cameras' right axes (x) do not tilt with the pitch: they stay level whatever the camera
//! looks at. So up is the direction most orthogonal to all the right axes (the eigenvector of
//! Σ xxᵀ with the smallest eigenvalue), signed by the mean up vector. When the right axes are
//! nearly parallel (the cameras do not turn: a forward-facing capture) they fix only one
//! direction, and up is the mean up vector with its component along them removed. With cameras
//! level and all around, both agree with the mean up vector.
//!
//! **Agreement.** Each camera's horizon tilt (its roll about its optical axis against the
//! estimated up: 0° level, 180° upside down) is measured, leaving out the cameras that look
//! within [`ALONG_UP_DEGREES`] of straight up or down (their roll says nothing of up). The
//! **spread** is the 90th percentile of the tilts: above [`MAX_SPREAD_DEGREES`] the cameras
//! disagree (mixed conventions in one file, photos turned to portrait, a file that is not a
//! capture's cameras), and the estimate is refused.

use glam::{DMat3, DVec3};

/// A spread (90th percentile of the cameras' horizon tilt) above this is disagreement:
/// handheld captures tilt by a few degrees, a camera on a stick rarely by 10°.
pub const MAX_SPREAD_DEGREES: f64 = 20.0;
/// Cameras looking within this angle of straight up or down are left out of the spread.
pub const ALONG_UP_DEGREES: f64 = 10.0;
/// Fewer cameras than this cannot be checked for agreement.
pub const MIN_CAMERAS: usize = 3;
/// The right axes fix up only when they turn: the middle eigenvalue of Σ xxᵀ must exceed this
/// share of the camera count (nerfstudio's singular value 0.17·√n, squared; about 10° of
/// turn).
const TURNING: f64 = 0.17 * 0.17;

/// Up as the cameras of a capture give it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CamerasUp {
    /// Unit world up.
    pub up: [f64; 3],
    /// Cameras read.
    pub cameras: usize,
    /// 90th percentile of the cameras' horizon tilt against `up`, degrees.
    pub spread_degrees: f64,
    /// The camera file, for messages.
    pub file: String,
}

impl CamerasUp {
    /// `up from 120 cameras in cameras.json (spread 3.2°)`.
    pub fn describe(&self) -> String {
        format!(
            "up from {} cameras in {} (spread {:.1}°)",
            self.cameras, self.file, self.spread_degrees
        )
    }
}

/// Why cameras gave no up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CamerasUpError {
    /// Too few cameras to check them against each other.
    #[error("{file}: {count} camera(s), at least {MIN_CAMERAS} are needed to agree on up")]
    TooFew {
        /// The camera file.
        file: String,
        /// Cameras in it.
        count: usize,
    },
    /// A rotation is not finite.
    #[error("{file}: camera {index} has a non-finite rotation")]
    NonFinite {
        /// The camera file.
        file: String,
        /// The camera.
        index: usize,
    },
    /// The cameras disagree on up.
    #[error(
        "{file}: the {cameras} cameras disagree on up: 10 % of them tilt their horizon by more \
         than {spread_degrees:.1}° (at most {MAX_SPREAD_DEGREES}° is agreement; {tilted} tilt by \
         more than that, {upside_down} are upside down); mixed camera conventions, photos \
         turned to portrait, or not this capture's cameras? Set `scene.up = [x, y, z]`"
    )]
    Disagree {
        /// The camera file.
        file: String,
        /// Cameras in it.
        cameras: usize,
        /// The spread found, degrees.
        spread_degrees: f64,
        /// Cameras tilted by more than [`MAX_SPREAD_DEGREES`].
        tilted: usize,
        /// Cameras tilted by more than 90°.
        upside_down: usize,
    },
}

/// Up from the camera-to-world rotations (OpenCV axes) of a capture's cameras read from
/// `file`: see the module docs.
pub fn cameras_up(rotations: &[DMat3], file: &str) -> Result<CamerasUp, CamerasUpError> {
    let file = file.to_string();
    if rotations.len() < MIN_CAMERAS {
        return Err(CamerasUpError::TooFew {
            file,
            count: rotations.len(),
        });
    }
    if let Some(index) = rotations.iter().position(|r| !r.is_finite()) {
        return Err(CamerasUpError::NonFinite { file, index });
    }
    let ups: Vec<DVec3> = rotations.iter().map(|r| -r.y_axis).collect();
    let mean_up = ups.iter().sum::<DVec3>().normalize_or_zero();
    let up = level_direction(rotations, mean_up);
    let mut tilts: Vec<f64> = rotations
        .iter()
        .filter_map(|r| horizon_tilt_degrees(r, up))
        .collect();
    tilts.sort_by(f64::total_cmp);
    let spread_degrees = if tilts.is_empty() {
        // Every camera looks along the axis: nothing contradicts it.
        0.0
    } else {
        tilts[((tilts.len() - 1) as f64 * 0.9).round() as usize]
    };
    if up == DVec3::ZERO || spread_degrees > MAX_SPREAD_DEGREES {
        return Err(CamerasUpError::Disagree {
            file,
            cameras: rotations.len(),
            spread_degrees: if up == DVec3::ZERO {
                180.0
            } else {
                spread_degrees
            },
            tilted: tilts.iter().filter(|t| **t > MAX_SPREAD_DEGREES).count(),
            upside_down: tilts.iter().filter(|t| **t > 90.0).count(),
        });
    }
    Ok(CamerasUp {
        up: up.to_array(),
        cameras: rotations.len(),
        spread_degrees,
        file,
    })
}

/// The direction most orthogonal to the cameras' right axes, signed by `mean_up`; for right
/// axes that hardly turn, `mean_up` without its component along them. Zero when `mean_up` is
/// (the cameras' ups cancel out).
fn level_direction(rotations: &[DMat3], mean_up: DVec3) -> DVec3 {
    if mean_up == DVec3::ZERO {
        return DVec3::ZERO;
    }
    let scatter = rotations.iter().fold(nalgebra::Matrix3::zeros(), |m, r| {
        let x = nalgebra::Vector3::new(r.x_axis.x, r.x_axis.y, r.x_axis.z);
        m + x * x.transpose()
    });
    // nalgebra's symmetric eigen-solver (the scene crate already uses it for covariances).
    let eigen = nalgebra::SymmetricEigen::new(scatter);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let column = |k: usize| {
        let c = eigen.eigenvectors.column(order[k]);
        DVec3::new(c[0], c[1], c[2])
    };
    let turning = eigen.eigenvalues[order[1]] > TURNING * rotations.len() as f64;
    if turning {
        let normal = column(0);
        if normal.dot(mean_up) >= 0.0 {
            normal
        } else {
            -normal
        }
    } else {
        let right = column(2);
        (mean_up - right * right.dot(mean_up)).normalize_or_zero()
    }
}

/// How far the camera of `r` (R_wc, OpenCV axes) is rolled about its optical axis against
/// world `up`, degrees in [0, 180]: 0 when its horizon is level and its top is up; `None` when
/// it looks within [`ALONG_UP_DEGREES`] of `up` or `-up`, where roll says nothing.
fn horizon_tilt_degrees(r: &DMat3, up: DVec3) -> Option<f64> {
    // World up in camera coordinates: x right, y down, z forward.
    let u = r.transpose() * up;
    if u.z.abs() > ALONG_UP_DEGREES.to_radians().cos() {
        return None;
    }
    Some(u.x.atan2(-u.y).abs().to_degrees())
}
