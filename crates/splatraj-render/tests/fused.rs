//! The fused compositing op against the tensor path (its specification) in f64: images and the
//! gradients of all four inputs, on hand-built screen-space Gaussians that hit every rule, and
//! the pose gradient of full renders against the tensor path (`rasterizer.rs` checks both paths'
//! pose gradients against finite differences).

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use common::{Rng, host, pose_tensor};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::fused::{CompositePlan, composite_fused};
use splatraj_render::rasterize::{
    Approximations, CompositeOptions, MIN_ALPHA, MIN_TRANSMITTANCE, SplatInputs, composite,
};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render,
};
use splatraj_render::rows::PoseRows;
use splatraj_render::tiles::{TileGrid, TileWork};
use splatraj_scene::Scene;

/// Host-side screen-space Gaussians of a batch, rows b·n + g.
struct Splats {
    means: Vec<f64>,
    conics: Vec<f64>,
    opacities: Vec<f64>,
    values: Vec<f64>,
    channels: usize,
}

impl Splats {
    fn push(&mut self, mean: [f64; 2], cov: [f64; 3], opacity: f64, rng: &mut Rng) {
        let [a, b, c] = cov;
        let det = a * c - b * b;
        self.means.extend(mean);
        self.conics.extend([c / det, -b / det, a / det]);
        self.opacities.push(opacity);
        for _ in 0..self.channels {
            self.values.push(rng.range(-1.0, 1.0));
        }
    }
}

/// A 37×21 image (partial tiles on both axes), two poses, and per pose, front to back: an
/// opaque stack that stops pixels early (α clamped at 0.99, and
/// exactly 0.99 at a pixel centre), Gaussians with α just above and just below 1/255 at pixel
/// centres, and a stack that brings one pixel's T to just below 1e-4 (it stops there) and
/// another's to just above (it does not); then random Gaussians (some beyond the border). Lists run in depth order = row order, with one
/// long list (more than one tensor-path chunk) and empty tiles (nothing in the second pose's
/// last tile).
fn hard_case(channels: usize) -> (Splats, Vec<TileWork>, TileGrid, usize, usize) {
    let grid = TileGrid::new(37, 21);
    let batch = 2;
    let mut rng = Rng(0x5eed);
    let mut s = Splats {
        means: vec![],
        conics: vec![],
        opacities: vec![],
        values: vec![],
        channels,
    };
    let mut per_pose = Vec::new();
    for _ in 0..batch {
        let start = s.opacities.len();
        // α exactly 0.99 at pixel (5, 5) of tile 0 (o = 0.99, power 0), then α clamped.
        s.push([5.5, 5.5], [4.0, 0.0, 4.0], 0.99, &mut rng);
        s.push([6.0, 5.0], [9.0, 1.0, 4.0], 1.0, &mut rng);
        // α = 1/255 ± 1e-9 at the centre of pixel (20, 10).
        s.push([20.5, 10.5], [0.5, 0.0, 0.5], MIN_ALPHA + 1e-9, &mut rng);
        s.push([20.5, 10.5], [0.5, 0.0, 0.5], MIN_ALPHA - 1e-9, &mut rng);
        // T boundary at pixel (30, 3): after 0.9 and 0.99, T = 1e-3; a third α of 0.9 gives
        // T = 1e-4·(1 − 1e-7) (stops), at pixel (33, 3) α = 0.9·(1 − 2e-7)… gives T just above.
        for (x, o) in [(30.5, 0.9), (30.5, 0.99), (30.5, 0.9 + 1e-8)] {
            s.push([x, 3.5], [0.4, 0.0, 0.4], o, &mut rng);
        }
        for (x, o) in [(33.5, 0.9), (33.5, 0.99), (33.5, 0.9 - 1e-7)] {
            s.push([x, 3.5], [0.4, 0.0, 0.4], o, &mut rng);
        }
        // Behind the hand-placed ones (later rows are further back).
        for _ in 0..150 {
            let mean = [rng.range(-4.0, 40.0), rng.range(-4.0, 24.0)];
            let (sx, sy, rho) = (
                rng.range(0.6, 6.0),
                rng.range(0.6, 6.0),
                rng.range(-0.8, 0.8),
            );
            let cov = [sx * sx, rho * sx * sy, sy * sy];
            s.push(mean, cov, rng.range(0.02, 1.0), &mut rng);
        }
        per_pose.push((start, s.opacities.len()));
    }
    let n = per_pose[0].1 - per_pose[0].0;
    // Lists: a Gaussian goes into every tile its 3σ box touches, front to back = row order.
    let mut work = Vec::new();
    for b in 0..batch {
        for tile in 0..grid.len() {
            if b == 1 && tile == grid.len() - 1 {
                continue; // an empty tile
            }
            let (tx, ty) = (tile % grid.tiles_x, tile / grid.tiles_x);
            let gaussians: Vec<u32> = (0..n)
                .filter(|&g| {
                    let row = b * n + g;
                    let [a, bb, c] = [
                        s.conics[3 * row],
                        s.conics[3 * row + 1],
                        s.conics[3 * row + 2],
                    ];
                    // Σ = conic⁻¹; 3.5σ along the major axis: everything outside has α < 1/255,
                    // so the lists hold every Gaussian that counts (the brute force below).
                    let det = a * c - bb * bb;
                    let (sxx, sxy, syy) = (c / det, -bb / det, a / det);
                    let mid = 0.5 * (sxx + syy);
                    let lambda = mid + (mid * mid - (sxx * syy - sxy * sxy)).max(0.0).sqrt();
                    let radius = 3.5 * lambda.sqrt() + 1.0;
                    let (xs, ys) = grid.touched(s.means[2 * row], s.means[2 * row + 1], radius);
                    xs.contains(&tx) && ys.contains(&ty)
                })
                .map(|g| g as u32)
                .collect();
            if !gaussians.is_empty() {
                work.push(TileWork {
                    batch: b,
                    tile,
                    gaussians,
                });
            }
        }
    }
    (s, work, grid, n, batch)
}

