//! Clearance and motion limits: exact distances to ellipsoids against closed forms and brute
//! force, the occupancy index against a scan of every ellipsoid, both path costs (the motion
//! cost's orbit limit on a circle too) against closed forms and f64 finite differences, a camera inside geometry pushed out, and a speed
//! limit that holds on the densely sampled path.

mod common;

use common::{host, poses_tensor};

use burn::tensor::{DType, Device, Tensor};
use glam::{DMat3, DQuat, DVec3};
use splatraj_render::camera::Pose;
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_traj::clearance::{Ellipsoid, Occupancy, OccupancySpec};
use splatraj_traj::costs::{
    ClearanceCost, Cost, CostInputs, CostsConfig, MotionCost, PathSamples, PriorCost, QueryContext,
};
use splatraj_traj::metrics::path_metrics;
use splatraj_traj::optimise::{
    Problem, SinglePoseOptions, TrajectoryOptions, WindowTarget, optimise_single_pose,
    optimise_trajectory, window_start_trajectory,
};
use splatraj_traj::trajectory::{Rbf, Trajectory, TrajectoryModel};

const SPEC: OccupancySpec = OccupancySpec {
    sigma: 2.0,
    min_opacity: 0.2,
};

fn context(object_centre: [f64; 3]) -> QueryContext {
    QueryContext {
        object_centre,
        prior_radius: 0.5,
        world_up: [0.0, 0.0, 1.0],
        target_ratio: 0.15,
    }
}

/// A scene of Gaussians given as (mean, scale, rotation (w, x, y, z)), all opaque, grey.
fn scene(gaussians: &[([f32; 3], [f32; 3], [f32; 4])]) -> Scene {
    let n = gaussians.len();
    Scene {
        means: gaussians.iter().map(|g| g.0).collect(),
        scales: gaussians.iter().map(|g| g.1).collect(),
        rotations: gaussians.iter().map(|g| g.2).collect(),
        opacities: vec![0.9; n],
        sh_degree: 0,
        sh: vec![0.0; n * 3],
        extras: Default::default(),
    }
}

