//! Where the optimisations start: an earlier trajectory (ours, or another tool's camera file),
//! a fixed pose, or object-facing or random poses per restart (`[start]`).

use anyhow::{Context, Result};
use splatraj_render::camera::Pose;
use splatraj_traj::optimise::start::START_FIT_SAMPLES;
use splatraj_traj::optimise::{
    WindowTarget, object_start_poses, random_start_poses, window_start_trajectory,
};
use splatraj_traj::trajectory::{Trajectory, TrajectoryModel, TrajectoryRecord, uniform_times};

use crate::config::StartKind;
use crate::experiment::Experiment;

impl Experiment {
    /// The starting trajectories of `[start]`: one re-fitted from `start.trajectory`, one
    /// holding `start.pose`, or one per restart from object-facing or random poses, all in
    /// the `[trajectory]` model with one window per query.
    pub fn start_trajectories(&self) -> Result<Vec<TrajectoryRecord>> {
        let config = &self.config;
        let model = self.model()?;
        let (device, dtype) = (&self.device, self.dtype);
        if let Some(file) = &config.start.trajectory {
            let path = config.resolve(file);
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("`start.trajectory`: cannot read {}", path.display()))?;
            let record: TrajectoryRecord = match serde_json::from_str(&text) {
                Ok(record) => record,
                // Another tool's camera file: its poses, fitted to the model.
                Err(_) if splatraj_report::detect(&path).is_ok() => {
                    return Ok(vec![self.camera_file_start(&path, model)?]);
                }
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!(
                            "`start.trajectory`: {} is not a trajectory.json (needs `model` and \
                             `weights`) nor a camera file (nerfstudio camera_path.json, COLMAP \
                             images.txt, INRIA cameras.json, SuperSplat settings.json)",
                            path.display()
                        )
                    });
                }
            };
            let loaded = self
                .trajectory(&record)
                .with_context(|| format!("`start.trajectory`: {}", path.display()))?;
            let refitted = if record.model == model {
                loaded
            } else {
                loaded.refit(model, START_FIT_SAMPLES)?
            };
            return Ok(vec![refitted.record()]);
        }
        let n = self.windows.len();
        let per_restart = match config.start.pose {
            Some(pose) => vec![vec![Pose(pose); n]],
            None => self.start_poses(&self.windows)?,
        };
        per_restart
            .iter()
            .map(|per_window| {
                Ok(window_start_trajectory(model.clone(), per_window, device, dtype)?.record())
            })
            .collect()
    }

    /// A start fitted to the poses of another tool's camera file (`start.trajectory` = a
    /// nerfstudio `camera_path.json`, COLMAP `images.txt`, INRIA `cameras.json` or SuperSplat
    /// `settings.json`; `docs/interchange.md`): its frames spread evenly over t ∈ [0, 1], linear
    /// between them, and least-squares fitted to `model`.
    fn camera_file_start(
        &self,
        path: &std::path::Path,
        model: TrajectoryModel,
    ) -> Result<TrajectoryRecord> {
        let context = || format!("`start.trajectory`: {}", path.display());
        let (_, camera_path) = splatraj_report::read_camera_path(path).with_context(context)?;
        let times = uniform_times(START_FIT_SAMPLES);
        let poses = camera_path.resampled_phis(START_FIT_SAMPLES);
        let fitted = Trajectory::fit(model, &times, &poses, &self.device, self.dtype)
            .with_context(context)?;
        Ok(fitted.record())
    }

    /// The `[trajectory]` model for the experiment's windows (a custom model built from
    /// [`Extensions::models`](crate::Extensions::models)).
    pub fn model(&self) -> Result<TrajectoryModel> {
        self.config
            .trajectory
            .build_with(self.windows.len(), &self.extensions.models)
            .context("`trajectory`")
    }

    /// For each restart, one start pose per window in `windows` (object-facing or random; a
    /// random start is the same pose for every window).
    pub fn start_poses(&self, windows: &[WindowTarget]) -> Result<Vec<Vec<Pose>>> {
        let config = &self.config;
        let (centre, half) = self.bounds;
        let restarts = config.start.restarts;
        Ok(match config.start.kind {
            StartKind::Objects => {
                let objects: Vec<([f64; 3], f64)> = windows
                    .iter()
                    .map(|w| (w.context.object_centre, w.context.prior_radius))
                    .collect();
                (0..restarts)
                    .map(|r| {
                        object_start_poses(
                            &objects,
                            centre,
                            self.up.up,
                            config.start.object_view(),
                            r,
                            config.seed,
                        )
                    })
                    .collect::<Result<_, _>>()?
            }
            StartKind::Random => random_start_poses(
                centre,
                half,
                self.up.up,
                &config.start.distribution(),
                restarts,
                config.seed,
            )?
            .into_iter()
            .map(|p| vec![p; windows.len()])
            .collect(),
        })
    }
}
