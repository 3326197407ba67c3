//! LDJ against the minimum-jerk closed form, its invariance to distance and duration, and the
//! ordering the paper reports (waypoint trajectories are jerkier than RBF ones).

use burn::tensor::{DType, Device};
use splatraj_traj::metrics::{DEFAULT_LDJ_SAMPLES, ldj, pose_ldj, trajectory_ldj};
use splatraj_traj::trajectory::{
    Polynomial, Pose, Rbf, Trajectory, TrajectoryModel, Waypoint, uniform_times,
};

/// Minimum-jerk position x(t) = x0 + (x1 − x0)(10τ³ − 15τ⁴ + 6τ⁵), τ = t/T.
fn min_jerk(tau: f64) -> f64 {
    tau.powi(3) * (10.0 - 15.0 * tau + 6.0 * tau * tau)
}

/// Closed form for the minimum-jerk profile, D = x1 − x0, duration T:
/// v(τ) = D/T·30τ²(1 − τ)², largest at τ = ½: v_peak = D/T·30/16 = 1.875·D/T.
/// jerk(τ) = D/T³·60(1 − 6τ + 6τ²); with u = τ − ½ the bracket is 6u² − ½, and
/// ∫₀¹ (6u² − ½)² dτ = ∫_{−½}^{½} (36u⁴ − 6u² + ¼) du = 36/80 − 6/12 + 1/4 = 0.2, so
/// ∫₀^T jerk² dt = T·D²/T⁶·3600·0.2 = 720·D²/T⁵.
/// LDJ = ln(T³/(1.875·D/T)² · 720·D²/T⁵) = ln(720/1.875²) = ln(204.8) ≈ 5.3220.
fn min_jerk_ldj() -> f64 {
    (720.0f64 / (1.875 * 1.875)).ln()
}

fn profile(samples: usize, f: impl Fn(f64) -> f64) -> Vec<[f64; 1]> {
    uniform_times(samples).into_iter().map(|t| [f(t)]).collect()
}

#[test]
fn min_jerk_profile_has_the_closed_form_ldj() {
    let want = min_jerk_ldj();
    assert!((want - 5.3220).abs() < 1e-4, "closed form {want}");
    // Second-order scheme: the error shrinks ~4× per halving of h; 2001 samples are well inside
    // 1e-4, and even a coarse 201-sample grid is within 1e-2.
    let fine = ldj(&profile(2001, min_jerk), 1.0).unwrap();
    assert!((fine - want).abs() < 1e-4, "{fine} vs {want}");
    let coarse = ldj(&profile(201, min_jerk), 1.0).unwrap();
    assert!((coarse - want).abs() < 1e-2, "{coarse} vs {want}");
    assert!((coarse - want).abs() > (fine - want).abs());
}

#[test]
fn ldj_is_invariant_to_distance_and_duration() {
    // Same shape, distance D ∈ {1, 37, 1e-3}, duration T ∈ {1, 4.5, 0.02}, offset x0: same LDJ.
    let shapes: [fn(f64) -> f64; 2] = [min_jerk, |t| (3.0 * t).sin() + 0.3 * (11.0 * t).cos()];
    for shape in shapes {
        let base = ldj(&profile(1001, shape), 1.0).unwrap();
        for (d, duration, x0) in [(37.0, 4.5, -2.0), (1e-3, 0.02, 5.0), (-3.0, 1.0, 0.0)] {
            let scaled = profile(1001, |t| x0 + d * shape(t));
            let value = ldj(&scaled, duration).unwrap();
            // Not exact: third differences amplify the samples' round-off by ~1/h³, most for
            // a small move far from the origin (D = 1e-3 at x0 = 5: ~1e-6). A missing T³ or
            // v_peak² would be off by whole units.
            assert!(
                (value - base).abs() < 1e-5,
                "D = {d}, T = {duration}: {value} vs {base}"
            );
        }
    }
}

#[test]
fn ldj_uses_the_norm_of_a_vector_motion() {
    // A straight-line min-jerk move in 3-D along any direction is the 1-D profile.
    let dir = [3.0, -4.0, 12.0]; // Length 13.
    let samples: Vec<[f64; 3]> = uniform_times(2001)
        .into_iter()
        .map(|t| dir.map(|d| 1.0 + d * min_jerk(t)))
        .collect();
    let value = ldj(&samples, 2.0).unwrap();
    assert!((value - min_jerk_ldj()).abs() < 1e-4, "{value}");
}

