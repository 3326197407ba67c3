//! Every compiled backend (flex by default; ndarray and wgpu with their features) renders the
//! same image as the independent f64 reference renderer, and the same pose gradient as flex in
//! f64 (itself checked against finite differences in tests/rasterizer.rs).

mod common;

use burn::tensor::{DType, Tensor, TensorData};
use common::{host, ref_camera};
use glam::DVec3;
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::{RefChannels, render_reference};
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_scene::Scene;

/// A 5×4 grid of overlapping Gaussians at depth ~3 in front of a camera looking along +z;
/// every third belongs to the object mask.
fn scene() -> (Scene, Vec<f32>) {
    let mut scene = Scene::default();
    let mut mask = Vec::new();
    for i in 0..20 {
        let (gx, gy) = ((i % 5) as f32, (i / 5) as f32);
        scene
            .means
            .push([0.35 * (gx - 2.0), 0.3 * (gy - 1.5), 3.0 + 0.1 * gx]);
        scene.scales.push([0.12 + 0.02 * gy, 0.08, 0.05]);
        let angle = 0.3 * i as f32;
        scene
            .rotations
            .push([(angle / 2.0).cos(), 0.0, 0.0, (angle / 2.0).sin()]);
        scene.opacities.push(0.5 + 0.025 * i as f32);
        scene.sh.extend([0.2 * gx - 0.4, 0.1 * gy, -0.3]);
        mask.push(if i % 3 == 0 { 1.0 } else { 0.0 });
    }
    (scene, mask)
}

fn setup() -> (Scene, Vec<f32>, Intrinsics, Pose) {
    let (scene, mask) = scene();
    let intrinsics = Intrinsics::new(40.0, 40.0, 24.0, 17.0, 48, 34).unwrap();
    let pose = Pose::look_at(
        DVec3::new(0.1, -0.05, 0.0),
        DVec3::new(0.0, 0.0, 3.0),
        DVec3::new(0.0, -1.0, 0.0),
    )
    .unwrap();
    (scene, mask, intrinsics, pose)
}

/// Mask image and d(Σ mask)/dΦ on a backend with a rasterizer.
fn mask_and_gradient(
    backend: BackendKind,
    precision: Precision,
    rasterizer: Rasterizer,
) -> (Vec<f64>, Vec<f64>) {
    let (scene, mask, intrinsics, pose) = setup();
    let device = backend.device().expect("compiled backend").autodiff();
    let dtype = precision.dtype();
    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let poses = Tensor::<2>::from_data(TensorData::new(pose.0.to_vec(), [1, 6]), (&device, dtype))
        .require_grad();
    let mut request = RenderRequest::new(intrinsics, vec![Channel::Mask(mask)]);
    request.pruning = Pruning::ObjectOnly;
    request.rasterizer = rasterizer;
    let out = render(&uploaded, poses.clone(), &request).unwrap();
    let grads = out.images.clone().sum().backward();
    let image = host(out.images);
    let grad = host(poses.grad(&grads).unwrap());
    (image, grad)
}

fn reference_mask() -> Vec<f64> {
    let (scene, mask, k, pose) = setup();
    let camera = ref_camera(&pose, &k);
    render_reference(
        &scene,
        &camera,
        &RefChannels {
            rgb: false,
            depth: false,
            masks: vec![&mask],
        },
    )
    .masks
    .remove(0)
}

#[test]
fn compiled_backends_agree_on_image_and_gradient() {
    let compiled = BackendKind::compiled();
    assert!(
        !compiled.is_empty(),
        "a build without any backend cannot render"
    );
    let reference = reference_mask();
    assert!(reference.iter().any(|&v| v > 0.2), "the object is in view");
    let (_, flex_grad) = mask_and_gradient(BackendKind::Flex, Precision::F64, Rasterizer::Tensor);
    assert!(
        flex_grad.iter().any(|g| g.abs() > 1e-3),
        "a gradient to compare"
    );
    for backend in compiled {
        let precisions: &[Precision] = if backend == BackendKind::Wgpu {
            &[Precision::F32]
        } else {
            &[Precision::F32, Precision::F64]
        };
        for (&precision, rasterizer) in precisions
            .iter()
            .flat_map(|p| [(p, Rasterizer::Fused), (p, Rasterizer::Tensor)])
        {
            let (image, grad) = mask_and_gradient(backend, precision, rasterizer);
            let tolerance = if precision == Precision::F64 {
                1e-9
            } else {
                1e-4
            };
            let image_error = image
                .iter()
                .zip(&reference)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                image_error <= tolerance,
                "{backend} {precision:?} {rasterizer:?}: image differs by {image_error}"
            );
            for (k, (got, want)) in grad.iter().zip(&flex_grad).enumerate() {
                let relative = (got - want).abs() / want.abs().max(1.0);
                assert!(
                    relative <= 1e-3,
                    "{backend} {precision:?} {rasterizer:?}: dΦ[{k}] = {got}, flex f64 tensor says {want}"
                );
            }
        }
    }
}

#[test]
fn missing_backend_names_its_feature() {
    for backend in BackendKind::ALL.into_iter().filter(|b| !b.is_compiled()) {
        let message = backend.device().unwrap_err().to_string();
        assert!(
            message.contains(&format!("--features {}", backend.feature())),
            "{message}"
        );
    }
    assert_eq!("cpu".parse::<BackendKind>(), Ok(BackendKind::Flex));
    assert!(
        "cuda"
            .parse::<BackendKind>()
            .unwrap_err()
            .contains("unknown backend 'cuda'")
    );
}

#[test]
fn f64_is_really_f64() {
    let device = BackendKind::Flex.device().unwrap();
    let x = Tensor::<1>::from_data(
        TensorData::new(vec![1.0f64 + 1e-12], [1]),
        (&device, DType::F64),
    );
    assert_eq!(host(x)[0], 1.0 + 1e-12);
}
