//! The spatial blocks against the full scan: on a wide scene whose blocks mostly lie outside
//! the view, deciding block by block keeps exactly the Gaussians a per-Gaussian scan keeps, so
//! the tile lists, the images and the pose gradients are the same bits, pruned or not.

mod common;

use std::sync::Arc;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{host, pose_tensor};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::decide::{HostGeometry, decide};
use splatraj_render::project::NEAR_PLANE;
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_scene::Scene;

/// The wide floor of tests/common with the clusters within 1.5 m of (1, 4) as the object.
fn wide_scene() -> (Scene, Vec<f32>) {
    let (scene, clusters) = common::floor_of_clusters();
    (scene, common::mask_near(&clusters, [1.0, 4.0], 1.5))
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 96, 72).unwrap()
}

fn poses() -> [Pose; 2] {
    let object = DVec3::new(1.0, 4.0, 0.2);
    [
        Pose::look_at(DVec3::new(0.0, -1.0, 1.5), object, DVec3::Z).unwrap(),
        // Low and close: blocks straddle the near plane and lie behind the camera.
        Pose::look_at(DVec3::new(1.8, 2.2, 0.3), object, DVec3::Z).unwrap(),
    ]
}

/// Images and pose gradient of a weighted sum of the images, f64 on the autodiff device.
fn images_and_gradient(
    scene: &DeviceScene,
    request: &RenderRequest,
    device: &Device,
) -> (Vec<f64>, Vec<f64>) {
    let poses = pose_tensor(&poses(), device, DType::F64).require_grad();
    let out = render(scene, poses.clone(), request).unwrap();
    let [b, h, w, c] = out.images.dims();
    let weights: Vec<f64> = (0..b * h * w * c)
        .map(|i| ((i * 7919) % 13) as f64 / 13.0)
        .collect();
    let weights =
        Tensor::<4>::from_data(TensorData::new(weights, [b, h, w, c]), (device, DType::F64));
    let grads = (out.images.clone() * weights).sum().backward();
    (host(out.images), host(poses.grad(&grads).unwrap()))
}

#[test]
fn blocks_keep_what_the_full_scan_keeps() {
    let (scene, mask) = wide_scene();
    let n = scene.len();
    let blocked = HostGeometry::new(&scene);
    let scanned = blocked.clone().with_unbounded_blocks();
    let decisions = decide(&blocked, &poses(), &intrinsics(), NEAR_PLANE, None);
    let full = decide(&scanned, &poses(), &intrinsics(), NEAR_PLANE, None);
    assert_eq!(decisions.kept, full.kept);
    for kept in &decisions.kept {
        assert!(!kept.is_empty());
        // Most of the floor is out of view: the block tests have something to skip.
        assert!(kept.len() * 4 < n, "{} of {n} kept", kept.len());
    }

    let device = Device::flex().autodiff();
    let with_blocks = DeviceScene::new(&scene, &device, DType::F64);
    let full_scan = DeviceScene {
        host: Arc::new(scanned),
        ..with_blocks.clone()
    };
    let requests = [
        (
            Pruning::None,
            vec![Channel::Rgb, Channel::Depth, Channel::Mask(mask.clone())],
        ),
        (Pruning::ObjectOnly, vec![Channel::Mask(mask.clone())]),
    ];
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        for (pruning, channels) in &requests {
            let mut request = RenderRequest::new(intrinsics(), channels.clone());
            request.pruning = *pruning;
            request.rasterizer = rasterizer;
            let (image, gradient) = images_and_gradient(&with_blocks, &request, &device);
            let (image_full, gradient_full) = images_and_gradient(&full_scan, &request, &device);
            assert!(
                image.iter().any(|&v| v > 0.1),
                "{pruning:?}: something drawn"
            );
            assert!(gradient.iter().any(|&g| g.abs() > 1e-9));
            assert_eq!(image, image_full, "{rasterizer:?} {pruning:?}: images");
            assert_eq!(
                gradient, gradient_full,
                "{rasterizer:?} {pruning:?}: gradient"
            );
        }
    }
}
