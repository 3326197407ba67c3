//! A camera that shows a selection: the picture `splatraj query` draws.

use anyhow::{Result, anyhow, bail};
use glam::DVec3;
use serde::Serialize;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::to_host;
use splatraj_render::images::{highlight, png_rgb};
use splatraj_render::orbit::Orbit;
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, RenderRequest, render_poses,
};
use splatraj_scene::{Scene, resolve_up};
use splatraj_semantic::Target;

/// Horizontal field of view of the diagnostic camera, degrees.
pub const FOV_X_DEGREES: f64 = 60.0;
/// Share of the frame's smaller side the selection's extent spans.
const FRAME_SHARE: f64 = 1.0 / 3.0;
/// Azimuths tried around the preferred view, degrees (0 first: the preferred one).
const AZIMUTHS: [f64; 8] = [0.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0];
/// The preferred view is kept while it shows at least this share of the best view's mask.
const KEEP_PREFERRED: f64 = 0.5;
/// Width of the low-resolution mask renders that compare the views.
const SEARCH_WIDTH: usize = 64;
/// Strength of the selection's highlight.
const HIGHLIGHT: f64 = 0.6;

/// How the diagnostic view is chosen.
#[derive(Debug, Clone, Copy)]
pub struct ViewOptions {
    /// Preferred elevation above the horizontal, degrees.
    pub elevation_degrees: f64,
    /// Try other views when the selection is hidden in the preferred one.
    pub search: bool,
    /// World up (unit length); `None`: guessed from the scene.
    pub up: Option<[f64; 3]>,
}

/// The diagnostic camera.
#[derive(Debug, Clone, Serialize)]
pub struct CameraReport {
    /// Camera centre.
    pub eye: [f64; 3],
    /// Point looked at (the selection's centre).
    pub look_at: [f64; 3],
    /// World up used (guessed, or +z).
    pub up: [f64; 3],
    /// Whether `up` came from the scene (`guess`) or the fallback (`default`).
    pub up_from: &'static str,
    /// Distance from the eye to the centre.
    pub distance: f64,
    /// Φ = [ω, c].
    pub pose: [f64; 6],
    /// Horizontal field of view, degrees.
    pub fov_x_degrees: f64,
    /// Azimuth of the view from the preferred one (toward the scene's middle), degrees.
    pub azimuth_degrees: f64,
    /// Elevation of the view above the horizontal, degrees.
    pub elevation_degrees: f64,
    /// Views compared by their visible mask (0: no search).
    pub searched_views: usize,
    /// Picture width.
    pub width: usize,
    /// Picture height.
    pub height: usize,
}

