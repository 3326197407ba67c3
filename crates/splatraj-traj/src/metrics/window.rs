//! Per-window image metrics of a trajectory: TCE, TRE, IoU and visibility (docs/conventions.md
//! "Metrics").
//!
//! Each window is evaluated on a fixed grid of times (the middles of `samples` equal strata,
//! so runs are comparable), never on the optimiser's random samples. At each time the object's
//! mask is rendered twice: with the whole scene (what the camera sees, occluders included) and
//! with the object alone; TCE and TRE come from the first, IoU compares the two. A sample
//! counts as showing the object when its visible mask has a pixel at or above the IoU threshold
//! (0.5); the window's `visible` is true when every sample shows it.
//!
//! **Occlusion.** A sample's occluded share is 1 − Σ visible mask / Σ mask of the object alone
//! (what the occluders take away from what the frame would show; measured only where the
//! object alone is in frame). The sample is *hidden* when more than half of the object is
//! occluded. `occlusion.longest_hidden` is the longest run of consecutive hidden samples as a
//! share of the window (consecutive samples are adjacent strata, each 1/`samples` of the
//! window), and in seconds when the caller knows the window's duration. An object out of
//! frame is not "hidden": `visible_fraction` reports that.
//!
//! **Framing where it is judged** ([`Framing`]). The window's first and last quarters are where
//! the camera pans from the previous object and on to the next; the framing a viewer judges
//! is the middle half's. `framing` holds TCE and coverage averaged over the middle half's
//! samples that show the object (None when none does: an object never seen has no framing
//! error, rather than the 0 an empty mask's TCE would give), the same TCE over the whole
//! window's samples that show it, and the share of samples whose camera centre lies inside the
//! object's box (a camera inside the object sees its inside, or nothing).
//!
//! **Framed share.** A mean can hide a window that is centred half of the time and far off
//! the rest. `framing.framed_share` counts, over the samples of the window's middle
//! [`MIDDLE_SHARE`] (stratum middles within 20 %–80 % of the window, where no pan should be),
//! the share that both show the object and have a TCE of at most [`FRAMED_TCE`]. The grid
//! must be dense there for the share to mean anything: at the default 30 samples per window
//! (`output.metric_samples`) 18 fall in the middle 60 %, one every 0.1 s of a 3 s window (every
//! third frame at 30 fps), so the share moves in steps of 1/18.

use burn::tensor::{Tensor, TensorData};
use serde::Serialize;
use splatraj_render::camera::{Intrinsics, Pose as CameraPose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::pass_size::{passes, poses_per_pass};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, Rasterizer, RenderError, RenderRequest, Zoom,
    render_poses,
};

use crate::costs::{
    HostMoments, IOU_THRESHOLD, box_from_hits, box_iou, mask_hits, moment_sums, tce_on_host,
    tre_on_host,
};
use crate::optimise::sampling::stratified_times;
use crate::trajectory::Pose;

/// Share of the window, about its middle, where the object must stay framed (module docs).
pub const MIDDLE_SHARE: f64 = 0.6;

/// Largest TCE of a sample counted as framed: the object's centre within 15 % of the frame's
/// size from the middle (the verdict holds the middle half's mean to the same bound).
pub const FRAMED_TCE: f64 = 0.15;

/// Metrics of one query window, averaged over its samples.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowMetrics {
    /// Window index (0-based).
    pub window: usize,
    /// The query.
    pub name: String,
    /// Samples evaluated.
    pub samples: usize,
    /// Mean target centring error over the samples; `None` (`null` in `metrics.json`) when no
    /// sample shows the object: an object never seen has no centring error, and the empty
    /// mask's TCE of 0 would read as perfect framing.
    pub tce: Option<f64>,
    /// Mean target ratio error.
    pub tre: f64,
    /// Mean bounding-box IoU of the visible mask and the object alone.
    pub iou: f64,
    /// Mean share of the frame the visible object covers.
    pub coverage: f64,
    /// The share it should cover (TRE's target).
    pub target_ratio: f64,
    /// Share of samples that show the object.
    pub visible_fraction: f64,
    /// Whether every sample shows the object.
    pub visible: bool,
    /// Worst TCE over the samples (`None` when no sample shows the object, as `tce`).
    pub tce_max: Option<f64>,
    /// Worst TRE over the samples.
    pub tre_max: f64,
    /// How much of the object occluders hide (module docs).
    pub occlusion: Occlusion,
    /// Clearance and motion on the window's stretch of path (filled in by the caller from
    /// [`super::path_metrics`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<super::PathMetrics>,
    /// Deviation from the window's shot preset, when it has one (filled in by the caller
    /// from [`super::shot_metrics`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shot: Option<super::ShotMetrics>,
    /// Framing where it is judged, and the camera inside the object (module docs).
    pub framing: Framing,
    /// Whether the window passes the first-try checks (filled in by the caller from
    /// [`super::verdict()`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verdict: Option<super::Verdict>,
    /// The lens at each sample when the trajectory zooms (absent for the fixed lens).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lens: Option<LensSamples>,
}

