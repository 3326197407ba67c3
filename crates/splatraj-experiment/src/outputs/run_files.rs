//! The outputs of a finished trajectory that other tools read: frames and `video.mp4`, the
//! camera path in every interchange format (`exports/<format>/`), and `report.html`. The
//! frames, the video and the exports share one set of times and poses
//! ([`Experiment::output_frames`]), so an exported path rendered back gives the run's frames.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Result;
use splatraj_scene::stop::Since;
use splatraj_traj::trajectory::{Trajectory, uniform_times};

use crate::outputs::camera_paths::{PathFrames, frame_cuts, write_all_exports};
use crate::outputs::evaluation::Evaluation;
use crate::outputs::path_render::{PathObject, PathRender, RenderedPath, Video, render_path};
use crate::outputs::run_report::write_run_report;
use crate::prepare::experiment::Experiment;

/// What [`Experiment::write_outputs`] measured, and how long its parts took.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// The metrics, each window judged with what its frames show too.
    pub evaluation: Evaluation,
    /// Time of the metrics.
    pub metrics: Duration,
    /// Time of the frames, video and exports.
    pub frames: Duration,
}

impl Experiment {
    /// The outputs of a finished `trajectory` in the run folder `dir`: its metrics and
    /// verdicts ([`Experiment::evaluate`]), the frames, `frame_metrics.csv` and `video.mp4`
    /// (the verdicts judged again with the frames' wobble, [`Evaluation::with_frames`], and a
    /// dolly zoom's hold of its object's size, [`Experiment::with_zoom_holds`]), then
    /// the same poses in every export format. `progress` hears each frame done (of
    /// `output.frame_count`). A stop requested `since` ([`splatraj_scene::stop`]) ends it at
    /// the next whole window of metrics, frame or export format with
    /// [`splatraj_scene::stop::Stopped`].
    pub fn write_outputs(
        &self,
        trajectory: &Trajectory,
        dir: &Path,
        progress: &mut dyn FnMut(usize),
        since: Since,
    ) -> Result<Outputs> {
        splatraj_scene::stop::honour();
        let started = Instant::now();
        let mut evaluation = self.evaluate_since(trajectory, since)?;
        let metrics = started.elapsed();
        // The frames begin their own count of requests: one made before must stop them here.
        since.stop_point(|| "the metrics were computed, no frame is written".to_string())?;
        let started = Instant::now();
        let frames = self.output_frames(trajectory)?;
        if let Some(rendered) = self.write_output_frames(&frames, dir, progress)? {
            // Before `with_frames`, which judges the windows again with what the frames add.
            self.with_zoom_holds(&mut evaluation.windows, &rendered.metrics, &frames.cameras)?;
            evaluation.with_frames(&rendered.metrics, frames.fps);
        }
        self.write_exports(&frames, dir, since)?;
        Ok(Outputs {
            evaluation,
            metrics,
            frames: started.elapsed(),
        })
    }

    /// The frames of the run's output: `output.frame_count()` evenly spaced times over [0, 1],
    /// the trajectory's poses there, the output camera (zoomed by the trajectory's s(t) when
    /// the lens zooms), at `output.fps`.
    pub fn output_frames(&self, trajectory: &Trajectory) -> Result<PathFrames> {
        let times = uniform_times(self.config.output.frame_count(self.windows.len()));
        let poses = trajectory.poses_at(&times);
        let cuts = frame_cuts(&times, &trajectory.model().shots(self.windows.len()));
        let camera = self.output_intrinsics()?;
        let cameras = trajectory
            .zooms_at(&times)
            .into_iter()
            .map(|s| camera.zoomed(s))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(PathFrames {
            cameras,
            times,
            poses,
            fps: self.config.output.fps,
            cuts,
        })
    }

    /// Each window's object, for path renders.
    pub fn path_objects(&self) -> Vec<PathObject<'_>> {
        self.windows
            .iter()
            .map(|w| PathObject {
                mask: &w.mask,
                target_ratio: w.context.target_ratio,
            })
            .collect()
    }

    /// Renders `frames` into the run folder `dir`: `frames/`, `frame_metrics.csv` and
    /// `video.mp4` (nothing when there are no frames); `progress` is told after each frame.
    pub fn write_output_frames(
        &self,
        frames: &PathFrames,
        dir: &Path,
        progress: &mut dyn FnMut(usize),
    ) -> Result<Option<RenderedPath>> {
        if frames.poses.is_empty() {
            return Ok(None);
        }
        let job = PathRender {
            frames,
            objects: self.path_objects(),
            overlay: self.config.output.mask_overlay,
            rasterizer: self.config.rasterizer,
            video: Video::Mp4,
        };
        Ok(Some(render_path(&self.plain_scene(), &job, dir, progress)?))
    }

    /// Writes `frames` in every interchange format into `exports/<format>/` under `dir`
    /// (nothing when there are no frames); a stop requested `since` ends it between formats.
    pub fn write_exports(&self, frames: &PathFrames, dir: &Path, since: Since) -> Result<()> {
        if frames.poses.is_empty() {
            return Ok(());
        }
        let centres: Vec<[f64; 3]> = self
            .windows
            .iter()
            .map(|w| w.context.object_centre)
            .collect();
        write_all_exports(dir, frames, &centres, since)
    }

    /// Writes `report.html` into the run folder `dir` from its files, with this scene under
    /// the path views; call it last (it reads `metrics.json`).
    pub fn write_report(&self, dir: &Path) -> Result<PathBuf> {
        write_run_report(dir, Some(&self.scene))
    }
}
