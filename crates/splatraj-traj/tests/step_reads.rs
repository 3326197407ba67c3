//! What an optimisation step moves between host and device, counted (`splatraj_render::counters`):
//! each step reads back once (its poses, with the previous step's loss terms, gradient check and
//! weights), whatever the windows and costs (renders, the object alone, the clearance cost's
//! lookup on the host, path costs), and the scene is not uploaded again; and a step whose
//! gradient is not finite is still undone (read one step late).
//!
//! Its own test binary: the counters are process-wide, so nothing else may run beside the
//! counted work (the tests here take one lock).

mod common;

use std::sync::Mutex;

use burn::tensor::{DType, Device, Tensor};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::counters::{self, Counts};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_scene::demo::DEMO_UP;
use splatraj_traj::clearance::{Occupancy, OccupancySpec};
use splatraj_traj::costs::{
    ClearanceCost, Cost, CostError, CostInputs, CostsConfig, DEFAULT_CLEARANCE_SIGMA,
    DEFAULT_MIN_OPACITY, HostPoses, MotionCost, OrAuto, VisibilityCost, WeightedCosts,
};
use splatraj_traj::optimise::{
    Flow, ObjectView, Problem, StepPasses, TrajectoryOptions, WindowPath, WindowSamples,
    WindowTarget, object_start_poses, optimise_trajectory, window_start_trajectory,
};
use splatraj_traj::trajectory::{Polynomial, Rbf, Trajectory, TrajectoryModel};

static COUNTED: Mutex<()> = Mutex::new(());

fn scene() -> Scene {
    common::demo_room(20_000)
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 48, 36).unwrap()
}

fn windows(scene: &Scene, names: &[&str]) -> Vec<WindowTarget> {
    names
        .iter()
        .map(|name| common::demo_window(scene, name, &intrinsics(), 0.15))
        .collect()
}

/// The clearance cost's occupancy of `scene` at the default settings.
fn occupancy(scene: &Scene) -> Occupancy {
    Occupancy::new(
        scene,
        OccupancySpec {
            sigma: DEFAULT_CLEARANCE_SIGMA,
            min_opacity: DEFAULT_MIN_OPACITY,
        },
    )
}

/// The reference a shared step must equal: each window evaluated on its own (`rows(i)`: its
/// samples' poses and its path), the loss the mean over windows of each window's mean total.
/// Returns the loss, every window's term means (window after window) and d loss/d `poses`.
fn one_window_at_a_time(
    problem: &Problem,
    poses: &Tensor<2>,
    hosts: &[HostPoses],
    rows: impl Fn(usize) -> (Tensor<2>, Option<(Tensor<2>, f64)>),
) -> (f64, Vec<f64>, Vec<f64>) {
    let mut loss: Option<Tensor<1>> = None;
    let mut means = Vec::new();
    for (i, host) in hosts.iter().enumerate() {
        let (own, path) = rows(i);
        let terms = problem
            .evaluate_along(i, own, None, path, Some(host), 0, None)
            .unwrap()
            .terms;
        means.extend(terms.means().into_iter().map(|(_, _, m)| m));
        let mean = terms.total.mean().div_scalar(hosts.len() as f64);
        loss = Some(match loss {
            Some(l) => l + mean,
            None => mean,
        });
    }
    let loss = loss.expect("at least one window");
    let gradient = to_host(poses.grad(&loss.clone().backward()).unwrap()).unwrap();
    (to_host(loss).unwrap()[0], means, gradient)
}

/// Each window's start pose (its object seen from the scene's side, restart `restart`).
fn start_poses(windows: &[WindowTarget], restart: usize) -> Vec<Pose> {
    let objects: Vec<([f64; 3], f64)> = windows
        .iter()
        .map(|w| (w.context.object_centre, w.context.prior_radius))
        .collect();
    object_start_poses(
        &objects,
        [0.0, 0.0, 0.5],
        DEMO_UP.map(f64::from),
        ObjectView::default(),
        restart,
        1,
    )
    .unwrap()
}

