//! Both rasterizers (fused and tensor) against the independent f64 reference renderer, their
//! pruning and the tensor path's chunking against the plain render (exactness), and their pose
//! gradients against finite differences.

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{Rng, host, pose_tensor, ref_camera};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::rasterize::CompositeOptions;
use splatraj_render::reference::{RefChannels, render_reference};
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_scene::Scene;

/// A scene in front of a camera at the origin looking along +y (z up): random anisotropic
/// Gaussians, some far off to the side (cut by the image border), and a stack of opaque ones
/// at the centre so that pixels terminate early. SH degree 1.
fn test_scene(seed: u64) -> (Scene, Vec<f32>) {
    let mut rng = Rng(seed);
    let mut scene = Scene {
        sh_degree: 1,
        ..Default::default()
    };
    let mut mask = Vec::new();
    let push = |scene: &mut Scene,
                mean: [f64; 3],
                scale: [f64; 3],
                rotation: [f64; 4],
                opacity: f64,
                rng: &mut Rng| {
        scene.means.push(mean.map(|v| v as f32));
        scene.scales.push(scale.map(|v| v as f32));
        let norm = rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
        scene.rotations.push(rotation.map(|v| (v / norm) as f32));
        scene.opacities.push(opacity as f32);
        for _ in 0..12 {
            scene.sh.push(rng.range(-1.0, 1.0) as f32);
        }
    };
    for i in 0..60 {
        let mean = [
            rng.range(-1.6, 1.6),
            rng.range(2.0, 6.0),
            rng.range(-1.0, 1.0),
        ];
        let scale = [
            rng.range(0.02, 0.3),
            rng.range(0.02, 0.3),
            rng.range(0.005, 0.1),
        ];
        let rotation = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        let opacity = rng.range(0.2, 1.0);
        push(&mut scene, mean, scale, rotation, opacity, &mut rng);
        mask.push(if i % 3 == 0 { 1.0 } else { 0.0 });
    }
    for k in 0..6 {
        // Opaque stack on the optical axis: o = 1 gives α = 0.99, so T hits 1e-4 after two.
        let mean = [0.05 * k as f64, 3.0 + 0.2 * k as f64, 0.02 * k as f64];
        push(
            &mut scene,
            mean,
            [0.3, 0.05, 0.3],
            [1.0, 0.0, 0.0, 0.0],
            1.0,
            &mut rng,
        );
        mask.push(if k == 4 { 1.0 } else { 0.0 });
    }
    (scene, mask)
}

fn intrinsics() -> Intrinsics {
    // Non-square, partial tiles on both axes, off-centre principal point.
    Intrinsics::new(30.0, 32.0, 21.0, 13.5, 40, 28).unwrap()
}

