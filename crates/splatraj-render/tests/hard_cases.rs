//! Inputs that break naive rasterizers: values and pose gradients must stay finite and the
//! image sensible (and, where the reference renderer is defined, equal to it).

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{host, ref_camera};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::{RefChannels, render_reference};
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_scene::Scene;

fn push(scene: &mut Scene, mean: [f32; 3], scale: [f32; 3], opacity: f32) {
    scene.means.push(mean);
    scene.scales.push(scale);
    scene
        .rotations
        .push([0.9, 0.1, -0.3, 0.2].map(|v: f32| v / 0.994_987_4));
    scene.opacities.push(opacity);
    scene.sh.extend([0.4, -0.2, 0.1]);
}

/// Camera at the origin looking along +z (ω = 0), so camera and world coordinates coincide.
fn hard_scene() -> (Scene, Vec<f32>) {
    let mut scene = Scene::default();
    push(&mut scene, [0.0, 0.0, -2.0], [0.3; 3], 0.9); // behind the camera
    push(&mut scene, [0.1, 0.0, 0.0], [0.5; 3], 0.9); // straddles the near plane
    push(&mut scene, [0.0, 0.0, 0.0], [0.2; 3], 0.9); // at the camera centre
    push(&mut scene, [0.0, 0.0, 0.01], [0.2; 3], 0.9); // exactly on the near plane
    push(&mut scene, [0.2, 0.1, 2.0], [1e-8; 3], 1.0); // vanishingly small
    push(&mut scene, [0.0, 0.0, 50.0], [1e4; 3], 0.5); // enormous, around the camera
    push(&mut scene, [-0.3, 0.2, 3.0], [0.2, 0.1, 0.05], 0.0); // fully transparent
    push(&mut scene, [0.3, -0.2, 3.0], [0.2, 0.1, 0.05], 1.0); // fully opaque
    push(&mut scene, [0.0, 0.05, 4.0], [0.4, 0.4, 0.1], 1.0);
    push(&mut scene, [5.0, 0.0, 1.0], [0.3; 3], 0.8); // far off-screen, inside the clamp region
    let mask = (0..scene.len())
        .map(|i| if i % 2 == 1 { 1.0 } else { 0.0 })
        .collect();
    (scene, mask)
}

fn poses() -> Vec<Pose> {
    let near_pi = std::f64::consts::PI - 1e-6;
    let axis = DVec3::new(0.0, 1.0, 0.0);
    vec![
        Pose([0.0; 6]),
        // Turned almost half-way round about y, and stepped back so it sees the scene again.
        Pose([
            axis.x * near_pi,
            axis.y * near_pi,
            axis.z * near_pi,
            0.0,
            0.0,
            6.0,
        ]),
        // Looking away from everything: an empty view.
        Pose([0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0, -30.0]),
    ]
}

struct Output {
    images: Vec<f64>,
    alpha: Vec<f64>,
    grad: Vec<f64>,
}

/// Renders the three poses with both rasterizers; both must give the same result, returned once.
fn run(
    scene: &Scene,
    channels: Vec<Channel>,
    pruning: Pruning,
    k: Intrinsics,
    dtype: DType,
) -> Output {
    let fused = run_with(
        scene,
        channels.clone(),
        pruning,
        k,
        dtype,
        Rasterizer::Fused,
    );
    let tensor = run_with(scene, channels, pruning, k, dtype, Rasterizer::Tensor);
    let tolerance = if dtype == DType::F64 { 1e-9 } else { 2e-3 };
    for (name, a, b) in [
        ("images", &fused.images, &tensor.images),
        ("alpha", &fused.alpha, &tensor.alpha),
        ("pose gradient", &fused.grad, &tensor.grad),
    ] {
        let error = a
            .iter()
            .zip(b.iter())
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / y.abs().max(1.0)));
        // NaN compares false: a non-finite value on one path only fails here too.
        assert!(
            error <= tolerance || a.iter().chain(b.iter()).any(|v| !v.is_finite()),
            "{dtype:?} {pruning:?}: fused and tensor {name} differ by {error}"
        );
    }
    fused
}

fn run_with(
    scene: &Scene,
    channels: Vec<Channel>,
    pruning: Pruning,
    k: Intrinsics,
    dtype: DType,
    rasterizer: Rasterizer,
) -> Output {
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(scene, &device, dtype);
    let flat: Vec<f64> = poses().iter().flat_map(|p| p.0).collect();
    let poses =
        Tensor::<2>::from_data(TensorData::new(flat, [3, 6]), (&device, dtype)).require_grad();
    let mut request = RenderRequest::new(k, channels);
    request.pruning = pruning;
    request.rasterizer = rasterizer;
    let out = render(&uploaded, poses.clone(), &request).unwrap();
    let grads = (out.images.clone().sum() + out.alpha().unwrap().sum()).backward();
    Output {
        alpha: host(out.alpha().unwrap()),
        images: host(out.images),
        grad: host(poses.grad(&grads).expect("a gradient, even if zero")),
    }
}

fn assert_finite_and_sensible(out: &Output, what: &str) {
    assert!(
        out.images
            .iter()
            .chain(&out.alpha)
            .chain(&out.grad)
            .all(|v| v.is_finite()),
        "{what}: NaN/Inf"
    );
    assert!(
        out.alpha.iter().all(|&a| (0.0..=1.0).contains(&a)),
        "{what}: alpha outside [0, 1]"
    );
}

