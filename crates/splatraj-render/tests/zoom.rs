//! The per-pose zoom s (focal lengths fx·s, fy·s about the fixed principal point) in the
//! projection and the render: the fused projection against the tensor projection (rows, pose
//! and zoom gradients, f64, 1e-10), both against the same camera with fx·s, fy·s written into
//! its intrinsics (an independent route through the unzoomed code, and the f64 reference
//! renderer), and d L/ds of a whole render against central finite differences.

mod common;

use burn::tensor::{DType, Device, Int, Tensor, TensorData};
use common::{Rng, host, pose_tensor, projection_poses, projection_scene, ref_camera, row_weights};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose, zoomed_intrinsics};
use splatraj_render::fused::projection::{
    PackedColumn, ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS, project_packed_zoomed,
};
use splatraj_render::project::{NEAR_PLANE, SceneTensors, project_zoomed};
use splatraj_render::reference::{RefChannels, render_reference};
use splatraj_render::render::{
    Channel, DeviceScene, Rasterizer, RenderError, RenderRequest, Zoom, render, render_at,
};
use splatraj_scene::Scene;

/// One zoom per projection pose: in, out, far in, and 1.
const ZOOMS: [f64; 4] = [1.7, 0.55, 2.4, 1.0];

fn projection_intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 160, 120).unwrap()
}

fn zoom_tensor(zoom: &[f64], device: &Device, dtype: DType) -> Tensor<1> {
    Tensor::from_data(
        TensorData::new(zoom.to_vec(), [zoom.len()]),
        (device, dtype),
    )
}

/// Which projection runs.
#[derive(Debug, Clone, Copy)]
enum Projection {
    Fused,
    Tensor,
}

/// Rows `[B, U, 7]` of every Gaussian, packed like the fused op's, from either projection.
fn packed(
    projection: Projection,
    geometry: &SceneTensors,
    poses: Tensor<2>,
    zoom: Option<Tensor<1>>,
    intrinsics: &Intrinsics,
) -> Tensor<3> {
    let n = geometry.len();
    match projection {
        Projection::Fused => {
            let batch = poses.dims()[0];
            let used: Vec<u32> = (0..n as u32).collect();
            let plan =
                ProjectionPlan::dense(&used, batch, ProjectionCamera::new(intrinsics, NEAR_PLANE));
            project_packed_zoomed(geometry, poses, zoom, plan).reshape([batch, n, 7])
        }
        Projection::Tensor => {
            let [batch, _] = poses.dims();
            let device = poses.device();
            let index = Tensor::<1, Int>::from_data(
                TensorData::new((0..n as i64).collect::<Vec<_>>(), [n]),
                &device,
            );
            let selected = geometry.select(index);
            let projected = project_zoomed(&selected, poses, zoom, intrinsics, NEAR_PLANE);
            let opacity = selected.opacities.reshape([1, n, 1]).repeat_dim(0, batch);
            let depth = projected.depth.unsqueeze_dim::<3>(2);
            Tensor::cat(
                vec![projected.means_2d, projected.conics, opacity, depth],
                2,
            )
        }
    }
}

/// (rows, d loss/dΦ, d loss/ds) of Σ w·rows in f64 on Flex.
fn rows_and_gradients(projection: Projection, zoom: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let device = Device::flex().autodiff();
    let geometry = SceneTensors::new(&projection_scene(7), None, &device, DType::F64);
    let poses = pose_tensor(&projection_poses(), &device, DType::F64).require_grad();
    let s = zoom_tensor(zoom, &device, DType::F64).require_grad();
    let rows = packed(
        projection,
        &geometry,
        poses.clone(),
        Some(s.clone()),
        &projection_intrinsics(),
    );
    let [batch, count, _] = rows.dims();
    let grads = (rows.clone() * row_weights(batch, count, &device, DType::F64))
        .sum()
        .backward();
    (
        host(rows.detach()),
        host(poses.grad(&grads).expect("the poses have a gradient")),
        host(s.grad(&grads).expect("the zoom has a gradient")),
    )
}