fn xorshift(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

fn axis_aligned(centre: [f64; 3], radii: [f64; 3]) -> Ellipsoid {
    Ellipsoid {
        centre: DVec3::from(centre),
        axes: DMat3::IDENTITY,
        radii: DVec3::from(radii),
    }
}

#[test]
fn distances_to_spheres_and_axis_points_are_closed_form() {
    let sphere = axis_aligned([1.0, 2.0, 3.0], [2.0, 2.0, 2.0]);
    let at = |p: [f64; 3]| sphere.nearest(DVec3::from(p)).distance;
    assert!((at([6.0, 2.0, 3.0]) - 3.0).abs() < 1e-12);
    assert!((at([1.0, 2.0, 3.5]) + 1.5).abs() < 1e-12);
    assert!((at([1.0 + 3.0, 2.0 + 4.0, 3.0]) - 3.0).abs() < 1e-12);
    // The centre of a sphere is a radius deep.
    assert!((at([1.0, 2.0, 3.0]) + 2.0).abs() < 1e-12);

    // Semi-axes 3, 2, 1: on an axis the nearest point is the axis' end (outside), and
    // inside on the shortest axis too; the centre is the shortest semi-axis deep.
    let e = axis_aligned([0.0; 3], [3.0, 2.0, 1.0]);
    let at = |p: [f64; 3]| e.nearest(DVec3::from(p));
    for (p, d, x) in [
        ([5.0, 0.0, 0.0], 2.0, [3.0, 0.0, 0.0]),
        ([0.0, -4.0, 0.0], 2.0, [0.0, -2.0, 0.0]),
        ([0.0, 0.0, 1.5], 0.5, [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 0.25], -0.75, [0.0, 0.0, 1.0]),
        ([0.0, 0.0, -0.25], -0.75, [0.0, 0.0, -1.0]),
    ] {
        let s = at(p);
        assert!((s.distance - d).abs() < 1e-12, "{p:?}: {s:?}");
        assert!(s.point.distance(DVec3::from(x)) < 1e-12, "{p:?}: {s:?}");
    }
    assert!((at([0.0; 3]).distance + 1.0).abs() < 1e-12);
    // Inside on the long axis, near the flat side: the nearest point leaves the axis. Closed
    // form (Lagrange): x₀ = e₀² y₀/(e₀² − e₂²), x₂ = e₂ √(1 − (e₀ y₀/(e₀² − e₂²))²).
    let y0 = 1.0;
    let x0 = 9.0 * y0 / 8.0;
    let x2 = (1.0 - (3.0 * y0 / 8.0f64).powi(2)).sqrt();
    let s = at([y0, 0.0, 0.0]);
    assert!(
        s.point
            .distance(DVec3::new(x0, 0.0, x2))
            .min(s.point.distance(DVec3::new(x0, 0.0, -x2)))
            < 1e-9,
        "{s:?}"
    );
    assert!((s.distance + ((x0 - y0).powi(2) + x2 * x2).sqrt()).abs() < 1e-9);
}

/// Brute force: the nearest of many surface points (a fine (θ, φ) grid), an independent
/// reference for rotated ellipsoids and points anywhere.
fn brute_force(e: &Ellipsoid, p: DVec3) -> f64 {
    let (nt, np) = (400, 800);
    let mut best = f64::INFINITY;
    for i in 0..=nt {
        let theta = std::f64::consts::PI * i as f64 / nt as f64;
        for j in 0..np {
            let phi = std::f64::consts::TAU * j as f64 / np as f64;
            let local = DVec3::new(
                e.radii.x * theta.sin() * phi.cos(),
                e.radii.y * theta.sin() * phi.sin(),
                e.radii.z * theta.cos(),
            );
            best = best.min((e.centre + e.axes * local).distance(p));
        }
    }
    best
}

#[test]
fn distances_to_rotated_ellipsoids_match_brute_force() {
    let mut rng = 0x5EED_u64;
    for case in 0..12 {
        let mut r = || xorshift(&mut rng);
        let q = DQuat::from_xyzw(r() - 0.5, r() - 0.5, r() - 0.5, r() - 0.5).normalize();
        let e = Ellipsoid {
            centre: DVec3::new(r(), r(), r()),
            axes: DMat3::from_quat(q),
            radii: DVec3::new(0.2 + r(), 0.05 + 0.5 * r(), 0.01 + 0.3 * r()),
        };
        // Half the points inside, half outside.
        let scale = if case % 2 == 0 { 0.6 } else { 2.5 };
        let p = e.centre + e.axes * (e.radii * DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * scale);
        let s = e.nearest(p);
        let reference = brute_force(&e, p);
        // The grid's spacing bounds its error: ~π·1.2/400.
        assert!(
            (s.distance.abs() - reference).abs() < 5e-3,
            "case {case}: {s:?} vs {reference}"
        );
        assert_eq!(s.distance < 0.0, e.contains(p), "case {case}: sign");
        // The returned point lies on the surface and the normal is the gradient direction.
        let local = e.axes.transpose() * (s.point - e.centre);
        assert!(((local / e.radii).length_squared() - 1.0).abs() < 1e-9);
        assert!((s.point.distance(p) - s.distance.abs()).abs() < 1e-9);
    }
}

#[test]
fn the_index_finds_the_same_nearest_surface_as_a_scan_and_the_same_clear_points() {
    let mut rng = 0xC1EA_u64;
    let mut r = || xorshift(&mut rng);
    let gaussians: Vec<([f32; 3], [f32; 3], [f32; 4])> = (0..300)
        .map(|i| {
            // Sizes over three orders of magnitude (several tiers).
            let size = 0.002 * 10f64.powf(3.0 * r()) as f32;
            (
                [4.0 * r() as f32, 4.0 * r() as f32, 4.0 * r() as f32],
                [size, size * (0.2 + r() as f32), size * 0.1],
                [1.0, (i % 3) as f32 * 0.3, 0.1, 0.0],
            )
        })
        .collect();
    let occupancy = Occupancy::new(&scene(&gaussians), SPEC);
    assert_eq!(occupancy.len(), 300);
    for k in 0..300 {
        // Points in the open and, one in three, just beside or inside an ellipsoid (negative
        // clearances, where the search radius shrinks below zero).
        let p = if k % 3 == 0 {
            let e = occupancy.ellipsoids()[k % occupancy.len()];
            e.centre + e.radii.x * DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5)
        } else {
            DVec3::new(5.0 * r() - 0.5, 5.0 * r() - 0.5, 5.0 * r() - 0.5)
        };
        let scan = occupancy
            .ellipsoids()
            .iter()
            .map(|e| e.nearest(p).distance)
            .fold(f64::INFINITY, f64::min);
        assert!(
            occupancy.upper_bound(p) >= scan,
            "{p}: bound below the scan"
        );
        let found = occupancy.nearest(p, 0.05).unwrap().surface.distance;
        assert!((found - scan).abs() < 1e-12, "{p}: {found} vs {scan}");
        let within = occupancy.nearest_within(p, 0.1);
        if scan <= 0.1 {
            assert!((within.unwrap().surface.distance - scan).abs() < 1e-12);
        }
        // The early-exit test agrees with the scan (away from the threshold's rounding).
        for radius in [0.0, 0.05, 0.3] {
            if (scan - radius).abs() > 1e-9 {
                assert_eq!(
                    occupancy.is_clear(p, radius),
                    scan >= radius,
                    "{p}, {radius}"
                );
            }
        }
    }
}