/// The lens at each of a window's samples (docs/conventions.md "The lens").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LensSamples {
    /// The samples' times t ∈ [0, 1].
    pub t: Vec<f64>,
    /// The zoom s at each (focal lengths fx·s, fy·s).
    pub zoom: Vec<f64>,
    /// Horizontal field of view, degrees, at each.
    pub fov_x_degrees: Vec<f64>,
    /// Vertical field of view, degrees, at each.
    pub fov_y_degrees: Vec<f64>,
}

/// Framing over the samples that show the object (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Framing {
    /// Mean TCE over the middle half's samples that show the object.
    pub tce_middle: Option<f64>,
    /// Mean coverage over the same samples.
    pub coverage_middle: Option<f64>,
    /// Mean TCE over all of the window's samples that show the object.
    pub tce_in_view: Option<f64>,
    /// Share of the middle [`MIDDLE_SHARE`]'s samples that show the object with a TCE of at
    /// most [`FRAMED_TCE`] (None: no sample lies there).
    pub framed_share: Option<f64>,
    /// Share of the samples whose camera centre lies inside the object's box.
    pub inside_object: f64,
    /// The wobble of the frames' TCE in the window ([`super::wobble()`]), once frames were
    /// rendered (filled in by the caller).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wobble: Option<f64>,
}

/// What occluders hide of a window's object (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Occlusion {
    /// Mean occluded share over the samples whose object alone is in frame (0 when none is).
    pub mean_occluded: f64,
    /// Share of the samples that are hidden (more than half of the object occluded).
    pub hidden_fraction: f64,
    /// Longest run of consecutive hidden samples, as a share of the window.
    pub longest_hidden: f64,
    /// `longest_hidden` in seconds, when the trajectory's duration is known (filled in by
    /// the caller with [`Occlusion::with_window_seconds`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub longest_hidden_seconds: Option<f64>,
}

impl Occlusion {
    /// From each sample's occluded share in time order (None: the object alone is out of
    /// frame there).
    pub fn from_shares(shares: &[Option<f64>]) -> Self {
        let framed: Vec<f64> = shares.iter().flatten().copied().collect();
        let hidden: Vec<bool> = shares.iter().map(|s| s.is_some_and(|s| s > 0.5)).collect();
        let mut longest = 0;
        let mut run = 0;
        for &h in &hidden {
            run = if h { run + 1 } else { 0 };
            longest = longest.max(run);
        }
        let n = shares.len().max(1) as f64;
        Self {
            mean_occluded: framed.iter().sum::<f64>() / framed.len().max(1) as f64,
            hidden_fraction: hidden.iter().filter(|&&h| h).count() as f64 / n,
            longest_hidden: longest as f64 / n,
            longest_hidden_seconds: None,
        }
    }

    /// The same with `longest_hidden_seconds` for a window lasting `seconds`.
    pub fn with_window_seconds(mut self, seconds: f64) -> Self {
        self.longest_hidden_seconds = Some(self.longest_hidden * seconds);
        self
    }
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
    /// The object's box as (centre, half extent), for `framing.inside_object` (None: 0).
    pub bounds: Option<([f64; 3], [f64; 3])>,
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
    window_metrics_zoomed(
        scene, object, index, windows, samples, intrinsics, pose_at, None,
    )
}

/// The zoom s of a path at given times (docs/conventions.md "The lens").
pub type ZoomAt<'a> = &'a dyn Fn(&[f64]) -> Vec<f64>;