fn max_abs(values: &[f64]) -> f64 {
    values.iter().fold(0.0, |m, v| m.max(v.abs()))
}

/// Largest |a − b| / (1 + |b|).
fn max_relative(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0, |m, (x, y)| m.max((x - y).abs() / (1.0 + y.abs())))
}

#[test]
fn zoomed_projection_matches_the_tensor_projection_in_f64() {
    let (rows, v_poses, v_zoom) = rows_and_gradients(Projection::Fused, &ZOOMS);
    let (rows_t, v_poses_t, v_zoom_t) = rows_and_gradients(Projection::Tensor, &ZOOMS);
    assert!(rows.iter().all(|v| v.is_finite()));
    let rows_error = max_relative(&rows, &rows_t);
    assert!(rows_error <= 1e-10, "rows: relative error {rows_error}");
    let pose_norm = max_abs(&v_poses_t);
    let zoom_norm = max_abs(&v_zoom_t);
    assert!(pose_norm > 1.0 && zoom_norm > 1.0, "gradients to compare");
    let worst = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
    };
    println!(
        "rows {rows_error:.1e} (relative); dΦ {:.1e}, ds {:.1e} (of max |gradient| {pose_norm:.1}, {zoom_norm:.1}); ds fused {v_zoom:?} tensor {v_zoom_t:?}",
        worst(&v_poses, &v_poses_t) / pose_norm,
        worst(&v_zoom, &v_zoom_t) / zoom_norm,
    );
    for (i, (f, t)) in v_poses.iter().zip(&v_poses_t).enumerate() {
        assert!(
            (f - t).abs() <= 1e-10 * pose_norm,
            "d loss/dΦ[{}][{}]: fused {f} vs tensor {t}",
            i / 6,
            i % 6
        );
    }
    for (b, (f, t)) in v_zoom.iter().zip(&v_zoom_t).enumerate() {
        assert!(
            (f - t).abs() <= 1e-10 * zoom_norm,
            "d loss/ds[{b}]: fused {f} vs tensor {t}"
        );
    }
    // The cases the zoom had to cover occurred: Gaussians behind the near plane, and in front
    // of a zoomed camera beyond its zoomed clamp |x/z| > 1.3·tan(half fov)/s but inside the
    // unzoomed one (so a clamp bound that ignored s would differ), and the reverse.
    let k = projection_intrinsics();
    let (lim_x, lim_y) = ProjectionCamera::new(&k, NEAR_PLANE).limits();
    let depth = PackedColumn::Depth as usize;
    let per_pose = projection_scene(7).len();
    let (mut behind, mut only_zoomed, mut only_unzoomed) = (0, 0, 0);
    for (r, row) in rows_t.chunks_exact(SPLAT_COLUMNS).enumerate() {
        let s = ZOOMS[r / per_pose];
        if row[depth] <= NEAR_PLANE {
            behind += 1;
            continue;
        }
        // x/z from u = fx·s·x/z + cx.
        let x_over_z = (row[0] - k.cx) / (k.fx * s);
        let y_over_z = (row[1] - k.cy) / (k.fy * s);
        let beyond = |lim_x: f64, lim_y: f64| x_over_z.abs() > lim_x || y_over_z.abs() > lim_y;
        match (beyond(lim_x / s, lim_y / s), beyond(lim_x, lim_y)) {
            (true, false) => only_zoomed += 1,
            (false, true) => only_unzoomed += 1,
            _ => {}
        }
    }
    println!("behind {behind}, clamped only zoomed {only_zoomed}, only unzoomed {only_unzoomed}");
    assert!(behind > 0, "some Gaussian lies behind a camera");
    assert!(
        only_zoomed > 0,
        "some Gaussian is clamped only when zoomed in"
    );
    assert!(
        only_unzoomed > 0,
        "some Gaussian is clamped only when not zoomed out"
    );
}

