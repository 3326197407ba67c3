//! The outputs stage's judgement of a trajectory: per-window metrics at the output resolution
//! on a fixed time grid, each window's verdict, and LDJ ([`Evaluation`],
//! [`Experiment::evaluate`]); the frames add their wobble ([`Evaluation::with_frames`]).

use anyhow::{Context, Result};
use splatraj_traj::metrics::{
    Smoothness, WindowMetrics, WindowObject, ZoomAt, trajectory_ldj, verdict, window_metrics_zoomed,
};
use splatraj_traj::trajectory::Trajectory;

use crate::prepare::experiment::Experiment;

/// Share of a window at each end left out of its wobble (see [`Evaluation::with_frames`]): the
/// quarters where the start pans from and to the neighbours (`ROUTE_TRANSITION`), as the
/// `framed` check leaves them out. Measured at 0.15 on the first-try biker, the turn of a pan
/// away (the framing error's V as the camera leaves the jacket) counted as a wobble of 0.10.
pub const WOBBLE_EDGE: f64 = 0.25;

/// Metrics of a trajectory: per window and smoothness.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// Per-window TCE, TRE, IoU, visibility at the output resolution, each with its verdict.
    pub windows: Vec<WindowMetrics>,
    /// LDJ of the camera centre and rotation.
    pub ldj: Smoothness,
}

impl Evaluation {
    /// Every failed check of every window, as sentences naming the query, what is wrong and
    /// the likely fix (empty when every window passes).
    pub fn problems(&self) -> Vec<String> {
        self.windows
            .iter()
            .filter_map(|w| w.verdict.as_ref())
            .flat_map(|v| v.problems.iter().cloned())
            .collect()
    }

    /// Adds what the rendered frames tell (each window's framing wobble over its frames at
    /// `fps`, [`splatraj_traj::metrics::wobble()`]) and judges every window again.
    ///
    /// A window's wobble is taken over its frames that show the object, leaving out the first
    /// and last [`WOBBLE_EDGE`] of the window, where the camera pans from and to the
    /// neighbouring objects (a pan is a change the wobble must not count), over each unbroken
    /// run of such frames.
    pub fn with_frames(&mut self, frames: &[crate::frame_metrics::FrameMetrics], fps: f64) {
        let n = self.windows.len().max(1);
        for (i, w) in self.windows.iter_mut().enumerate() {
            let (start, end) = splatraj_traj::optimise::sampling::window_bounds(i, n);
            let edge = WOBBLE_EDGE * (end - start);
            let kept: Vec<&crate::frame_metrics::FrameMetrics> = frames
                .iter()
                .filter(|f| {
                    f.window == i && f.coverage > 0.0 && f.t >= start + edge && f.t <= end - edge
                })
                .collect();
            // Each unbroken run of frames on its own: frames on either side of a moment out
            // of frame are not neighbours, and the jump between them is no swing.
            w.framing.wobble = kept
                .chunk_by(|a, b| b.frame == a.frame + 1)
                .filter_map(|run| {
                    let series: Vec<f64> = run.iter().filter_map(|f| f.tce).collect();
                    splatraj_traj::metrics::wobble(&series, fps)
                })
                .reduce(f64::max);
            w.verdict = Some(verdict(w));
        }
    }

    /// How many windows fail their verdict.
    pub fn failing(&self) -> usize {
        self.windows
            .iter()
            .filter(|w| w.verdict.as_ref().is_some_and(|v| !v.pass))
            .count()
    }
}

impl Experiment {
    /// Per-window metrics at the output resolution (`output.metric_samples` per window) and
    /// LDJ (`output.ldj_samples`) of `trajectory`.
    pub fn evaluate(&self, trajectory: &Trajectory) -> Result<Evaluation> {
        self.evaluate_since(trajectory, splatraj_scene::stop::Since::now())
    }

    /// [`Experiment::evaluate`] that a stop requested `since` ends before the next window's
    /// metrics ([`splatraj_scene::stop::Stopped`]; nothing is written).
    pub fn evaluate_since(
        &self,
        trajectory: &Trajectory,
        since: splatraj_scene::stop::Since,
    ) -> Result<Evaluation> {
        let output = self.output_intrinsics()?;
        let plain = self.plain_scene();
        let n = self.windows.len();
        let pose_at = |times: &[f64]| trajectory.poses_at(times);
        let zoom_at = |times: &[f64]| trajectory.zooms_at(times);
        let zoom_at: Option<ZoomAt<'_>> = trajectory.lens.is_some().then_some(&zoom_at);
        let windows = (0..n)
            .map(|i| {
                since.stop_point(|| format!("the metrics of {i} of {n} windows were computed"))?;
                let samples = self.config.output.metric_samples;
                let path = (&pose_at as &dyn Fn(&[f64]) -> Vec<[f64; 6]>, zoom_at);
                self.window_metrics(&plain, i, (i, n), samples, &output, path)
            })
            .collect::<Result<Vec<_>>>()?;
        let mut windows = self.with_path_metrics(windows, trajectory)?;
        for w in &mut windows {
            w.verdict = Some(verdict(w));
        }
        let ldj = trajectory_ldj(trajectory, self.config.output.ldj_samples);
        Ok(Evaluation { windows, ldj })
    }

    /// Metrics of window `i`'s object on the time grid of window `grid.0` of `grid.1`, at the
    /// poses `pose_at` gives for the grid times, through the zoom `zoom_at` gives (None: the
    /// fixed lens).
    pub(crate) fn window_metrics(
        &self,
        plain: &splatraj_render::render::DeviceScene,
        i: usize,
        (index, n): (usize, usize),
        samples: usize,
        intrinsics: &splatraj_render::camera::Intrinsics,
        (pose_at, zoom_at): PathAt<'_>,
    ) -> Result<WindowMetrics> {
        let w = &self.windows[i];
        let alone = self.object_alone(i);
        let object = WindowObject {
            name: &w.name,
            mask: &w.mask,
            alone: &alone,
            target_ratio: w.context.target_ratio,
            rasterizer: self.config.rasterizer,
            bounds: self.boxes.get(i).copied(),
        };
        window_metrics_zoomed(
            plain, &object, index, n, samples, intrinsics, pose_at, zoom_at,
        )
        .with_context(|| format!("metrics of window {i}"))
    }
}

/// Where a path is at given times: its poses, and its zooms when the lens zooms.
pub(crate) type PathAt<'a> = (&'a dyn Fn(&[f64]) -> Vec<[f64; 6]>, Option<ZoomAt<'a>>);
