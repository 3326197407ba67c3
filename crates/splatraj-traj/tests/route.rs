//! Planned starts around geometry: a scene built for it (two objects with a wall of flat
//! Gaussians between them), where the straight way from one object's camera to the other's
//! crosses the wall. The planned route keeps the margin everywhere (checked against every
//! ellipsoid, not through the planner's index), and an optimisation from the planned start
//! keeps it along the densely sampled path, while the same optimisation from the straight
//! start stays in the wall (so the check can fail).

use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_traj::clearance::{Occupancy, OccupancySpec};
use splatraj_traj::costs::{ClearanceCost, CostsConfig, PriorCost, QueryContext, TceCost, TreCost};
use splatraj_traj::metrics::path_metrics;
use splatraj_traj::optimise::start::window_joins;
use splatraj_traj::optimise::{
    Flow, Problem, Route, RoutePlanner, TrajectoryOptions, WindowStart, WindowTarget,
    optimise_trajectory, plan_transitions, routed_start_trajectory,
};
use splatraj_traj::trajectory::{Rbf, Trajectory, TrajectoryModel};

const MARGIN: f64 = 0.1;
const SPEC: OccupancySpec = OccupancySpec {
    sigma: 2.0,
    min_opacity: 0.2,
};

/// Object a (5 Gaussians at x = −1), object b (at x = 1), and between them a wall in the
/// plane x = 0: 7 × 7 flat Gaussians 0.3 apart whose 2σ ellipsoids (semi-axes 0.04, 0.5,
/// 0.5) overlap into one sheet over |y|, |z| ≤ 1.4.
fn walled_scene() -> Scene {
    let mut gaussians: Vec<([f32; 3], [f32; 3])> = Vec::new();
    for x in [-1.0f32, 1.0] {
        for d in [
            [0.0, 0.0],
            [0.05, 0.0],
            [-0.05, 0.0],
            [0.0, 0.05],
            [0.0, -0.05],
        ] {
            gaussians.push(([x, d[0], d[1]], [0.04; 3]));
        }
    }
    for j in -3..=3 {
        for k in -3..=3 {
            gaussians.push(([0.0, 0.3 * j as f32, 0.3 * k as f32], [0.02, 0.25, 0.25]));
        }
    }
    let n = gaussians.len();
    Scene {
        means: gaussians.iter().map(|g| g.0).collect(),
        scales: gaussians.iter().map(|g| g.1).collect(),
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![0.9; n],
        sh_degree: 0,
        sh: vec![0.0; n * 3],
        extras: Default::default(),
    }
}

/// Cameras 1 unit outside each object, looking at it: on opposite sides of the wall.
fn camera_starts() -> [Pose; 2] {
    [-1.0, 1.0].map(|x: f64| {
        let o = DVec3::new(x, 0.0, 0.0);
        Pose::look_at(o + DVec3::new(x, 0.0, 0.3), o, DVec3::Z).unwrap()
    })
}

fn planner(occupancy: &Occupancy) -> RoutePlanner {
    let starts = camera_starts();
    let (lo, hi) = (
        DVec3::new(-2.0, -1.4, -1.4).min(starts[0].centre()),
        DVec3::new(2.0, 1.4, 1.4).max(starts[1].centre()),
    );
    RoutePlanner::new(occupancy, MARGIN, lo, hi)
}