#[test]
fn zoom_gradient_of_the_projection_matches_finite_differences() {
    // Σ w·rows as a function of each s_b alone, by central differences of the fused forward.
    let (_, _, v_zoom) = rows_and_gradients(Projection::Fused, &ZOOMS);
    let device = Device::flex();
    let geometry = SceneTensors::new(&projection_scene(7), None, &device, DType::F64);
    let loss = |zoom: &[f64]| -> f64 {
        let poses = pose_tensor(&projection_poses(), &device, DType::F64);
        let rows = packed(
            Projection::Fused,
            &geometry,
            poses,
            Some(zoom_tensor(zoom, &device, DType::F64)),
            &projection_intrinsics(),
        );
        let [batch, count, _] = rows.dims();
        (rows * row_weights(batch, count, &device, DType::F64))
            .sum()
            .into_scalar::<f64>()
    };
    for b in 0..ZOOMS.len() {
        let h = 1e-6;
        let (mut plus, mut minus) = (ZOOMS, ZOOMS);
        plus[b] += h;
        minus[b] -= h;
        let fd = (loss(&plus) - loss(&minus)) / (2.0 * h);
        let error = (v_zoom[b] - fd).abs() / fd.abs().max(1.0);
        println!(
            "s[{b}]: fused {} fd {fd} relative error {error:.1e}",
            v_zoom[b]
        );
        assert!(
            error <= 1e-6,
            "d loss/ds[{b}]: fused {} vs finite differences {fd} (relative error {error})",
            v_zoom[b]
        );
    }
}

#[test]
fn a_zoom_projects_as_the_focal_lengths_times_s() {
    // Independent route: no zoom, the intrinsics of each pose with fx·s, fy·s (and so its own
    // field of view and clamp bound), one pose at a time.
    let device = Device::flex();
    let geometry = SceneTensors::new(&projection_scene(7), None, &device, DType::F64);
    let k = projection_intrinsics();
    let poses = projection_poses();
    for projection in [Projection::Fused, Projection::Tensor] {
        let zoomed = host(packed(
            projection,
            &geometry,
            pose_tensor(&poses, &device, DType::F64),
            Some(zoom_tensor(&ZOOMS, &device, DType::F64)),
            &k,
        ));
        let per_pose = zoomed.len() / poses.len();
        for (b, (pose, s)) in poses.iter().zip(ZOOMS).enumerate() {
            let scaled = host(packed(
                projection,
                &geometry,
                pose_tensor(&[*pose], &device, DType::F64),
                None,
                &zoomed_intrinsics(&k, s),
            ));
            let error = max_relative(&zoomed[b * per_pose..(b + 1) * per_pose], &scaled);
            println!("{projection:?} pose {b}: zoom vs fx·s rows {error:.1e}");
            assert!(
                error <= 1e-10,
                "{projection:?} pose {b} (s = {s}): relative error {error}"
            );
        }
    }
}

