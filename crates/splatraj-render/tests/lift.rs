//! Lifting per-pixel values onto the Gaussians (`lift_views`, through the rasterizer's
//! backward) against Σ_p w_i(p)·f(p) summed in f64 over the reference renderer's blending
//! weights; both rasterizers; occluded and unseen Gaussians; bad input.

mod common;

use burn::tensor::{DType, Device};
use common::{Rng, ref_camera};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::lift::{LiftSums, lift_views};
use splatraj_render::reference::reference_weights;
use splatraj_render::render::{DeviceScene, Rasterizer, RenderError};
use splatraj_scene::Scene;

/// Values per pixel in the tests.
const DIM: usize = 2;

/// Appends one Gaussian (SH degree 0, random colour).
fn push(scene: &mut Scene, mean: [f64; 3], scale: [f64; 3], rotation: [f64; 4], opacity: f64) {
    scene.means.push(mean.map(|v| v as f32));
    scene.scales.push(scale.map(|v| v as f32));
    let norm = rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
    scene.rotations.push(rotation.map(|v| (v / norm) as f32));
    scene.opacities.push(opacity as f32);
    scene.sh.extend([0.1, 0.2, 0.3]);
}

/// Index of the Gaussian behind the camera and of the one far to the side (seen by no view).
const UNSEEN: [usize; 2] = [0, 1];

/// Cameras near the origin look along +y (z up). Two unseen Gaussians, random anisotropic
/// ones overlapping each other (some cut by the image border), and an opaque stack on the
/// optical axis that stops pixels (α = 0.99 twice gives T = 1e-4) with small ones behind it.
fn test_scene(seed: u64) -> Scene {
    let mut rng = Rng(seed);
    let mut scene = Scene::default();
    push(
        &mut scene,
        [0.0, -3.0, 0.0],
        [0.2; 3],
        [1.0, 0.0, 0.0, 0.0],
        0.9,
    );
    push(
        &mut scene,
        [40.0, 4.0, 0.0],
        [0.2; 3],
        [1.0, 0.0, 0.0, 0.0],
        0.9,
    );
    for _ in 0..40 {
        let mean = [
            rng.range(-2.0, 2.0),
            rng.range(2.0, 6.0),
            rng.range(-1.2, 1.2),
        ];
        let scale = [
            rng.range(0.02, 0.3),
            rng.range(0.02, 0.3),
            rng.range(0.005, 0.1),
        ];
        let rotation = [0.0; 4].map(|_| rng.range(-1.0, 1.0));
        let opacity = rng.range(0.2, 1.0);
        push(&mut scene, mean, scale, rotation, opacity);
    }
    for k in 0..4 {
        let mean = [0.03 * k as f64, 3.0 + 0.2 * k as f64, 0.02 * k as f64];
        push(
            &mut scene,
            mean,
            [0.3, 0.05, 0.3],
            [1.0, 0.0, 0.0, 0.0],
            1.0,
        );
    }
    for k in 0..4 {
        let mean = [0.05 * k as f64 - 0.1, 4.5, 0.04 * k as f64 - 0.05];
        push(&mut scene, mean, [0.04; 3], [1.0, 0.0, 0.0, 0.0], 0.8);
    }
    scene
}

fn intrinsics() -> Intrinsics {
    // Non-square, partial tiles in x, off-centre principal point.
    Intrinsics::new(30.0, 32.0, 21.0, 15.5, 40, 32).unwrap()
}

fn poses() -> Vec<Pose> {
    [
        (DVec3::new(0.1, -0.2, 0.15), DVec3::new(0.0, 4.0, 0.0)),
        (DVec3::new(-0.6, 0.3, 0.4), DVec3::new(0.2, 4.0, -0.1)),
        (DVec3::new(0.8, 0.0, -0.3), DVec3::new(-0.3, 4.5, 0.2)),
    ]
    .map(|(eye, target)| Pose::look_at(eye, target, DVec3::Z).unwrap())
    .to_vec()
}

/// Random pixel values in [−1, 1). `[B, H, W, dim]`
fn random_pixels(views: usize, k: &Intrinsics, dim: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng(seed);
    (0..views * k.width * k.height * dim)
        .map(|_| rng.range(-1.0, 1.0) as f32)
        .collect()
}

