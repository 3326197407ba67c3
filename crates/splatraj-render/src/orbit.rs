//! Cameras on a sphere around a point: the one place that turns "azimuth, elevation, distance
//! around this target, with this world up" into a pose.
//!
//! Azimuth 0 points from the target along [`Orbit::reference`] (made horizontal), azimuth 90°
//! along up × reference; elevation is measured from the horizontal plane toward up.

use glam::DVec3;

use crate::camera::{CameraError, Pose};

/// A target, a world up and a horizontal reference direction (azimuth 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orbit {
    /// The point every camera of the orbit looks at.
    pub target: DVec3,
    /// World up, unit length.
    pub up: DVec3,
    /// Horizontal unit direction of azimuth 0 (from the target toward the camera).
    pub reference: DVec3,
}

impl Orbit {
    /// An orbit around `target` whose azimuth 0 lies toward `toward` (its horizontal part;
    /// any horizontal direction when that is vanishingly small compared with `scale`).
    pub fn new(target: DVec3, up: DVec3, toward: DVec3, scale: f64) -> Self {
        let up = up.normalize();
        let mut reference = toward - up * toward.dot(up);
        if reference.length() < 1e-6 * scale.max(1e-9) {
            let helper = if up.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
            reference = helper - up * helper.dot(up);
        }
        Self {
            target,
            up,
            reference: reference.normalize(),
        }
    }

    /// Unit direction from the target toward a camera at `azimuth`, `elevation` (radians).
    pub fn direction(&self, azimuth: f64, elevation: f64) -> DVec3 {
        let side = self.up.cross(self.reference);
        let horizontal = self.reference * azimuth.cos() + side * azimuth.sin();
        horizontal * elevation.cos() + self.up * elevation.sin()
    }

    /// The camera at `azimuth`, `elevation` (radians) and `distance` looking at the target,
    /// image up toward world up.
    pub fn pose(&self, azimuth: f64, elevation: f64, distance: f64) -> Result<Pose, CameraError> {
        let eye = self.target + self.direction(azimuth, elevation) * distance;
        Pose::look_at(eye, self.target, self.up)
    }

    /// [`Orbit::pose`] with the angles in degrees.
    pub fn pose_degrees(
        &self,
        azimuth: f64,
        elevation: f64,
        distance: f64,
    ) -> Result<Pose, CameraError> {
        self.pose(azimuth.to_radians(), elevation.to_radians(), distance)
    }
}