/// A render scene in front of a camera at the origin looking along +y (z up): random
/// anisotropic Gaussians, some cut by the border, an opaque stack at the centre, and four wide
/// ones off to the sides whose x/z lies beyond the Jacobian's clamp when zoomed in but whose
/// footprint reaches the image. SH degree 1.
fn render_scene(seed: u64) -> (Scene, Vec<f32>) {
    let mut rng = Rng(seed);
    let mut scene = Scene {
        sh_degree: 1,
        ..Default::default()
    };
    let mut mask = Vec::new();
    for i in 0..66 {
        let stack = i >= 60;
        let k = (i as f64) - 60.0;
        let mean = if stack {
            [0.05 * k, 3.0 + 0.2 * k, 0.02 * k]
        } else {
            [
                rng.range(-1.6, 1.6),
                rng.range(2.0, 6.0),
                rng.range(-1.0, 1.0),
            ]
        };
        let scale = if stack {
            [0.3, 0.05, 0.3]
        } else {
            [
                rng.range(0.02, 0.3),
                rng.range(0.02, 0.3),
                rng.range(0.005, 0.1),
            ]
        };
        let rotation: [f64; 4] = std::array::from_fn(|_| rng.range(-1.0, 1.0));
        let norm = rotation.iter().map(|v| v * v).sum::<f64>().sqrt();
        scene.means.push(mean.map(|v| v as f32));
        scene.scales.push(scale.map(|v| v as f32));
        scene.rotations.push(rotation.map(|v| (v / norm) as f32));
        scene
            .opacities
            .push(if stack { 1.0 } else { rng.range(0.2, 1.0) } as f32);
        for _ in 0..12 {
            scene.sh.push(rng.range(-1.0, 1.0) as f32);
        }
        mask.push(if i % 3 == 0 || i == 64 { 1.0 } else { 0.0 });
    }
    for (x, z) in [(2.4, 0.2), (-2.6, -0.3), (0.3, 1.9), (-0.2, -2.0)] {
        scene.means.push([x, 3.0, z]);
        scene.scales.push([0.6, 0.4, 0.5]);
        scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
        scene.opacities.push(0.6);
        for _ in 0..12 {
            scene.sh.push(rng.range(-1.0, 1.0) as f32);
        }
        mask.push(1.0);
    }
    (scene, mask)
}

fn render_intrinsics() -> Intrinsics {
    // Non-square, partial tiles on both axes, off-centre principal point.
    Intrinsics::new(30.0, 32.0, 21.0, 13.5, 40, 28).unwrap()
}

fn render_poses() -> Vec<Pose> {
    vec![
        Pose::look_at(
            DVec3::new(0.1, -0.2, 0.15),
            DVec3::new(0.0, 4.0, 0.0),
            DVec3::Z,
        )
        .unwrap(),
        Pose::look_at(
            DVec3::new(-0.4, 0.3, -0.1),
            DVec3::new(0.2, 3.5, 0.1),
            DVec3::Z,
        )
        .unwrap(),
    ]
}

const RENDER_ZOOMS: [f64; 2] = [1.6, 0.7];

const RASTERIZERS: [Rasterizer; 2] = [Rasterizer::Fused, Rasterizer::Tensor];

#[test]
fn a_zoomed_render_is_the_render_with_scaled_focal_lengths() {
    let (scene, mask) = render_scene(23);
    let k = render_intrinsics();
    let device = Device::flex();
    let uploaded = DeviceScene::new(&scene, &device, DType::F64);
    let poses = render_poses();
    let channels = vec![Channel::Rgb, Channel::Depth, Channel::Mask(mask.clone())];
    for rasterizer in RASTERIZERS {
        let mut request = RenderRequest::new(k, channels.clone());
        request.rasterizer = rasterizer;
        request.zoom = Some(Zoom::new(zoom_tensor(&RENDER_ZOOMS, &device, DType::F64)));
        let zoomed = render(
            &uploaded,
            pose_tensor(&poses, &device, DType::F64),
            &request,
        )
        .unwrap();
        let alpha = host(zoomed.alpha().unwrap());
        let images = host(zoomed.images);
        let pixels = k.width * k.height;
        for (b, (pose, s)) in poses.iter().zip(RENDER_ZOOMS).enumerate() {
            let scaled_k = zoomed_intrinsics(&k, s);
            let mut plain = RenderRequest::new(scaled_k, channels.clone());
            plain.rasterizer = rasterizer;
            let scaled = render(
                &uploaded,
                pose_tensor(&[*pose], &device, DType::F64),
                &plain,
            )
            .unwrap();
            let image = &images[b * pixels * 5..(b + 1) * pixels * 5];
            let error = max_relative(image, &host(scaled.images));
            println!("{rasterizer:?} pose {b}: zoom vs fx·s images {error:.1e}");
            assert!(
                error <= 1e-10,
                "{rasterizer:?} pose {b}: images differ by {error}"
            );
            // And the f64 reference renderer (its own projection and compositing).
            let reference = render_reference(
                &scene,
                &ref_camera(pose, &scaled_k),
                &RefChannels {
                    rgb: false,
                    depth: false,
                    masks: vec![&mask],
                },
            );
            let a = &alpha[b * pixels..(b + 1) * pixels];
            let error = max_relative(a, &reference.alpha);
            assert!(
                error <= 1e-5,
                "{rasterizer:?} pose {b}: alpha vs reference {error}"
            );
            let reference_mask = &reference.masks[0];
            let rendered_mask: Vec<f64> = image.chunks_exact(5).map(|p| p[4]).collect();
            let error = max_relative(&rendered_mask, reference_mask);
            println!("{rasterizer:?} pose {b}: mask vs reference {error:.1e}");
            assert!(
                error <= 1e-5,
                "{rasterizer:?} pose {b}: mask vs reference {error}"
            );
        }
    }
}