fn tensor(values: &[f64], shape: Vec<usize>, device: &Device) -> Tensor<2> {
    let rows = shape[0];
    let cols = values.len() / rows.max(1);
    Tensor::from_data(
        TensorData::new(values.to_vec(), [rows, cols]),
        (device, DType::F64),
    )
}

/// Images, alpha and the gradients of Σ w·image + Σ w'·alpha w.r.t. the four inputs.
fn composite_and_gradients(
    rasterizer: Rasterizer,
    chunk: usize,
    stop_transmittance: f64,
) -> Vec<Vec<f64>> {
    let (s, work, grid, n, batch) = hard_case(3);
    let device = Device::flex().autodiff();
    let rows = s.opacities.len();
    let means = tensor(&s.means, vec![rows, 2], &device).require_grad();
    let conics = tensor(&s.conics, vec![rows, 3], &device).require_grad();
    let opacities = Tensor::<1>::from_data(
        TensorData::new(s.opacities.clone(), [rows]),
        (&device, DType::F64),
    )
    .require_grad();
    let values = tensor(&s.values, vec![rows, s.channels], &device).require_grad();
    let inputs = SplatInputs {
        means_2d: means.clone(),
        conics: conics.clone(),
        opacities: opacities.clone(),
        values: values.clone(),
    };
    let out = match rasterizer {
        Rasterizer::Fused => composite_fused(
            &inputs,
            CompositePlan::new(&work, &PoseRows::dense(batch, n), grid)
                .with_stop_transmittance(stop_transmittance),
        ),
        Rasterizer::Tensor => composite(
            &inputs,
            &work,
            &PoseRows::dense(batch, n),
            &grid,
            CompositeOptions {
                chunk,
                tile_group: 3,
                stop_transmittance,
            },
        ),
    };
    let count = batch * grid.height * grid.width;
    let w_image: Vec<f64> = (0..count * 3)
        .map(|i| ((i * 7919) % 23) as f64 / 23.0 - 0.4)
        .collect();
    let w_alpha: Vec<f64> = (0..count)
        .map(|i| ((i * 104729) % 19) as f64 / 19.0 - 0.5)
        .collect();
    let w_image = Tensor::<4>::from_data(
        TensorData::new(w_image, [batch, grid.height, grid.width, 3]),
        (&device, DType::F64),
    );
    let w_alpha = Tensor::<3>::from_data(
        TensorData::new(w_alpha, [batch, grid.height, grid.width]),
        (&device, DType::F64),
    );
    let loss = (out.images.clone() * w_image).sum() + (out.alpha().unwrap() * w_alpha).sum();
    let grads = loss.backward();
    vec![
        host(out.images.clone()),
        host(out.alpha().unwrap()),
        host(means.grad(&grads).unwrap()),
        host(conics.grad(&grads).unwrap()),
        host(opacities.grad(&grads).unwrap()),
        host(values.grad(&grads).unwrap()),
    ]
}

