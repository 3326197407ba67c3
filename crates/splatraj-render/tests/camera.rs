//! Camera and pose maths against independent references: glam's quaternion route for
//! rotations, closed forms at ω = 0, and central finite differences in f64.

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::{DMat3, DMat4, DQuat, DVec3};
use splatraj_render::camera::{
    Intrinsics, Pose, matrix_to_rotation_vector, rotation_matrices, rotation_vector_to_matrix,
};
use std::f64::consts::PI;

fn device() -> Device {
    Device::flex().autodiff()
}

/// Reference: rotation vector → quaternion → matrix (glam), no Rodrigues involved.
fn reference_matrix(omega: DVec3) -> DMat3 {
    DMat3::from_quat(DQuat::from_scaled_axis(omega))
}

fn max_abs_diff(a: DMat3, b: DMat3) -> f64 {
    (a - b)
        .to_cols_array()
        .iter()
        .fold(0.0, |m, v| m.max(v.abs()))
}

/// Test rotation vectors: zero, tiny, around the series threshold, generic, near π.
fn omegas() -> Vec<DVec3> {
    let axis = DVec3::new(0.3, -0.5, 0.8).normalize();
    let mut v = vec![
        DVec3::ZERO,
        DVec3::new(1e-9, 0.0, 0.0),
        DVec3::new(0.0, -3e-5, 2e-5),
    ];
    for theta in [0.0999, 0.1, 0.1001, 0.5, 1.7, 3.0, PI - 1e-6] {
        v.push(axis * theta);
    }
    v.push(DVec3::new(-2.0, 1.0, 0.5));
    v
}

fn tensor_rotations(omegas: &[DVec3], dtype: DType) -> (Tensor<2>, Tensor<3>) {
    let flat: Vec<f64> = omegas.iter().flat_map(|o| o.to_array()).collect();
    let omega =
        Tensor::<2>::from_data(TensorData::new(flat, [omegas.len(), 3]), (&device(), dtype))
            .require_grad();
    (omega.clone(), rotation_matrices(omega))
}

fn to_mats(r: Tensor<3>) -> Vec<DMat3> {
    let values: Vec<f64> = r.into_data().convert::<f64>().try_to_vec::<f64>().unwrap();
    // Row-major [3, 3] per batch entry.
    values
        .chunks(9)
        .map(|m| DMat3::from_cols_array(&[m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8]]))
        .collect()
}

#[test]
fn host_rodrigues_matches_quaternion_route() {
    for omega in omegas() {
        assert!(
            max_abs_diff(rotation_vector_to_matrix(omega), reference_matrix(omega)) < 1e-12,
            "{omega}"
        );
    }
}

#[test]
fn tensor_rodrigues_matches_reference_in_f64_and_f32() {
    let omegas = omegas();
    for (dtype, tolerance) in [(DType::F64, 1e-12), (DType::F32, 2e-6)] {
        let (_, r) = tensor_rotations(&omegas, dtype);
        for (got, omega) in to_mats(r).into_iter().zip(&omegas) {
            let error = max_abs_diff(got, reference_matrix(*omega));
            assert!(error < tolerance, "{dtype:?} ω = {omega}: error {error}");
        }
    }
}

/// Loss Σ W ⊙ R(ω) for a fixed W, evaluated on the host in f64.
fn weighted_sum(omega: DVec3, w: &[f64; 9]) -> f64 {
    let r = reference_matrix(omega);
    (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| w[i * 3 + j] * r.col(j)[i])
        .sum()
}

#[test]
fn gradient_matches_finite_differences_and_is_finite_at_zero_and_near_pi() {
    let w = [0.3, -1.2, 0.7, 2.0, 0.1, -0.4, 0.9, 1.5, -0.8];
    let omegas = omegas();
    let (omega, r) = tensor_rotations(&omegas, DType::F64);
    let weights =
        Tensor::<2>::from_data(TensorData::new(w.to_vec(), [3, 3]), (&device(), DType::F64))
            .unsqueeze_dim::<3>(0);
    let grads = (r * weights).sum().backward();
    let grad: Vec<f64> = omega
        .grad(&grads)
        .unwrap()
        .into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .unwrap();
    for (b, o) in omegas.iter().enumerate() {
        for k in 0..3 {
            let h = 1e-6;
            let mut e = DVec3::ZERO;
            e[k] = h;
            let fd = (weighted_sum(*o + e, &w) - weighted_sum(*o - e, &w)) / (2.0 * h);
            let got = grad[b * 3 + k];
            assert!(got.is_finite(), "ω = {o}: gradient {got}");
            assert!(
                (got - fd).abs() <= 1e-6 * (1.0 + fd.abs()),
                "ω = {o}, k = {k}: autodiff {got}, finite differences {fd}"
            );
        }
    }
    // At ω = 0 exactly, dR/dω_k = skew(e_k): the gradient is the closed form
    // (W₂₁ − W₁₂, W₀₂ − W₂₀, W₁₀ − W₀₁) (rows i, columns j of W).
    let closed = [w[7] - w[5], w[2] - w[6], w[3] - w[1]];
    for k in 0..3 {
        assert!(
            (grad[k] - closed[k]).abs() < 1e-12,
            "{:?} vs {closed:?}",
            &grad[..3]
        );
    }
}