#[test]
fn ones_render_what_no_zoom_renders() {
    let (scene, mask) = render_scene(5);
    let k = render_intrinsics();
    let device = Device::flex().autodiff();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let poses = render_poses();
    for rasterizer in RASTERIZERS {
        let run = |zoom: Option<Zoom>| {
            let mut request = RenderRequest::new(k, vec![Channel::Mask(mask.clone())]);
            request.rasterizer = rasterizer;
            request.zoom = zoom;
            let p = pose_tensor(&poses, &device, DType::F32).require_grad();
            let out = render(&uploaded, p.clone(), &request).unwrap();
            let grads = out.images.clone().sum().backward();
            (host(out.images), host(p.grad(&grads).unwrap()))
        };
        let ones = Zoom::at(zoom_tensor(&[1.0, 1.0], &device, DType::F32), vec![1.0; 2]);
        assert_eq!(
            run(None),
            run(Some(ones)),
            "{rasterizer:?}: s = 1 changes no bit"
        );
    }
}

/// Weighted sum of the RGB and mask channels, plus a TCE-like term (the mask centroid's
/// distance from the image centre, with a floored mask sum) for each pose.
fn render_loss(
    uploaded: &DeviceScene,
    mask: &[f32],
    rasterizer: Rasterizer,
    poses: Tensor<2>,
    zoom: Tensor<1>,
    host_zoom: Option<Vec<f64>>,
) -> Tensor<1> {
    let k = render_intrinsics();
    let device = poses.device();
    let [batch, _] = poses.dims();
    let mut request = RenderRequest::new(k, vec![Channel::Rgb, Channel::Mask(mask.to_vec())]);
    request.rasterizer = rasterizer;
    request.zoom = Some(Zoom {
        values: zoom,
        host: host_zoom,
    });
    let out = render_at(uploaded, poses, None, &request).unwrap();
    let (h, w) = (k.height, k.width);
    let weights: Vec<f64> = (0..batch * h * w * 4)
        .map(|i| ((i * 31) % 17) as f64 / 17.0 - 0.3)
        .collect();
    let weights = Tensor::<4>::from_data(
        TensorData::new(weights, [batch, h, w, 4]),
        (&device, DType::F64),
    );
    let weighted = (out.images.clone() * weights).sum();
    let m = out.images.narrow(3, 3, 1).reshape([batch, h * w]); // [B, H·W]
    let xs: Vec<f64> = (0..h * w).map(|p| (p % w) as f64 + 0.5).collect();
    let ys: Vec<f64> = (0..h * w).map(|p| (p / w) as f64 + 0.5).collect();
    let column =
        |v: Vec<f64>| Tensor::<2>::from_data(TensorData::new(v, [h * w, 1]), (&device, DType::F64));
    let total = m.clone().sum_dim(1).clamp_min(1e-3); // [B, 1]
    let cx = m.clone().matmul(column(xs)) / total.clone() / w as f64; // [B, 1]
    let cy = m.matmul(column(ys)) / total / h as f64; // [B, 1]
    let tce = ((cx - 0.5).square() + (cy - 0.5).square()).sqrt().sum();
    weighted + tce
}