/// Largest |a − b| / max(1, |b|).
fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0, |m, (x, y)| m.max((x - y).abs() / y.abs().max(1.0)))
}

#[test]
fn fused_matches_the_tensor_path_on_every_rule() {
    let names = [
        "images",
        "alpha",
        "v_means",
        "v_conics",
        "v_opacities",
        "v_values",
    ];
    let fused = composite_and_gradients(Rasterizer::Fused, 0, MIN_TRANSMITTANCE);
    // Chunks of 8 split the long lists into many pieces; 128 is the default.
    for chunk in [8, 128] {
        let tensor = composite_and_gradients(Rasterizer::Tensor, chunk, MIN_TRANSMITTANCE);
        for (i, name) in names.iter().enumerate() {
            let tolerance = if i < 2 { 1e-10 } else { 1e-8 };
            let error = relative_error(&fused[i], &tensor[i]);
            assert!(
                error <= tolerance,
                "{name} (chunk {chunk}): error {error:e}"
            );
        }
    }
    let (s, work, grid, n, _) = hard_case(3);
    assert!(
        work.iter().any(|w| w.gaussians.len() > 128),
        "a list longer than one chunk"
    );
    assert!(work.len() < 2 * grid.len(), "an empty tile");
    let _ = (s, n);
    // The rules were hit: the image has opaque pixels, and gradients are not trivially zero.
    assert!(fused[1].iter().any(|&a| a > 0.999), "some pixel is opaque");
    for (i, name) in names.iter().enumerate().skip(2) {
        assert!(
            fused[i].iter().any(|&g| g.abs() > 1e-6),
            "{name} is not all zero"
        );
    }
}

#[test]
fn rule_edges_are_decided_as_specified() {
    // Pixel values checked against a hand computation of the same rules.
    let (s, work, grid, n, batch) = hard_case(1);
    let device = Device::flex();
    let rows = s.opacities.len();
    let inputs = SplatInputs {
        means_2d: tensor(&s.means, vec![rows, 2], &device),
        conics: tensor(&s.conics, vec![rows, 3], &device),
        opacities: Tensor::from_data(
            TensorData::new(s.opacities.clone(), [rows]),
            (&device, DType::F64),
        ),
        values: tensor(&s.values, vec![rows, 1], &device),
    };
    let out = composite_fused(
        &inputs,
        CompositePlan::new(&work, &PoseRows::dense(batch, n), grid),
    );
    let alpha = host(out.alpha().unwrap());
    let image = host(out.images);
    // Brute force over all n Gaussians of pose 0 in row order (the lists' order), one pixel.
    let brute = |x: usize, y: usize| -> (f64, f64) {
        let (mut t, mut value) = (1.0f64, 0.0);
        for g in 0..n {
            let dx = x as f64 + 0.5 - s.means[2 * g];
            let dy = y as f64 + 0.5 - s.means[2 * g + 1];
            let [a, b, c] = [s.conics[3 * g], s.conics[3 * g + 1], s.conics[3 * g + 2]];
            let power = (-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy).min(0.0);
            let alpha = (s.opacities[g] * power.exp()).min(0.99);
            if alpha < 1.0 / 255.0 {
                continue;
            }
            if t * (1.0 - alpha) < 1e-4 {
                break;
            }
            value += s.values[g] * alpha * t;
            t *= 1.0 - alpha;
        }
        (value, 1.0 - t)
    };
    for (x, y) in [(5, 5), (20, 10), (30, 3), (33, 3), (0, 0), (36, 20)] {
        let pixel = y * grid.width + x;
        let (value, a) = brute(x, y);
        assert!(
            (image[pixel] - value).abs() < 1e-12,
            "pixel ({x}, {y}): {} vs {value}",
            image[pixel]
        );
        assert!((alpha[pixel] - a).abs() < 1e-12, "pixel ({x}, {y}) alpha");
    }
}