/// Σ_views Σ_p w_i(p)·f(p) and Σ w_i(p) from the reference renderer's weights, in f64.
fn reference_sums(
    scene: &Scene,
    poses: &[Pose],
    k: &Intrinsics,
    pixels: &[f32],
    dim: usize,
) -> LiftSums {
    let mut sums = LiftSums::zeros(scene.len(), dim);
    let per_view = k.width * k.height;
    for (b, pose) in poses.iter().enumerate() {
        let weights = reference_weights(scene, &ref_camera(pose, k));
        for (p, pairs) in weights.iter().enumerate() {
            let f = &pixels[(b * per_view + p) * dim..(b * per_view + p + 1) * dim];
            for &(g, w) in pairs {
                sums.weights[g] += w;
                let row = &mut sums.weighted[g * dim..(g + 1) * dim];
                for (sum, &value) in row.iter_mut().zip(f) {
                    *sum += w * f64::from(value);
                }
            }
        }
    }
    sums
}

fn lift(scene: &Scene, dtype: DType, rasterizer: Rasterizer, pixels: &[f32]) -> LiftSums {
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(scene, &device, dtype);
    lift_views(&uploaded, &poses(), &intrinsics(), pixels, DIM, rasterizer).unwrap()
}

/// Largest error over Gaussians and channels (and Σ w), relative to the Gaussian's Σ w (a
/// bound on its |Σ w·f| since |f| < 1), floored at 1e-2 (a fraction of one pixel's weight).
fn max_relative_error(got: &LiftSums, want: &LiftSums) -> f64 {
    let mut worst: f64 = 0.0;
    for g in 0..want.len() {
        let scale = want.weights[g].max(1e-2);
        worst = worst.max((got.weights[g] - want.weights[g]).abs() / scale);
        for c in 0..want.dim {
            let i = g * want.dim + c;
            worst = worst.max((got.weighted[i] - want.weighted[i]).abs() / scale);
        }
    }
    worst
}

#[test]
fn lifted_sums_match_the_reference_weights() {
    let scene = test_scene(3);
    let pixels = random_pixels(poses().len(), &intrinsics(), DIM, 17);
    let want = reference_sums(&scene, &poses(), &intrinsics(), &pixels, DIM);
    // The scene exercises what it should: stopped pixels, several Gaussians with weight.
    let weights_of = |pose: &Pose| reference_weights(&scene, &ref_camera(pose, &intrinsics()));
    let pixels_stopped = weights_of(&poses()[0])
        .iter()
        .filter(|pairs| pairs.iter().map(|p| p.1).sum::<f64>() > 0.9998)
        .count();
    assert!(pixels_stopped > 0, "no pixel terminated early");
    let seen = want.weights.iter().filter(|&&w| w > 0.0).count();
    assert!(seen > 30, "only {seen} Gaussians have weight");

    for (dtype, tolerance) in [(DType::F64, 1e-9), (DType::F32, 1e-4)] {
        for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
            let got = lift(&scene, dtype, rasterizer, &pixels);
            let error = max_relative_error(&got, &want);
            println!("{dtype:?} {rasterizer:?}: max relative error {error:.3e}");
            assert!(
                error <= tolerance,
                "{dtype:?} {rasterizer:?}: max relative error {error:.3e}"
            );
        }
    }
}

#[test]
fn fused_and_tensor_rasterizers_agree() {
    let scene = test_scene(5);
    let pixels = random_pixels(poses().len(), &intrinsics(), DIM, 23);
    let fused = lift(&scene, DType::F64, Rasterizer::Fused, &pixels);
    let tensor = lift(&scene, DType::F64, Rasterizer::Tensor, &pixels);
    let error = max_relative_error(&fused, &tensor);
    assert!(error <= 1e-10, "fused vs tensor: {error:.3e}");
}

#[test]
fn views_add_up_across_passes() {
    // More views than one pass renders, against the sum of single-view lifts.
    let scene = test_scene(7);
    let k = intrinsics();
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(&scene, &device, DType::F64);
    let views: Vec<Pose> = poses().into_iter().cycle().take(5).collect();
    let pixels = random_pixels(views.len(), &k, DIM, 29);
    let all = lift_views(&uploaded, &views, &k, &pixels, DIM, Rasterizer::Fused).unwrap();
    let mut summed = LiftSums::zeros(scene.len(), DIM);
    let per_view = k.width * k.height * DIM;
    for (view, pixels) in views.iter().zip(pixels.chunks(per_view)) {
        let one = lift_views(
            &uploaded,
            std::slice::from_ref(view),
            &k,
            pixels,
            DIM,
            Rasterizer::Fused,
        )
        .unwrap();
        summed.add(&one);
    }
    assert!(max_relative_error(&all, &summed) <= 1e-12);
}

