//! Poses, pinhole intrinsics and camera paths in splatraj's conventions (`docs/conventions.md`):
//! OpenCV camera axes (x right, y down, z forward), R_wc the rotation taking camera axes to
//! world axes (column k is camera axis k in world coordinates), c the camera centre, and
//! Φ = [ω, c] with ω the rotation vector of R_wc.
//!
//! Every format module converts between these and its own file; nothing here depends on burn.

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// How far from a rotation a matrix read from a file may be (largest entry of RᵀR − I, and
/// |det R − 1|) before it is refused; within it, the matrix is projected onto the nearest
/// rotation. Files written with 6–7 significant digits pass.
pub const ROTATION_TOLERANCE: f64 = 1e-4;

/// A camera pose: R_wc and the centre, OpenCV camera axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Camera-to-world rotation R_wc: column k is camera axis k in world coordinates.
    pub rotation: DMat3,
    /// Camera centre c in world coordinates.
    pub centre: DVec3,
}

impl CameraPose {
    /// The pose of Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z].
    pub fn from_phi(phi: [f64; 6]) -> Self {
        let omega = DVec3::new(phi[0], phi[1], phi[2]);
        Self {
            rotation: DMat3::from_quat(DQuat::from_scaled_axis(omega)),
            centre: DVec3::new(phi[3], phi[4], phi[5]),
        }
    }

    /// Φ = [ω, c], with the rotation angle |ω| in [0, π].
    pub fn phi(&self) -> [f64; 6] {
        let mut q = DQuat::from_mat3(&self.rotation).normalize();
        if q.w < 0.0 {
            q = -q;
        }
        // ω = angle · axis with angle = 2·atan2(|v|, w): exact down to tiny angles (glam's
        // `to_scaled_axis` returns zero below |v| = 1e-8).
        let v = q.xyz();
        let length = v.length();
        let omega = if length > 0.0 {
            v * (2.0 * length.atan2(q.w) / length)
        } else {
            DVec3::ZERO
        };
        let c = self.centre;
        [omega.x, omega.y, omega.z, c.x, c.y, c.z]
    }

    /// A pose from a camera-to-world rotation (checked and projected onto the nearest
    /// rotation, see [`ROTATION_TOLERANCE`]) and a centre.
    pub fn new(rotation: DMat3, centre: DVec3) -> Result<Self, String> {
        if !centre.is_finite() {
            return Err(format!("camera centre {centre} is not finite"));
        }
        Ok(Self {
            rotation: nearest_rotation(rotation)?,
            centre,
        })
    }