/// Σ of the cost's values and its gradient in the poses, f64 on flex.
fn value_and_gradient(
    cost: &dyn Cost,
    poses: &[[f64; 6]],
    build: &dyn Fn(Tensor<2>) -> CostInputs,
) -> (f64, Vec<f64>) {
    let device = Device::flex().autodiff();
    let tensor = poses_tensor(poses, &device).require_grad();
    let value = cost.evaluate(&build(tensor.clone())).unwrap().sum();
    let total = host(value.clone())[0];
    let grads = value.backward();
    (total, host(tensor.grad(&grads).unwrap()))
}

fn check_finite_differences(
    cost: &dyn Cost,
    poses: &[[f64; 6]],
    build: &dyn Fn(Tensor<2>) -> CostInputs,
) {
    let (_, gradient) = value_and_gradient(cost, poses, build);
    let h = 1e-6;
    for (k, g) in gradient.iter().enumerate() {
        let shifted = |delta: f64| {
            let mut p = poses.to_vec();
            p[k / 6][k % 6] += delta;
            value_and_gradient(cost, &p, build).0
        };
        let numeric = (shifted(h) - shifted(-h)) / (2.0 * h);
        assert!(
            (numeric - g).abs() <= 1e-5 * (1.0 + numeric.abs()),
            "component {k}: autodiff {g}, finite differences {numeric}"
        );
    }
}

#[test]
fn clearance_cost_is_the_hinge_on_the_exact_distance_and_its_gradient_matches() {
    let occupancy = Occupancy::new(
        &scene(&[
            ([0.0, 0.0, 0.0], [0.5, 0.25, 0.1], [1.0, 0.0, 0.0, 0.0]),
            ([2.0, 0.0, 0.0], [0.2, 0.2, 0.2], [0.9, 0.1, 0.3, 0.2]),
        ]),
        SPEC,
    );
    let cost = ClearanceCost::with_margin(0.3);
    let poses = [
        [0.1, 0.2, 0.3, 1.2, 0.1, 0.05], // outside the first, within the margin
        [0.0, 0.0, 0.0, 0.3, 0.1, 0.05], // inside the first
        [0.0, 0.0, 0.0, 2.1, 0.0, 0.52], // near the second's top
        [0.0, 0.0, 0.0, 1.0, 1.5, 0.0],  // clear of both
    ];
    let build = |t: Tensor<2>| {
        CostInputs::new(t, None, 0, context([0.0; 3]))
            .unwrap()
            .with_occupancy(occupancy.clone())
    };
    // Values: (m − d)²/m² with d the exact distance, 0 beyond the margin.
    let device = Device::flex();
    let got = host(
        cost.evaluate(&build(poses_tensor(&poses, &device)))
            .unwrap(),
    );
    for (pose, value) in poses.iter().zip(&got) {
        let p = DVec3::new(pose[3], pose[4], pose[5]);
        let d = occupancy
            .ellipsoids()
            .iter()
            .map(|e| e.nearest(p).distance)
            .fold(f64::INFINITY, f64::min);
        let want = ((0.3 - d).max(0.0) / 0.3).powi(2);
        assert!((value - want).abs() < 1e-12, "{pose:?}: {value} vs {want}");
    }
    assert!(got[1] > 1.0 && got[3] == 0.0);
    check_finite_differences(&cost, &poses, &build);
}

