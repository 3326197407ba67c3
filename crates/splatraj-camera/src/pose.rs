//! A camera pose two ways: [`Pose`], Φ = [ω, c] as trajectories optimise it, and
//! [`CameraPose`], R_wc and the centre as camera files read and write it; world-to-camera and
//! camera-to-world matrices; OpenCV ↔ OpenGL camera axes.

use glam::{DMat3, DMat4, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::error::CameraError;
use crate::rotation::{
    ROTATION_TOLERANCE, matrix_to_rotation_vector, nearest_rotation, rotation_vector_to_matrix,
};

/// A camera pose Φ = [ω, c]: rotation vector of R_wc and camera centre, world coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose(pub [f64; 6]);

impl Pose {
    /// From the rotation R_wc (camera-to-world) and the camera centre.
    pub fn from_rotation_and_centre(rotation_wc: DMat3, centre: DVec3) -> Self {
        let omega = matrix_to_rotation_vector(rotation_wc);
        Pose([omega.x, omega.y, omega.z, centre.x, centre.y, centre.z])
    }

    /// The rotation vector ω.
    pub fn omega(&self) -> DVec3 {
        DVec3::new(self.0[0], self.0[1], self.0[2])
    }

    /// The camera centre c in world coordinates.
    pub fn centre(&self) -> DVec3 {
        DVec3::new(self.0[3], self.0[4], self.0[5])
    }

    /// R_wc: columns are the camera's x (right), y (down), z (forward) axes in world.
    pub fn rotation_wc(&self) -> DMat3 {
        rotation_vector_to_matrix(self.omega())
    }

    /// 4×4 camera-to-world transform.
    pub fn camera_to_world(&self) -> DMat4 {
        let r = self.rotation_wc();
        DMat4::from_cols(
            r.x_axis.extend(0.0),
            r.y_axis.extend(0.0),
            r.z_axis.extend(0.0),
            self.centre().extend(1.0),
        )
    }

    /// 4×4 world-to-camera transform: p_cam = R_wcᵀ (p − c).
    pub fn world_to_camera(&self) -> DMat4 {
        let r_cw = self.rotation_wc().transpose();
        let t = -(r_cw * self.centre());
        DMat4::from_cols(
            r_cw.x_axis.extend(0.0),
            r_cw.y_axis.extend(0.0),
            r_cw.z_axis.extend(0.0),
            t.extend(1.0),
        )
    }

    /// From a 4×4 world-to-camera matrix, checking that it is rigid (within
    /// [`ROTATION_TOLERANCE`]; see [`CameraPose::from_world_to_camera`]).
    pub fn from_world_to_camera(m: DMat4) -> Result<Self, CameraError> {
        let pose =
            CameraPose::from_world_to_camera(&matrix_rows(&m)).map_err(CameraError::NotRigid)?;
        Ok(Self::from_rotation_and_centre(pose.rotation, pose.centre))
    }

    /// A camera at `eye` looking at `target`, with the image's up (−y) toward `world_up`
    /// (see [`CameraPose::look_at`]).
    pub fn look_at(eye: DVec3, target: DVec3, world_up: DVec3) -> Result<Self, CameraError> {
        let pose = CameraPose::look_at(eye, target, world_up)?;
        Ok(Self::from_rotation_and_centre(pose.rotation, pose.centre))
    }
}

/// A camera pose: R_wc and the centre, OpenCV camera axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Camera-to-world rotation R_wc: column k is camera axis k in world coordinates.
    pub rotation: DMat3,
    /// Camera centre c in world coordinates.
    pub centre: DVec3,
}

impl CameraPose {
    /// The pose of Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z], through glam's unit quaternion: the path
    /// every camera file export has been written with (it agrees with
    /// [`rotation_vector_to_matrix`] to rounding, as a test checks; kept so that exported files
    /// stay bit-identical).
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
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3) -> Result<Self, CameraError> {
        let forward = (target - eye).normalize_or_zero();
        if forward == DVec3::ZERO || !forward.is_finite() {
            return Err(CameraError::DegenerateLookAt(format!(
                "target {target} is not away from the camera {eye}"
            )));
        }
        let right = forward.cross(up).normalize_or_zero();
        if right == DVec3::ZERO || !right.is_finite() {
            return Err(CameraError::DegenerateLookAt(format!(
                "viewing direction {forward} is parallel to the up direction {up}"
            )));
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

impl From<Pose> for CameraPose {
    /// The same pose as R_wc and centre ([`CameraPose::from_phi`]).
    fn from(pose: Pose) -> Self {
        CameraPose::from_phi(pose.0)
    }
}

impl From<CameraPose> for Pose {
    /// The same pose as Φ ([`CameraPose::phi`], |ω| ≤ π).
    fn from(pose: CameraPose) -> Self {
        Pose(pose.phi())
    }
}

/// The rows of a 4×4 matrix, row-major (how files write matrices; glam stores columns).
pub fn matrix_rows(m: &DMat4) -> [[f64; 4]; 4] {
    std::array::from_fn(|r| std::array::from_fn(|c| m.col(c)[r]))
}

/// The 4×4 rigid transform [r | t] as rows.
fn rigid_rows(r: DMat3, t: DVec3) -> [[f64; 4]; 4] {
    let row = |i: usize| [r.x_axis[i], r.y_axis[i], r.z_axis[i], t[i]];
    [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
}

/// The rotation block and translation of a 4×4 rigid transform given as rows, or why it is not one.
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
