//! Where the run pans and where it cuts (`[output] transitions`): each join of consecutive
//! windows judged on the first restart's start (its views, shots and planned routes,
//! `splatraj_traj::transitions`), and the run's trajectory model cut into the shots that
//! gives. Every restart, the checkpoint and `trajectory.json` share that one model.

use anyhow::{Result, bail};
use splatraj_render::camera::Pose;
use splatraj_traj::optimise::WindowStart;
use splatraj_traj::pacing::{MAX_ORBIT_RATE, MAX_TURN_RATE};
use splatraj_traj::trajectory::{TrajectoryModel, TrajectoryRecord};
use splatraj_traj::transitions::{
    CutReason, Join, JoinKind, JoinLimits, JoinPart, TransitionMode, plan_joins, shot_spans,
};

use crate::prepare::experiment::Experiment;

impl Experiment {
    /// What each join of windows k and k + 1 becomes (one per join), judged once and kept.
    ///
    /// `"pan"` and `"cut"` are what they say. `"auto"` judges the first restart's start
    /// against the verdict's pacing limits (module docs of `splatraj_traj::transitions`); a
    /// start from a file (`start.trajectory`) keeps the file's cuts (each at the window
    /// boundary nearest it); a fixed `start.pose`, or a custom trajectory model (whose basis
    /// cannot be cut), pans.
    pub fn joins(&self) -> Result<Vec<JoinKind>> {
        // What the judgement reads besides the scene and the windows (fixed by `prepare`):
        // a config edited since is judged afresh.
        let config = &self.config;
        let key = format!(
            "{:?} {:?} {:?} {:?} {:?} {:?}",
            config.output.transitions,
            self.path_seconds(),
            config.start,
            config.costs.motion,
            config.costs.clearance,
            self.intrinsics
        );
        self.joins_memo.get_or_make(key, || self.judge_joins())
    }

    /// [`Experiment::joins`] without the cache.
    fn judge_joins(&self) -> Result<Vec<JoinKind>> {
        let n = self.windows.len();
        let mode = self.config.output.transitions;
        let custom = matches!(self.model, TrajectoryModel::Custom(_));
        if mode == TransitionMode::Cut && custom {
            bail!(
                "`output.transitions` = \"cut\" needs a built-in trajectory model (rbf, waypoint \
                 or polynomial): `trajectory.kind` = {:?} cannot be cut into shots",
                self.model.name()
            );
        }
        let start = &self.config.start;
        if mode == TransitionMode::Auto && !custom && n >= 2 && start.trajectory.is_some() {
            return self.start_file_joins();
        }
        let judged = mode == TransitionMode::Auto
            && !custom
            && start.trajectory.is_none()
            && start.pose.is_none();
        if n < 2 || !judged {
            let kind = match mode {
                TransitionMode::Cut => JoinKind::Cut(CutReason::Asked),
                TransitionMode::Pan | TransitionMode::Auto => JoinKind::Pan,
            };
            return Ok(vec![kind; n.saturating_sub(1)]);
        }
        let all: Vec<usize> = (0..n).collect();
        let per_window = self
            .start_poses(&all, 1)?
            .into_iter()
            .next()
            .unwrap_or_default();
        let shots = self.shot_paths()?;
        let starts = self.window_starts(&per_window, &shots);
        let planner = self.route_planner(std::slice::from_ref(&per_window), &shots)?;
        let joins: Vec<Join> = (0..n - 1)
            .map(|k| {
                let (from, to) = (starts[k].pose_at(1.0), starts[k + 1].pose_at(0.0));
                Join {
                    from,
                    to,
                    parts: [k, k + 1].map(|i| JoinPart {
                        centre: self.windows[i].context.object_centre,
                        bounds: self.boxes[i],
                    }),
                    route: planner
                        .as_ref()
                        .map(|p| p.route(from.centre(), to.centre())),
                }
            })
            .collect();
        Ok(plan_joins(mode, &joins, &self.join_limits()))
    }

    /// The joins of a start from a file (`start.trajectory`): a cut where the file cuts, at
    /// the window boundary nearest it (our `trajectory.json`: its cut model's shots; another
    /// tool's camera file: its marked cuts, its frames spread evenly over t ∈ [0, 1]).
    fn start_file_joins(&self) -> Result<Vec<JoinKind>> {
        let n = self.windows.len();
        let Some(file) = &self.config.start.trajectory else {
            return Ok(vec![JoinKind::Pan; n.saturating_sub(1)]);
        };
        let path = self.config.resolve(file);
        let text = splatraj_scene::input::read_text(&path).unwrap_or_default();
        // Cut times in t; a file neither reads is the start's to refuse, naming it.
        let times: Vec<f64> = match serde_json::from_str::<TrajectoryRecord>(&text) {
            Ok(record) => record.model.shots(n).cut_times(),
            Err(_) => match splatraj_camera_paths::read_camera_path(&path) {
                Ok((_, camera_path)) => {
                    let last = camera_path.frames.len().saturating_sub(1).max(1) as f64;
                    camera_path.cuts.iter().map(|&c| c as f64 / last).collect()
                }
                Err(_) => Vec::new(),
            },
        };
        let cut_before: Vec<usize> = times
            .iter()
            .map(|t| (t * n as f64).round() as usize)
            .filter(|&w| w >= 1 && w < n)
            .collect();
        Ok((1..n)
            .map(|w| match cut_before.contains(&w) {
                true => JoinKind::Cut(CutReason::Start),
                false => JoinKind::Pan,
            })
            .collect())
    }

    /// The limits joins are judged against: the verdict's turning and orbit rates, the
    /// motion cost's speed limit when it has one, the windows' duration.
    fn join_limits(&self) -> JoinLimits {
        let n = self.windows.len().max(1);
        JoinLimits {
            turn: MAX_TURN_RATE,
            orbit: MAX_ORBIT_RATE,
            speed: self
                .config
                .costs
                .motion
                .as_ref()
                .and_then(|m| m.max_speed)
                .and_then(|s| s.value()),
            window_seconds: self.path_seconds().unwrap_or(1.0) / n as f64,
        }
    }

    /// The trajectory model the run optimises: `[trajectory]`'s, cut into shots where
    /// [`Experiment::joins`] cuts (the model itself when every join pans).
    pub fn run_model(&self) -> Result<TrajectoryModel> {
        let spans = shot_spans(self.windows.len(), &self.joins()?)?;
        if spans.is_empty() {
            return Ok(self.model.clone());
        }
        Ok(self.model.clone().cut(spans)?)
    }

    /// One line per join: pan, or cut and why (for the plan a run prints).
    pub fn transition_lines(&self) -> Result<Vec<String>> {
        Ok(self
            .joins()?
            .iter()
            .enumerate()
            .map(|(k, join)| match join {
                JoinKind::Pan => format!("windows {k} → {}: pan", k + 1),
                JoinKind::Cut(reason) => {
                    format!("windows {k} → {}: cut ({})", k + 1, reason.describe())
                }
            })
            .collect())
    }

    /// What each window of a start asks: its shot's path (`shots[i]`) or holding its pose.
    pub(crate) fn window_starts(
        &self,
        per_window: &[Pose],
        shots: &[Option<splatraj_traj::shots::ShotPath>],
    ) -> Vec<WindowStart> {
        per_window
            .iter()
            .zip(shots)
            .map(|(pose, shot)| match shot {
                Some(s) => WindowStart::Shot(*s),
                None => WindowStart::Hold(*pose),
            })
            .collect()
    }
}