#[test]
fn motion_cost_matches_closed_forms_and_finite_differences() {
    // A camera moving along x at speed v and turning about z at rate ω, sampled every Δt.
    let (seconds, time_step) = (10.0, 0.01);
    let dt = seconds * time_step;
    let (v, omega) = (2.0, 0.3); // units/s, rad/s
    let poses: Vec<[f64; 6]> = (0..8)
        .map(|k| {
            let t = k as f64 * dt;
            [0.0, 0.0, omega * t, v * t, 0.5, 1.0]
        })
        .collect();
    let build = |t: Tensor<2>| {
        CostInputs::new(t.clone(), None, 0, context([0.0; 3]))
            .unwrap()
            .with_path(PathSamples::new(
                t,
                time_step,
                Some(seconds),
                context([0.0; 3]),
            ))
    };
    let evaluate = |cost: &MotionCost| -> f64 {
        host(
            cost.evaluate(&build(poses_tensor(&poses, &Device::flex())))
                .unwrap(),
        )[0]
    };
    let speed = MotionCost {
        max_speed: Some(1.5.into()),
        ..MotionCost::default()
    };
    let want = (v / 1.5f64).powi(2) - 1.0;
    assert!(
        (evaluate(&speed) - want).abs() < 1e-9,
        "{} vs {want}",
        evaluate(&speed)
    );
    // Within the limits (constant velocity: no acceleration): nothing to pay.
    let within = MotionCost {
        max_speed: Some(2.5.into()),
        max_acceleration: Some(0.1),
        ..MotionCost::default()
    };
    assert!(evaluate(&within).abs() < 1e-12);
    let turning = MotionCost {
        max_angular_speed: Some(0.2f64.to_degrees()),
        ..MotionCost::default()
    };
    let want = (omega / 0.2f64).powi(2) - 1.0;
    assert!(
        (evaluate(&turning) - want).abs() < 1e-3 * want,
        "{} vs {want}",
        evaluate(&turning)
    );

    // Gradients on an uneven, accelerating path with every term on.
    let mut rng = 0xA11CE_u64;
    let uneven: Vec<[f64; 6]> = poses
        .iter()
        .map(|p| std::array::from_fn(|i| p[i] + 0.05 * (xorshift(&mut rng) - 0.5)))
        .collect();
    let all = MotionCost {
        weight: 1.0,
        max_speed: Some(1.0.into()),
        max_acceleration: Some(5.0),
        max_angular_speed: Some(10.0),
        max_orbit_speed: Some(5.0),
        even_speed: 0.5,
    };
    check_finite_differences(&all, &uneven, &build);
}