#[test]
fn a_step_reads_once_and_the_scene_is_uploaded_once() {
    let (shared, shared_counts) = counted_steps(StepPasses::Shared);
    let (per_window, per_window_counts) = counted_steps(StepPasses::PerWindow);
    // The same compositing work either way: one call composites the tile–Gaussian pairs the
    // windows' calls do, and projects their rows (each pose its own Gaussians), no more.
    assert!(shared_counts.pairs > 0, "{shared_counts:?}");
    assert_eq!(
        shared_counts.pairs, per_window_counts.pairs,
        "{shared_counts:?} vs {per_window_counts:?}"
    );
    assert_eq!(
        shared_counts.rows, per_window_counts.rows,
        "{shared_counts:?} vs {per_window_counts:?}"
    );
    // The same images and costs either way (the shared pass evaluates the batching costs once
    // on every window's samples), so the same optimisation, term by term (to f32 rounding).
    assert_eq!(shared.len(), per_window.len());
    for (a, b) in shared.iter().zip(&per_window) {
        assert!(
            (a - b).abs() <= 1e-5 * b.abs().max(1.0),
            "{shared:?} vs {per_window:?}"
        );
    }
}

/// Five steps of two windows with every kind of cost, counted; the sampled loss of each step
/// and the counts.
fn counted_steps(passes: StepPasses) -> (Vec<f64>, Counts) {
    let _counted = COUNTED.lock().unwrap();
    let scene = scene();
    let windows = windows(&scene, &["blue box", "red mug"]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let occupancy = occupancy(&scene);
    // Every kind of cost: image costs, the object alone, a path cost with a host lookup, motion.
    let costs = CostsConfig {
        clearance: Some(ClearanceCost {
            margin: OrAuto::Value(0.1),
            ..ClearanceCost::default()
        }),
        visibility: Some(VisibilityCost::default()),
        motion: Some(MotionCost::default()),
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let per_window = start_poses(&windows, 0);
    let model = TrajectoryModel::Rbf(Rbf::new(windows.len(), 3, None));
    let start = window_start_trajectory(model, &per_window, &device, DType::F32)
        .unwrap()
        .record();
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics())
        .with_occupancy(Some(&occupancy))
        .with_step_passes(passes);
    let iterations = 5;
    let options = TrajectoryOptions {
        iterations,
        samples_per_window: 3,
        ..TrajectoryOptions::default()
    };
    let before = counters::snapshot();
    let result = optimise_trajectory(&problem, &start, &options, 1, &mut |_| Flow::Continue)
        .expect("the optimisation runs");
    let counts = counters::snapshot().since(&before);
    assert_eq!(result.history.len(), iterations);
    assert!(result.history.iter().all(|row| row.total.is_finite()));
    assert_eq!(
        counts.reads,
        iterations as u64 + 1,
        "one read per step and one for the last step's results: {counts:?}"
    );
    // What a read holds: poses, term means, a flag and the weights; never an image (one 48×36
    // mask is 6912 bytes).
    let per_read = counts.bytes_down / counts.reads;
    assert!(per_read < 4096, "{per_read} bytes per read: {counts:?}");
    assert_eq!(
        counts.scene_uploads, 0,
        "the scene is uploaded once, before"
    );
    // Both windows and both objects alone share one render pass a step, or each window
    // (with its object alone) has one.
    let per_step = match passes {
        StepPasses::Shared => 1,
        StepPasses::PerWindow => windows.len() as u64,
    };
    assert_eq!(
        counts.renders,
        per_step * iterations as u64,
        "{passes:?}: render passes: {counts:?}"
    );
    assert!(
        counts.uploads > 0,
        "poses, indices and mask values go up each pass"
    );
    // Each step's loss, then each window's weighted terms in order.
    let losses = result
        .history
        .iter()
        .flat_map(|row| {
            let terms = row.windows.iter().flatten().map(|&(_, w, mean)| w * mean);
            std::iter::once(row.total).chain(terms)
        })
        .collect();
    (losses, counts)
}

/// A cost that is 0 and whose gradient is NaN from step 2 on (√u at u = 0, u ≡ 0).
#[derive(Debug)]
struct NanGradientFrom2;

impl Cost for NanGradientFrom2 {
    fn name(&self) -> &'static str {
        "nan_gradient"
    }
    fn weight(&self, _step: usize) -> f64 {
        1.0
    }
    fn validate(&self) -> Result<(), CostError> {
        Ok(())
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let poses = inputs.poses().clone();
        let [batch, _] = poses.dims();
        let zero = (poses.clone() - poses).sum_dim(1).reshape([batch]); // [B], ≡ 0
        Ok(if inputs.step() >= 2 {
            zero.sqrt()
        } else {
            zero
        })
    }
}