#[test]
fn zoom_gradient_of_a_render_matches_finite_differences() {
    let (scene, mask) = render_scene(23);
    let poses = render_poses();
    let autodiff = Device::flex().autodiff();
    let plain = Device::flex();
    let scene_ad = DeviceScene::new(&scene, &autodiff, DType::F64);
    let scene_plain = DeviceScene::new(&scene, &plain, DType::F64);
    let mut by_rasterizer = Vec::new();
    for rasterizer in RASTERIZERS {
        let s = zoom_tensor(&RENDER_ZOOMS, &autodiff, DType::F64).require_grad();
        let p = pose_tensor(&poses, &autodiff, DType::F64);
        let grads = render_loss(&scene_ad, &mask, rasterizer, p, s.clone(), None).backward();
        let v_zoom = host(s.grad(&grads).expect("the zoom has a gradient"));
        let value = |zoom: &[f64]| -> f64 {
            let p = pose_tensor(&poses, &plain, DType::F64);
            let s = zoom_tensor(zoom, &plain, DType::F64);
            render_loss(&scene_plain, &mask, rasterizer, p, s, Some(zoom.to_vec()))
                .into_scalar::<f64>()
        };
        for (b, autodiff) in v_zoom.iter().enumerate() {
            let h = 1e-6;
            let (mut plus, mut minus) = (RENDER_ZOOMS, RENDER_ZOOMS);
            plus[b] += h;
            minus[b] -= h;
            let fd = (value(&plus) - value(&minus)) / (2.0 * h);
            let error = (autodiff - fd).abs() / fd.abs().max(1e-3);
            println!(
                "{rasterizer:?} s[{b}]: autodiff {autodiff} fd {fd} relative error {error:.2e}"
            );
            assert!(
                fd.abs() > 1e-2 && error <= 1e-5,
                "{rasterizer:?} s[{b}]: autodiff {autodiff} vs finite differences {fd} (relative error {error})"
            );
        }
        by_rasterizer.push(v_zoom);
    }
    let error = max_relative(&by_rasterizer[0], &by_rasterizer[1]);
    println!("d L/ds fused vs tensor {error:.1e}");
    assert!(
        error <= 1e-8,
        "fused {:?} vs tensor {:?}",
        by_rasterizer[0],
        by_rasterizer[1]
    );
}

#[test]
fn a_zoom_must_be_one_positive_value_per_pose() {
    let (scene, mask) = render_scene(1);
    let device = Device::flex();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let poses = pose_tensor(&render_poses(), &device, DType::F32);
    let mut request = RenderRequest::new(render_intrinsics(), vec![Channel::Mask(mask)]);
    request.zoom = Some(Zoom::new(zoom_tensor(&[1.0], &device, DType::F32)));
    assert_eq!(
        render(&uploaded, poses.clone(), &request).unwrap_err(),
        RenderError::ZoomCount { batch: 2, got: 1 }
    );
    request.zoom = Some(Zoom::at(
        zoom_tensor(&[1.0, 2.0], &device, DType::F32),
        vec![1.0],
    ));
    assert_eq!(
        render(&uploaded, poses.clone(), &request).unwrap_err(),
        RenderError::ZoomCount { batch: 2, got: 1 }
    );
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        request.zoom = Some(Zoom::new(zoom_tensor(&[1.0, bad], &device, DType::F32)));
        match render(&uploaded, poses.clone(), &request).unwrap_err() {
            RenderError::BadZoom { index: 1, .. } => {}
            other => panic!("zoom {bad}: {other:?}"),
        }
    }
}
