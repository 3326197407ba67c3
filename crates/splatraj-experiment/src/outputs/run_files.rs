//! [`RunOutputs`], the outputs stage of a trajectory run: what a finished trajectory (the
//! run's best) becomes in the run folder besides its records. Its metrics and verdicts, then
//! the files other tools read: frames and `video.mp4`, the camera path in every interchange
//! format (`exports/<format>/`), and `report.html`. The frames, the video and the exports
//! share one set of times and poses ([`RunOutputs::frames`]), so an exported path rendered
//! back gives the run's frames.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Result;
use splatraj_render::counters::{self, Counts};
use splatraj_scene::stop::Since;
use splatraj_traj::trajectory::{Trajectory, uniform_times};

use crate::optimise::trajectory_run::TrajectoryRun;
use crate::outputs::camera_paths::{PathFrames, frame_cuts, write_all_exports};
use crate::outputs::evaluation::Evaluation;
use crate::outputs::path_render::{PathRender, RenderedPath, Video, render_path};
use crate::outputs::run_report::write_run_report;
use crate::prepare::experiment::Experiment;

/// What [`RunOutputs::write`] measured, and how long its parts took.
#[derive(Debug, Clone)]
pub struct Outputs {
    /// The metrics, each window judged with what its frames show too.
    pub evaluation: Evaluation,
    /// Time of the metrics.
    pub metrics: Duration,
    /// Time of the frames, video and exports.
    pub frames: Duration,
    /// The device counters of the metrics.
    pub metrics_counts: Counts,
    /// The device counters of the frames, video and exports.
    pub frames_counts: Counts,
}

/// The outputs stage's state: the experiment every stage shares (config, scene, windows)
/// and the one trajectory whose outputs are written.
#[derive(Debug)]
pub struct RunOutputs<'a> {
    /// What every stage shares.
    experiment: &'a Experiment,
    /// The trajectory the outputs show.
    trajectory: Trajectory,
}

impl<'a> RunOutputs<'a> {
    /// The outputs of `trajectory` (any trajectory on `experiment`'s windows).
    pub fn new(experiment: &'a Experiment, trajectory: Trajectory) -> Self {
        Self {
            experiment,
            trajectory,
        }
    }

    /// The outputs of `run`'s best trajectory.
    pub fn of_run(experiment: &'a Experiment, run: &TrajectoryRun) -> Result<Self> {
        Ok(Self::new(
            experiment,
            experiment.trajectory(&run.best().best)?,
        ))
    }

    /// The trajectory the outputs show.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// The outputs in the run folder `dir`: the trajectory's metrics and verdicts
    /// ([`Experiment::evaluate`]), the frames, `frame_metrics.csv` and `video.mp4`
    /// (the verdicts judged again with the frames' wobble, [`Evaluation::with_frames`], and a
    /// dolly zoom's hold of its object's size, [`Experiment::with_zoom_holds`]), then
    /// the same poses in every export format. `progress` hears each frame done (of
    /// `output.frame_count`). A stop requested `since` ([`splatraj_scene::stop`]) ends it at
    /// the next whole window of metrics, frame or export format with
    /// [`splatraj_scene::stop::Stopped`].
    pub fn write(
        &self,
        dir: &Path,
        progress: &mut dyn FnMut(usize),
        since: Since,
    ) -> Result<Outputs> {
        splatraj_scene::stop::honour();
        let started = Instant::now();
        let counted = counters::snapshot();
        let experiment = self.experiment;
        let mut evaluation = experiment.evaluate_since(&self.trajectory, since)?;
        let metrics = started.elapsed();
        let metrics_counts = counters::snapshot().since(&counted);
        // The frames begin their own count of requests: one made before must stop them here.
        since.stop_point(|| "the metrics were computed, no frame is written".to_string())?;
        let started = Instant::now();
        let counted = counters::snapshot();
        let frames = self.frames()?;
        if let Some(rendered) = self.write_frames(&frames, dir, progress)? {
            // Before `with_frames`, which judges the windows again with what the frames add.
            experiment.with_zoom_holds(
                &mut evaluation.windows,
                &rendered.metrics,
                &frames.cameras,
            )?;
            evaluation.with_frames(&rendered.metrics, frames.fps);
        }
        self.write_exports(&frames, dir, since)?;
        Ok(Outputs {
            evaluation,
            metrics,
            frames: started.elapsed(),
            metrics_counts,
            frames_counts: counters::snapshot().since(&counted),
        })
    }

    /// The frames of the run's output: `output.frame_count()` evenly spaced times over [0, 1],
    /// the trajectory's poses there, the output camera (zoomed by the trajectory's s(t) when
    /// the lens zooms), at `output.fps`.
    pub fn frames(&self) -> Result<PathFrames> {
        let (experiment, trajectory) = (self.experiment, &self.trajectory);
        let windows = experiment.windows.len();
        let times = uniform_times(experiment.config.output.frame_count(windows));
        let poses = trajectory.poses_at(&times);
        let cuts = frame_cuts(&times, &trajectory.model().shots(windows));
        let camera = experiment.output_intrinsics()?;
        let cameras = trajectory
            .zooms_at(&times)
            .into_iter()
            .map(|s| camera.zoomed(s))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(PathFrames {
            cameras,
            times,
            poses,
            fps: experiment.config.output.fps,
            cuts,
        })
    }

    /// Renders `frames` into the run folder `dir`: `frames/`, `frame_metrics.csv` and
    /// `video.mp4` (nothing when there are no frames); `progress` is told after each frame.
    fn write_frames(
        &self,
        frames: &PathFrames,
        dir: &Path,
        progress: &mut dyn FnMut(usize),
    ) -> Result<Option<RenderedPath>> {
        if frames.poses.is_empty() {
            return Ok(None);
        }
        let experiment = self.experiment;
        let job = PathRender {
            frames,
            objects: experiment.path_objects(),
            overlay: experiment.config.output.mask_overlay,
            rasterizer: experiment.config.rasterizer,
            video: Video::Mp4,
        };
        Ok(Some(render_path(
            &experiment.plain_scene(),
            &job,
            dir,
            progress,
        )?))
    }

    /// Writes `frames` in every interchange format into `exports/<format>/` under `dir`
    /// (nothing when there are no frames); a stop requested `since` ends it between formats.
    fn write_exports(&self, frames: &PathFrames, dir: &Path, since: Since) -> Result<()> {
        if frames.poses.is_empty() {
            return Ok(());
        }
        let centres: Vec<[f64; 3]> = self
            .experiment
            .windows
            .iter()
            .map(|w| w.context.object_centre)
            .collect();
        write_all_exports(dir, frames, &centres, since)
    }

    /// Writes `report.html` into the run folder `dir` from its files, with this scene under
    /// the path views; call it last (it reads `metrics.json`).
    pub fn write_report(&self, dir: &Path) -> Result<PathBuf> {
        write_run_report(dir, Some(&self.experiment.scene))
    }
}
