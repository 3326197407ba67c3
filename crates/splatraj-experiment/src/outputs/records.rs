//! What the run folder's files hold: `trajectory.json`, `history.csv`, `pose.json`,
//! `sgld_samples.csv` (as serialisable values and CSV rows; [`crate::outputs`] writes them).

use anyhow::Result;
use serde::{Deserialize, Serialize};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::camera_file::matrix_rows;
use splatraj_traj::optimise::sampling::{window_bounds, window_of};
use splatraj_traj::optimise::{SinglePoseResult, StopReason};
use splatraj_traj::trajectory::{LensPath, Trajectory, TrajectoryModel, uniform_times};
use splatraj_traj::transitions::{JoinKind, shot_spans};

use crate::config::Ablation;
use crate::optimise::pose_run::{PoseRun, Posterior};
use crate::optimise::trajectory_run::TrajectoryRun;
use crate::outputs::Csv;
use crate::prepare::experiment::Experiment;

/// One pose of the densely sampled trajectory in `trajectory.json`.
#[derive(Debug, Serialize)]
pub struct SampledPose {
    /// Time t ∈ [0, 1].
    pub t: f64,
    /// The window t falls in.
    pub window: usize,
    /// The shot t falls in (0 without cuts): consecutive samples of different shots are the
    /// two sides of a cut, not a motion.
    pub shot: usize,
    /// Φ = [ω, c].
    pub pose: [f64; 6],
    /// 4×4 world-to-camera matrix (OpenCV axes), row-major.
    pub world_to_camera: [[f64; 4]; 4],
    /// The zoom s there, when the lens zooms (the frame camera's focal lengths times s).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zoom: Option<f64>,
    /// The frame camera's horizontal field of view there (degrees), when the lens zooms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fov_x_degrees: Option<f64>,
}

/// One window in `trajectory.json`.
#[derive(Debug, Serialize)]
pub struct WindowInfo {
    /// Window index.
    pub index: usize,
    /// The query.
    pub query: String,
    /// Start of the window in t.
    pub start: f64,
    /// End of the window in t.
    pub end: f64,
    /// Gaussians its target selected.
    pub selected_gaussians: usize,
    /// Object centre.
    pub object_centre: [f64; 3],
    /// Prior radius.
    pub prior_radius: f64,
    /// Target ratio.
    pub target_ratio: f64,
}

/// One shot in `trajectory.json`: a run of windows joined by pans, its own continuous path;
/// a cut separates it from the next (`[output] transitions`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShotInfo {
    /// Shot index.
    pub index: usize,
    /// Start of the shot in t (a cut's time, or 0).
    pub start: f64,
    /// End of the shot in t (the next cut's time, or 1).
    pub end: f64,
    /// Its windows.
    pub windows: Vec<usize>,
    /// Their queries.
    pub queries: Vec<String>,
    /// Why the cut into this shot was made, in words (none for the first shot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cut_reason: Option<String>,
}

/// The scene a trajectory was made on, as `trajectory.json` records it (key `scene`): a path
/// means nothing in another scene's world, so a render checks it ([`crate::outputs::camera_paths`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneRecord {
    /// Where the scene came from (its path, or `demo (…)`).
    pub name: String,
    /// Its Gaussian count (after any invalid ones were dropped).
    pub gaussians: usize,
}

impl SceneRecord {
    /// The scene of `experiment`.
    pub fn of(experiment: &Experiment) -> Self {
        Self {
            name: experiment.scene_name.clone(),
            gaussians: experiment.scene.len(),
        }
    }
}

/// `trajectory.json`: reads back as a `TrajectoryRecord` (`model`, `weights`).
#[derive(Debug, Serialize)]
pub struct TrajectoryFile {
    /// The scene it was made on.
    pub scene: SceneRecord,
    /// Trajectory model.
    pub model: TrajectoryModel,
    /// Weights `[K][6]`, scene units.
    pub weights: Vec<[f64; 6]>,
    /// The zoom s(t) (range and weights, docs/conventions.md "The lens"); absent for the
    /// fixed lens.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lens: Option<LensPath>,
    /// The pose convention in words.
    pub convention: &'static str,
    /// World up.
    pub world_up: [f64; 3],
    /// Optimisation camera.
    pub intrinsics: Intrinsics,
    /// Frame camera.
    pub output_intrinsics: Intrinsics,
    /// The query windows.
    pub windows: Vec<WindowInfo>,
    /// Times of the cuts in t, ascending (empty: one continuous shot; the model holds them
    /// too, as `kind = "cuts"`).
    pub cuts: Vec<f64>,
    /// The shots, in order.
    pub shots: Vec<ShotInfo>,
    /// Densely sampled poses (`output.trajectory_samples`).
    pub poses: Vec<SampledPose>,
}

