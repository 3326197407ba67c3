//! The 2D-mask route end to end: label masks rendered from automatically chosen views, lifted
//! back onto the Gaussians, recover each labelled object's Gaussians (IoU ≥ 0.9 against the
//! scene's true labels) on the demo room and on the real fruit_drops capture.

use std::collections::BTreeMap;
use std::path::PathBuf;

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_lift::progress::silent;
use splatraj_lift::{MaskOptions, MaskView, View, ViewOptions, lift_masks, plan_views};
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, render};
use splatraj_scene::demo::{DEMO_UP, DemoConfig, demo_scene};
use splatraj_scene::{ReadOptions, Scene, read_scene};

/// Renders each Gaussian's true label as a one-hot feature and takes, per pixel, the label
/// with the most weight, as a segmenter prompted for the `objects` would hand a mask over:
/// `id + 1` where one of them leads, 0 where another label (floor, table, unlabelled) leads or
/// nothing covers the pixel.
fn label_mask(
    scene: &DeviceScene,
    truth: &[i32],
    objects: &[i32],
    view: &View,
    device: &Device,
) -> Vec<i32> {
    let ids: Vec<i32> = truth
        .iter()
        .copied()
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let dim = ids.len();
    let values: Vec<f32> = truth
        .iter()
        .flat_map(|t| ids.iter().map(move |id| f32::from(u8::from(id == t))))
        .collect();
    let pose = Tensor::<2>::from_data(
        TensorData::new(view.pose.0.to_vec(), [1, 6]),
        (device, DType::F32),
    );
    let request = RenderRequest::new(view.intrinsics, vec![Channel::Features { dim, values }]);
    let out = render(scene, pose, &request).expect("renders");
    let image: Vec<f32> = out
        .images
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap();
    let alpha: Vec<f32> = out
        .alpha
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .unwrap();
    image
        .chunks_exact(dim)
        .zip(&alpha)
        .map(|(px, &a)| {
            if a < 0.5 {
                return 0;
            }
            let (best, _) = px
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(y.1))
                .unwrap();
            if objects.contains(&ids[best]) {
                ids[best] + 1
            } else {
                0
            }
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
            labels: label_mask(&device_scene, &truth, objects, view, &device),
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