/// The moments' pixel centres go up once per image size and device, not every pass (on a GPU
/// each upload is a transfer a pass waits behind): a second mask of the same size uploads
/// nothing, one of another height its rows' centres. Sizes no other test here renders.
#[test]
fn the_moments_pixel_centres_go_up_once_per_size() {
    use splatraj_traj::costs::MaskMoments;

    let _counted = COUNTED.lock().unwrap();
    let device = Device::flex();
    let mask =
        |height: usize, width: usize| Tensor::<3>::ones([2, height, width], (&device, DType::F32));
    let uploads_of = |mask: Tensor<3>| {
        let before = counters::snapshot();
        let moments = MaskMoments::of(mask);
        to_host(moments.mass()).unwrap();
        counters::snapshot().since(&before).uploads
    };
    // One constant per image axis (the columns' centres, the rows').
    assert_eq!(uploads_of(mask(29, 37)), 2, "a new size: both axes");
    assert_eq!(uploads_of(mask(29, 37)), 0, "the same size again");
    assert_eq!(uploads_of(mask(31, 37)), 1, "another height: its rows only");
    assert_eq!(uploads_of(mask(31, 37)), 0);
}

#[test]
fn a_step_with_a_non_finite_gradient_is_undone() {
    let _counted = COUNTED.lock().unwrap();
    let scene = scene();
    let windows = windows(&scene, &["red mug"]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    // A constant trajectory (one polynomial term): the loss does not depend on the sampled
    // times, so steps taken at the same weights have the same loss, bit for bit.
    let centre = windows[0].context.object_centre;
    let eye = glam::DVec3::from(centre) + glam::DVec3::new(0.0, -1.2, 0.4);
    let pose = splatraj_render::camera::Pose::look_at(
        eye,
        glam::DVec3::from(centre),
        glam::DVec3::from(DEMO_UP.map(f64::from)),
    )
    .unwrap();
    let model = TrajectoryModel::Polynomial(Polynomial { terms: 1 });
    let mut start = Trajectory::zeros(model, &device, DType::F32)
        .unwrap()
        .record();
    start.weights = vec![pose.0];
    let options = TrajectoryOptions {
        iterations: 5,
        samples_per_window: 2,
        ..TrajectoryOptions::default()
    };
    let run = |nan: bool| {
        // No prior: its weight decays with the step, and the loss must depend on the weights
        // alone.
        let mut costs: WeightedCosts = CostsConfig {
            prior: None,
            ..CostsConfig::default()
        }
        .build()
        .unwrap();
        if nan {
            costs = costs.with_cost(Box::new(NanGradientFrom2)).unwrap();
        }
        let problem = Problem::new(&on_device, &windows, &costs, intrinsics());
        optimise_trajectory(&problem, &start, &options, 3, &mut |_| Flow::Continue).unwrap()
    };
    let plain = run(false);
    let nan = run(true);
    let totals = |r: &splatraj_traj::optimise::TrajectoryResult| -> Vec<f64> {
        r.history.iter().map(|row| row.total).collect()
    };
    let (plain_totals, nan_totals) = (totals(&plain), totals(&nan));
    assert_eq!(nan.skipped_steps, 3, "steps 2, 3 and 4 are skipped");
    let updated: Vec<bool> = nan.history.iter().map(|row| row.updated).collect();
    assert_eq!(updated, [true, true, false, false, false]);
    // Steps 0–2 are evaluated at the same weights in both runs; after the skipped step 2 the
    // weights stay those of step 2, so steps 3 and 4 repeat its loss exactly.
    assert_eq!(nan_totals[..3], plain_totals[..3]);
    assert_eq!(nan_totals[3], nan_totals[2]);
    assert_eq!(nan_totals[4], nan_totals[2]);
    assert_ne!(
        plain_totals[3], plain_totals[2],
        "without the skip the weights move"
    );
}

/// The single-pose loop (`pose`, Table I) reads twice a step (the poses, then the totals, terms
/// and gradient together) and once for its last evaluation's poses and terms; SGLD, whose
/// chains live on the host, reads once a step. Neither reads an image.
#[test]
fn pose_loops_read_twice_and_once_a_step() {
    use splatraj_render::camera::Pose;
    use splatraj_traj::optimise::{
        SgldOptions, SinglePoseOptions, optimise_poses, sample_poses_sgld,
    };

    let _counted = COUNTED.lock().unwrap();
    let scene = scene();
    let windows = windows(&scene, &["blue box"]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let costs = CostsConfig::default().build().unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics());
    // Two starts: the object's view from two restarts.
    let starts: Vec<Pose> = (0..2)
        .map(|restart| start_poses(&windows[..1], restart).remove(0))
        .collect();
    assert_eq!(starts.len(), 2);

    let options = SinglePoseOptions {
        iterations: 4,
        ..SinglePoseOptions::default()
    };
    let before = counters::snapshot();
    let results = optimise_poses(&problem, &starts, &options).expect("the poses optimise");
    let counts = counters::snapshot().since(&before);
    assert!(
        results
            .iter()
            .all(|r| r.history.len() == 5 && r.total.is_finite())
    );
    assert_eq!(counts.reads, 2 * 4 + 2, "{counts:?}");
    assert!(counts.bytes_down / counts.reads < 1024, "{counts:?}");

    let options = SgldOptions {
        iterations: 6,
        burn_in: 2,
        thin: 2,
        ..SgldOptions::default()
    };
    let before = counters::snapshot();
    let units = SinglePoseOptions::default().units();
    let result = sample_poses_sgld(&problem, &starts, units, &options, 7).expect("the chains run");
    let counts = counters::snapshot().since(&before);
    assert_eq!(result.samples.len(), 2 * 2);
    assert_eq!(counts.reads, 6, "{counts:?}");
}

/// Several windows evaluated together (the costs that batch run once on every sample with its
/// own window's context; one render call or one per window) give each window's terms, the
/// loss and its pose gradient of one window evaluated at a time (f64).
#[test]
fn windows_together_equal_windows_one_at_a_time() {
    let _counted = COUNTED.lock().unwrap();
    let scene = scene();
    let windows = windows(&scene, &["blue box", "red mug", "plant"]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let costs = CostsConfig {
        visibility: Some(VisibilityCost::default()),
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let starts = start_poses(&windows, 0);
    // Three samples a window, spread around each window's start; windows of 3, 2 and 3.
    let counts = [3, 2, 3];
    let rows: Vec<Vec<Pose>> = starts
        .iter()
        .zip(counts)
        .map(|(start, count)| {
            (0..count)
                .map(|k| {
                    let mut p = start.0;
                    p[3] += 0.07 * k as f64;
                    p[1] += 0.05 * k as f64;
                    Pose(p)
                })
                .collect()
        })
        .collect();
    let hosts = common::host_samples(&rows);
    let all: Vec<Pose> = rows.iter().flatten().copied().collect();

    // One window at a time: the mean over windows of each window's mean total.
    let poses = on_device.poses(&all).require_grad();
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics());
    let firsts: Vec<usize> = counts
        .iter()
        .scan(0, |at, &c| {
            *at += c;
            Some(*at - c)
        })
        .collect();
    let (loss, means, gradient) = one_window_at_a_time(&problem, &poses, &hosts, |i| {
        (poses.clone().narrow(0, firsts[i], counts[i]), None)
    });
    assert!(gradient.iter().any(|g| g.abs() > 1e-6));

    for passes in [StepPasses::Shared, StepPasses::PerWindow] {
        let poses = on_device.poses(&all).require_grad();
        let samples = counts
            .iter()
            .enumerate()
            .map(|(i, &count)| WindowSamples {
                window: i,
                count,
                times: None,
                path: None,
                host: Some(&hosts[i]),
                zoom: None,
            })
            .collect();
        let together = problem
            .with_step_passes(passes)
            .evaluate_windows(poses.clone(), samples, 0, None)
            .unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        let got = to_host(together.means).unwrap();
        assert_eq!(got.len(), means.len());
        for (k, (a, b)) in got.iter().zip(&means).enumerate() {
            assert!(close(*a, *b), "{passes:?}: mean {k}: {a} vs {b}");
        }
        let names: Vec<Vec<&str>> = together
            .labels
            .iter()
            .map(|w| w.iter().map(|l| l.0).collect())
            .collect();
        assert!(names.iter().all(|w| *w == costs.names()), "{names:?}");
        let v = to_host(poses.grad(&together.loss.clone().backward()).unwrap()).unwrap();
        let together_loss = to_host(together.loss).unwrap()[0];
        assert!(
            close(together_loss, loss),
            "{passes:?}: {together_loss} vs {loss}"
        );
        // The reference's gradient is uniformly 3e-8 (relative) larger than this one, what 1/3
        // rounded to f32 (0.33333334) would give in its division by the window count.
        for (a, b) in v.iter().zip(&gradient) {
            assert!(
                (a - b).abs() <= 1e-7 * b.abs().max(1e-3),
                "{passes:?}: gradient {v:?} vs {gradient:?}"
            );
        }
    }
}

/// The path costs (motion with every limit and even speed, clearance) evaluated once on every
/// window's stretch of path joined give each window's terms, the loss and its pose gradient
/// of one window evaluated at a time (f64): no term pairs one window's path with the next's.
/// Stretches of different lengths and time steps, so each row needs its own window's.
#[test]
fn path_costs_together_equal_windows_one_at_a_time() {
    let _counted = COUNTED.lock().unwrap();
    let scene = scene();
    let windows = windows(&scene, &["blue box", "red mug", "plant"]);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let occupancy = occupancy(&scene);
    // Limits low enough that every term charges something.
    let costs = CostsConfig {
        clearance: Some(ClearanceCost {
            margin: OrAuto::Value(0.4),
            ..ClearanceCost::default()
        }),
        motion: Some(MotionCost {
            weight: 1.0,
            max_speed: Some(0.05.into()),
            max_acceleration: Some(0.01),
            max_angular_speed: Some(0.5),
            max_orbit_speed: Some(0.5),
            even_speed: 0.5,
        }),
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let starts = start_poses(&windows, 0);
    // Per window: samples, path poses, the path's time step.
    let shape = [(3, 7, 0.01), (2, 5, 0.02), (3, 9, 0.0125)];
    let mut rng = 0x5EED_u64;
    let mut jitter = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % 1000) as f64 / 1000.0 - 0.5
    };
    let mut hosts = Vec::new();
    for (start, &(samples, path, _)) in starts.iter().zip(&shape) {
        let mut along = |count: usize, step: f64| -> Vec<[f64; 6]> {
            (0..count)
                .map(|k| {
                    let mut p = start.0;
                    p[3] += step * k as f64 + 0.02 * jitter();
                    p[4] += 0.5 * step * k as f64 + 0.02 * jitter();
                    p[2] += 0.3 * step * k as f64 + 0.02 * jitter();
                    p
                })
                .collect()
        };
        hosts.push(HostPoses {
            samples: along(samples, 0.07),
            path: Some(along(path, 0.03)),
        });
    }
    // Every sample, then every path, as a step holds them.
    let rows: Vec<Pose> = hosts
        .iter()
        .flat_map(|h| h.samples.iter())
        .chain(hosts.iter().flat_map(|h| h.path.iter().flatten()))
        .map(|&p| Pose(p))
        .collect();
    let sample_rows: usize = shape.iter().map(|s| s.0).sum();
    // (first sample row, first path row) per window.
    let firsts: Vec<(usize, usize)> = shape
        .iter()
        .scan((0, sample_rows), |at, &(s, p, _)| {
            let first = *at;
            *at = (at.0 + s, at.1 + p);
            Some(first)
        })
        .collect();
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics())
        .with_occupancy(Some(&occupancy))
        .with_seconds(Some(10.0));

    // One window at a time: the mean over windows of each window's mean total.
    let poses = on_device.poses(&rows).require_grad();
    let (loss, means, gradient) = one_window_at_a_time(&problem, &poses, &hosts, |i| {
        let ((samples, path, time_step), (s0, p0)) = (shape[i], firsts[i]);
        (
            poses.clone().narrow(0, s0, samples),
            Some((poses.clone().narrow(0, p0, path), time_step)),
        )
    });
    let names = costs.names();
    let term = |name: &str, window: usize| {
        means[window * names.len() + names.iter().position(|n| *n == name).unwrap()]
    };
    for window in 0..windows.len() {
        assert!(
            term("motion", window) > 0.0,
            "motion charges window {window}"
        );
    }
    assert!(
        (0..windows.len()).any(|w| term("clearance", w) > 0.0),
        "clearance charges some window: {means:?}"
    );

    // The samples alone (the joined path cut out of the windows' paths and joined again), and
    // the samples then the paths as the optimiser passes them (the joined path one slice).
    let poses = on_device.poses(&rows).require_grad();
    for given in [poses.clone().narrow(0, 0, sample_rows), poses.clone()] {
        let samples = shape
            .iter()
            .zip(&firsts)
            .enumerate()
            .map(|(i, (&(count, path, time_step), &(_, p0)))| WindowSamples {
                window: i,
                count,
                times: None,
                path: Some(WindowPath::Poses(
                    Box::new(poses.clone().narrow(0, p0, path)),
                    time_step,
                )),
                host: Some(&hosts[i]),
                zoom: None,
            })
            .collect();
        let together = problem
            .with_step_passes(StepPasses::Shared)
            .evaluate_windows(given, samples, 0, None)
            .unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-10 * b.abs().max(1.0);
        let got = to_host(together.means).unwrap();
        assert_eq!(got.len(), means.len());
        for (k, (a, b)) in got.iter().zip(&means).enumerate() {
            assert!(
                close(*a, *b),
                "mean {k} ({}): {a} vs {b}",
                names[k % names.len()]
            );
        }
        let labels: Vec<Vec<&str>> = together
            .labels
            .iter()
            .map(|w| w.iter().map(|l| l.0).collect())
            .collect();
        assert!(labels.iter().all(|w| *w == names), "{labels:?}");
        let v = to_host(poses.grad(&together.loss.clone().backward()).unwrap()).unwrap();
        let together_loss = to_host(together.loss).unwrap()[0];
        assert!(close(together_loss, loss), "{together_loss} vs {loss}");
        let largest = gradient.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (k, (a, b)) in v.iter().zip(&gradient).enumerate() {
            assert!(
                (a - b).abs() <= 1e-10 * largest,
                "gradient {k} (pose {}): {a} vs {b}",
                k / 6
            );
        }
    }
}