#[test]
fn orbit_limit_matches_the_circle_closed_form_and_finite_differences() {
    // A camera circling o = (1, −2, 0.5) at radius ρ and rate Ω in a tilted plane, sampled
    // every Δt: each step's chord between unit directions is 2 sin(ΩΔt/2), so the charge is
    // (2 sin(ΩΔt/2)/Δt)²/ψ² − 1 at every step.
    let (seconds, time_step) = (10.0, 0.01);
    let dt = seconds * time_step;
    let (rho, omega) = (1.7, 0.9); // units, rad/s
    let o = DVec3::new(1.0, -2.0, 0.5);
    let (a, b) = (
        DVec3::new(1.0, 0.0, 0.3).normalize(),
        DVec3::new(0.0, 1.0, 0.0),
    );
    let circle: Vec<[f64; 6]> = (0..9)
        .map(|k| {
            let phase = omega * k as f64 * dt;
            let c = o + rho * (a * phase.cos() + b * phase.sin());
            [0.1, -0.2, 0.3, c.x, c.y, c.z]
        })
        .collect();
    let build = |t: Tensor<2>| {
        CostInputs::new(t.clone(), None, 0, context(o.to_array()))
            .unwrap()
            .with_path(PathSamples::new(
                t,
                time_step,
                Some(seconds),
                context(o.to_array()),
            ))
    };
    let evaluate = |cost: &MotionCost, poses: &[[f64; 6]]| -> f64 {
        host(
            cost.evaluate(&build(poses_tensor(poses, &Device::flex())))
                .unwrap(),
        )[0]
    };
    let limit = 0.4f64; // rad/s
    let orbit = MotionCost {
        max_orbit_speed: Some(limit.to_degrees()),
        ..MotionCost::default()
    };
    let rate = 2.0 * (0.5 * omega * dt).sin() / dt;
    let want = (rate / limit).powi(2) - 1.0;
    let got = evaluate(&orbit, &circle);
    assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
    // Within the limit: nothing to pay.
    let slow = MotionCost {
        max_orbit_speed: Some(1.0f64.to_degrees()),
        ..MotionCost::default()
    };
    assert!(evaluate(&slow, &circle).abs() < 1e-12);
    // Straight at the object and through it (the floored distance at o): no orbit before o,
    // a half turn of the direction as the camera passes o, and a finite value.
    let through: Vec<[f64; 6]> = (-3..=3)
        .map(|k| {
            let c = o + a * (0.5 * k as f64);
            [0.0, 0.0, 0.0, c.x, c.y, c.z]
        })
        .collect();
    let radial = evaluate(&orbit, &through);
    assert!(radial.is_finite());
    // The steps into and out of o move the direction by a chord of 1 (from ±a to the floored
    // zero vector's direction, which is 0): two of six steps, each charged (1/Δt)²/ψ² − 1.
    let want = 2.0 / 6.0 * ((1.0 / dt / limit).powi(2) - 1.0);
    assert!((radial - want).abs() < 1e-6 * want, "{radial} vs {want}");

    // Gradients on an uneven circle (turning too, so both rotation and orbit terms act).
    let mut rng = 0x0_B17_u64;
    let uneven: Vec<[f64; 6]> = circle
        .iter()
        .map(|p| std::array::from_fn(|i| p[i] + 0.05 * (xorshift(&mut rng) - 0.5)))
        .collect();
    let both = MotionCost {
        max_angular_speed: Some(10.0),
        max_orbit_speed: Some(limit.to_degrees()),
        ..MotionCost::default()
    };
    check_finite_differences(&both, &uneven, &build);
}

fn pose_only_problem_costs(config: CostsConfig) -> splatraj_traj::costs::WeightedCosts {
    config.build().unwrap()
}

fn no_image_costs() -> CostsConfig {
    CostsConfig {
        tce: None,
        tre: None,
        upright: None,
        prior: None,
        clearance: None,
        motion: None,
        visibility: None,
        custom: Default::default(),
    }
}

