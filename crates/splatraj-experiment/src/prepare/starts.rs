//! Where the optimisations start: an earlier trajectory (ours, or another tool's camera file),
//! a fixed pose, or object-facing or random poses per restart (`[start]`); a window with a
//! shot preset (`[[queries]] shot`) starts on its shot's path instead, and the shot's cost
//! keeps it there. With `[start] route` planned (by default when the clearance cost is on),
//! the start goes around the geometry between windows whose straight join does not keep the
//! margin.

use anyhow::{Context, Result};
use glam::DVec3;
use splatraj_render::camera::Pose;
use splatraj_traj::costs::{ShotCost, WeightedCosts};
use splatraj_traj::optimise::route::ROUTE_TRANSITION;
use splatraj_traj::optimise::start::START_FIT_SAMPLES;
use splatraj_traj::optimise::start::window_joins;
use splatraj_traj::optimise::{
    Candidate, PanLimits, RouteKind, RoutePlanner, ViewSearch, ViewWeights, ViewedObject,
    WindowStart, WindowViews, choose_views, object_side, object_start_poses, pan_shares,
    plan_transitions, random_start_poses, routed_start_trajectory, search_views,
};
use splatraj_traj::shots::{ShotFrame, ShotPath};
use splatraj_traj::trajectory::{Trajectory, TrajectoryModel, TrajectoryRecord, uniform_times};
use splatraj_traj::transitions::JoinKind;

use crate::config::StartKind;
use crate::prepare::experiment::Experiment;

impl Experiment {
    /// The starting trajectories of `[start]`: one re-fitted from `start.trajectory`, one
    /// holding `start.pose`, or one per restart from object-facing or random poses, all in
    /// the `[trajectory]` model with one window per query.
    pub fn start_trajectories(&self) -> Result<Vec<TrajectoryRecord>> {
        self.first_start_trajectories(self.config.start.restarts)
    }

    /// How many starts [`Experiment::start_trajectories`] gives (without building them): one
    /// for `start.trajectory` or `start.pose`, else `start.restarts`.
    pub fn start_count(&self) -> usize {
        let start = &self.config.start;
        if start.trajectory.is_some() || start.pose.is_some() {
            1
        } else {
            start.restarts
        }
    }

