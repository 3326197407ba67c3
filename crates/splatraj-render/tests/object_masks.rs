//! Several objects' masks in one pass ([`Channel::ObjectMasks`]): each pose's image and pose
//! gradient equal those of a pass of its own — its object's mask in the scene
//! ([`Channel::Mask`]), or the object's Gaussians alone (a scene holding only them, mask 1) —
//! pruned or not, on both rasterizers. This is what lets an optimisation step render all its
//! windows, and each object alone, in one call.

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{floor_of_clusters, host, mask_near, pose_tensor};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::focus::Surroundings;
use splatraj_render::render::{
    Channel, DeviceScene, ObjectMasks, ObjectView, Pruning, Rasterizer, RenderError, RenderRequest,
    render,
};

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 80, 60).unwrap()
}

/// Image `[H, W]` and pose gradient `[6]` of each pose of one pass, for the loss
/// Σ w·image with fixed weights per pixel (the same for every pose).
fn per_pose(
    scene: &DeviceScene,
    poses: &[Pose],
    request: &RenderRequest,
    device: &Device,
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let tensor = pose_tensor(poses, device, DType::F64).require_grad();
    let out = render(scene, tensor.clone(), request).unwrap();
    let [b, h, w, c] = out.images.dims();
    assert_eq!(c, 1);
    let weights: Vec<f64> = (0..b * h * w)
        .map(|i| (((i % (h * w)) * 7919) % 13) as f64 / 13.0)
        .collect();
    let weights =
        Tensor::<4>::from_data(TensorData::new(weights, [b, h, w, 1]), (device, DType::F64));
    let grads = (out.images.clone() * weights).sum().backward();
    let images = host(out.images);
    let gradient = host(tensor.grad(&grads).unwrap());
    (0..b)
        .map(|k| {
            (
                images[k * h * w..(k + 1) * h * w].to_vec(),
                gradient[k * 6..(k + 1) * 6].to_vec(),
            )
        })
        .collect()
}

fn close(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1e-12_f64, |m, v| m.max(v.abs()));
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() <= 1e-12 * scale, "{what}: {x} vs {y}");
    }
}

#[test]
fn one_pass_of_several_objects_equals_a_pass_per_pose() {
    let (scene, clusters) = floor_of_clusters();
    let objects = [
        mask_near(&clusters, [1.0, 4.0], 1.5),
        mask_near(&clusters, [-1.0, 3.0], 1.0),
    ];
    let device = Device::flex().autodiff();
    let on_device = DeviceScene::new(&scene, &device, DType::F64);
    let alone: Vec<DeviceScene> = objects
        .iter()
        .map(|mask| {
            let mut part = scene.clone();
            part.retain(&mask.iter().map(|&m| m != 0.0).collect::<Vec<_>>());
            DeviceScene::new(&part, &device, DType::F64)
        })
        .collect();
    let up = DVec3::Z;
    let cameras = [
        Pose::look_at(DVec3::new(0.0, -1.0, 1.5), DVec3::new(0.5, 3.5, 0.2), up).unwrap(),
        // Low and close to the second object: the first one partly behind it.
        Pose::look_at(DVec3::new(-2.0, 1.0, 0.4), DVec3::new(0.0, 3.8, 0.2), up).unwrap(),
    ];
    // (pose, object, surroundings) of each row of the shared pass.
    let rows = [
        (0, 0, Surroundings::Scene),
        (1, 0, Surroundings::Scene),
        (0, 1, Surroundings::Scene),
        (1, 1, Surroundings::Scene),
        (0, 0, Surroundings::Nothing),
        (1, 1, Surroundings::Nothing),
    ];
    let poses: Vec<Pose> = rows.iter().map(|r| cameras[r.0]).collect();
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        for pruning in [Pruning::ObjectOnly, Pruning::None] {
            let what = format!("{rasterizer:?} {pruning:?}");
            let shared = Channel::ObjectMasks(ObjectMasks {
                masks: objects.to_vec().into(),
                views: rows
                    .iter()
                    .map(|&(_, object, surroundings)| ObjectView {
                        object,
                        surroundings,
                    })
                    .collect(),
            });
            let mut request = RenderRequest::new(intrinsics(), vec![shared]);
            request.pruning = pruning;
            request.rasterizer = rasterizer;
            let together = per_pose(&on_device, &poses, &request, &device);
            for (k, &(camera, object, surroundings)) in rows.iter().enumerate() {
                let (scene, mask) = match surroundings {
                    Surroundings::Scene => (&on_device, objects[object].clone()),
                    Surroundings::Nothing => (&alone[object], vec![1.0; alone[object].len()]),
                };
                let mut own = RenderRequest::new(intrinsics(), vec![Channel::Mask(mask)]);
                own.pruning = pruning;
                own.rasterizer = rasterizer;
                let expected = per_pose(scene, &[cameras[camera]], &own, &device);
                let (image, gradient) = &together[k];
                assert!(
                    expected[0].0.iter().any(|&v| v > 0.1),
                    "{what} row {k}: the object is in view"
                );
                close(image, &expected[0].0, &format!("{what} row {k}: image"));
                close(
                    gradient,
                    &expected[0].1,
                    &format!("{what} row {k}: gradient"),
                );
            }
            // The object alone is not the object in the scene: something covers it here.
            assert_ne!(together[0].0, together[4].0, "{what}: an occluder in view");
        }
    }
}

#[test]
fn object_masks_name_one_object_per_pose() {
    let (scene, clusters) = floor_of_clusters();
    let mask = mask_near(&clusters, [1.0, 4.0], 1.5);
    let device = Device::flex();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let camera = Pose::look_at(
        DVec3::new(0.0, -1.0, 1.5),
        DVec3::new(1.0, 4.0, 0.2),
        DVec3::Z,
    )
    .unwrap();
    let view = |object| ObjectView {
        object,
        surroundings: Surroundings::Scene,
    };
    let cases = [
        (vec![view(0)], 2, "1 views for a batch of 2 poses"),
        (vec![view(1)], 1, "names object 1, but there are 1 masks"),
    ];
    for (views, batch, message) in cases {
        let request = RenderRequest::new(
            intrinsics(),
            vec![Channel::ObjectMasks(ObjectMasks {
                masks: vec![mask.clone()].into(),
                views,
            })],
        );
        let poses = pose_tensor(&vec![camera; batch], &device, DType::F32);
        let error = render(&on_device, poses, &request).unwrap_err();
        assert!(
            matches!(error, RenderError::ObjectViews { .. }) && error.to_string().contains(message),
            "{error}"
        );
    }
}