/// [`window_metrics`] of a camera that zooms: `zoom_at` gives the zoom s at the grid times
/// (the masks are rendered through fx·s, fy·s, and the metrics record the lens per sample).
#[allow(clippy::too_many_arguments)]
pub fn window_metrics_zoomed(
    scene: &DeviceScene,
    object: &WindowObject<'_>,
    index: usize,
    windows: usize,
    samples: usize,
    intrinsics: &Intrinsics,
    pose_at: &dyn Fn(&[f64]) -> Vec<Pose>,
    zoom_at: Option<ZoomAt<'_>>,
) -> Result<WindowMetrics, RenderError> {
    let times = stratified_times(index, windows, samples.max(1), None);
    let zooms = zoom_at.map(|z| z(&times));
    let lens = zooms.as_ref().map(|zooms| {
        let cameras: Vec<Intrinsics> = zooms
            .iter()
            .map(|&s| intrinsics.zoomed(s).unwrap_or(*intrinsics))
            .collect();
        LensSamples {
            t: times.clone(),
            zoom: zooms.clone(),
            fov_x_degrees: cameras.iter().map(|k| k.horizontal_fov_degrees()).collect(),
            fov_y_degrees: cameras.iter().map(|k| k.vertical_fov_degrees()).collect(),
        }
    });
    let poses = pose_at(&times);
    let poses: Vec<CameraPose> = poses.into_iter().map(CameraPose).collect();
    let inside = poses
        .iter()
        .filter(|p| {
            object.bounds.is_some_and(|(centre, half)| {
                let offset = (p.centre() - glam::DVec3::from(centre)).abs();
                offset.cmple(glam::DVec3::from(half)).all()
            })
        })
        .count();
    // In passes that fit the device (30 masks of 1280×720 with their alpha are 221 MB, more
    // than a software GPU's largest buffer), each pass read back and reduced before the next.
    let per_pass = poses_per_pass(
        &scene.device(),
        scene.dtype(),
        intrinsics.width,
        intrinsics.height,
        1,
    );
    // One pass in flight while the one before is read: on a GPU the host decides and bins the
    // next samples while the device composites these.
    let mut each = Vec::with_capacity(poses.len());
    let mut in_flight: Option<QueuedSamples> = None;
    for pass in passes(poses.len(), per_pass) {
        let zoom = zooms.as_ref().map(|z| z[pass.clone()].to_vec());
        let queued = queue_samples(scene, object, intrinsics, &poses[pass], zoom)?;
        if let Some(done) = in_flight.replace(queued) {
            each.extend(done.finish()?);
        }
    }
    if let Some(done) = in_flight {
        each.extend(done.finish()?);
    }
    let batch = each.len();
    let column = |f: fn(&SampleMetrics) -> f64| each.iter().map(f).collect::<Vec<f64>>();
    let (tces, tres, coverages, ious) = (
        column(|m| m.tce),
        column(|m| m.tre),
        column(|m| m.coverage),
        column(|m| m.iou),
    );
    let shows: Vec<bool> = each.iter().map(|m| m.shows).collect();
    let shown = shows.iter().filter(|&&s| s).count();
    // The middle half of the window: samples whose stratum middle lies in [¼, ¾] of it.
    let middle = |k: usize| {
        let s = (k as f64 + 0.5) / batch.max(1) as f64;
        (0.25..=0.75).contains(&s)
    };
    let mean_where = |values: &[f64], keep: &dyn Fn(usize) -> bool| {
        let picked: Vec<f64> = (0..values.len())
            .filter(|&k| shows[k] && keep(k))
            .map(|k| values[k])
            .collect();
        (!picked.is_empty()).then(|| picked.iter().sum::<f64>() / picked.len() as f64)
    };
    let in_middle_share = |k: usize| {
        let s = (k as f64 + 0.5) / batch.max(1) as f64;
        (s - 0.5).abs() <= 0.5 * MIDDLE_SHARE + 1e-12
    };
    let judged: Vec<usize> = (0..batch).filter(|&k| in_middle_share(k)).collect();
    let framed = judged
        .iter()
        .filter(|&&k| shows[k] && tces[k] <= FRAMED_TCE)
        .count();
    let framing = Framing {
        framed_share: (!judged.is_empty()).then(|| framed as f64 / judged.len() as f64),
        tce_middle: mean_where(&tces, &middle),
        coverage_middle: mean_where(&coverages, &middle),
        tce_in_view: mean_where(&tces, &|_| true),
        inside_object: inside as f64 / batch.max(1) as f64,
        wobble: None,
    };
    let occluded: Vec<Option<f64>> = each.iter().map(|m| m.occluded).collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let max = |v: &[f64]| v.iter().copied().fold(f64::NAN, f64::max);
    Ok(WindowMetrics {
        window: index,
        name: object.name.to_string(),
        samples: batch,
        tce: (shown > 0).then(|| mean(&tces)),
        tre: mean(&tres),
        iou: mean(&ious),
        coverage: mean(&coverages),
        target_ratio: object.target_ratio,
        visible_fraction: shown as f64 / batch.max(1) as f64,
        visible: shown == batch,
        tce_max: (shown > 0).then(|| max(&tces)),
        tre_max: max(&tres),
        occlusion: Occlusion::from_shares(&occluded),
        path: None,
        shot: None,
        framing,
        verdict: None,
        lens,
    })
}