    /// The first `count` of [`Experiment::start_trajectories`]: a check builds one, since
    /// what can fail is the same for every restart and building them all takes time in
    /// proportion to `start.restarts`.
    pub fn first_start_trajectories(&self, count: usize) -> Result<Vec<TrajectoryRecord>> {
        let config = &self.config;
        // `[trajectory]`'s model, cut into shots where the windows cut (`[output] transitions`).
        let model = self.run_model()?;
        let (device, dtype) = (&self.device, self.dtype);
        if let Some(file) = &config.start.trajectory {
            let path = config.resolve(file);
            let text = splatraj_scene::input::read_text(&path)
                .with_context(|| format!("`start.trajectory`: cannot read {}", path.display()))?;
            let record: TrajectoryRecord = match serde_json::from_str(&text) {
                Ok(record) => record,
                // Another tool's camera file: its poses, fitted to the model.
                Err(_) if splatraj_camera_paths::detect(&path).is_ok() => {
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
            None => self.start_poses(&(0..n).collect::<Vec<_>>(), count)?,
        };
        // A fixed `start.pose` is taken as given; object and random starts follow the shots.
        let shots = match config.start.pose {
            Some(_) => vec![None; n],
            None => self.shot_paths()?,
        };
        let planner = self.route_planner(&per_restart, &shots)?;
        // Many restarts take a while to build: a stop request ends it at the next start.
        let since = splatraj_scene::stop::Since::now();
        per_restart
            .iter()
            .enumerate()
            .map(|(r, per_window)| {
                since.stop_point(|| format!("{r} of {count} starts were built, none run"))?;
                let starts = self.window_starts(per_window, &shots);
                let shares = self.join_shares(&starts)?;
                let transitions = match &planner {
                    Some(planner) => {
                        let has_shot: Vec<bool> = shots.iter().map(Option::is_some).collect();
                        let (routes, walled_in) =
                            plan_transitions(planner, &window_joins(&starts), &has_shot, &shares);
                        for i in walled_in {
                            tracing::warn!(
                                "start {r}: no route keeps `costs.clearance.margin` from \
                                 window {i} to window {}; the start goes straight",
                                i + 1
                            );
                        }
                        routes
                    }
                    None => Vec::new(),
                };
                Ok(routed_start_trajectory(
                    model.clone(),
                    &starts,
                    &transitions,
                    &shares,
                    device,
                    dtype,
                )?
                .record())
            })
            .collect()
    }

    /// The share of each window on both sides of each join over which the start pans: none
    /// at a cut (each side holds its view up to the switch), else [`Experiment::pan_shares`].
    fn join_shares(&self, starts: &[WindowStart]) -> Result<Vec<f64>> {
        let pans = self.pan_shares(starts);
        Ok(self
            .joins()?
            .iter()
            .enumerate()
            .map(|(k, join)| match join {
                JoinKind::Cut(_) => 0.0,
                JoinKind::Pan => pans.get(k).copied().unwrap_or(ROUTE_TRANSITION),
            })
            .collect())
    }

    /// How long the start pans at each join of `starts`: long enough for the motion cost's
    /// turning and orbit limits ([`pan_shares`]); a quarter window each side without limits.
    fn pan_shares(&self, starts: &[WindowStart]) -> Vec<f64> {
        let (Some(motion), Some(seconds)) = (&self.config.costs.motion, self.path_seconds()) else {
            return Vec::new();
        };
        let centres: Vec<[f64; 3]> = self
            .windows
            .iter()
            .map(|w| w.context.object_centre)
            .collect();
        let limits = PanLimits {
            turn: motion.max_angular_speed,
            orbit: motion.max_orbit_speed,
            window_seconds: seconds / self.windows.len().max(1) as f64,
        };
        pan_shares(starts, &centres, limits)
    }

    /// The grid `[start] route` plans on (None when the starts go straight): over the
    /// scene's robust bounds and every start's camera centres, keeping the clearance margin.
    pub(crate) fn route_planner(
        &self,
        per_restart: &[Vec<Pose>],
        shots: &[Option<ShotPath>],
    ) -> Result<Option<RoutePlanner>> {
        let clearance = match (self.config.start.route, &self.config.costs.clearance) {
            (RouteKind::Straight, _) | (RouteKind::Auto, None) => return Ok(None),
            (_, Some(c)) => c,
            (RouteKind::Planned, None) => anyhow::bail!(
                "`start.route` = \"planned\" needs `[costs.clearance]` (its margin and geometry)"
            ),
        };
        if self.windows.len() < 2 {
            return Ok(None);
        }
        let Some(occupancy) = self.occupancy()? else {
            return Ok(None);
        };
        let (centre, half) = (DVec3::from(self.bounds.0), DVec3::from(self.bounds.1));
        let (mut lo, mut hi) = (centre - half, centre + half);
        let shot_centres = shots
            .iter()
            .flatten()
            .flat_map(|s| [s.centre_at(0.0), s.centre_at(1.0)]);
        for c in per_restart
            .iter()
            .flatten()
            .map(|p| p.centre())
            .chain(shot_centres)
        {
            (lo, hi) = (lo.min(c), hi.max(c));
        }
        let margin = clearance.margin().map_err(anyhow::Error::msg)?;
        Ok(Some(RoutePlanner::new(&occupancy, margin, lo, hi)))
    }

    /// Azimuth 0 of shots and of the view search: the horizontal direction from the windows'
    /// mean object centre toward the scene's middle ([`object_side`]).
    pub fn azimuth_zero(&self) -> [f64; 3] {
        let centres: Vec<[f64; 3]> = self
            .windows
            .iter()
            .map(|w| w.context.object_centre)
            .collect();
        object_side(&centres, self.bounds.0, self.up.up)
    }

    /// Each window's shot (`queries.<i>.shot`) placed around its object, seen at azimuth 0
    /// ([`Experiment::azimuth_zero`]); None for a window without one.
    pub fn shot_paths(&self) -> Result<Vec<Option<ShotPath>>> {
        let side = self.azimuth_zero();
        self.config
            .queries
            .iter()
            .zip(&self.windows)
            .enumerate()
            .map(|(i, (query, window))| {
                let Some(spec) = query.window_shot() else {
                    return Ok(None);
                };
                let frame = ShotFrame {
                    object_centre: window.context.object_centre,
                    working_radius: window.context.prior_radius,
                    world_up: self.up.up,
                    side,
                };
                spec.place(&frame)
                    .map(Some)
                    .with_context(|| format!("`queries.{i}.shot` ({})", spec.kind()))
            })
            .collect()
    }

    /// `costs` with the shots' cost added when some query has a shot (trajectory runs).
    pub fn with_shot_cost(&self, costs: WeightedCosts) -> Result<WeightedCosts> {
        let shots = self.shot_paths()?;
        if shots.iter().all(Option::is_none) {
            return Ok(costs);
        }
        costs
            .with_cost(Box::new(ShotCost { shots }))
            .map_err(anyhow::Error::msg)
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
        let (_, camera_path) =
            splatraj_camera_paths::read_camera_path(path).with_context(context)?;
        let times = uniform_times(START_FIT_SAMPLES);
        let poses = camera_path.resampled_phis(START_FIT_SAMPLES);
        let fitted = Trajectory::fit(model, &times, &poses, &self.device, self.dtype)
            .with_context(context)?;
        Ok(fitted.record())
    }

    /// For the first `count` restarts (of `start.restarts`), one start pose per window of
    /// `which` (indices into the windows): searched, object-facing or random (a random start
    /// is the same pose for every window).
    pub fn start_poses(&self, which: &[usize], count: usize) -> Result<Vec<Vec<Pose>>> {
        let config = &self.config;
        let (centre, half) = self.bounds;
        let restarts = count.min(config.start.restarts);
        Ok(match config.start.kind {
            // The search chooses every restart's views (and caches them for the run), each
            // later restart's depending on the earlier ones'.
            StartKind::Search => self
                .searched_views(which, config.start.restarts)?
                .into_iter()
                .take(restarts.max(1))
                .map(|views| views.iter().map(|c| Pose(c.pose)).collect())
                .collect(),
            StartKind::Objects => {
                let objects: Vec<([f64; 3], f64)> = which
                    .iter()
                    .map(|&i| {
                        let w = &self.windows[i];
                        (w.context.object_centre, w.context.prior_radius)
                    })
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
            .map(|p| vec![p; which.len()])
            .collect(),
        })
    }

    /// The views the first restart starts from, one per window, when the start is the view
    /// search (`[start] kind = "search"` without a fixed `pose` or `trajectory`); None for
    /// another start.
    pub fn start_views(&self) -> Result<Option<Vec<Candidate>>> {
        let start = &self.config.start;
        if start.kind != StartKind::Search || start.pose.is_some() || start.trajectory.is_some() {
            return Ok(None);
        }
        let all: Vec<usize> = (0..self.windows.len()).collect();
        Ok(self
            .searched_views(&all, start.restarts)?
            .into_iter()
            .next())
    }

    /// The view search's choice for the windows of `which`, one list per restart: restart 0
    /// takes the best sequence, each later one the best with earlier restarts' views (and
    /// their neighbours) charged extra
    /// (`splatraj_traj::optimise::views`). Measured at the optimisation camera's aspect, with
    /// the clearance cost's geometry and margin when it is on.
    pub fn searched_views(&self, which: &[usize], restarts: usize) -> Result<Vec<Vec<Candidate>>> {
        let all: Vec<usize> = (0..self.windows.len()).collect();
        // What the search depends on besides the scene and the windows (fixed by `prepare`):
        // a config edited since gets a fresh search.
        let key = format!(
            "{restarts} {:?} {:?} {:?}",
            self.clearance_margin(),
            self.intrinsics,
            self.config.rasterizer
        );
        // Only the search over every window is kept: it is the one the check, the plan and the
        // run each ask for.
        if which == all.as_slice() {
            self.views_memo
                .get_or_make(key, || self.search_and_choose(which, restarts))
        } else {
            self.search_and_choose(which, restarts)
        }
    }

    /// [`Experiment::searched_views`] without the cache.
    fn search_and_choose(&self, which: &[usize], restarts: usize) -> Result<Vec<Vec<Candidate>>> {
        let windows = self.measured_views(which)?;
        let margin = self.clearance_margin();
        let mut windows = windows;
        let weights = ViewWeights::default();
        let mut chosen = Vec::with_capacity(restarts);
        for _ in 0..restarts.max(1) {
            let picks = choose_views(&windows, &weights, margin)
                .context("the view search found no candidate view for some window")?;
            let views: Vec<Candidate> = picks
                .iter()
                .zip(&windows)
                .map(|(&k, w)| w.candidates[k])
                .collect();
            for (w, &k) in windows.iter_mut().zip(&picks) {
                w.used.push(k);
            }
            chosen.push(views);
        }
        Ok(chosen)
    }

    /// Every candidate view of the windows of `which`, measured (renders of each object's
    /// mask with the scene and alone, the camera's clearance).
    pub fn measured_views(&self, which: &[usize]) -> Result<Vec<WindowViews>> {
        let scene = self.plain_optimisation_scene();
        let windows = self.optimisation_windows();
        let occupancy = self.occupancy()?;
        let margin = self.clearance_margin();
        let geometry = occupancy.as_ref().zip(margin);
        let reference = self.azimuth_zero();
        which
            .iter()
            .map(|&i| {
                let w = &windows[i];
                let alone = self.optimisation_alone(i, &self.device);
                let object = ViewedObject {
                    scene: &scene,
                    alone: &alone,
                    mask: &w.mask,
                    centre: w.context.object_centre,
                    half_extent: self.boxes[i].1,
                    radius: w.context.prior_radius,
                    target_ratio: w.context.target_ratio,
                };
                let candidates = search_views(
                    &object,
                    &ViewSearch::default(),
                    reference,
                    self.up.up,
                    &self.intrinsics,
                    self.config.rasterizer,
                    geometry,
                )
                .with_context(|| format!("view search of `queries.{i}` ({:?})", w.name))?;
                Ok(WindowViews {
                    candidates,
                    radius: w.context.prior_radius,
                    target_ratio: w.context.target_ratio,
                    used: Vec::new(),
                })
            })
            .collect()
    }
}