impl Experiment {
    /// The `trajectory.json` of `trajectory`.
    pub fn trajectory_file(&self, trajectory: &Trajectory) -> Result<TrajectoryFile> {
        let n = self.windows.len();
        let times = uniform_times(self.config.output.trajectory_samples);
        let sampled = trajectory.poses_at(&times);
        // A non-finite pose must never reach a file.
        if let Some((pose, t)) = sampled
            .iter()
            .zip(&times)
            .find(|(p, _)| !p.iter().all(|v| v.is_finite()))
        {
            anyhow::bail!("the trajectory is not finite at t = {t}: pose {pose:?}");
        }
        let spans = trajectory.model().shots(n);
        let output = self.output_intrinsics()?;
        let zooms = trajectory.zooms_at(&times);
        let zooming = trajectory.lens.is_some();
        let poses = sampled
            .into_iter()
            .zip(&times)
            .zip(zooms)
            .map(|((pose, &t), s)| {
                Ok(SampledPose {
                    t,
                    window: window_of(t, n),
                    shot: spans.shot_of(t),
                    pose,
                    world_to_camera: matrix_rows(&Pose(pose).world_to_camera()),
                    zoom: zooming.then_some(s),
                    fov_x_degrees: if zooming {
                        Some(output.zoomed(s)?.horizontal_fov_degrees())
                    } else {
                        None
                    },
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let windows = self
            .windows
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let (start, end) = window_bounds(i, n);
                WindowInfo {
                    index: i,
                    query: w.name.clone(),
                    start,
                    end,
                    selected_gaussians: self.selected[i],
                    object_centre: w.context.object_centre,
                    prior_radius: w.context.prior_radius,
                    target_ratio: w.context.target_ratio,
                }
            })
            .collect();
        // The reasons of the joins when they made this model's cuts (a start from a file may
        // bring its own).
        let joins = self
            .joins()
            .ok()
            .filter(|j| shot_spans(n, j).ok().as_ref() == Some(&spans));
        let shots = (0..spans.len())
            .map(|j| {
                let (start, end) = spans.span(j);
                let windows: Vec<usize> = spans.window_range(j).collect();
                let cut_reason = (j > 0).then(|| {
                    joins
                        .as_ref()
                        .and_then(|joins| joins.get(windows[0] - 1))
                        .and_then(|join| match join {
                            JoinKind::Cut(reason) => Some(reason.describe()),
                            JoinKind::Pan => None,
                        })
                        .unwrap_or_else(|| "the trajectory's own cut".to_string())
                });
                ShotInfo {
                    index: j,
                    start,
                    end,
                    queries: windows
                        .iter()
                        .map(|&i| self.windows[i].name.clone())
                        .collect(),
                    windows,
                    cut_reason,
                }
            })
            .collect();
        let record = trajectory.record();
        Ok(TrajectoryFile {
            scene: SceneRecord::of(self),
            model: record.model,
            weights: record.weights,
            lens: record.lens,
            convention: "pose = [ω (rotation vector of camera-to-world), camera centre]; OpenCV camera axes (x right, y down, z forward); t in [0, 1]",
            world_up: self.up.up,
            intrinsics: self.intrinsics,
            output_intrinsics: self.output_intrinsics()?,
            windows,
            cuts: spans.cut_times(),
            shots,
            poses,
        })
    }
}

fn strings<const N: usize>(names: [&str; N]) -> Vec<String> {
    names.map(String::from).to_vec()
}

/// `history.csv` of a trajectory run: every cost term of every window per step.
pub fn trajectory_history(run: &TrajectoryRun, windows: usize) -> Csv {
    let mut header = strings([
        "restart",
        "step",
        "elapsed_s",
        "total",
        "best_total",
        "updated",
    ]);
    for i in 0..windows {
        for name in &run.cost_names {
            header.push(format!("q{i}_{name}"));
        }
    }
    let rows = run
        .results
        .iter()
        .enumerate()
        .flat_map(|(r, result)| {
            result.history.iter().map(move |s| {
                let mut row = vec![
                    r.to_string(),
                    s.step.to_string(),
                    format!("{:.4}", s.elapsed.as_secs_f64()),
                    s.total.to_string(),
                    s.best_total.to_string(),
                    u8::from(s.updated).to_string(),
                ];
                for w in &s.windows {
                    row.extend(w.iter().map(|(_, _, v)| v.to_string()));
                }
                row
            })
        })
        .collect();
    (header, rows)
}

/// `history.csv` of a pose run: every start's pose and terms per step.
pub fn pose_history(results: &[SinglePoseResult]) -> Csv {
    let mut header = strings([
        "start", "step", "total", "updated", "wx", "wy", "wz", "cx", "cy", "cz",
    ]);
    header.extend(results[0].history[0].terms.iter().map(|t| t.0.to_string()));
    let rows = results
        .iter()
        .enumerate()
        .flat_map(|(s, r)| {
            r.history.iter().map(move |h| {
                let mut row = vec![
                    s.to_string(),
                    h.step.to_string(),
                    h.total.to_string(),
                    u8::from(h.updated).to_string(),
                ];
                row.extend(h.pose.0.iter().map(|v| v.to_string()));
                row.extend(h.terms.iter().map(|t| t.2.to_string()));
                row
            })
        })
        .collect();
    (header, rows)
}

/// `sgld_samples.csv`: chain, step, total and pose of every kept sample.
pub fn sgld_samples(posterior: &Posterior) -> Csv {
    let header = strings(["chain", "step", "total", "wx", "wy", "wz", "cx", "cy", "cz"]);
    let rows = posterior
        .samples
        .iter()
        .map(|s| {
            let mut row = vec![s.chain.to_string(), s.step.to_string(), s.total.to_string()];
            row.extend(s.pose.0.iter().map(|v| v.to_string()));
            row
        })
        .collect();
    (header, rows)
}

/// One start's outcome in `pose.json`.
#[derive(Debug, Serialize)]
pub struct StartReport {
    /// Start pose.
    pub start: [f64; 6],
    /// Best pose from it.
    pub pose: [f64; 6],
    /// Its total.
    pub total: f64,
    /// Step of the best pose.
    pub best_step: usize,
    /// Its terms `(name, weight, value)`.
    pub terms: Vec<(&'static str, f64, f64)>,
}

/// `pose.json`.
#[derive(Debug, Serialize)]
pub struct PoseFile {
    /// The query.
    pub query: String,
    /// The ablation.
    pub ablation: Ablation,
    /// Its costs.
    pub costs: Vec<&'static str>,
    /// Best pose Φ = [ω, c] (OpenCV camera axes).
    pub pose: [f64; 6],
    /// Its 4×4 world-to-camera matrix, row-major.
    pub world_to_camera: [[f64; 4]; 4],
    /// Its total.
    pub total: f64,
    /// `finished`, or `interrupted` by Ctrl-C.
    pub stop: StopReason,
    /// Every start's result.
    pub starts: Vec<StartReport>,
    /// Skipped non-finite steps.
    pub skipped_steps: usize,
    /// Wall time of the optimisation.
    pub optimisation_s: f64,
    /// Per step.
    pub per_iteration_ms: f64,
}

impl PoseFile {
    /// The `pose.json` of `run`.
    pub fn new(experiment: &Experiment, run: &PoseRun) -> Self {
        let best = run.best();
        let optimisation_s = run.elapsed.as_secs_f64();
        PoseFile {
            query: experiment.windows[run.window].name.clone(),
            ablation: experiment.config.pose.ablation,
            costs: run.cost_names.clone(),
            pose: best.pose.0,
            world_to_camera: matrix_rows(&best.pose.world_to_camera()),
            total: best.total,
            stop: best.stop,
            starts: run
                .results
                .iter()
                .zip(&run.starts)
                .map(|(r, s)| StartReport {
                    start: s.0,
                    pose: r.pose.0,
                    total: r.total,
                    best_step: r.best_step,
                    terms: r.terms.clone(),
                })
                .collect(),
            skipped_steps: best.skipped_steps,
            optimisation_s,
            per_iteration_ms: 1e3 * optimisation_s / run.iterations_run() as f64,
        }
    }
}
