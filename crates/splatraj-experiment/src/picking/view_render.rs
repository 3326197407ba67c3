//! One view of a scene rendered for picking: its colour as a PNG and its depth per pixel, what
//! the views page shows (and its strip of candidate ups, [`crate::picking::up_choices`]).

use anyhow::Result;
use splatraj_lift::View;
use splatraj_render::host::to_host;
use splatraj_render::images::{png_rgb8, rgb8};
use splatraj_render::render::{Channel, DeviceScene, RenderError, RenderRequest, render_poses};
use splatraj_report::views_page::PickView;

/// A pixel's depth is kept where the render covers at least this share of it; elsewhere the
/// pixel is background (a click there picks nothing) rather than a depth diluted by emptiness.
pub const MIN_COVER: f64 = 0.5;

/// Colour and depth of one view.
pub(crate) fn render_view(
    uploaded: &DeviceScene,
    view: &View,
    caption: String,
) -> Result<PickView> {
    let k = view.intrinsics;
    let request = RenderRequest::new(k, vec![Channel::Rgb, Channel::Depth]);
    let rendered = render_poses(uploaded, &[view.pose], &request)?;
    let alpha = rendered.alpha().ok_or(RenderError::AlphaDropped)?;
    let pixels = to_host(rendered.images)?;
    let alpha = to_host(alpha)?;
    let png = png_rgb8(&rgb8(&pixels, 4, None), k.width, k.height)?;
    let depth = pixels
        .chunks_exact(4)
        .zip(&alpha)
        .map(|(px, &a)| {
            if a >= MIN_COVER {
                (px[3] / a) as f32
            } else {
                f32::NAN
            }
        })
        .collect();
    Ok(PickView {
        caption,
        intrinsics: k,
        pose: view.pose,
        png,
        depth,
    })
}