#[test]
fn hard_scene_is_finite_in_f32_and_f64() {
    let (scene, mask) = hard_scene();
    let k = Intrinsics::new(50.0, 50.0, 32.0, 24.0, 64, 48).unwrap();
    for dtype in [DType::F32, DType::F64] {
        let out = run(
            &scene,
            vec![Channel::Rgb, Channel::Depth, Channel::Mask(mask.clone())],
            Pruning::None,
            k,
            dtype,
        );
        assert_finite_and_sensible(&out, &format!("{dtype:?} all channels"));
        let out = run(
            &scene,
            vec![Channel::Mask(mask.clone())],
            Pruning::ObjectOnly,
            k,
            dtype,
        );
        assert_finite_and_sensible(&out, &format!("{dtype:?} pruned mask"));
        assert!(
            out.images.iter().all(|&m| (0.0..=1.0 + 1e-6).contains(&m)),
            "mask outside [0, 1]"
        );
    }
}

#[test]
fn hard_scene_matches_the_reference_at_omega_zero() {
    let (scene, mask) = hard_scene();
    let k = Intrinsics::new(50.0, 50.0, 32.0, 24.0, 64, 48).unwrap();
    let out = run(
        &scene,
        vec![Channel::Mask(mask.clone())],
        Pruning::None,
        k,
        DType::F64,
    );
    let camera = ref_camera(&Pose([0.0; 6]), &k);
    let reference = render_reference(
        &scene,
        &camera,
        &RefChannels {
            rgb: false,
            depth: false,
            masks: vec![&mask],
        },
    );
    let first = &out.images[..k.width * k.height]; // pose 0 is ω = 0 at the origin
    let error = first
        .iter()
        .zip(&reference.masks[0])
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(error <= 1e-5, "max difference {error}");
    assert!(
        reference.masks[0].iter().any(|&v| v > 0.5),
        "the opaque object Gaussian is in view"
    );
}

#[test]
fn empty_view_and_empty_mask_give_zero_images_and_zero_gradient() {
    let (scene, mask) = hard_scene();
    let k = Intrinsics::new(50.0, 50.0, 32.0, 24.0, 64, 48).unwrap();
    // Pose 2 looks away: its image must be empty.
    let out = run(
        &scene,
        vec![Channel::Mask(mask)],
        Pruning::ObjectOnly,
        k,
        DType::F64,
    );
    let per_pose = k.width * k.height;
    assert!(out.images[2 * per_pose..].iter().all(|&v| v == 0.0));
    assert!(
        out.grad[12..].iter().all(|&g| g == 0.0),
        "no gradient from an empty view: {:?}",
        &out.grad[12..]
    );
    // An all-zero mask renders nothing at all, with a zero (not missing) gradient.
    let zeros = vec![0.0; scene.len()];
    let out = run(
        &scene,
        vec![Channel::Mask(zeros)],
        Pruning::ObjectOnly,
        k,
        DType::F64,
    );
    assert!(out.images.iter().all(|&v| v == 0.0));
    assert!(out.grad.iter().all(|&g| g == 0.0));
}

#[test]
fn tiny_and_very_non_square_images() {
    let (scene, mask) = hard_scene();
    for (w, h) in [(1, 1), (1, 40), (300, 2), (17, 3)] {
        let f = 0.8 * w.max(h) as f64;
        let k = Intrinsics::new(f, f, 0.5 * w as f64, 0.5 * h as f64, w, h).unwrap();
        let out = run(
            &scene,
            vec![Channel::Rgb, Channel::Mask(mask.clone())],
            Pruning::None,
            k,
            DType::F32,
        );
        assert_eq!(out.alpha.len(), 3 * w * h);
        assert_finite_and_sensible(&out, &format!("{w}×{h}"));
    }
}

#[test]
fn a_million_gaussians_render_in_bounded_blocks() {
    // A million small Gaussians on a plane in front of the camera; the decision pass works in
    // blocks and the differentiable pass sees only what the object's tiles need.
    let mut scene = Scene::default();
    let side = 1000;
    for i in 0..side * side {
        let (x, y) = (
            (i % side) as f32 / side as f32 - 0.5,
            (i / side) as f32 / side as f32 - 0.5,
        );
        scene.means.push([4.0 * x, 3.0 * y, 5.0 + 0.1 * x]);
        scene.scales.push([0.004, 0.004, 0.001]);
        scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
        scene.opacities.push(0.8);
        scene.sh.extend([0.0; 3]);
    }
    let mask: Vec<f32> = scene
        .means
        .iter()
        .map(|m| {
            if m[0].abs() < 0.2 && m[1].abs() < 0.2 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let k = Intrinsics::new(40.0, 40.0, 32.0, 32.0, 64, 64).unwrap();
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let poses = Tensor::<2>::from_data(
        TensorData::new(vec![0.0f64; 6], [1, 6]),
        (&device, DType::F32),
    )
    .require_grad();
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        let mut request = RenderRequest::new(k, vec![Channel::Mask(mask.clone())]);
        request.pruning = Pruning::ObjectOnly;
        request.rasterizer = rasterizer;
        let out = render(&uploaded, poses.clone(), &request).unwrap();
        let coverage = out.images.clone().mean().into_scalar::<f64>();
        let grads = out.images.sum().backward();
        let grad = host(poses.grad(&grads).unwrap());
        // The object is a 0.4 × 0.4 square at depth 5: 3.2 × 3.2 pixels of 64 × 64, nearly opaque.
        assert!(
            coverage > 0.5 * 10.24 / 4096.0 && coverage < 2.0 * 10.24 / 4096.0,
            "{rasterizer:?}: coverage {coverage}"
        );
        assert!(grad.iter().all(|g| g.is_finite()), "{rasterizer:?}");
    }
}
