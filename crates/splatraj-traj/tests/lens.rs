//! The lens over time (`trajectory::lens`): the zoom's bounded map against its closed form,
//! the loss's gradient in the zoom's weights (through the rasterizer's `Zoom`) against central
//! differences, the optimiser moving the zoom to meet TRE, and `trajectory.json`'s `lens`.

mod common;

use burn::tensor::{DType, Device};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::to_host;
use splatraj_render::render::{DeviceScene, Zoom};
use splatraj_scene::Scene;
use splatraj_scene::demo::DEMO_UP;
use splatraj_traj::costs::{CostsConfig, HostPoses, QueryContext, TreCost};
use splatraj_traj::optimise::{
    Flow, ObjectView, Problem, StepPasses, TrajectoryOptions, WindowSamples, WindowTarget,
    object_start_poses, optimise_trajectory, window_start_trajectory,
};
use splatraj_traj::trajectory::{
    Lens, LensPath, Polynomial, Trajectory, TrajectoryModel, TrajectoryRecord, ZoomRange,
};

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 48, 36).unwrap()
}

fn window(scene: &Scene, name: &str, target_ratio: f64) -> WindowTarget {
    common::demo_window(scene, name, &intrinsics(), target_ratio)
}

fn start_pose(w: &WindowTarget) -> Pose {
    object_start_poses(
        &[(w.context.object_centre, w.context.prior_radius)],
        [0.0, 0.0, 0.5],
        DEMO_UP.map(f64::from),
        ObjectView::default(),
        0,
        1,
    )
    .unwrap()[0]
}

#[test]
fn the_zoom_map_is_bounded_smooth_and_one_at_zero() {
    let range = ZoomRange::default();
    range.validate().unwrap();
    assert!(
        (range.zoom(0.0) - 1.0).abs() < 1e-15,
        "u = 0 is the fixed lens"
    );
    // Closed form: s = min·(max/min)^σ(u).
    for u in [-30.0, -2.0, -0.3, 0.7, 4.0, 30.0] {
        let sigma = 1.0 / (1.0 + f64::exp(-u));
        let want = 0.5 * 4f64.powf(sigma);
        let s = range.zoom(u);
        assert!((s - want).abs() < 1e-12, "u = {u}: {s} vs {want}");
        assert!((0.5..=2.0).contains(&s));
        if s > 0.5 + 1e-9 && s < 2.0 - 1e-9 {
            assert!(
                (range.free(s) - u).abs() < 1e-6,
                "free inverts zoom at u = {u}"
            );
        }
    }
    // The tensor map agrees with the host map.
    let device = Device::flex();
    let u = [-3.0, -0.5, 0.0, 0.25, 5.0];
    let t = burn::tensor::Tensor::<1>::from_data(
        burn::tensor::TensorData::new(u.to_vec(), [u.len()]),
        (&device, DType::F64),
    );
    let got = to_host(range.zoom_tensor(t)).unwrap();
    for (g, &u) in got.iter().zip(&u) {
        assert!((g - range.zoom(u)).abs() < 1e-12);
    }
}

#[test]
fn a_bad_zoom_range_names_its_key() {
    for (min, max) in [
        (0.0, 2.0),
        (1.0, 2.0),
        (0.5, 0.9),
        (0.5, f64::NAN),
        (-1.0, 1.5),
    ] {
        let err = ZoomRange { min, max }.validate().unwrap_err().to_string();
        assert!(err.contains("zoom_range"), "{err}");
    }
    let lens = LensPath {
        range: ZoomRange::default(),
        weights: vec![0.0; 2],
    };
    let err = lens.validate(3).unwrap_err().to_string();
    assert!(err.contains("lens.weights"), "{err}");
}