    /// The camera at `eye` looking at `target`, its image "up" (−y) as close to `up` as the
    /// viewing direction allows (no roll about the viewing axis).
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3) -> Result<Self, String> {
        let forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || !forward.is_finite() {
            return Err(format!("target {target} is not away from the camera {eye}"));
        }
        let right = forward.cross(up).normalize_or_zero();
        if right == DVec3::ZERO || !right.is_finite() {
            return Err(format!(
                "viewing direction {forward} is parallel to the up direction {up}"
            ));
        }
        let down = forward.cross(right);
        Ok(Self {
            rotation: DMat3::from_cols(right, down, forward),
            centre: eye,
        })
    }

    /// The viewing direction (camera +z) in world coordinates.
    pub fn forward(&self) -> DVec3 {
        self.rotation.z_axis
    }

    /// World-to-camera rotation R_cw = R_wcᵀ.
    pub fn world_to_camera_rotation(&self) -> DMat3 {
        self.rotation.transpose()
    }

    /// World-to-camera translation t = −R_cw c (p_cam = R_cw p + t).
    pub fn world_to_camera_translation(&self) -> DVec3 {
        -(self.world_to_camera_rotation() * self.centre)
    }

    /// The 4×4 world-to-camera matrix, row-major (OpenCV axes).
    pub fn world_to_camera(&self) -> [[f64; 4]; 4] {
        rigid_rows(
            self.world_to_camera_rotation(),
            self.world_to_camera_translation(),
        )
    }

    /// The pose of a 4×4 world-to-camera matrix given as rows (OpenCV axes).
    pub fn from_world_to_camera(rows: &[[f64; 4]; 4]) -> Result<Self, String> {
        let (r_cw, t) = split_rigid(rows)?;
        let r_cw = nearest_rotation(r_cw)?;
        Self::new(r_cw.transpose(), -(r_cw.transpose() * t))
    }

    /// The 4×4 camera-to-world matrix, row-major, with OpenGL camera axes (x right, y up,
    /// z backward): R_wc·diag(1, −1, −1) and the centre.
    pub fn camera_to_world_opengl(&self) -> [[f64; 4]; 4] {
        rigid_rows(
            self.rotation * DMat3::from_diagonal(OPENGL_FLIP),
            self.centre,
        )
    }

    /// The pose of a 4×4 camera-to-world matrix with OpenGL camera axes, given as rows.
    pub fn from_camera_to_world_opengl(rows: &[[f64; 4]; 4]) -> Result<Self, String> {
        let (r, t) = split_rigid(rows)?;
        Self::new(r * DMat3::from_diagonal(OPENGL_FLIP), t)
    }

    /// Largest difference of rotation entries and of centre coordinates with `other`.
    pub fn max_difference(&self, other: &CameraPose) -> (f64, f64) {
        let rotation = (self.rotation - other.rotation)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        let centre = (self.centre - other.centre).abs().max_element();
        (rotation, centre)
    }
}

/// OpenCV ↔ OpenGL camera axes: y and z flip.
const OPENGL_FLIP: DVec3 = DVec3::new(1.0, -1.0, -1.0);

fn rigid_rows(r: DMat3, t: DVec3) -> [[f64; 4]; 4] {
    let row = |i: usize| [r.x_axis[i], r.y_axis[i], r.z_axis[i], t[i]];
    [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
}

fn split_rigid(rows: &[[f64; 4]; 4]) -> Result<(DMat3, DVec3), String> {
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err("the matrix holds a value that is not finite".into());
    }
    let last = rows[3];
    if last[0].abs() > ROTATION_TOLERANCE
        || last[1].abs() > ROTATION_TOLERANCE
        || last[2].abs() > ROTATION_TOLERANCE
        || (last[3] - 1.0).abs() > ROTATION_TOLERANCE
    {
        return Err(format!(
            "the last row is {last:?}, not [0, 0, 0, 1] (not a rigid transform)"
        ));
    }
    let col = |j: usize| DVec3::new(rows[0][j], rows[1][j], rows[2][j]);
    Ok((DMat3::from_cols(col(0), col(1), col(2)), col(3)))
}

/// `m` projected onto the nearest rotation, or why it is not close to one.
pub fn nearest_rotation(m: DMat3) -> Result<DMat3, String> {
    if !m.is_finite() {
        return Err("the rotation holds a value that is not finite".into());
    }
    let gram = m.transpose() * m - DMat3::IDENTITY;
    let off = gram
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    let det = m.determinant();
    if off > ROTATION_TOLERANCE || (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!(
            "not a rotation (RᵀR differs from I by {off:.2e}, det R = {det:.6}); scaled, \
             sheared or mirrored cameras are not supported"
        ));
    }
    Ok(DMat3::from_quat(DQuat::from_mat3(&m).normalize()))
}

/// Pinhole intrinsics in pixels (the centre of pixel (i, j) is at (i + 0.5, j + 0.5)); the
/// same fields as splatraj's `Intrinsics`, so `trajectory.json` reads into it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pinhole {
    /// Focal length along x.
    pub fx: f64,
    /// Focal length along y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
}

