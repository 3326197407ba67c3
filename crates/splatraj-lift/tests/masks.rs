//! The 2D-mask route end to end: label masks rendered from automatically chosen views, lifted
//! back onto the Gaussians, recover each labelled object's Gaussians (IoU ≥ 0.9 against the
//! scene's true labels) on the demo room and on the real fruit_drops capture.

use std::collections::BTreeMap;
use std::path::PathBuf;

use burn::tensor::{DType, Device};
use splatraj_lift::mask_files::render_label_mask;
use splatraj_lift::progress::silent;
use splatraj_lift::{MaskOptions, MaskView, View, ViewOptions, lift_masks, plan_views};
use splatraj_render::render::DeviceScene;
use splatraj_scene::demo::{DEMO_UP, DemoConfig, demo_scene};
use splatraj_scene::{ReadOptions, Scene, read_scene};

/// The mask a segmenter prompted for `objects` would hand over: per pixel the true label with
/// the most weight (the library's [`render_label_mask`]), as `id + 1` where one of `objects`
/// leads, 0 where another label (floor, table, unlabelled) leads or nothing covers the pixel.
fn label_mask(scene: &DeviceScene, truth: &[i32], objects: &[i32], view: &View) -> Vec<i32> {
    render_label_mask(scene, truth, view)
        .expect("renders")
        .into_iter()
        .map(|label| match label {
            Some(id) if objects.contains(&id) => id + 1,
            _ => 0,
        })
        .collect()
}

/// Per label of `objects`: IoU of the lifted Gaussians with the true ones.
fn recover(scene: &Scene, up: [f64; 3], objects: &[i32]) -> BTreeMap<i32, f64> {
    let truth = scene
        .extras
        .labels
        .as_ref()
        .expect("labelled scene")
        .ids
        .clone();
    let device = Device::default().autodiff();
    let device_scene = DeviceScene::new(scene, &device, DType::F32);
    let plan = plan_views(
        scene,
        &device_scene,
        up,
        &ViewOptions::default(),
        512,
        &silent,
    )
    .expect("views planned");
    assert!(plan.views.len() >= 8, "{} views", plan.views.len());
    let masks: Vec<MaskView> = plan
        .views
        .iter()
        .map(|view| MaskView {
            view: *view,
            labels: label_mask(&device_scene, &truth, objects, view),
        })
        .collect();
    let lifted = lift_masks(
        scene,
        &device_scene,
        &masks,
        &MaskOptions::default(),
        &silent,
    )
    .expect("lifts");
    // What the vote rule rests on (masks.rs): the share of its own object that each Gaussian
    // of an object holds, against the largest share of that object held by any other Gaussian.
    for &id in objects {
        let column = lifted
            .labels
            .iter()
            .position(|&l| l == id + 1)
            .expect("object in masks");
        let share = |i: usize| lifted.shares[i * lifted.labels.len() + column];
        let mut own: Vec<f32> = (0..scene.len())
            .filter(|&i| truth[i] == id)
            .map(share)
            .collect();
        let mut other: Vec<f32> = (0..scene.len())
            .filter(|&i| truth[i] != id)
            .map(share)
            .collect();
        own.sort_by(f32::total_cmp);
        other.sort_by(f32::total_cmp);
        let at = |v: &[f32], q: f64| v[((v.len() - 1) as f64 * q) as usize];
        eprintln!(
            "label {id}: own share q10 {:.2} q50 {:.2}; others' share q99.9 {:.2}",
            at(&own, 0.1),
            at(&own, 0.5),
            at(&other, 0.999)
        );
    }
    objects
        .iter()
        .map(|&id| {
            let ours = |i: usize| lifted.ids[i] == id + 1;
            let theirs = |i: usize| truth[i] == id;
            let both = (0..scene.len()).filter(|&i| ours(i) && theirs(i)).count();
            let either = (0..scene.len()).filter(|&i| ours(i) || theirs(i)).count();
            (id, both as f64 / either.max(1) as f64)
        })
        .collect()
}

#[test]
fn demo_room_objects_are_recovered_from_rendered_masks() {
    let scene = demo_scene(&DemoConfig {
        seed: 7,
        gaussians: 30_000,
    })
    .expect("demo scene");
    let objects: Vec<i32> = (3..=10).collect();
    let iou = recover(&scene, DEMO_UP.map(f64::from), &objects);
    println!("demo IoU per label: {iou:?}");
    for (id, v) in &iou {
        assert!(*v >= 0.9, "label {id}: IoU {v:.3} < 0.9 ({iou:?})");
    }
}

#[test]
fn fruit_drops_objects_are_recovered_from_rendered_masks() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../splatraj-scene/tests/data");
    let scene = read_scene(
        &dir.join("fruit_drops_minimal.ply"),
        &ReadOptions {
            labels: Some(dir.join("fruit_drops_minimal.json")),
            ..Default::default()
        },
    )
    .expect("fixture reads")
    .scene;
    let up = splatraj_scene::up_axis::resolve_up(None, false, &scene).up;
    let objects: Vec<i32> = (1..=8).collect();
    let iou = recover(&scene, up, &objects);
    println!("fruit_drops IoU per label: {iou:?}");
    for (id, v) in &iou {
        assert!(*v >= 0.9, "label {id}: IoU {v:.3} < 0.9 ({iou:?})");
    }
}

#[test]
fn no_masks_is_an_error_not_a_panic() {
    let scene = demo_scene(&DemoConfig {
        seed: 7,
        gaussians: 1_000,
    })
    .unwrap();
    let device_scene = DeviceScene::new(&scene, &Device::default().autodiff(), DType::F32);
    let error = lift_masks(&scene, &device_scene, &[], &MaskOptions::default(), &silent);
    assert!(error.unwrap_err().to_string().contains("no masks"));
}