/// What one metric sample's masks say.
struct SampleMetrics {
    tce: f64,
    tre: f64,
    coverage: f64,
    /// IoU of the boxes of the visible mask and of the object alone.
    iou: f64,
    /// Whether the visible mask shows the object (a pixel at or above the IoU threshold).
    shows: bool,
    /// The occluded share, where the object alone is in frame and draws something.
    occluded: Option<f64>,
}

/// A pass of metric samples queued on the device: everything [`SampleMetrics`] needs, in one
/// tensor to read (see [`queue_samples`]).
struct QueuedSamples {
    /// The visible mask's moment sums `[B·4]` ([`moment_sums`]), the object alone's mass
    /// `[B]`, then the row hits `[2·B·H]` and the column hits `[2·B·W]` of the visible mask
    /// and the object alone.
    read: Tensor<1>,
    /// The object's target ratio, for TRE.
    target_ratio: f64,
    batch: usize,
    height: usize,
    width: usize,
}

/// Queues the metrics of `poses` (one render pass: the visible mask and the object alone),
/// through the lens of `zooms` when the camera zooms, and has the device start on them.
fn queue_samples(
    scene: &DeviceScene,
    object: &WindowObject<'_>,
    intrinsics: &Intrinsics,
    poses: &[CameraPose],
    zooms: Option<Vec<f64>>,
) -> Result<QueuedSamples, RenderError> {
    let zoom = zooms.map(|host| {
        let data = TensorData::new(host.clone(), [host.len()]);
        Zoom::at(
            splatraj_render::host::upload(data, &scene.device(), scene.dtype()),
            host,
        )
    });
    let mask_of = |scene: &DeviceScene, mask: Vec<f32>| -> Result<Tensor<3>, RenderError> {
        let request = RenderRequest {
            pruning: Pruning::ObjectOnly,
            rasterizer: object.rasterizer,
            zoom: zoom.clone(),
            alpha: AlphaChannel::Dropped,
            ..RenderRequest::new(*intrinsics, vec![Channel::Mask(mask)])
        };
        let images = render_poses(scene, poses, &request)?.images;
        let [b, h, w, _] = images.dims();
        Ok(images.reshape([b, h, w]))
    };
    let visible = mask_of(scene, object.mask.to_vec())?;
    let alone = mask_of(object.alone, vec![1.0; object.alone.len()])?;
    let [batch, height, width] = visible.dims();
    // Everything the metrics need in one read (one wait on a GPU), reduced where the masks
    // are: the visible mask's moments (TCE, TRE and coverage are made of them on the host, as
    // a frame's are), the masks' boxes from their row and column hits, the object alone's
    // sum for the occlusion.
    let (seen_rows, seen_columns) = mask_hits(visible.clone(), IOU_THRESHOLD);
    let (alone_rows, alone_columns) = mask_hits(alone.clone(), IOU_THRESHOLD);
    let flat = |t: Tensor<2>| {
        let [a, b] = t.dims();
        t.reshape([a * b])
    };
    let read = Tensor::cat(
        vec![
            flat(moment_sums(visible.unsqueeze_dim(3), 0)),
            alone.sum_dim(2).sum_dim(1).reshape([batch]),
            flat(seen_rows),
            flat(alone_rows),
            flat(seen_columns),
            flat(alone_columns),
        ],
        0,
    );
    scene
        .device()
        .flush()
        .map_err(|e| RenderError::ReadBack(format!("starting the metrics' renders: {e}")))?;
    Ok(QueuedSamples {
        read,
        target_ratio: object.target_ratio,
        batch,
        height,
        width,
    })
}