/// Clearance of `p` from every ellipsoid, by a scan (no index).
fn scanned_clearance(occupancy: &Occupancy, p: DVec3) -> f64 {
    occupancy
        .ellipsoids()
        .iter()
        .map(|e| e.nearest(p).distance)
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn the_planned_route_goes_around_the_wall_and_keeps_the_margin() {
    let occupancy = Occupancy::new(&walled_scene(), SPEC);
    let planner = planner(&occupancy);
    let [a, b] = camera_starts().map(|p| p.centre());
    // The straight way crosses the wall.
    assert!(scanned_clearance(&occupancy, DVec3::new(0.0, 0.0, 0.3)) < 0.0);
    let Route::Around(points) = planner.route(a, b) else {
        panic!("no route around the wall");
    };
    assert_eq!((points[0], *points.last().unwrap()), (a, b));
    let mut length = 0.0;
    let mut closest = f64::INFINITY;
    for w in points.windows(2) {
        length += w[0].distance(w[1]);
        let steps = (w[0].distance(w[1]) / 0.005).ceil() as usize;
        for k in 0..=steps {
            let p = w[0].lerp(w[1], k as f64 / steps as f64);
            closest = closest.min(scanned_clearance(&occupancy, p));
        }
    }
    println!(
        "route: {} points, length {length:.3}, closest {closest:.4}, cell {:.3}",
        points.len(),
        planner.cell()
    );
    assert!(closest >= MARGIN, "the route comes {closest} from the wall");
    // Around the wall's nearest edge (z = 1.4, the cameras are at z = 0.3) the shortest way is
    // 2·√(2² + 1.1²) ≈ 4.57; a route that wanders would be much longer.
    assert!(length > 4.5 && length < 6.0, "route length {length}");
    // Points far apart from the geometry go straight.
    let (p, q) = (DVec3::new(-2.0, 0.0, 0.3), DVec3::new(-2.0, 1.0, 0.3));
    assert_eq!(planner.route(p, q), Route::Straight);
}

/// Two windows (object a, then b) optimised with TCE, TRE, the prior and clearance (margin
/// 0.1, weight 30), from the starts' held poses joined straight or along the planned route;
/// the smallest clearance along the trajectory sampled finely (refined to margin/4 steps).
fn walled_run(planned: bool) -> f64 {
    let host = walled_scene();
    let occupancy = Occupancy::new(&host, SPEC);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&host, &device, DType::F32);
    let windows: Vec<WindowTarget> = [-1.0, 1.0]
        .into_iter()
        .enumerate()
        .map(|(w, x)| WindowTarget {
            name: format!("object {w}"),
            mask: (0..host.len())
                .map(|i| if i / 5 == w { 1.0 } else { 0.0 })
                .collect(),
            context: QueryContext {
                object_centre: [x, 0.0, 0.0],
                prior_radius: 1.0,
                world_up: [0.0, 0.0, 1.0],
                target_ratio: 0.05,
            },
        })
        .collect();
    let costs = CostsConfig {
        tce: Some(TceCost::default()),
        tre: Some(TreCost::default()),
        upright: None,
        prior: Some(PriorCost {
            alpha0: 1.0,
            gamma: 0.99,
            radius: None,
        }),
        clearance: Some(ClearanceCost {
            weight: 30.0,
            margin: MARGIN.into(),
            sigma: SPEC.sigma,
            min_opacity: SPEC.min_opacity,
        }),
        motion: None,
        visibility: None,
        custom: Default::default(),
    }
    .build()
    .unwrap();
    let k = Intrinsics::from_fov_x(60.0, 16, 12).unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, k).with_occupancy(Some(&occupancy));
    let starts = camera_starts().map(WindowStart::Hold);
    let transitions = if planned {
        let (routes, walled_in) = plan_transitions(
            &planner(&occupancy),
            &window_joins(&starts),
            &[false, false],
            &[],
        );
        assert!(walled_in.is_empty() && routes.len() == 1);
        routes
    } else {
        Vec::new()
    };
    let model = TrajectoryModel::Rbf(Rbf::new(2, 8, None));
    let start = routed_start_trajectory(model, &starts, &transitions, &[], &device, DType::F32)
        .unwrap()
        .record();
    let options = TrajectoryOptions {
        iterations: 100,
        samples_per_window: 3,
        learning_rate: 0.02,
        path_samples: 24,
        ..TrajectoryOptions::default()
    };
    let result =
        optimise_trajectory(&problem, &start, &options, 3, &mut |_| Flow::Continue).unwrap();
    let trajectory = Trajectory::from_record(&result.best, &Device::flex(), DType::F64).unwrap();
    let metrics = path_metrics(
        &|t: &[f64]| trajectory.poses_at(t),
        2,
        401,
        Some((&occupancy, MARGIN)),
        None,
        &[],
    );
    for (w, m) in metrics.iter().enumerate() {
        println!("planned {planned}, window {w}: {:?}", m.clearance);
    }
    metrics
        .iter()
        .map(|m| m.clearance.as_ref().unwrap().min_clearance)
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn a_path_through_a_wall_is_rerouted_by_the_planned_start() {
    let planned = walled_run(true);
    assert!(
        planned >= MARGIN,
        "the planned start's path comes {planned} from the wall"
    );
    // From the straight start, gradient descent pushes each point out to its own side of the
    // wall: the path still crosses it.
    let straight = walled_run(false);
    assert!(
        straight < 0.0,
        "the straight start's path cleared the wall ({straight})"
    );
}