#[test]
fn matrix_to_rotation_vector_round_trips_including_pi() {
    let mut cases = omegas();
    cases.push(DVec3::new(0.0, 0.0, PI));
    cases.push(DVec3::new(PI, 0.0, 0.0) * 0.999_999_999);
    for omega in cases {
        let back = matrix_to_rotation_vector(reference_matrix(omega));
        // At exactly π, ω and −ω are the same rotation.
        let same = back.distance(omega) < 1e-7
            || (omega.length() > PI - 1e-9 && back.distance(-omega) < 1e-7);
        let rotation_error = max_abs_diff(reference_matrix(back), reference_matrix(omega));
        assert!(same || rotation_error < 1e-9, "{omega} came back as {back}");
        assert!(back.length() <= PI + 1e-12);
    }
}

#[test]
fn pose_matrices_follow_the_convention() {
    let pose = Pose([0.2, -0.4, 1.1, 1.0, 2.0, -3.0]);
    let p = DVec3::new(0.5, -1.5, 4.0);
    // p_cam = R_wcᵀ (p − c), written out without the 4×4 helper.
    let expected = pose.rotation_wc().transpose() * (p - pose.centre());
    assert!(
        pose.world_to_camera()
            .transform_point3(p)
            .distance(expected)
            < 1e-12
    );
    assert!((pose.world_to_camera() * pose.camera_to_world()).abs_diff_eq(DMat4::IDENTITY, 1e-12));
    let back = Pose::from_world_to_camera(pose.world_to_camera()).unwrap();
    for k in 0..6 {
        assert!((back.0[k] - pose.0[k]).abs() < 1e-12);
    }
    let mut sheared = pose.world_to_camera();
    sheared.x_axis.x *= 1.5;
    assert!(
        Pose::from_world_to_camera(sheared)
            .unwrap_err()
            .to_string()
            .contains("not a rotation")
    );
}

#[test]
fn look_at_points_the_optical_axis_and_keeps_up_up() {
    let (eye, target, up) = (
        DVec3::new(3.0, -2.0, 1.5),
        DVec3::new(0.0, 0.5, 0.2),
        DVec3::Z,
    );
    let pose = Pose::look_at(eye, target, up).unwrap();
    let w2c = pose.world_to_camera();
    let t = w2c.transform_point3(target);
    assert!(
        t.x.abs() < 1e-12 && t.y.abs() < 1e-12 && t.z > 0.0,
        "target on the optical axis: {t}"
    );
    // A point above the target appears higher in the image: smaller y.
    let above = w2c.transform_point3(target + up * 0.1);
    assert!(above.y < 0.0 && above.x.abs() < 1e-12, "{above}");
    assert!(Pose::look_at(eye, eye, up).is_err());
    assert!(Pose::look_at(DVec3::ZERO, DVec3::Z, DVec3::Z).is_err());
}

#[test]
fn intrinsics_from_fov_and_rescale() {
    let k = Intrinsics::from_fov_x(90.0, 640, 480).unwrap();
    assert!((k.fx - 320.0).abs() < 1e-9 && (k.fy - 320.0).abs() < 1e-9);
    assert_eq!((k.cx, k.cy), (320.0, 240.0));
    let half = k.rescaled(320, 240).unwrap();
    assert!((half.fx - 160.0).abs() < 1e-9 && half.cx == 160.0 && half.cy == 120.0);
    assert!(Intrinsics::new(0.0, 1.0, 0.0, 0.0, 10, 10).is_err());
    assert!(Intrinsics::new(1.0, 1.0, 0.0, 0.0, 0, 10).is_err());
}