impl QueuedSamples {
    /// Reads the pass back: each sample's [`SampleMetrics`].
    fn finish(self) -> Result<Vec<SampleMetrics>, RenderError> {
        let Self {
            read,
            target_ratio,
            batch,
            height,
            width,
        } = self;
        let read = to_host(read).map_err(|e| RenderError::ReadBack(e.to_string()))?;
        Ok(sample_metrics_of(&read, target_ratio, batch, height, width))
    }
}

/// Each sample's [`SampleMetrics`] from a pass's values read back ([`QueuedSamples::read`]).
fn sample_metrics_of(
    read: &[f64],
    target_ratio: f64,
    batch: usize,
    height: usize,
    width: usize,
) -> Vec<SampleMetrics> {
    let (sums, rest) = read.split_at(4 * batch);
    let (alone_sums, rest) = rest.split_at(batch);
    let (rows, columns) = rest.split_at(2 * batch * height);
    let moments = HostMoments::from_sums(sums, height * width);
    let box_of = |mask: usize, k: usize| {
        let at = mask * batch + k;
        box_from_hits(
            &rows[at * height..(at + 1) * height],
            &columns[at * width..(at + 1) * width],
        )
    };
    (0..batch)
        .map(|k| {
            let (seen, alone) = (box_of(0, k), box_of(1, k));
            let visible = &moments[k];
            SampleMetrics {
                tce: tce_on_host(visible),
                tre: tre_on_host(visible, target_ratio),
                coverage: visible.coverage(),
                iou: box_iou(seen, alone),
                shows: seen.is_some(),
                occluded: (alone.is_some() && alone_sums[k] > 0.0)
                    .then(|| (1.0 - visible.mass / alone_sums[k]).clamp(0.0, 1.0)),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use burn::tensor::{DType, Device};
    use splatraj_scene::demo::{DemoConfig, demo_layout, demo_scene};

    use super::*;

    /// The window metrics split their samples into passes that fit the device: a sample's
    /// metrics must not depend on which pass it was in, or on that pass's size.
    #[test]
    fn a_sample_measures_the_same_whatever_pass_it_is_in() {
        let scene = demo_scene(&DemoConfig {
            seed: 7,
            gaussians: 3000,
        })
        .unwrap();
        let object = demo_layout().into_iter().next().unwrap();
        let ids = &scene.extras.labels.as_ref().unwrap().ids;
        let keep: Vec<bool> = ids.iter().map(|&id| id == object.id).collect();
        let mask: Vec<f32> = keep.iter().map(|&k| f32::from(u8::from(k))).collect();
        let device = Device::flex();
        let whole = DeviceScene::new(&scene, &device, DType::F64);
        let alone = DeviceScene::new(&scene.subset(&keep), &device, DType::F64);
        let window = WindowObject {
            name: object.name,
            mask: &mask,
            alone: &alone,
            target_ratio: 0.1,
            rasterizer: Rasterizer::default(),
            bounds: None,
        };
        let centre = glam::DVec3::from(object.center.map(f64::from));
        // Seven cameras circling the object at varied distances, some zoomed.
        let poses: Vec<CameraPose> = (0..7)
            .map(|k| {
                let angle = 0.9 * k as f64;
                let eye = centre
                    + glam::DVec3::new(angle.cos(), angle.sin(), 0.3) * (1.0 + 0.4 * k as f64);
                CameraPose::look_at(eye, centre, glam::DVec3::Z).unwrap()
            })
            .collect();
        let zooms: Vec<f64> = (0..7).map(|k| 1.0 + 0.2 * k as f64).collect();
        let k = Intrinsics::from_fov_x(60.0, 64, 48).unwrap();
        let measure = |per_pass: usize| -> Vec<Vec<Option<f64>>> {
            passes(poses.len(), per_pass)
                .flat_map(|pass| {
                    let zoom = Some(zooms[pass.clone()].to_vec());
                    queue_samples(&whole, &window, &k, &poses[pass], zoom)
                        .and_then(QueuedSamples::finish)
                        .unwrap()
                })
                .map(|m| {
                    vec![
                        Some(m.tce),
                        Some(m.tre),
                        Some(m.coverage),
                        Some(m.iou),
                        Some(f64::from(u8::from(m.shows))),
                        m.occluded,
                    ]
                })
                .collect()
        };
        let together = measure(7);
        assert!(
            together.iter().any(|m| m[4] == Some(1.0)),
            "no camera sees the object: the test shows nothing"
        );
        for per_pass in [1, 3] {
            assert_eq!(measure(per_pass), together, "passes of {per_pass}");
        }
    }
}
