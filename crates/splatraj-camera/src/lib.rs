//! splatraj's camera conventions, in one place and without burn (`docs/conventions.md`).
//!
//! - Pinhole [`Intrinsics`] in pixels with OpenCV camera axes: x right, y down, z forward; the
//!   centre of pixel (i, j) is at (i + 0.5, j + 0.5).
//! - A pose two ways: [`Pose`], the 6-vector Φ = [ω, c] that trajectories optimise (ω the
//!   rotation vector of R_wc, c the camera centre), and [`CameraPose`], the same pose as the
//!   matrix R_wc and the centre, which camera files read and write. `From` converts between them.
//! - World-to-camera (p_cam = R_wcᵀ (p − c)) and camera-to-world matrices, OpenCV ↔ OpenGL
//!   camera axes (nerfstudio, SuperSplat), the rotation conversions ([`rotation`]) and the
//!   single-camera JSON file ([`camera_file`], `splatraj render --camera`).
//!
//! The renderer (`splatraj-render`) builds its burn tensors from these types; the camera file
//! formats of other tools (`splatraj-report`: nerfstudio, COLMAP, INRIA, SuperSplat) convert
//! between them and their files.
//!
//! ```
//! use glam::DVec3;
//! use splatraj_camera::{CameraPose, Pose};
//!
//! // A camera at z = −2 looking at the origin, image up along world −y (COLMAP-style y down).
//! let pose = Pose::look_at(DVec3::new(0.0, 0.0, -2.0), DVec3::ZERO, DVec3::NEG_Y).unwrap();
//! let world_to_camera = pose.world_to_camera();
//! // The origin is 2 units in front of the camera.
//! let origin = world_to_camera.transform_point3(DVec3::ZERO);
//! assert!((origin - DVec3::new(0.0, 0.0, 2.0)).length() < 1e-12);
//! // The same pose as R_wc and centre, as camera files see it.
//! let matrices = CameraPose::from(pose);
//! assert!((matrices.forward() - DVec3::Z).length() < 1e-12);
//! ```

#![warn(missing_docs)]

pub mod camera_file;
pub mod error;
pub mod intrinsics;
pub mod pose;
pub mod rotation;

pub use error::CameraError;
pub use intrinsics::Intrinsics;
pub use pose::{CameraPose, Pose};
pub use rotation::{
    ROTATION_TOLERANCE, matrix_to_rotation_vector, nearest_rotation, rotation_vector_to_matrix,
};