impl Pinhole {
    /// Checks sizes ≥ 1, positive finite focal lengths and a finite principal point.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size {}×{} must be at least 1×1",
                self.width, self.height
            ));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be a positive number"));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(format!("{name} = {v} is not finite"));
            }
        }
        Ok(())
    }

    /// A centred pinhole of the given size with focal length `focal` on both axes.
    pub fn centred(focal: f64, width: usize, height: usize) -> Self {
        Self {
            fx: focal,
            fy: focal,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            width,
            height,
        }
    }

    /// Vertical field of view in degrees: 2·atan(height / (2·fy)).
    pub fn vertical_fov_degrees(&self) -> f64 {
        (2.0 * (self.height as f64 / (2.0 * self.fy)).atan()).to_degrees()
    }

    /// The focal length (pixels) of a vertical field of view in degrees over `height` pixels.
    pub fn focal_from_vertical_fov(fov_degrees: f64, height: usize) -> f64 {
        height as f64 / 2.0 / (fov_degrees.to_radians() / 2.0).tan()
    }

    /// Width over height.
    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }
}

/// One camera of a path: its pose and, where the file has them, its intrinsics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The pose.
    pub pose: CameraPose,
    /// The intrinsics (every export needs them; imports give them when the file has them).
    pub camera: Option<Pinhole>,
}

/// A camera path: frames in order, shown at `fps` frames per second.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraPath {
    /// The frames, in playing order.
    pub frames: Vec<Frame>,
    /// Frames per second, where the file says.
    pub fps: Option<f64>,
}

impl CameraPath {
    /// A path of `poses` (Φ) all seen through `camera`, at `fps`.
    pub fn from_phis(poses: &[[f64; 6]], camera: Pinhole, fps: f64) -> Self {
        Self {
            frames: poses
                .iter()
                .map(|&phi| Frame {
                    pose: CameraPose::from_phi(phi),
                    camera: Some(camera),
                })
                .collect(),
            fps: Some(fps),
        }
    }

    /// The poses as Φ = [ω, c].
    pub fn phis(&self) -> Vec<[f64; 6]> {
        self.frames.iter().map(|f| f.pose.phi()).collect()
    }

    /// The poses as Φ with each ω the rotation vector of its rotation nearest the previous
    /// frame's (angles may pass π), so a path that turns smoothly has smooth Φ: what a
    /// trajectory model should be fitted to.
    pub fn continuous_phis(&self) -> Vec<[f64; 6]> {
        let mut out: Vec<[f64; 6]> = Vec::with_capacity(self.frames.len());
        for phi in self.phis() {
            let omega = DVec3::new(phi[0], phi[1], phi[2]);
            let best = match out.last() {
                Some(prev) => {
                    let prev = DVec3::new(prev[0], prev[1], prev[2]);
                    let angle = omega.length();
                    let axis = if angle > 0.0 {
                        omega / angle
                    } else {
                        // A zero rotation is also a full turn about any axis: the previous one.
                        prev.normalize_or_zero()
                    };
                    // Every rotation vector of this rotation: axis·(angle + 2πk).
                    (-3i32..=3)
                        .map(|k| axis * (angle + 2.0 * std::f64::consts::PI * f64::from(k)))
                        .min_by(|a, b| a.distance(prev).total_cmp(&b.distance(prev)))
                        .unwrap_or(omega)
                }
                None => omega,
            };
            out.push([best.x, best.y, best.z, phi[3], phi[4], phi[5]]);
        }
        out
    }

    /// [`CameraPath::continuous_phis`] resampled at `count` evenly spaced times over the path
    /// (the frames at evenly spaced times, linear in Φ between them): dense samples to fit a
    /// trajectory model to.
    pub fn resampled_phis(&self, count: usize) -> Vec<[f64; 6]> {
        let phis = self.continuous_phis();
        if phis.len() < 2 || count < 2 {
            return phis.first().map_or(Vec::new(), |p| vec![*p; count]);
        }
        let last = (phis.len() - 1) as f64;
        (0..count)
            .map(|i| {
                let s = i as f64 / (count - 1) as f64 * last;
                let k = (s.floor() as usize).min(phis.len() - 2);
                let f = s - k as f64;
                std::array::from_fn(|j| phis[k][j] * (1.0 - f) + phis[k + 1][j] * f)
            })
            .collect()
    }
}