#[test]
fn hidden_gaussians_get_almost_no_weight_and_unseen_ones_no_vote() {
    // Behind two opaque walls, and the same Gaussian with nothing in front of it.
    let mut walled = Scene::default();
    for y in [3.0, 3.2] {
        push(
            &mut walled,
            [0.0, y, 0.0],
            [1.0, 0.05, 1.0],
            [1.0, 0.0, 0.0, 0.0],
            1.0,
        );
    }
    push(
        &mut walled,
        [0.0, 5.0, 0.0],
        [0.03; 3],
        [1.0, 0.0, 0.0, 0.0],
        0.9,
    );
    let mut open = Scene::default();
    push(
        &mut open,
        [0.0, 5.0, 0.0],
        [0.03; 3],
        [1.0, 0.0, 0.0, 0.0],
        0.9,
    );
    let pose = [Pose::look_at(DVec3::ZERO, DVec3::new(0.0, 4.0, 0.0), DVec3::Z).unwrap()];
    let k = intrinsics();
    let pixels = vec![1.0f32; k.width * k.height];
    let device = Device::flex().autodiff();
    let lift_one = |scene: &Scene, rasterizer| {
        let uploaded = DeviceScene::new(scene, &device, DType::F32);
        lift_views(&uploaded, &pose, &k, &pixels, 1, rasterizer).unwrap()
    };
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        let hidden = lift_one(&walled, rasterizer).weights[2];
        let visible = lift_one(&open, rasterizer).weights[0];
        assert!(visible > 0.5, "{rasterizer:?}: visible weight {visible}");
        assert!(
            hidden <= 1e-3 * visible,
            "{rasterizer:?}: hidden {hidden} vs visible {visible}"
        );
    }

    // Gaussians behind the camera or off to the side of every view: exactly 0, no vote.
    let scene = test_scene(3);
    let pixels = random_pixels(poses().len(), &k, DIM, 31);
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        let sums = lift(&scene, DType::F32, rasterizer, &pixels);
        let mean = sums.mean(1e-6);
        for g in UNSEEN {
            assert_eq!(sums.weights[g], 0.0);
            assert_eq!(&sums.weighted[g * DIM..(g + 1) * DIM], &[0.0; DIM]);
            assert_eq!(&mean[g * DIM..(g + 1) * DIM], &[None; DIM]);
        }
        // Seen Gaussians vote with a weighted average of values in [−1, 1).
        let voted: Vec<f32> = mean.iter().flatten().copied().collect();
        assert!(voted.len() > 30 * DIM);
        assert!(voted.iter().all(|v| (-1.0..=1.0).contains(v)));
    }
}

#[test]
fn bad_input_is_an_error() {
    let scene = test_scene(3);
    let k = intrinsics();
    let views = poses();
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let pixels = random_pixels(views.len(), &k, DIM, 37);
    let run = |scene: &DeviceScene, pixels: &[f32], dim| {
        lift_views(scene, &views, &k, pixels, dim, Rasterizer::Fused)
    };
    assert_eq!(
        run(&uploaded, &pixels[1..], DIM).unwrap_err(),
        RenderError::PixelCount {
            got: pixels.len() - 1,
            expected: pixels.len()
        }
    );
    assert!(matches!(
        run(&uploaded, &pixels, 3),
        Err(RenderError::PixelCount { .. })
    ));
    assert!(matches!(
        run(&uploaded, &[], 0),
        Err(RenderError::ZeroWidth { .. })
    ));
    let mut poisoned = pixels.clone();
    poisoned[5] = f32::NAN;
    assert_eq!(
        run(&uploaded, &poisoned, DIM).unwrap_err(),
        RenderError::NonFinitePixel { index: 5 }
    );
    let plain = DeviceScene::new(&scene, &Device::flex(), DType::F32);
    assert_eq!(
        run(&plain, &pixels, DIM).unwrap_err(),
        RenderError::NeedsAutodiff
    );
    // No views: nothing to add, no error.
    let none = lift_views(&uploaded, &[], &k, &[], DIM, Rasterizer::Fused).unwrap();
    assert_eq!(none, LiftSums::zeros(scene.len(), DIM));
}