/// A small scene in front of the camera (the rasterizer test's layout, fewer Gaussians).
fn scene() -> (Scene, Vec<f32>) {
    let mut rng = Rng(99);
    let mut scene = Scene {
        sh_degree: 1,
        ..Default::default()
    };
    let mut mask = Vec::new();
    for i in 0..80 {
        scene.means.push([
            rng.range(-1.5, 1.5) as f32,
            rng.range(2.0, 6.0) as f32,
            rng.range(-1.0, 1.0) as f32,
        ]);
        scene.scales.push([
            rng.range(0.02, 0.3) as f32,
            rng.range(0.02, 0.3) as f32,
            rng.range(0.01, 0.1) as f32,
        ]);
        let q = [
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        ];
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        scene.rotations.push(q.map(|v| (v / norm) as f32));
        scene.opacities.push(rng.range(0.2, 1.0) as f32);
        for _ in 0..12 {
            scene.sh.push(rng.range(-1.0, 1.0) as f32);
        }
        mask.push(if i % 3 == 0 { 1.0 } else { 0.0 });
    }
    (scene, mask)
}

fn poses() -> Vec<Pose> {
    vec![
        Pose::look_at(
            DVec3::new(0.1, -0.2, 0.15),
            DVec3::new(0.0, 4.0, 0.0),
            DVec3::Z,
        )
        .unwrap(),
        Pose::look_at(
            DVec3::new(-0.4, 0.3, 0.4),
            DVec3::new(0.2, 4.0, -0.1),
            DVec3::Z,
        )
        .unwrap(),
        Pose::look_at(
            DVec3::new(0.6, 0.0, -0.2),
            DVec3::new(-0.3, 3.5, 0.2),
            DVec3::Z,
        )
        .unwrap(),
    ]
}

/// Weighted sum of [RGB, depth, mask] images of a batch, and its pose gradient.
fn render_loss(
    rasterizer: Rasterizer,
    pruning: Pruning,
    channels: Vec<Channel>,
) -> (Vec<f64>, Vec<f64>) {
    render_scene_loss(
        &scene().0,
        rasterizer,
        pruning,
        channels,
        Approximations::default(),
        AlphaChannel::Returned,
    )
}

/// [`render_loss`] of any scene, with rendering approximations; Σ alpha is in the loss where
/// `alpha` is returned.
fn render_scene_loss(
    scene: &Scene,
    rasterizer: Rasterizer,
    pruning: Pruning,
    channels: Vec<Channel>,
    approximations: Approximations,
    alpha: AlphaChannel,
) -> (Vec<f64>, Vec<f64>) {
    let k = Intrinsics::new(30.0, 32.0, 21.0, 13.5, 40, 28).unwrap();
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(scene, &device, DType::F64);
    let poses = pose_tensor(&poses(), &device, DType::F64).require_grad();
    let mut request = RenderRequest::new(k, channels);
    request.rasterizer = rasterizer;
    request.pruning = pruning;
    request.approximations = approximations;
    request.alpha = alpha;
    let out = render(&uploaded, poses.clone(), &request).unwrap();
    let [b, h, w, c] = out.images.dims();
    let weights: Vec<f64> = (0..b * h * w * c)
        .map(|i| ((i * 31) % 17) as f64 / 17.0 - 0.3)
        .collect();
    let weights = Tensor::<4>::from_data(
        TensorData::new(weights, [b, h, w, c]),
        (&device, DType::F64),
    );
    let mut loss = (out.images.clone() * weights).sum();
    match alpha {
        AlphaChannel::Returned => loss = loss + out.alpha().unwrap().sum(),
        AlphaChannel::Dropped => assert!(out.alpha().is_none(), "{rasterizer:?}: alpha dropped"),
    }
    let grads = loss.backward();
    (host(out.images), host(poses.grad(&grads).unwrap()))
}

/// The fused and tensor renders agree, images to 1e-10 and pose gradients to 1e-8, on five
/// channels (RGB, depth, mask) and on a mask alone, with alpha returned (and in the loss) or
/// dropped; returns the fused images of each case.
fn assert_fused_matches_tensor(alpha: AlphaChannel) -> Vec<Vec<f64>> {
    let (scene, mask) = scene();
    let mut images = Vec::new();
    for (pruning, channels) in [
        (
            Pruning::None,
            vec![Channel::Rgb, Channel::Depth, Channel::Mask(mask.clone())],
        ),
        (Pruning::ObjectOnly, vec![Channel::Mask(mask.clone())]),
    ] {
        let run = |rasterizer: Rasterizer| {
            render_scene_loss(
                &scene,
                rasterizer,
                pruning,
                channels.clone(),
                Approximations::default(),
                alpha,
            )
        };
        let (image, grad) = run(Rasterizer::Fused);
        let (want_image, want_grad) = run(Rasterizer::Tensor);
        assert!(
            relative_error(&image, &want_image) < 1e-10,
            "{pruning:?} {alpha:?}: images"
        );
        assert!(
            relative_error(&grad, &want_grad) < 1e-8,
            "{pruning:?} {alpha:?}: pose gradients {grad:?} vs {want_grad:?}"
        );
        assert!(grad.iter().any(|g| g.abs() > 1e-4), "a gradient to compare");
        images.push(image);
    }
    images
}