/// d loss / d w_s from the backward pass through the rasterizer's zoom, against central
/// differences of the loss in each zoom weight (f64, TRE and TCE on the demo's blue box).
#[test]
fn the_zoom_weights_gradient_matches_central_differences() {
    let scene = common::demo_room(20_000);
    let windows = vec![window(&scene, "blue box", 0.15)];
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let costs = CostsConfig::default().build().unwrap();
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics());
    let model = TrajectoryModel::Polynomial(Polynomial { terms: 3 });
    let pose = start_pose(&windows[0]);
    let times = [0.1, 0.45, 0.8];
    let loss_at = |lens_weights: &[f64]| -> (f64, Vec<f64>) {
        let trajectory = window_start_trajectory(model.clone(), &[pose], &device, DType::F64)
            .unwrap()
            .with_lens(Some(&LensPath {
                range: ZoomRange::default(),
                weights: lens_weights.to_vec(),
            }))
            .unwrap();
        let poses = trajectory.forward_at(&times);
        let zoom = trajectory.zoom_at(&times).unwrap();
        let host_zoom = trajectory.zooms_at(&times);
        let host = HostPoses {
            samples: trajectory.poses_at(&times),
            path: None,
        };
        let samples = vec![WindowSamples {
            window: 0,
            count: times.len(),
            times: Some(&times),
            path: None,
            host: Some(&host),
            zoom: Some(Zoom::at(zoom, host_zoom)),
        }];
        let evaluated = problem.evaluate_windows(poses, samples, 0, None).unwrap();
        let grads = evaluated.loss.clone().backward();
        let lens = trajectory.lens.as_ref().unwrap().val();
        let gradient = to_host(lens.grad(&grads).unwrap()).unwrap();
        (to_host(evaluated.loss).unwrap()[0], gradient)
    };
    let weights = [0.3, -0.6, 0.4];
    let (loss, gradient) = loss_at(&weights);
    assert!(loss.is_finite());
    assert!(
        gradient.iter().any(|g| g.abs() > 1e-3),
        "the zoom moves the loss: {gradient:?}"
    );
    // The render's host decisions (tiles, culling) are piecewise constant in s, so a step
    // of 1e-4 already crosses one (central differences 7 % off); 1e-6 stays on one piece.
    let h = 1e-6;
    for k in 0..weights.len() {
        let mut plus = weights;
        plus[k] += h;
        let mut minus = weights;
        minus[k] -= h;
        let numeric = (loss_at(&plus).0 - loss_at(&minus).0) / (2.0 * h);
        assert!(
            (numeric - gradient[k]).abs() <= 1e-6 * gradient[k].abs().max(1e-2),
            "weight {k}: backward {} vs central differences {numeric}",
            gradient[k]
        );
    }
}

