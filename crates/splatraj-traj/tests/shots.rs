//! Shot presets: the placed orbit and dolly paths against their closed forms, bad values named
//! by key, and an optimised orbit that keeps the requested elevation, radius and sweep and
//! the object centred while TRE and the prior pull the camera elsewhere.

use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_traj::costs::{CostsConfig, PriorCost, QueryContext, ShotCost, TceCost, TreCost};
use splatraj_traj::optimise::{
    Flow, Problem, TrajectoryOptions, WindowStart, WindowTarget, optimise_trajectory,
    start_trajectory,
};
use splatraj_traj::shots::{Direction, DollySpec, OrbitSpec, ShotFrame, ShotPath, ShotSpec};
use splatraj_traj::trajectory::{Rbf, Trajectory, TrajectoryModel};

const UP: [f64; 3] = [0.0, 0.0, 1.0];

fn frame(object_centre: [f64; 3]) -> ShotFrame {
    ShotFrame {
        object_centre,
        working_radius: 1.0,
        world_up: UP,
        // Not unit length and not horizontal: placing a shot must normalise and flatten it.
        side: [2.0, 0.0, 0.7],
    }
}

fn orbit(elevation: f64, radius: f64, sweep: f64, direction: Direction) -> ShotSpec {
    ShotSpec::Orbit(OrbitSpec {
        elevation,
        radius: Some(radius),
        sweep,
        direction,
        ..OrbitSpec::default()
    })
}

fn close(a: DVec3, b: DVec3) -> bool {
    a.distance(b) < 1e-9
}

#[test]
fn orbit_and_dolly_paths_are_closed_form() {
    let o = DVec3::new(1.0, 2.0, 3.0);
    let (c30, s30) = (30f64.to_radians().cos(), 0.5);
    // Counter-clockwise about +z turns +x toward +y; clockwise toward −y.
    let ccw = orbit(30.0, 2.0, 90.0, Direction::Ccw)
        .place(&frame(o.to_array()))
        .unwrap();
    assert!(close(
        ccw.centre_at(0.0),
        o + 2.0 * DVec3::new(c30, 0.0, s30)
    ));
    assert!(close(
        ccw.centre_at(1.0),
        o + 2.0 * DVec3::new(0.0, c30, s30)
    ));
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!(close(
        ccw.centre_at(0.5),
        o + 2.0 * DVec3::new(c30 * h, c30 * h, s30)
    ));
    let cw = orbit(30.0, 2.0, 90.0, Direction::Cw)
        .place(&frame(o.to_array()))
        .unwrap();
    assert!(close(
        cw.centre_at(1.0),
        o + 2.0 * DVec3::new(0.0, -c30, s30)
    ));
    // The ideal pose looks straight at the object, upright (camera x horizontal).
    for s in [0.0, 0.3, 1.0] {
        let pose = ccw.pose_at(s);
        let r = pose.rotation_wc();
        let forward = (o - pose.centre()).normalize();
        assert!(close(r.z_axis, forward), "s = {s}");
        assert!(r.x_axis.z.abs() < 1e-9, "s = {s}: camera x {:?}", r.x_axis);
    }
    // Azimuth turns the start counter-clockwise: 90° starts where the ccw orbit ends.
    let turned = ShotSpec::Orbit(OrbitSpec {
        azimuth: 90.0,
        radius: Some(2.0),
        ..OrbitSpec::default()
    })
    .place(&frame(o.to_array()))
    .unwrap();
    assert!(close(turned.centre_at(0.0), ccw.centre_at(1.0)));
    // A dolly goes from `from` to `to` along one view line; defaults 1.5 r and r.
    let dolly = ShotSpec::Dolly(DollySpec {
        elevation: 0.0,
        from: Some(3.0),
        to: Some(1.0),
        ..DollySpec::default()
    })
    .place(&frame(o.to_array()))
    .unwrap();
    assert!(close(dolly.centre_at(0.0), o + DVec3::new(3.0, 0.0, 0.0)));
    assert!(close(dolly.centre_at(0.5), o + DVec3::new(2.0, 0.0, 0.0)));
    assert!(close(dolly.centre_at(1.0), o + DVec3::new(1.0, 0.0, 0.0)));
    let default = ShotSpec::Dolly(DollySpec::default())
        .place(&frame(o.to_array()))
        .unwrap();
    assert_eq!(default.radius, (1.5, 1.0));
}

