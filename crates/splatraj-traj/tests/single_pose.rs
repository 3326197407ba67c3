//! Single-pose optimisation on the demo scene: from a poor start it reaches TCE < 0.05 and
//! TRE < 0.05 (checked by an independent render), and it stays finite from degenerate starts.

use std::time::Instant;

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::{DMat3, DVec3};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, render};
use splatraj_scene::Scene;
use splatraj_scene::demo::{DEMO_UP, DemoConfig, DemoObject, demo_layout, demo_scene};
use splatraj_traj::costs::{CostsConfig, QueryContext, default_prior_radius, tce, tre};
use splatraj_traj::optimise::{
    Problem, SinglePoseOptions, SinglePoseResult, WindowTarget, optimise_single_pose,
};

const TARGET_RATIO: f64 = 0.15;

/// One window holding `mask` and `context` (a single-pose problem's window).
fn one_window(mask: &[f32], context: &QueryContext) -> [WindowTarget; 1] {
    [WindowTarget {
        name: "object".into(),
        mask: mask.to_vec(),
        context: *context,
    }]
}

/// The 30 000-Gaussian demo scene, the blue box's layout entry and its 0/1 Gaussian mask.
fn setup() -> (Scene, DemoObject, Vec<f32>) {
    let scene = demo_scene(&DemoConfig {
        seed: 7,
        gaussians: 30_000,
    })
    .unwrap();
    let object = demo_layout()
        .into_iter()
        .find(|o| o.name == "blue box")
        .unwrap();
    let labels = scene.extras.labels.as_ref().unwrap();
    let mask: Vec<f32> = labels
        .ids
        .iter()
        .map(|&id| if id == object.id { 1.0 } else { 0.0 })
        .collect();
    assert!(
        mask.iter().sum::<f32>() > 100.0,
        "the blue box has Gaussians"
    );
    (scene, object, mask)
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 64, 48).unwrap()
}

fn centre(object: &DemoObject) -> DVec3 {
    DVec3::from(object.center.map(f64::from))
}

fn up() -> DVec3 {
    DVec3::from(DEMO_UP.map(f64::from))
}

/// The query: object centre, default prior radius for its extent and the camera's fov.
fn context(object: &DemoObject, k: &Intrinsics) -> QueryContext {
    let (tx, ty) = k.tan_half_fov();
    let radius = default_prior_radius(
        object.size.map(f64::from),
        2.0 * tx.atan(),
        2.0 * ty.atan(),
        TARGET_RATIO,
    )
    .unwrap();
    QueryContext {
        object_centre: centre(object).to_array(),
        prior_radius: radius,
        world_up: up().to_array(),
        target_ratio: TARGET_RATIO,
    }
}

fn run(start: Pose, iterations: usize) -> (SinglePoseResult, Scene, DemoObject, Vec<f32>) {
    let (scene, object, mask) = setup();
    let k = intrinsics();
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let costs = CostsConfig::default().build().unwrap();
    let options = SinglePoseOptions {
        iterations,
        ..SinglePoseOptions::default()
    };
    let result = optimise_single_pose(
        &Problem::new(
            &on_device,
            &one_window(&mask, &context(&object, &k)),
            &costs,
            k,
        ),
        start,
        &options,
    )
    .unwrap();
    (result, scene, object, mask)
}

/// TCE and TRE of `pose` from a fresh render on a plain (non-autodiff) device, no pruning.
fn independent_tce_tre(scene: &Scene, mask: &[f32], pose: Pose) -> (f64, f64) {
    let device = Device::flex();
    let on_device = DeviceScene::new(scene, &device, DType::F32);
    let poses = Tensor::<2>::from_data(
        TensorData::new(pose.0.to_vec(), [1, 6]),
        (&device, DType::F32),
    );
    let request = RenderRequest::new(intrinsics(), vec![Channel::Mask(mask.to_vec())]);
    let images = render(&on_device, poses, &request).unwrap().images;
    let [b, h, w, _] = images.dims();
    let m = images.reshape([b, h, w]);
    let scalar = |t: Tensor<1>| t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()[0];
    (scalar(tce(m.clone())), scalar(tre(m, TARGET_RATIO)))
}

fn assert_history_finite(result: &SinglePoseResult) {
    assert_eq!(result.skipped_steps, 0, "a step had a non-finite gradient");
    for row in &result.history {
        assert!(
            row.total.is_finite(),
            "step {}: total {}",
            row.step,
            row.total
        );
        assert!(
            row.terms
                .iter()
                .all(|(_, w, v)| w.is_finite() && v.is_finite()),
            "step {}: {:?}",
            row.step,
            row.terms
        );
        assert!(row.pose.0.iter().all(|v| v.is_finite()), "{:?}", row.pose);
    }
}

