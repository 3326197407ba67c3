//! The scenes `splatraj bench render` times: a demo scene framing one object at about the
//! target ratio, or a real scene with a sphere of Gaussians at its centre as the object.
//!
//! The camera distance comes from the object's size and the field of view, then corrections
//! from measured coverage (coverage ∝ 1/d²), at a fixed calibration size so that every
//! resolution sees the same view.

use std::path::Path;

use anyhow::{Result, anyhow};
use burn::tensor::{DType, Device};
use glam::DVec3;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, scalar};
use splatraj_render::orbit::Orbit;
use splatraj_render::render::{AlphaChannel, Channel, DeviceScene, Pruning, RenderRequest, render};
use splatraj_scene::demo::{DEMO_VIEWPOINT, DemoConfig, demo_layout, demo_scene};
use splatraj_scene::{ReadOptions, Scene, read_scene, resolve_up};

/// A scene, its object mask and a camera framing the object.
#[derive(Debug)]
pub struct BenchScene {
    /// `demo` or the file's name.
    pub name: String,
    /// The scene.
    pub scene: Scene,
    /// The object, one value per Gaussian.
    pub mask: Vec<f32>,
    /// The camera.
    pub pose: Pose,
}

/// Measured coverage of `mask` from `pose` (forward only, pruned).
fn measure_coverage(
    scene: &Scene,
    mask: &[f32],
    pose: &Pose,
    intrinsics: &Intrinsics,
    device: &Device,
) -> Result<f64> {
    let uploaded = DeviceScene::new(scene, device, DType::F32);
    let request = RenderRequest {
        pruning: Pruning::ObjectOnly,
        alpha: AlphaChannel::Dropped,
        ..RenderRequest::new(*intrinsics, vec![Channel::Mask(mask.to_vec())])
    };
    let out = render(&uploaded, uploaded.poses(&[*pose]), &request)?;
    Ok(scalar(out.images.sum()) / (intrinsics.width * intrinsics.height) as f64)
}

/// Refuses a target ratio that is not a share of the frame in (0, 1] (the benches'
/// `--target-ratio`): a NaN or 0 would place the camera nowhere.
pub fn check_target_ratio(ratio: f64) -> anyhow::Result<()> {
    if !(ratio > 0.0 && ratio <= 1.0) {
        anyhow::bail!("--target-ratio {ratio} must be a share of the frame in (0, 1]");
    }
    Ok(())
}

/// Distance at which a silhouette of `area` m² covers `ratio` of a frame.
fn framing_distance(area: f64, ratio: f64, k: &Intrinsics) -> f64 {
    // Pixel area = area · fx · fy / d², frame = W · H.
    (area * k.fx * k.fy / (ratio * (k.width * k.height) as f64)).sqrt()
}

/// The demo scene of `gaussians` Gaussians framing `object` (a demo label name) at `ratio`
/// of the `calibration` camera, seen from the demo's standing viewpoint.
pub fn demo_bench_scene(
    object: &str,
    gaussians: usize,
    ratio: f64,
    calibration: &Intrinsics,
    device: &Device,
) -> Result<BenchScene> {
    check_target_ratio(ratio)?;
    let layout = demo_layout();
    let object = layout
        .iter()
        .find(|o| o.name.eq_ignore_ascii_case(object.trim()))
        .ok_or_else(|| {
            anyhow!(
                "--object {object:?} is not a demo object; available: {}",
                layout.iter().map(|o| o.name).collect::<Vec<_>>().join(", ")
            )
        })?;
    let scene = demo_scene(&DemoConfig {
        gaussians,
        ..DemoConfig::default()
    })?;
    let ids = &scene
        .extras
        .labels
        .as_ref()
        .ok_or_else(|| anyhow!("the demo scene has no labels"))?
        .ids;
    let mask: Vec<f32> = ids
        .iter()
        .map(|&id| if id == object.id { 1.0 } else { 0.0 })
        .collect();
    let centre = DVec3::from_array(object.center.map(f64::from));
    let size = object.size.map(f64::from);
    // Silhouette ≈ a disc whose radius is half the geometric mean of the box's edges.
    let radius = 0.5 * (size[0] * size[1] * size[2]).cbrt();
    let area = std::f64::consts::PI * radius * radius;
    // View from the demo's standing viewpoint, the way a person would look at the object.
    let direction = (DVec3::from_array(DEMO_VIEWPOINT.map(f64::from)) - centre).normalize();
    let mut distance = framing_distance(area, ratio, calibration);
    let pose_at = |d: f64| Pose::look_at(centre + direction * d, centre, DVec3::Z);
    for _ in 0..2 {
        let coverage = measure_coverage(&scene, &mask, &pose_at(distance)?, calibration, device)?;
        tracing::debug!(distance, coverage, "camera distance calibration");
        if coverage > 0.0 {
            distance *= (coverage / ratio).sqrt();
        }
    }
    Ok(BenchScene {
        name: "demo".into(),
        pose: pose_at(distance)?,
        scene,
        mask,
    })
}

/// A real scene seen from outside its robust bounds' sphere (30° around up, 25° above), the
/// object a sphere of Gaussians at its centre sized to cover about `ratio` of the frame.
pub fn file_bench_scene(
    path: &Path,
    ratio: f64,
    calibration: &Intrinsics,
    device: &Device,
) -> Result<BenchScene> {
    check_target_ratio(ratio)?;
    let scene = read_scene(path, &ReadOptions::default())?.scene;
    let bounds = scene
        .robust_bounds(0.02)
        .ok_or_else(|| anyhow!("{} holds no Gaussian", path.display()))?;
    let centre = DVec3::from_array(bounds.center().map(f64::from));
    let up = DVec3::from_array(resolve_up(None, false, &scene).up);
    let half = DVec3::from_array(bounds.size().map(f64::from)).length() * 0.5;
    let (tan_x, _) = calibration.tan_half_fov();
    let distance = half.max(1e-3) / tan_x.atan().sin();
    let pose = Orbit::new(centre, up, DVec3::ZERO, 1.0).pose_degrees(30.0, 25.0, distance)?;
    // The object: Gaussians within ρ of the centre, ρ sized for the target coverage, then
    // corrected from measured coverage (real scenes are not uniformly dense).
    let mut rho =
        framing_distance(1.0, ratio, calibration).recip() * distance / std::f64::consts::PI.sqrt();
    let sphere = |rho: f64| -> Vec<f32> {
        scene
            .means
            .iter()
            .map(|m| {
                let d = DVec3::from_array(m.map(f64::from)) - centre;
                if d.length() <= rho { 1.0 } else { 0.0 }
            })
            .collect()
    };
    for _ in 0..4 {
        let coverage = measure_coverage(&scene, &sphere(rho), &pose, calibration, device)?;
        tracing::debug!(rho, coverage, distance, "object sphere calibration");
        let factor = if coverage > 0.0 {
            (ratio / coverage).sqrt().clamp(0.5, 2.0)
        } else {
            2.0
        };
        rho *= factor;
    }
    let mask = sphere(rho);
    Ok(BenchScene {
        name: path
            .file_name()
            .map_or_else(|| "scene".into(), |n| n.to_string_lossy().into_owned()),
        scene,
        mask,
        pose,
    })
}
