//! Per-window image metrics of a trajectory: TCE, TRE, IoU and visibility (docs/conventions.md
//! "Metrics").
//!
//! Each window is evaluated on a fixed grid of times (the middles of `samples` equal strata,
//! so runs are comparable), never on the optimiser's random samples. At each time the object's
//! mask is rendered twice: with the whole scene (what the camera sees, occluders included) and
//! with the object alone; TCE and TRE come from the first, IoU compares the two. A sample
//! counts as showing the object when its visible mask has a pixel at or above the IoU threshold
//! (0.5); the window's `visible` is true when every sample shows it.

use burn::tensor::Tensor;
use serde::Serialize;
use splatraj_render::camera::{Intrinsics, Pose as CameraPose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::render::{
    Channel, DeviceScene, Pruning, Rasterizer, RenderError, RenderRequest, render,
};

use crate::costs::{IOU_THRESHOLD, bbox_iou_batch, coverage, mask_box, tce, tre};
use crate::optimise::sampling::stratified_times;
use crate::trajectory::Pose;

/// Metrics of one query window, averaged over its samples.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowMetrics {
    /// Window index (0-based).
    pub window: usize,
    /// The query.
    pub name: String,
    /// Samples evaluated.
    pub samples: usize,
    /// Mean target centring error.
    pub tce: f64,
    /// Mean target ratio error.
    pub tre: f64,
    /// Mean bounding-box IoU of the visible mask and the object alone.
    pub iou: f64,
    /// Mean share of the frame the visible object covers.
    pub coverage: f64,
    /// Share of samples that show the object.
    pub visible_fraction: f64,
    /// Whether every sample shows the object.
    pub visible: bool,
    /// Worst TCE over the samples.
    pub tce_max: f64,
    /// Worst TRE over the samples.
    pub tre_max: f64,
    /// Clearance and motion on the window's stretch of path (filled in by the caller from
    /// [`super::path_metrics`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<super::PathMetrics>,
}

/// What one window's metrics need: its object and how to frame it.
#[derive(Debug, Clone)]
pub struct WindowObject<'a> {
    /// The query.
    pub name: &'a str,
    /// Per-Gaussian object mask for the whole scene.
    pub mask: &'a [f32],
    /// The object's Gaussians alone (every Gaussian of this scene is the object's).
    pub alone: &'a DeviceScene,
    /// Target ratio r_t of TRE.
    pub target_ratio: f64,
    /// Which rasterizer renders the masks.
    pub rasterizer: Rasterizer,
}

/// Metrics of window `index` of `windows`, at the poses `pose_at` gives for the grid times.
pub fn window_metrics(
    scene: &DeviceScene,
    object: &WindowObject<'_>,
    index: usize,
    windows: usize,
    samples: usize,
    intrinsics: &Intrinsics,
    pose_at: &dyn Fn(&[f64]) -> Vec<Pose>,
) -> Result<WindowMetrics, RenderError> {
    let times = stratified_times(index, windows, samples.max(1), None);
    let poses = pose_at(&times);
    let poses: Vec<CameraPose> = poses.into_iter().map(CameraPose).collect();
    let poses = scene.poses(&poses);
    let mask_of = |scene: &DeviceScene, mask: Vec<f32>| -> Result<Tensor<3>, RenderError> {
        let request = RenderRequest {
            pruning: Pruning::ObjectOnly,
            rasterizer: object.rasterizer,
            ..RenderRequest::new(*intrinsics, vec![Channel::Mask(mask)])
        };
        let images = render(scene, poses.clone(), &request)?.images;
        let [b, h, w, _] = images.dims();
        Ok(images.reshape([b, h, w]))
    };
    let visible = mask_of(scene, object.mask.to_vec())?;
    let alone = mask_of(object.alone, vec![1.0; object.alone.len()])?;
    let host = |t: Tensor<1>| -> Vec<f64> { to_host(t).unwrap_or_default() };
    let tces = host(tce(visible.clone()));
    let tres = host(tre(visible.clone(), object.target_ratio));
    let coverages = host(coverage(visible.clone()));
    let ious = bbox_iou_batch(visible.clone(), alone);
    let [batch, height, width] = visible.dims();
    let pixels = host(visible.reshape([batch * height * width]));
    let shown = pixels
        .chunks_exact(height * width)
        .filter(|m| mask_box(m, width, height, IOU_THRESHOLD).is_some())
        .count();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let max = |v: &[f64]| v.iter().copied().fold(f64::NAN, f64::max);
    Ok(WindowMetrics {
        window: index,
        name: object.name.to_string(),
        samples: batch,
        tce: mean(&tces),
        tre: mean(&tres),
        iou: mean(&ious),
        coverage: mean(&coverages),
        visible_fraction: shown as f64 / batch.max(1) as f64,
        visible: shown == batch,
        tce_max: max(&tces),
        tre_max: max(&tres),
        path: None,
    })
}
