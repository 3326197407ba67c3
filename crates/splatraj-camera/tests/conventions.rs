//! The camera conventions against closed forms worked out by hand, and every conversion
//! against its inverse.
//!
//! The known camera A (as in the report crate's format tests): centre c = (2, 0, 0), looking at
//! the origin (along −x) with world up +z. In OpenCV axes its camera x (right) is +y, camera y
//! (down) is −z and camera z (forward) is −x, so R_wc has columns (0, 1, 0), (0, 0, −1),
//! (−1, 0, 0): a 120° turn about (−1, −1, 1)/√3.

use std::f64::consts::PI;

use glam::{DMat3, DMat4, DVec3};
use splatraj_camera::camera_file::{CameraFile, Matrix4};
use splatraj_camera::pose::matrix_rows;
use splatraj_camera::{
    CameraError, CameraPose, Intrinsics, Pose, matrix_to_rotation_vector, rotation_vector_to_matrix,
};

fn phi_a() -> [f64; 6] {
    let s = 2.0 * PI / 3.0 / 3f64.sqrt();
    [-s, -s, s, 2.0, 0.0, 0.0]
}

fn rotation_a() -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, 1.0, 0.0),
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::new(-1.0, 0.0, 0.0),
    )
}

fn max_abs(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// Rotation vectors spread over every direction and angle in (0, π), plus the edge cases.
fn omegas() -> Vec<DVec3> {
    let mut out = vec![
        DVec3::ZERO,
        DVec3::new(1e-9, -2e-9, 0.5e-9),
        DVec3::new(0.0, 0.0, PI - 1e-7),
        DVec3::new(0.3, -0.2, 0.9),
    ];
    for i in 0..40 {
        let t = i as f64;
        let axis = DVec3::new(
            (1.3 * t).sin(),
            (0.7 * t + 1.0).cos(),
            (2.1 * t).sin() + 0.1,
        )
        .normalize();
        out.push(axis * (0.05 + 3.0 * (i as f64 / 40.0)));
    }
    out
}

#[test]
fn the_known_pose_has_the_hand_computed_rotation_both_ways() {
    let by_rodrigues = Pose(phi_a()).rotation_wc();
    let by_quaternion = CameraPose::from_phi(phi_a()).rotation;
    for (name, r) in [("Rodrigues", by_rodrigues), ("quaternion", by_quaternion)] {
        let error = max_abs(&r.to_cols_array(), &rotation_a().to_cols_array());
        assert!(error < 1e-12, "{name}: {r:?} ({error:e})");
    }
    let omega = matrix_to_rotation_vector(rotation_a());
    assert!(omega.distance(DVec3::from_slice(&phi_a()[..3])) < 1e-12);
}

#[test]
fn world_to_camera_is_the_closed_form_and_inverts_camera_to_world() {
    let pose = Pose(phi_a());
    // R_cw rows are R_wc's columns; t = −R_cw·c = (0, 0, 2): the origin is 2 ahead.
    let rows = matrix_rows(&pose.world_to_camera());
    let expected = [
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 0.0],
        [-1.0, 0.0, 0.0, 2.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    assert!(
        max_abs(rows.as_flattened(), expected.as_flattened()) < 1e-12,
        "{rows:?}"
    );
    assert!((pose.world_to_camera() * pose.camera_to_world()).abs_diff_eq(DMat4::IDENTITY, 1e-12));
    // The two pose types write the same matrix.
    let by_matrices = CameraPose::from(pose).world_to_camera();
    assert!(max_abs(rows.as_flattened(), by_matrices.as_flattened()) < 1e-12);
}

#[test]
fn quaternion_and_rodrigues_rotations_agree_to_rounding() {
    for omega in omegas() {
        let phi = [omega.x, omega.y, omega.z, 1.0, 2.0, 3.0];
        let a = rotation_vector_to_matrix(omega).to_cols_array();
        let b = CameraPose::from_phi(phi).rotation.to_cols_array();
        assert!(
            max_abs(&a, &b) < 1e-14,
            "ω = {omega}: {:e}",
            max_abs(&a, &b)
        );
    }
}

#[test]
fn pose_and_camera_pose_round_trip() {
    for omega in omegas() {
        let phi = [omega.x, omega.y, omega.z, -0.5, 4.0, 1e3];
        let back = Pose::from(CameraPose::from(Pose(phi)));
        assert!(max_abs(&back.0, &phi) < 1e-12, "{phi:?} → {back:?}");
        let again = matrix_to_rotation_vector(rotation_vector_to_matrix(omega));
        assert!(again.distance(omega) < 1e-9, "{omega} → {again}");
    }
}

#[test]
fn world_to_camera_matrices_round_trip_through_both_types() {
    for omega in omegas() {
        let pose = Pose([omega.x, omega.y, omega.z, 0.25, -3.0, 7.5]);
        let back = Pose::from_world_to_camera(pose.world_to_camera()).unwrap();
        let (r, c) = CameraPose::from(back).max_difference(&CameraPose::from(pose));
        assert!(r < 1e-12 && c < 1e-12, "{pose:?}: {r:e} {c:e}");
        let rows = CameraPose::from(pose).world_to_camera();
        let back = CameraPose::from_world_to_camera(&rows).unwrap();
        let (r, c) = back.max_difference(&CameraPose::from(pose));
        assert!(r < 1e-12 && c < 1e-12);
    }
}

#[test]
fn opengl_axes_flip_y_and_z_and_round_trip() {
    let pose = CameraPose::from_phi(phi_a());
    let gl = pose.camera_to_world_opengl();
    // Columns of the OpenGL camera-to-world: x = right (+y world), y = up (+z world),
    // z = backward (+x world), then the centre.
    let expected = [
        [0.0, 0.0, 1.0, 2.0],
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    assert!(
        max_abs(gl.as_flattened(), expected.as_flattened()) < 1e-12,
        "{gl:?}"
    );
    let back = CameraPose::from_camera_to_world_opengl(&gl).unwrap();
    let (r, c) = back.max_difference(&pose);
    assert!(r < 1e-12 && c < 1e-12);
}

#[test]
fn look_at_builds_the_known_pose_and_refuses_degenerate_ones() {
    let pose = Pose::look_at(DVec3::new(2.0, 0.0, 0.0), DVec3::ZERO, DVec3::Z).unwrap();
    assert!(max_abs(&pose.0, &phi_a()) < 1e-12, "{pose:?}");
    let same = CameraPose::look_at(DVec3::new(2.0, 0.0, 0.0), DVec3::ZERO, DVec3::Z).unwrap();
    assert_eq!(same.rotation, rotation_a());
    assert!(matches!(
        Pose::look_at(DVec3::ONE, DVec3::ONE, DVec3::Z),
        Err(CameraError::DegenerateLookAt(_))
    ));
    assert!(matches!(
        Pose::look_at(DVec3::ZERO, DVec3::Z, DVec3::Z),
        Err(CameraError::DegenerateLookAt(_))
    ));
}

#[test]
fn matrices_that_are_not_rigid_are_refused() {
    let mut sheared = Pose(phi_a()).world_to_camera();
    sheared.x_axis.y += 0.1;
    let error = Pose::from_world_to_camera(sheared).unwrap_err();
    assert!(matches!(&error, CameraError::NotRigid(m) if m.contains("not a rotation")));
    let mut projective = Pose(phi_a()).world_to_camera();
    projective.x_axis.w = 0.5;
    assert!(Pose::from_world_to_camera(projective).is_err());
}

#[test]
fn intrinsics_from_field_of_view_and_rescaled() {
    // 90° across 200 pixels: f = 100.
    let k = Intrinsics::from_fov_x(90.0, 200, 100).unwrap();
    assert!((k.fx - 100.0).abs() < 1e-12 && k.cx == 100.0 && k.cy == 50.0);
    let half = k.rescaled(100, 50).unwrap();
    assert!((half.fx - 50.0).abs() < 1e-12 && half.cx == 50.0);
    // Vertical field of view of a centred pinhole: 2·atan(50/100).
    let fov = k.vertical_fov_degrees();
    assert!((fov - 2.0 * 0.5f64.atan().to_degrees()).abs() < 1e-12);
    assert!((Intrinsics::focal_from_vertical_fov(fov, 100) - 100.0).abs() < 1e-9);
    assert!(Intrinsics::new(0.0, 1.0, 0.0, 0.0, 1, 1).is_err());
    assert!(Intrinsics::centred(1.0, 0, 1).validate().is_err());
}

#[test]
fn the_camera_file_reads_pose_or_world_to_camera_the_same() {
    let k = Intrinsics::centred(200.0, 300, 200);
    let by_pose = CameraFile::from_spec(&splatraj_camera::camera_file::CameraSpec {
        intrinsics: k,
        pose: Pose(phi_a()),
    });
    let mut by_matrix = by_pose.clone();
    by_matrix.pose = None;
    by_matrix.world_to_camera = Some(Matrix4::Rows(matrix_rows(&Pose(phi_a()).world_to_camera())));
    let a = by_pose.camera().unwrap();
    let b = by_matrix.camera().unwrap();
    assert_eq!(a.intrinsics, b.intrinsics);
    assert!(max_abs(&a.pose.0, &b.pose.0) < 1e-12);
    let text = serde_json::to_string(&by_pose).unwrap();
    let read: CameraFile = serde_json::from_str(&text).unwrap();
    assert_eq!(read.camera().unwrap(), a);
}