#[test]
fn a_camera_inside_geometry_is_pushed_out() {
    // A boulder (one round Gaussian, 2σ radius 1) and a slab beside it, overlapping.
    let boulder = scene(&[
        ([0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 0.0, 0.0, 0.0]),
        ([0.9, 0.0, 0.0], [0.1, 0.6, 0.6], [1.0, 0.0, 0.0, 0.0]),
    ]);
    let occupancy = Occupancy::new(&boulder, SPEC);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&boulder, &device, DType::F32);
    let costs = pose_only_problem_costs(CostsConfig {
        clearance: Some(ClearanceCost::with_margin(0.2)),
        ..no_image_costs()
    });
    let windows = [WindowTarget {
        name: "nothing".into(),
        mask: vec![0.0; 2],
        context: context([0.0; 3]),
    }];
    let k = splatraj_render::camera::Intrinsics::from_fov_x(60.0, 16, 12).unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, k).with_occupancy(Some(&occupancy));
    for start in [[0.2, 0.1, 0.0], [0.85, 0.1, -0.2], [-0.05, 0.0, 0.02]] {
        let start_pose = Pose([0.0, 0.0, 0.0, start[0], start[1], start[2]]);
        let before = occupancy
            .nearest(start_pose.centre(), 0.2)
            .unwrap()
            .surface
            .distance;
        assert!(before < 0.0, "the start {start:?} is inside");
        let options = SinglePoseOptions {
            iterations: 200,
            lr_position: 0.02,
            ..SinglePoseOptions::default()
        };
        let result = optimise_single_pose(&problem, start_pose, &options).unwrap();
        let after = occupancy
            .nearest(result.pose.centre(), 0.2)
            .unwrap()
            .surface
            .distance;
        assert!(
            after >= 0.19,
            "from {start:?}: clearance {before:.3} → {after:.3}"
        );
    }
}

/// Two windows looking at objects 4 units apart for `seconds`, with the prior (and optionally
/// a motion cost); the per-window path metrics of the result.
fn two_object_run(
    motion: Option<MotionCost>,
    seconds: f64,
) -> Vec<splatraj_traj::metrics::PathMetrics> {
    let tiny = scene(&[([0.0, 0.0, -5.0], [0.1, 0.1, 0.1], [1.0, 0.0, 0.0, 0.0])]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&tiny, &device, DType::F32);
    let windows: Vec<WindowTarget> = [[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
        .into_iter()
        .map(|o| WindowTarget {
            name: format!("{o:?}"),
            mask: vec![0.0],
            context: context(o),
        })
        .collect();
    let costs = CostsConfig {
        prior: Some(PriorCost {
            alpha0: 1.0,
            gamma: 0.995,
            radius: None,
        }),
        motion,
        ..no_image_costs()
    }
    .build()
    .unwrap();
    let k = splatraj_render::camera::Intrinsics::from_fov_x(60.0, 16, 12).unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, k).with_seconds(Some(seconds));
    let model = TrajectoryModel::Rbf(Rbf::new(2, 6, None));
    let starts: Vec<Pose> = windows
        .iter()
        .map(|w| {
            let o = DVec3::from(w.context.object_centre);
            Pose::look_at(o + DVec3::new(0.0, -0.5, 0.2), o, DVec3::Z).unwrap()
        })
        .collect();
    let start = window_start_trajectory(model, &starts, &device, DType::F32)
        .unwrap()
        .record();
    let options = TrajectoryOptions {
        iterations: 600,
        samples_per_window: 2,
        learning_rate: 0.02,
        // The cost sees the path at these points only; at 24 per window the smoothstep joins
        // of the start left the dense grid's peak 17 % above the limit between them.
        path_samples: 48,
        ..TrajectoryOptions::default()
    };
    let result = optimise_trajectory(&problem, &start, &options, 3, &mut |_| {
        splatraj_traj::optimise::Flow::Continue
    })
    .unwrap();
    let trajectory = Trajectory::from_record(&result.best, &Device::flex(), DType::F64).unwrap();
    path_metrics(
        &|t: &[f64]| trajectory.poses_at(t),
        2,
        2001,
        None,
        Some(seconds),
        &[],
    )
}

#[test]
fn a_speed_limit_holds_on_the_densely_sampled_path() {
    let seconds = 10.0;
    let free = two_object_run(None, seconds);
    let peak = |m: &[splatraj_traj::metrics::PathMetrics]| {
        m.iter().map(|w| w.motion.peak_speed).fold(0.0, f64::max)
    };
    let limit = 1.0;
    // Without a limit the camera crosses the 4 units between the objects in about a second.
    assert!(peak(&free) > 2.0 * limit, "free peak {}", peak(&free));
    let limited = two_object_run(
        Some(MotionCost {
            weight: 50.0,
            max_speed: Some(limit.into()),
            ..MotionCost::default()
        }),
        seconds,
    );
    assert!(
        peak(&limited) <= 1.1 * limit,
        "limited peak {}",
        peak(&limited)
    );
}