#[test]
fn pose_ldj_splits_centre_and_rotation_through_a_trajectory() {
    // Positional: min-jerk along (1, 2, 2); angular: a wiggle. The degree-5 polynomial model
    // holds the min-jerk profile exactly, so the model's sampled LDJ is the closed form.
    let times = uniform_times(200);
    let poses: Vec<Pose> = times
        .iter()
        .map(|&t| {
            let s = min_jerk(t);
            let w = 0.1 * t * t * (1.0 - t); // Cubic: also in the span.
            [w, -w, 0.5 * w, 1.0 + s, 2.0 * s, -2.0 * s]
        })
        .collect();
    let device = Device::flex();
    let traj = Trajectory::fit(
        TrajectoryModel::Polynomial(Polynomial::default()),
        &times,
        &poses,
        &device,
        DType::F64,
    )
    .unwrap();
    let smooth = trajectory_ldj(&traj, 2001);
    let positional = smooth.positional.unwrap();
    assert!((positional - min_jerk_ldj()).abs() < 1e-4, "{positional}");
    // The angular part is a different motion with its own value (computed directly).
    let angular_direct = ldj(&profile(2001, |t| 0.1 * t * t * (1.0 - t)), 1.0).unwrap();
    let angular = smooth.angular.unwrap();
    assert!(
        (angular - angular_direct).abs() < 1e-6,
        "{angular} vs {angular_direct}"
    );
    assert!((angular - positional).abs() > 0.1);
}

#[test]
fn waypoint_trajectory_is_jerkier_than_rbf_fitted_to_the_same_poses() {
    // A smooth tour past three places, looking around as it goes.
    let times = uniform_times(601);
    let poses: Vec<Pose> = times
        .iter()
        .map(|&t| {
            let a = std::f64::consts::TAU * t;
            [
                0.3 * a.sin(),
                0.5 * a + 0.2 * (2.0 * a).sin(),
                0.1 * (3.0 * a).cos(),
                2.0 * a.cos(),
                1.0 + 0.5 * (2.0 * a).sin(),
                2.0 * a.sin(),
            ]
        })
        .collect();
    let device = Device::flex();
    let fit = |model| Trajectory::fit(model, &times, &poses, &device, DType::F64).unwrap();
    let rbf = trajectory_ldj(
        &fit(TrajectoryModel::Rbf(Rbf::new(3, 3, None))),
        DEFAULT_LDJ_SAMPLES,
    );
    let waypoint = trajectory_ldj(
        &fit(TrajectoryModel::Waypoint(Waypoint::default())),
        DEFAULT_LDJ_SAMPLES,
    );
    let (rbf_pos, rbf_ang) = (rbf.positional.unwrap(), rbf.angular.unwrap());
    let (wp_pos, wp_ang) = (waypoint.positional.unwrap(), waypoint.angular.unwrap());
    // Jumps make the waypoint model's jerk huge; demand a wide margin, not just an ordering.
    assert!(
        wp_pos > rbf_pos + 5.0,
        "positional: waypoint {wp_pos}, rbf {rbf_pos}"
    );
    assert!(
        wp_ang > rbf_ang + 5.0,
        "angular: waypoint {wp_ang}, rbf {rbf_ang}"
    );
}

#[test]
fn waypoint_ldj_grows_like_three_ln_samples() {
    // The documented resolution dependence of a trajectory with jumps: doubling the samples adds
    // about 3·ln 2 ≈ 2.08 (jerk integral ~ h⁻⁵, v_peak² ~ h⁻²).
    let device = Device::flex();
    let w: Vec<Pose> = (0..100).map(|j| [((j as f64) * 0.3).sin(); 6]).collect();
    let traj = Trajectory::from_weights(
        TrajectoryModel::Waypoint(Waypoint::default()),
        &w,
        &device,
        DType::F64,
    )
    .unwrap();
    // Grids of 100·q + 1 points put segment boundaries on grid points every time.
    let coarse = trajectory_ldj(&traj, 1001).positional.unwrap();
    let fine = trajectory_ldj(&traj, 2001).positional.unwrap();
    let step = fine - coarse;
    assert!((step - 3.0 * 2f64.ln()).abs() < 0.3, "{coarse} → {fine}");
}

#[test]
fn still_and_jerk_free_motions() {
    // No motion: v_peak = 0, LDJ undefined.
    assert_eq!(ldj(&profile(101, |_| 2.5), 1.0), None);
    // Constant velocity: zero jerk, the floor's value ln(1e-12).
    let linear = ldj(&profile(101, |t| 1.0 + 3.0 * t), 1.0).unwrap();
    assert!((linear - 1e-12f64.ln()).abs() < 1e-9, "{linear}");
    // Too few samples or a bad duration: undefined.
    assert_eq!(ldj(&profile(4, min_jerk), 1.0), None);
    assert_eq!(ldj(&profile(101, min_jerk), 0.0), None);
    // A trajectory standing still in rotation but moving in position.
    let poses: Vec<Pose> = uniform_times(101)
        .into_iter()
        .map(|t| [0.2, 0.0, 0.0, min_jerk(t), 0.0, 0.0])
        .collect();
    let smooth = pose_ldj(&poses, 1.0);
    assert_eq!(smooth.angular, None);
    assert!(smooth.positional.is_some());
}