#[test]
fn pose_gradients_of_fused_and_tensor_renders_agree() {
    assert_fused_matches_tensor(AlphaChannel::Returned);
}

#[test]
fn dropping_alpha_keeps_the_channels_and_their_gradient() {
    // Without alpha the fused op writes C values a pixel instead of C + 1, and its backward
    // reads them so (alpha's gradient zero): checked against the tensor path, which composites
    // alpha and drops it after.
    let dropped = assert_fused_matches_tensor(AlphaChannel::Dropped);
    // The same channel images as a render that returns alpha.
    let returned = assert_fused_matches_tensor(AlphaChannel::Returned);
    assert_eq!(dropped, returned, "the channels do not depend on alpha");
}

#[test]
fn fused_is_deterministic_across_thread_counts() {
    let (_, mask) = scene();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                render_loss(
                    Rasterizer::Fused,
                    Pruning::None,
                    vec![Channel::Rgb, Channel::Mask(mask.clone())],
                )
            })
    };
    let one = run(1);
    for threads in [2, 3] {
        let other = run(threads);
        assert_eq!(one.0, other.0, "images with {threads} threads");
        assert_eq!(one.1, other.1, "gradients with {threads} threads");
    }
}

#[test]
fn a_larger_stop_transmittance_is_one_rule_on_both_paths() {
    let stop = 0.02;
    let fused = composite_and_gradients(Rasterizer::Fused, 0, stop);
    let tensor = composite_and_gradients(Rasterizer::Tensor, 8, stop);
    for i in 0..fused.len() {
        let tolerance = if i < 2 { 1e-10 } else { 1e-8 };
        let error = relative_error(&fused[i], &tensor[i]);
        assert!(error <= tolerance, "output {i}: error {error:e}");
    }
    // T never falls below the stop, so alpha = 1 − T stays at or below 1 − stop; the exact rule
    // lets the opaque stack of the hard case go past it.
    let max_alpha = |alpha: &[f64]| alpha.iter().fold(0.0f64, |m, &a| m.max(a));
    assert!(max_alpha(&fused[1]) <= 1.0 - stop + 1e-12);
    let exact = composite_and_gradients(Rasterizer::Fused, 0, MIN_TRANSMITTANCE);
    assert!(max_alpha(&exact[1]) > 1.0 - stop);
}

#[test]
fn min_opacity_renders_as_if_the_faint_gaussians_were_absent() {
    let (scene, mask) = scene();
    let min_opacity = 0.5;
    let keep: Vec<bool> = scene.opacities.iter().map(|&o| o >= min_opacity).collect();
    assert!(keep.iter().any(|&k| !k) && keep.iter().any(|&k| k));
    let mut kept = scene.clone();
    kept.retain(&keep);
    let kept_mask: Vec<f32> = mask
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(m, _)| *m)
        .collect();
    let approximate = Approximations {
        min_opacity: min_opacity as f64,
        ..Approximations::default()
    };
    for rasterizer in [Rasterizer::Fused, Rasterizer::Tensor] {
        let channels = |mask: &[f32]| vec![Channel::Rgb, Channel::Mask(mask.to_vec())];
        let (image, grad) = render_scene_loss(
            &scene,
            rasterizer,
            Pruning::None,
            channels(&mask),
            approximate,
            AlphaChannel::Returned,
        );
        let (want_image, want_grad) = render_scene_loss(
            &kept,
            rasterizer,
            Pruning::None,
            channels(&kept_mask),
            Approximations::default(),
            AlphaChannel::Returned,
        );
        assert!(
            relative_error(&image, &want_image) < 1e-12,
            "{rasterizer:?}: image"
        );
        assert!(
            relative_error(&grad, &want_grad) < 1e-10,
            "{rasterizer:?}: gradient"
        );
        let (exact, _) = render_scene_loss(
            &scene,
            rasterizer,
            Pruning::None,
            channels(&mask),
            Approximations::default(),
            AlphaChannel::Returned,
        );
        assert!(
            relative_error(&image, &exact) > 1e-3,
            "the faint Gaussians were drawn"
        );
    }
}