#[test]
fn bad_shot_values_name_their_key() {
    let field = |spec: ShotSpec| spec.place(&frame([0.0; 3])).unwrap_err().field;
    assert_eq!(field(orbit(90.0, 1.0, 90.0, Direction::Ccw)), "elevation");
    assert_eq!(
        field(orbit(f64::NAN, 1.0, 90.0, Direction::Ccw)),
        "elevation"
    );
    assert_eq!(field(orbit(30.0, -1.0, 90.0, Direction::Ccw)), "radius");
    assert_eq!(field(orbit(30.0, 1.0, 0.0, Direction::Ccw)), "sweep");
    let along_up = ShotFrame {
        side: UP,
        ..frame([0.0; 3])
    };
    let err = orbit(30.0, 1.0, 90.0, Direction::Ccw)
        .place(&along_up)
        .unwrap_err();
    assert_eq!(err.field, "side");
    // The config form: kind-tagged, unknown keys refused.
    let parsed: ShotSpec =
        toml::from_str("kind = \"orbit\"\nelevation = 20\nsweep = 45\ndirection = \"cw\"").unwrap();
    assert_eq!(parsed, orbit_default_radius(20.0, 45.0, Direction::Cw));
    assert!(toml::from_str::<ShotSpec>("kind = \"orbit\"\nelevaton = 20").is_err());
    assert!(toml::from_str::<ShotSpec>("kind = \"spiral\"").is_err());
}

fn orbit_default_radius(elevation: f64, sweep: f64, direction: Direction) -> ShotSpec {
    ShotSpec::Orbit(OrbitSpec {
        elevation,
        sweep,
        direction,
        ..OrbitSpec::default()
    })
}