/// A target ratio four times the start's is met by zooming: with the camera held (a
/// learning rate that moves only the zoom is not there, so the pose's own step is made tiny by
/// a huge position unit), the optimiser zooms in; with the fixed lens it cannot.
#[test]
fn the_optimiser_zooms_to_meet_the_target_ratio() {
    let scene = common::demo_room(20_000);
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let costs = CostsConfig {
        tce: None,
        upright: None,
        prior: None,
        tre: Some(TreCost::default()),
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let base = window(&scene, "blue box", 0.15);
    let pose = start_pose(&base);
    let model = TrajectoryModel::Polynomial(Polynomial { terms: 2 });
    let start = window_start_trajectory(model, &[pose], &Device::flex(), DType::F64)
        .unwrap()
        .record();
    // The start's own coverage at s = 1, measured, then a target of about twice its side.
    let probe = vec![base.clone()];
    let problem = Problem::new(&on_device, &probe, &costs, intrinsics());
    let coverage = problem.loss_at(0, &pose, false).unwrap().coverage.unwrap();
    assert!(
        coverage > 0.01,
        "the box is in view at the start: {coverage}"
    );
    let target = (coverage * 2.5).min(0.6);
    let windows = vec![WindowTarget {
        context: QueryContext {
            target_ratio: target,
            ..base.context
        },
        ..base
    }];
    let problem = Problem::new(&on_device, &windows, &costs, intrinsics());
    let options = TrajectoryOptions {
        iterations: 60,
        learning_rate: 0.05,
        samples_per_window: 2,
        // The camera barely moves: a normalised step is 1e-6 scene units and radians are
        // not in the loss (TRE only reads coverage; rotation is left free).
        position_unit: Some(1e-6),
        ..TrajectoryOptions::default()
    };
    let run = |lens: Lens| {
        let start = TrajectoryRecord {
            lens: lens.start(start.weights.len()),
            ..start.clone()
        };
        optimise_trajectory(&problem, &start, &options, 3, &mut |_| Flow::Continue).unwrap()
    };
    let zoomed = run(Lens::Zoom(ZoomRange::default()));
    let fixed = run(Lens::Fixed);
    assert!(fixed.best.lens.is_none());
    let zooms = zoomed.best.zooms_at(&[0.25, 0.75]);
    assert!(
        zooms.iter().all(|&s| s > 1.2),
        "the optimiser zoomed in: {zooms:?}"
    );
    assert!(
        zoomed.best_total < 0.5 * fixed.best_total,
        "zooming meets TRE better than the held camera with a fixed lens: {} vs {}",
        zoomed.best_total,
        fixed.best_total
    );
}

#[test]
fn trajectory_json_carries_the_lens_and_reads_old_files() {
    let model = TrajectoryModel::Polynomial(Polynomial { terms: 2 });
    let old =
        r#"{"model":{"kind":"polynomial","terms":2},"weights":[[0,0,0,0,0,1],[0,0,0,0,0,0]]}"#;
    let record: TrajectoryRecord = serde_json::from_str(old).unwrap();
    assert_eq!(record.lens, None);
    assert_eq!(record.zooms_at(&[0.0, 1.0]), vec![1.0, 1.0]);
    let with = TrajectoryRecord {
        model,
        weights: record.weights.clone(),
        lens: Some(LensPath {
            range: ZoomRange { min: 0.5, max: 3.0 },
            weights: vec![0.5, 1.0],
        }),
    };
    let text = serde_json::to_string(&with).unwrap();
    let back: TrajectoryRecord = serde_json::from_str(&text).unwrap();
    assert_eq!(back, with);
    back.validate().unwrap();
    // s(1) = min·(max/min)^σ(0.5 + 1.0 + u₀), u₀ = logit(ln 2 / ln 6).
    let sigma0 = 2f64.ln() / 6f64.ln();
    let u0 = (sigma0 / (1.0 - sigma0)).ln();
    let want = 0.5 * 6f64.powf(1.0 / (1.0 + f64::exp(-(1.5 + u0))));
    assert!((ZoomRange { min: 0.5, max: 3.0 }.zoom(0.0) - 1.0).abs() < 1e-12);
    assert!((back.zooms_at(&[1.0])[0] - want).abs() < 1e-12);
    // Through the module and back.
    let module = Trajectory::from_record(&back, &Device::flex(), DType::F64).unwrap();
    assert_eq!(module.record(), with);
    let bad = TrajectoryRecord {
        lens: Some(LensPath {
            range: ZoomRange::default(),
            weights: vec![0.0],
        }),
        ..with
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("lens.weights")
    );
}

/// The zoom in a pass of several windows (one render call, each object alone after the
/// samples: the GPU's `StepPasses::Shared`) is each sample's own: the loss and its gradient in
/// the zoom weights equal those of a call per window (f64).
#[test]
fn the_zoom_of_a_shared_pass_is_each_samples_own() {
    let scene = common::demo_room(20_000);
    let windows = vec![
        window(&scene, "blue box", 0.15),
        window(&scene, "red mug", 0.15),
    ];
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let costs = CostsConfig {
        visibility: Some(splatraj_traj::costs::VisibilityCost::default()),
        ..CostsConfig::default()
    }
    .build()
    .unwrap();
    let model = TrajectoryModel::Polynomial(Polynomial { terms: 3 });
    let starts = [start_pose(&windows[0]), start_pose(&windows[1])];
    let times = [[0.1, 0.3], [0.6, 0.9]];
    let run = |passes: StepPasses| -> (f64, Vec<f64>) {
        let trajectory = window_start_trajectory(model.clone(), &starts, &device, DType::F64)
            .unwrap()
            .with_lens(Some(&LensPath {
                range: ZoomRange::default(),
                weights: vec![0.4, -1.1, 0.9],
            }))
            .unwrap();
        let all: Vec<f64> = times.iter().flatten().copied().collect();
        let poses = trajectory.forward_at(&all);
        let zoom = trajectory.zoom_at(&all).unwrap();
        let host_zoom = trajectory.zooms_at(&all);
        let hosts: Vec<HostPoses> = times
            .iter()
            .map(|t| HostPoses {
                samples: trajectory.poses_at(t),
                path: None,
            })
            .collect();
        let samples = (0..2)
            .map(|i| WindowSamples {
                window: i,
                count: 2,
                times: Some(&times[i]),
                path: None,
                host: Some(&hosts[i]),
                zoom: Some(Zoom::at(
                    zoom.clone().narrow(0, 2 * i, 2),
                    host_zoom[2 * i..2 * i + 2].to_vec(),
                )),
            })
            .collect();
        let problem =
            Problem::new(&on_device, &windows, &costs, intrinsics()).with_step_passes(passes);
        let evaluated = problem.evaluate_windows(poses, samples, 0, None).unwrap();
        let grads = evaluated.loss.clone().backward();
        let lens = trajectory.lens.as_ref().unwrap().val();
        let gradient = to_host(lens.grad(&grads).unwrap()).unwrap();
        (to_host(evaluated.loss).unwrap()[0], gradient)
    };
    let (shared, shared_gradient) = run(StepPasses::Shared);
    let (per_window, per_window_gradient) = run(StepPasses::PerWindow);
    assert!(
        (shared - per_window).abs() <= 1e-9 * per_window.abs().max(1.0),
        "{shared} vs {per_window}"
    );
    assert!(
        per_window_gradient.iter().any(|g| g.abs() > 1e-4),
        "{per_window_gradient:?}"
    );
    for (a, b) in shared_gradient.iter().zip(&per_window_gradient) {
        assert!(
            (a - b).abs() <= 1e-7 * b.abs().max(1e-3),
            "{shared_gradient:?} vs {per_window_gradient:?}"
        );
    }
}