fn pose() -> Pose {
    Pose::look_at(
        DVec3::new(0.1, -0.2, 0.15),
        DVec3::new(0.0, 4.0, 0.0),
        DVec3::Z,
    )
    .unwrap()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// Both rasterizers.
const RASTERIZERS: [Rasterizer; 2] = [Rasterizer::Fused, Rasterizer::Tensor];

/// The same scene through a long lens (10× the focal length, 168×100): slanted splats tens of
/// pixels long over many tiles, where the binning keeps only the tiles their α ≥ 1/255 ellipse
/// meets (`alpha_reach`); the reference bins by the whole 3σ square.
fn close_up() -> Intrinsics {
    Intrinsics::new(300.0, 320.0, 86.0, 47.5, 168, 100).unwrap()
}

/// Render of [RGB, depth, mask] against the reference, pixel by pixel.
fn compare_with_reference(dtype: DType, tolerance: f64, k: Intrinsics) {
    for rasterizer in RASTERIZERS {
        compare_with_reference_on(dtype, tolerance, rasterizer, k);
    }
}

fn compare_with_reference_on(dtype: DType, tolerance: f64, rasterizer: Rasterizer, k: Intrinsics) {
    let (scene, mask) = test_scene(7);
    let device = Device::flex();
    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let mut request = RenderRequest::new(
        k,
        vec![Channel::Rgb, Channel::Depth, Channel::Mask(mask.clone())],
    );
    request.rasterizer = rasterizer;
    let out = render(&uploaded, pose_tensor(&[pose()], &device, dtype), &request).unwrap();
    let got = host(out.images.clone()); // [1, H, W, 5]
    let reference = render_reference(
        &scene,
        &ref_camera(&pose(), &k),
        &RefChannels {
            rgb: true,
            depth: true,
            masks: vec![&mask],
        },
    );
    let mut want = Vec::new();
    for p in 0..k.width * k.height {
        want.extend(reference.rgb.as_ref().unwrap()[p]);
        want.push(reference.depth.as_ref().unwrap()[p]);
        want.push(reference.masks[0][p]);
    }
    let error = max_diff(&got, &want);
    assert!(
        error <= tolerance,
        "{dtype:?} {rasterizer:?}: max abs difference {error}"
    );
    let alpha: Vec<f64> = host(out.alpha().unwrap());
    assert!(max_diff(&alpha, &reference.alpha) <= tolerance);
    // The scene must exercise early termination: some pixel saturated near 1 − 1e-4.
    assert!(
        reference.alpha.iter().any(|&a| a > 0.9998),
        "no pixel terminated early"
    );
}

#[test]
fn a_close_up_matches_reference_in_f64() {
    compare_with_reference(DType::F64, 1e-5, close_up());
}

#[test]
fn matches_reference_in_f64() {
    compare_with_reference(DType::F64, 1e-5, intrinsics());
}

#[test]
fn matches_reference_in_f32() {
    compare_with_reference(DType::F32, 1e-4, intrinsics());
}

/// Mask image and pose gradient of Σ w ⊙ mask for a batch of poses.
fn mask_and_gradient(
    pruning: Pruning,
    composite: CompositeOptions,
    rasterizer: Rasterizer,
) -> (Vec<f64>, Vec<f64>) {
    let (scene, mask) = test_scene(11);
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(&scene, &device, DType::F64);
    let poses = [
        pose(),
        Pose::look_at(
            DVec3::new(-0.4, 0.3, 0.4),
            DVec3::new(0.2, 4.0, -0.1),
            DVec3::Z,
        )
        .unwrap(),
    ];
    let poses = pose_tensor(&poses, &device, DType::F64).require_grad();
    let mut request = RenderRequest::new(intrinsics(), vec![Channel::Mask(mask)]);
    request.pruning = pruning;
    request.composite = composite;
    request.rasterizer = rasterizer;
    let out = render(&uploaded, poses.clone(), &request).unwrap();
    let [b, h, w, _] = out.images.dims();
    let weights: Vec<f64> = (0..b * h * w)
        .map(|i| ((i * 7919) % 13) as f64 / 13.0)
        .collect();
    let weights = Tensor::<4>::from_data(
        TensorData::new(weights, [b, h, w, 1]),
        (&device, DType::F64),
    );
    let grads = (out.images.clone() * weights).sum().backward();
    let grad = host(poses.grad(&grads).unwrap());
    (host(out.images.clone()), grad)
}

#[test]
fn pruning_and_chunking_are_exact() {
    let (plain, plain_grad) = mask_and_gradient(
        Pruning::None,
        CompositeOptions::default(),
        Rasterizer::Tensor,
    );
    assert!(plain.iter().any(|&v| v > 0.1), "the object is in view");
    assert!(
        plain_grad.iter().any(|&g| g.abs() > 1e-6),
        "the gradient is not trivially zero"
    );
    let fused = CompositeOptions::default();
    for (pruning, options, rasterizer) in [
        (Pruning::None, fused, Rasterizer::Fused),
        (Pruning::ObjectOnly, fused, Rasterizer::Fused),
        (
            Pruning::ObjectOnly,
            CompositeOptions::default(),
            Rasterizer::Tensor,
        ),
        (
            Pruning::None,
            CompositeOptions {
                chunk: 3,
                tile_group: 2,
                ..Default::default()
            },
            Rasterizer::Tensor,
        ),
        (
            Pruning::ObjectOnly,
            CompositeOptions {
                chunk: 1,
                tile_group: 1,
                ..Default::default()
            },
            Rasterizer::Tensor,
        ),
    ] {
        let (image, grad) = mask_and_gradient(pruning, options, rasterizer);
        assert!(
            max_diff(&image, &plain) < 1e-12,
            "{rasterizer:?} {pruning:?} {options:?}: image"
        );
        assert!(
            max_diff(&grad, &plain_grad) < 1e-10,
            "{rasterizer:?} {pruning:?} {options:?}: gradient {grad:?} vs {plain_grad:?}"
        );
    }
}

#[test]
fn pose_gradient_matches_finite_differences() {
    let (scene, mask) = test_scene(23);
    let k = intrinsics();
    let weights: Vec<f64> = (0..k.width * k.height * 4)
        .map(|i| ((i * 31) % 17) as f64 / 17.0 - 0.3)
        .collect();
    for rasterizer in RASTERIZERS {
        let loss = |device: &Device, poses: Tensor<2>| {
            let uploaded = DeviceScene::new(&scene, device, DType::F64);
            let mut request =
                RenderRequest::new(k, vec![Channel::Rgb, Channel::Mask(mask.clone())]);
            request.rasterizer = rasterizer;
            let out = render(&uploaded, poses, &request).unwrap();
            let w = Tensor::<4>::from_data(
                TensorData::new(weights.clone(), [1, k.height, k.width, 4]),
                (device, DType::F64),
            );
            (out.images * w).sum()
        };
        let base = pose();
        let device = Device::flex().autodiff();
        let poses = pose_tensor(&[base], &device, DType::F64).require_grad();
        let grads = loss(&device, poses.clone()).backward();
        let grad = host(poses.grad(&grads).unwrap());
        let plain = Device::flex();
        let value =
            |p: Pose| loss(&plain, pose_tensor(&[p], &plain, DType::F64)).into_scalar::<f64>();
        for (i, autodiff) in grad.iter().enumerate() {
            let h = 1e-6;
            let (mut plus, mut minus) = (base, base);
            plus.0[i] += h;
            minus.0[i] -= h;
            let fd = (value(plus) - value(minus)) / (2.0 * h);
            let error = (autodiff - fd).abs() / fd.abs().max(1e-3);
            assert!(
                error <= 1e-4,
                "{rasterizer:?} Φ[{i}]: autodiff {autodiff} vs finite differences {fd} (relative error {error})"
            );
        }
    }
}

#[test]
fn feature_channels_composite_like_masks() {
    // Features (m, 1 − m): the first equals the mask render, and the two add up to alpha
    // (compositing is linear in the values and Σ α_i T_i = 1 − T_final).
    let (scene, mask) = test_scene(5);
    let device = Device::flex();
    let uploaded = DeviceScene::new(&scene, &device, DType::F64);
    let features: Vec<f32> = mask.iter().flat_map(|&m| [m, 1.0 - m]).collect();
    for rasterizer in RASTERIZERS {
        let mut request = RenderRequest::new(
            intrinsics(),
            vec![
                Channel::Features {
                    dim: 2,
                    values: features.clone(),
                },
                Channel::Mask(mask.clone()),
            ],
        );
        request.rasterizer = rasterizer;
        let out = render(
            &uploaded,
            pose_tensor(&[pose()], &device, DType::F64),
            &request,
        )
        .unwrap();
        let image = host(out.images.clone());
        let alpha: Vec<f64> = host(out.alpha().unwrap());
        for (p, px) in image.chunks(3).enumerate() {
            assert!(
                (px[0] - px[2]).abs() < 1e-12,
                "pixel {p}: feature 0 {} vs mask {}",
                px[0],
                px[2]
            );
            assert!(
                (px[0] + px[1] - alpha[p]).abs() < 1e-12,
                "pixel {p}: features do not sum to alpha"
            );
        }
        assert!(alpha.iter().any(|&a| a > 0.5));
    }
}