/// A small object (round Gaussians symmetric about the origin) and one far distractor.
fn scene() -> Scene {
    let means: Vec<[f32; 3]> = vec![
        [0.0, 0.0, 0.0],
        [0.08, 0.0, 0.0],
        [-0.08, 0.0, 0.0],
        [0.0, 0.08, 0.0],
        [0.0, -0.08, 0.0],
        [4.0, 4.0, 0.0],
    ];
    let n = means.len();
    Scene {
        means,
        scales: vec![[0.08; 3]; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![0.9; n],
        sh_degree: 0,
        sh: vec![0.0; n * 3],
        extras: Default::default(),
    }
}

/// Elevation (degrees), radius and azimuth (radians, about +z) of camera centre `c` around
/// the origin.
fn spherical(c: DVec3) -> (f64, f64, f64) {
    let radius = c.length();
    ((c.z / radius).asin().to_degrees(), radius, c.y.atan2(c.x))
}

/// Optimises a one-window orbit (elevation 30°, radius 1.2, 90° ccw) from its fitted start,
/// with `shot` on or off, against TRE asking for a much larger share of the frame; returns the optimised trajectory on the host and the orbit.
fn orbit_run(shot: bool) -> (Trajectory, ShotPath) {
    let device = Device::flex().autodiff();
    let host = scene();
    let on_device = DeviceScene::new(&host, &device, DType::F32);
    let windows = [WindowTarget {
        name: "object".into(),
        mask: vec![1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
        context: QueryContext {
            object_centre: [0.0; 3],
            prior_radius: 1.2,
            world_up: UP,
            target_ratio: 0.5,
        },
    }];
    let path = orbit(30.0, 1.2, 90.0, Direction::Ccw)
        .place(&ShotFrame {
            side: [1.0, 0.0, 0.0],
            ..frame([0.0; 3])
        })
        .unwrap();
    let mut costs = CostsConfig {
        tce: Some(TceCost::default()),
        tre: Some(TreCost::default()),
        upright: None,
        prior: Some(PriorCost {
            alpha0: 1.0,
            gamma: 0.99,
            radius: None,
        }),
        clearance: None,
        motion: None,
        custom: Default::default(),
    }
    .build()
    .unwrap();
    if shot {
        costs = costs
            .with_cost(Box::new(ShotCost {
                shots: vec![Some(path)],
            }))
            .unwrap();
    }
    let k = Intrinsics::from_fov_x(60.0, 16, 12).unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, k);
    let model = TrajectoryModel::Rbf(Rbf::new(1, 6, Some(0.3)));
    let start = start_trajectory(model, &[WindowStart::Shot(path)], &device, DType::F32)
        .unwrap()
        .record();
    let options = TrajectoryOptions {
        iterations: 150,
        samples_per_window: 4,
        // Small steps: Adam's step size is about the rate, here ~0.3° of turn at the end.
        learning_rate: 0.005,
        ..TrajectoryOptions::default()
    };
    let result =
        optimise_trajectory(&problem, &start, &options, 5, &mut |_| Flow::Continue).unwrap();
    let trajectory = Trajectory::from_record(&result.best, &Device::flex(), DType::F64).unwrap();
    (trajectory, path)
}

#[test]
fn an_orbit_keeps_its_elevation_radius_sweep_and_the_object_centred() {
    let times: Vec<f64> = (0..=40).map(|i| i as f64 / 40.0).collect();
    let (trajectory, path) = orbit_run(true);
    let poses: Vec<Pose> = trajectory.poses_at(&times).into_iter().map(Pose).collect();
    for (&t, pose) in times.iter().zip(&poses) {
        let (elevation, radius, _) = spherical(pose.centre());
        assert!(
            (elevation - 30.0).abs() < 3.0,
            "t = {t}: elevation {elevation:.2}°"
        );
        assert!((radius - 1.2).abs() < 0.06, "t = {t}: radius {radius:.3}");
        // Progress along the sweep: within 5° of the asked azimuth at every time.
        let (_, _, azimuth) = spherical(path.centre_at(t));
        let (_, _, got) = spherical(pose.centre());
        assert!(
            (got - azimuth).to_degrees().abs() < 5.0,
            "t = {t}: azimuth {:.1}° for {:.1}°",
            got.to_degrees(),
            azimuth.to_degrees()
        );
    }
    // The object stays centred: TCE of the object's mask rendered at each time.
    let device = Device::flex();
    let host = scene();
    let on_device = DeviceScene::new(&host, &device, DType::F64);
    let windows = [WindowTarget {
        name: "object".into(),
        mask: vec![1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
        context: QueryContext {
            object_centre: [0.0; 3],
            prior_radius: 1.2,
            world_up: UP,
            target_ratio: 0.1,
        },
    }];
    let tce_only = CostsConfig {
        tce: Some(TceCost::default()),
        tre: None,
        upright: None,
        prior: None,
        clearance: None,
        motion: None,
        custom: Default::default(),
    }
    .build()
    .unwrap();
    let k = Intrinsics::from_fov_x(60.0, 32, 24).unwrap();
    let problem = Problem::new(&on_device, &windows, &tce_only, k);
    for (&t, pose) in times.iter().zip(&poses).step_by(5) {
        let loss = problem.loss_at(0, pose, false).unwrap();
        let ideal = problem.loss_at(0, &path.pose_at(t), false).unwrap();
        let aim = pose
            .rotation_wc()
            .z_axis
            .angle_between(-pose.centre())
            .to_degrees();
        println!(
            "t = {t}: TCE {:.4} (ideal {:.4}), aim off by {aim:.2}°",
            loss.term("tce"),
            ideal.term("tce")
        );
        assert!(loss.coverage.unwrap() > 0.0, "t = {t}: object not seen");
        // Measured 0.0004–0.032 (the ideal look-at pose: 0.004); the ends, where the model is
        // stiffest, are the worst. An object in a corner has TCE 0.7.
        assert!(loss.term("tce") < 0.05, "t = {t}: TCE {}", loss.term("tce"));
        assert!(aim < 3.0, "t = {t}: view {aim:.2}° off the object");
    }

    // Without the shot's cost the same start is pulled off the orbit (so the checks above
    // can fail): TRE and the prior bring the camera closer.
    let (free, _) = orbit_run(false);
    let drift = free
        .poses_at(&times)
        .iter()
        .map(|p| (spherical(Pose(*p).centre()).1 - 1.2).abs())
        .fold(0.0, f64::max);
    println!("drift without the shot cost {drift:.3}");
    assert!(
        drift > 0.06,
        "without the shot cost the radius stayed within {drift:.3}"
    );
}
