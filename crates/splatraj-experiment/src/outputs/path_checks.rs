//! The per-window clearance and motion metrics of a trajectory (`metrics.json`'s `path` of
//! each window; the clearance geometry from [`crate::prepare::clearance`]), its shot adherence
//! (`shot`, with a dolly zoom's hold of the size from the frames) and the occlusion's longest
//! stretch in seconds.

use anyhow::Result;
use splatraj_render::camera::Intrinsics;
use splatraj_traj::metrics::{
    WindowMetrics, ZoomFrame, shot_metrics, shot_path_metrics, zoom_hold,
};
use splatraj_traj::trajectory::Trajectory;

use crate::frame_metrics::FrameMetrics;

use crate::prepare::experiment::Experiment;

impl Experiment {
    /// `windows` with each window's clearance (when the clearance cost is on) and motion
    /// metrics of `trajectory` filled in, on a grid of at least `output.ldj_samples` times;
    /// for a window with a shot, its deviation from the shot (`output.ldj_samples` / windows
    /// times per window); with `[output] seconds`, the longest occlusion in seconds.
    pub fn with_path_metrics(
        &self,
        mut windows: Vec<WindowMetrics>,
        trajectory: &Trajectory,
    ) -> Result<Vec<WindowMetrics>> {
        let occupancy = self.occupancy()?;
        let margin = self.clearance_margin();
        let clearance = occupancy.as_ref().zip(margin);
        let centres: Vec<[f64; 3]> = self
            .windows
            .iter()
            .map(|w| w.context.object_centre)
            .collect();
        // A cut is no motion: rates are taken within each shot only.
        let paths = shot_path_metrics(
            &|t: &[f64]| trajectory.poses_at(t),
            &trajectory.model().shots(windows.len()),
            self.config.output.ldj_samples,
            clearance,
            self.path_seconds(),
            &centres,
        );
        let n = windows.len();
        let shots = self.shot_paths()?;
        let per_window = (self.config.output.ldj_samples / n.max(1)).max(2);
        for (i, (w, p)) in windows.iter_mut().zip(paths).enumerate() {
            w.path = Some(p);
            w.shot = shots.get(i).copied().flatten().map(|shot| {
                shot_metrics(&shot, i, n, per_window, &|t: &[f64]| trajectory.poses_at(t))
            });
            if let Some(seconds) = self.path_seconds() {
                w.occlusion = w.occlusion.clone().with_window_seconds(seconds / n as f64);
            }
        }
        Ok(windows)
    }

    /// `windows` (of the frames' evaluation) with each dolly-zoom window's `shot.zoom` filled
    /// in from the rendered frames: their coverage (`metrics`, one per frame) and their
    /// cameras (`cameras`, frame k's at index k) ([`zoom_hold`]); the other windows as they
    /// are.
    pub fn with_zoom_holds(
        &self,
        windows: &mut [WindowMetrics],
        metrics: &[FrameMetrics],
        cameras: &[Intrinsics],
    ) -> Result<()> {
        let shots = self.shot_paths()?;
        let n = windows.len();
        for (i, w) in windows.iter_mut().enumerate() {
            let zooms = shots
                .get(i)
                .copied()
                .flatten()
                .is_some_and(|s| s.zoom_radius.is_some());
            let Some(shot) = w.shot.as_mut().filter(|_| zooms) else {
                continue;
            };
            let frames: Vec<ZoomFrame> = metrics
                .iter()
                .filter(|f| f.window == i)
                .filter_map(|f| {
                    Some(ZoomFrame {
                        t: f.t,
                        coverage: f.coverage,
                        fov_x_degrees: cameras.get(f.frame)?.horizontal_fov_degrees(),
                    })
                })
                .collect();
            shot.zoom = zoom_hold(&frames, i, n);
        }
        Ok(())
    }
}