/// Rotation about world up by `degrees` (yaw), applied to a camera's axes.
fn yaw(degrees: f64) -> DMat3 {
    DMat3::from_axis_angle(up(), degrees.to_radians())
}

#[test]
fn poor_start_reaches_centred_target_ratio() {
    let (_, object, _) = setup();
    let o = centre(&object);
    // 0.8 m away, in front and a little above, then turned 35° sideways: the 60° horizontal
    // fov leaves the box outside the frame, so only the prior can bring it back.
    let elevation = 20f64.to_radians();
    let eye = o + 0.8 * DVec3::new(0.0, -elevation.cos(), elevation.sin());
    let looking = Pose::look_at(eye, o, up()).unwrap();
    let start = Pose::from_rotation_and_centre(yaw(35.0) * looking.rotation_wc(), eye);

    let started = Instant::now();
    let (result, scene, _, mask) = run(start, 150);
    let seconds = started.elapsed().as_secs_f64();
    assert_history_finite(&result);

    let (start_tce, start_tre) = independent_tce_tre(&scene, &mask, start);
    let (tce, tre) = independent_tce_tre(&scene, &mask, result.pose);
    let term = |row: &splatraj_traj::optimise::HistoryRow, name| {
        row.terms.iter().find(|t| t.0 == name).unwrap().2
    };
    let first_good = result
        .history
        .iter()
        .find(|row| term(row, "tce") < 0.05 && term(row, "tre") < 0.05)
        .map(|row| row.step);
    eprintln!(
        "single pose: start TCE {start_tce:.4} TRE {start_tre:.4} → TCE {tce:.4} TRE {tre:.4} \
         (both < 0.05 from step {first_good:?}; best step {} of {}, {:.1} s, optimiser {:.1} s; \
         terms {:?})",
        result.best_step,
        result.history.len() - 1,
        seconds,
        result.elapsed.as_secs_f64(),
        result.terms
    );
    assert!(tce < 0.05, "TCE {tce}");
    assert!(tre < 0.05, "TRE {tre}");
    // The optimiser's own values at the best pose agree with the independent render.
    let own = |name| result.terms.iter().find(|t| t.0 == name).unwrap().2;
    assert!((own("tce") - tce).abs() < 1e-3, "{} vs {tce}", own("tce"));
    assert!((own("tre") - tre).abs() < 1e-3, "{} vs {tre}", own("tre"));
}

#[test]
fn degenerate_starts_stay_finite() {
    let (_, object, _) = setup();
    let o = centre(&object);
    let front = o + DVec3::new(0.0, -0.8, 0.2);
    let starts = [
        // Inside the object: the camera centre is the object centre.
        ("inside", Pose::from_rotation_and_centre(DMat3::IDENTITY, o)),
        // Looking away from everything: beyond the open front of the room, facing out.
        (
            "away",
            Pose::look_at(DVec3::new(0.0, -2.5, 1.2), DVec3::new(0.0, -4.0, 1.2), up()).unwrap(),
        ),
        // Exactly upside down, looking at the object.
        ("upside down", Pose::look_at(front, o, -up()).unwrap()),
    ];
    for (name, start) in starts {
        let (result, ..) = run(start, 1);
        assert_eq!(result.history.len(), 2, "{name}");
        assert_history_finite(&result);
        assert!(result.pose.0.iter().all(|v| v.is_finite()), "{name}");
    }
}

#[test]
fn bad_options_and_plain_devices_are_errors() {
    use splatraj_traj::optimise::OptimiseError;
    let (scene, object, mask) = setup();
    let k = intrinsics();
    let costs = CostsConfig::default().build().unwrap();
    let start = Pose::look_at(
        centre(&object) + DVec3::new(0.0, -0.8, 0.2),
        centre(&object),
        up(),
    )
    .unwrap();
    let call = |device: &Device, options: &SinglePoseOptions| {
        let on_device = DeviceScene::new(&scene, device, DType::F32);
        optimise_single_pose(
            &Problem::new(
                &on_device,
                &one_window(&mask, &context(&object, &k)),
                &costs,
                k,
            ),
            start,
            options,
        )
    };
    let ad = Device::flex().autodiff();
    let bad = SinglePoseOptions {
        beta2: 1.0,
        ..SinglePoseOptions::default()
    };
    match call(&ad, &bad) {
        Err(OptimiseError::InvalidOptions { field, .. }) => assert_eq!(field, "beta2"),
        other => panic!("{other:?}"),
    }
    match call(&Device::flex(), &SinglePoseOptions::default()) {
        Err(OptimiseError::NotAutodiff) => {}
        other => panic!("{other:?}"),
    }
}