/// A camera looking at the target's centre at the distance where the target's extent spans
/// a third of the frame's smaller side.
///
/// The preferred view looks down from `elevation_degrees` above the horizontal (w.r.t. the
/// guessed up axis, else +z), from the side of the scene's middle, so that in a room the
/// camera stands on the room's side of the object rather than behind a wall. Guessed axes
/// can be wrong and objects hidden, so unless `search` is off, the mask is also rendered
/// (small, pruned to the object) from other azimuths and from below, and the preferred view
/// gives way to the one that shows the most of the selection when it shows less than half
/// of that.
pub fn diagnostic_camera(
    scene: &Scene,
    uploaded: &DeviceScene,
    target: &Target,
    k: &Intrinsics,
    view: ViewOptions,
) -> Result<(Pose, CameraReport)> {
    let resolved = resolve_up(view.up, false, scene);
    let up = DVec3::from_array(resolved.up);
    let centre = DVec3::from_array(target.centre.map(f64::from));
    let bounds = scene
        .robust_bounds(0.02)
        .ok_or_else(|| anyhow!("the scene holds no Gaussian"))?;
    let scene_centre = DVec3::from_array(bounds.center().map(f64::from));
    let scene_size = DVec3::from_array(bounds.size().map(f64::from)).length();
    let orbit = Orbit::new(centre, up, scene_centre - centre, scene_size);

    // The extent's diagonal, floored so that a single Gaussian still gets a sensible view.
    let size = DVec3::from_array(target.extent.map(f64::from))
        .length()
        .max(scene_size * 0.01)
        .max(1e-3);
    let pixels = (k.width.min(k.height) as f64) * FRAME_SHARE;
    let distance = k.fx.min(k.fy) * size / pixels;

    let elevation = view.elevation_degrees;
    let mut views: Vec<(f64, f64)> = AZIMUTHS.iter().map(|&a| (a, elevation)).collect();
    if elevation != 0.0 {
        views.extend(AZIMUTHS.iter().map(|&a| (a, -elevation)));
    }
    if !view.search {
        views.truncate(1);
    }
    let poses = views
        .iter()
        .map(|&(a, e)| orbit.pose_degrees(a, e, distance))
        .collect::<Result<Vec<Pose>, _>>()?;

    let mut chosen = 0;
    let mut shown = Vec::new();
    if poses.len() > 1 {
        let height = ((SEARCH_WIDTH * k.height) as f64 / k.width as f64)
            .round()
            .max(1.0) as usize;
        let small = Intrinsics::from_fov_x(FOV_X_DEGREES, SEARCH_WIDTH, height)?;
        let request = RenderRequest {
            pruning: Pruning::ObjectOnly,
            alpha: AlphaChannel::Dropped,
            ..RenderRequest::new(small, vec![Channel::Mask(target.mask.clone())])
        };
        let images = to_host(render_poses(uploaded, &poses, &request)?.images)?;
        let per_view = small.width * small.height;
        shown = images
            .chunks_exact(per_view)
            .map(|image| image.iter().sum::<f64>() / per_view as f64)
            .collect::<Vec<f64>>();
        let best = (0..shown.len())
            .max_by(|&a, &b| shown[a].total_cmp(&shown[b]))
            .unwrap_or(0);
        if shown[0] < KEEP_PREFERRED * shown[best] {
            chosen = best;
        }
    }
    let pose = poses[chosen];
    let (azimuth_degrees, elevation_degrees) = views[chosen];
    let report = CameraReport {
        eye: pose.0[3..6].try_into().expect("3 values"),
        look_at: centre.to_array(),
        up: up.to_array(),
        up_from: resolved.source.name(),
        distance,
        pose: pose.0,
        fov_x_degrees: FOV_X_DEGREES,
        azimuth_degrees,
        elevation_degrees,
        searched_views: shown.len(),
        width: k.width,
        height: k.height,
    };
    Ok((pose, report))
}

/// The RGB render at `pose` with `target` blended over it as magenta, as PNG bytes, and the
/// share of pixels whose mask exceeds 0.5.
pub fn highlighted_picture(
    scene: &DeviceScene,
    target: &Target,
    pose: &Pose,
    k: &Intrinsics,
) -> Result<(Vec<u8>, f64)> {
    let request = RenderRequest::new(*k, vec![Channel::Rgb, Channel::Mask(target.mask.clone())]);
    let pixels = to_host(render_poses(scene, &[*pose], &request)?.images)?;
    highlighted_png(&pixels, k)
}

/// `pixels` `[H·W·4]` (R, G, B, mask) with the mask blended over as magenta, as PNG bytes,
/// and the share of pixels whose mask exceeds 0.5.
pub fn highlighted_png(pixels: &[f64], k: &Intrinsics) -> Result<(Vec<u8>, f64)> {
    let n = k.width * k.height;
    if pixels.len() != n * 4 {
        bail!(
            "the render returned {} values for a {}×{} picture with 4 channels",
            pixels.len(),
            k.width,
            k.height
        );
    }
    let highlighted = pixels.chunks_exact(4).filter(|px| px[3] > 0.5).count();
    let png = png_rgb(&highlight(pixels, HIGHLIGHT), k)?;
    Ok((png, highlighted as f64 / n as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn highlight_blends_magenta() {
        let k = Intrinsics::from_fov_x(60.0, 2, 1).unwrap();
        let (png, share) = highlighted_png(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0], &k).unwrap();
        assert_eq!(share, 0.5);
        let image = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(image.get_pixel(0, 0).0, [153, 31, 122]);
        assert_eq!(image.get_pixel(1, 0).0, [255, 255, 255]);
    }
}
