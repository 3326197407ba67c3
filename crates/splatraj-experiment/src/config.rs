//! The experiment config (`splatraj run` and `splatraj pose`): one TOML schema, every knob.
//!
//! ```toml
//! name = "demo"            # runs/<name>/<timestamp>/
//! seed = 7
//! backend = "flex"         # flex (= cpu) | ndarray | wgpu, among those compiled in
//! precision = "f32"        # f32 | f64
//! rasterizer = "fused"     # fused (default) | tensor: which compositing every render uses
//! # max_memory_gb = 8.0    # refuse sizes whose estimated peak memory is above (default: 75 % of RAM)
//!
//! [scene]                  # a file, or the built-in demo room
//! demo = { gaussians = 30000, seed = 7 }    # or: path = "scene.ply", labels = "labels.json"
//!
//! [targets]                # how queries become per-Gaussian 0/1 channels (splatraj-semantic)
//! source = "labels"
//!
//! [[queries]]              # one time window each, in order
//! text = "red mug"
//! # target_ratio = 0.15   # this window's share of the frame (default: [camera] target_ratio)
//! # mask = "mug.npy"      # a per-Gaussian 0/1 .npy instead of the target source
//! # shot = { kind = "orbit", elevation = 30, radius = 1.2, sweep = 90, direction = "ccw" }
//! #   a shot preset for this window (trajectory runs): `orbit` (elevation°, radius (default:
//! #   the working radius of target_ratio), sweep°, direction ccw|cw, azimuth°, weight),
//! #   `dolly` (elevation°, from, to (radii at the window's start and end), azimuth°, weight),
//! #   `reveal` (elevation°, radius, azimuth°, pan° (view turned away at the start, default 90),
//! #   direction (way the view turns), framed_from (share of the window, default 0.6), weight)
//! #   or `group` (objects = ["…", "…"]: texts grounded like queries, framed together; this
//! #   query's text only names the group; elevation°, radius, azimuth°, weight)
//!
//! [camera]                 # optimisation camera; [output] sets the final render's size
//! width = 96               # default 96 × 54 (the output's 16:9)
//! height = 54
//! fov_x = 60.0
//! # working_distance = "measured"   # or "box": the prior radius measured on renders, or estimated
//!
//! [trajectory]             # kind = "rbf" | "waypoint" | "polynomial" and its parameters,
//!                          # or kind = "custom.<name>" and [trajectory.custom.<name>]: a
//!                          # model registered in `Extensions` (as `source = "custom.<name>"`
//!                          # and [targets.custom.<name>] for a target source)
//! [costs]                  # tce, tre, upright, prior, clearance (margin, sigma, min_opacity),
//!                          # motion (max_speed, max_acceleration, max_angular_speed,
//!                          # even_speed), visibility (tolerance) tables; without `[costs]`
//!                          # the first-try set (all of them, margin and speed "auto": derived
//!                          # from the scene; `--set costs.<cost>.<key>=…` edits that set);
//!                          # with it, exactly the costs it lists;
//!                          # [costs.custom.<name>]: a cost registered in `Extensions`
//! [optimiser]              # iterations, samples_per_window, learning_rate, position_unit,
//!                          # path_samples (path points per window for clearance/motion) …
//! [start]                  # kind = "search" (default: views where each object shows) | "objects"
//!                          # (jitter) | "random" (spread), restarts; or pose = [...], or trajectory = "…";
//!                          # route = "auto" | "planned" | "straight" (around the geometry between windows)
//! [output]                 # frames (or fps × seconds; default 3 s per query at 30 fps),
//!                          # width, height (1280 × 720), mask_overlay (none), runs_dir …
//! [pose]                   # `splatraj pose`: query, ablation; [pose.optimiser]: its Adam
//! [approximations]         # optimisation renders only: stop_transmittance, min_opacity (exact by default)
//! [study]                  # `splatraj study`: factors, design, seeds, quality, evaluation
//! [sgld]                   # `splatraj pose --sgld`: Langevin settings
//! ```
//!
//! Unknown keys are errors (every table denies them), as are out-of-range values; both name
//! the key. `--set key=value` edits the parsed TOML before it is checked, so an override is
//! checked exactly like the file (`--set optimiser.iterations=50`, `--set queries.0.text=lamp`).
//! Relative paths are relative to the config file's folder ([`Config::base_dir`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::Intrinsics;
use splatraj_render::rasterize::Approximations;
use splatraj_render::render::Rasterizer;
use splatraj_semantic::TargetsConfig;
use splatraj_traj::costs::{CostsConfig, DEFAULT_TARGET_RATIO};
use splatraj_traj::optimise::{
    ObjectView, RouteKind, SgldOptions, SinglePoseOptions, StartDistribution, TrajectoryOptions,
};
use splatraj_traj::shots::ShotSpec;
use splatraj_traj::trajectory::TrajectoryModel;

use crate::extensions::Extensions;

/// The whole config file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Run name: outputs go to `<output.runs_dir>/<name>/<timestamp>/`.
    pub name: String,
    /// Seed of everything random (starts, time samples, SGLD noise).
    #[serde(default)]
    pub seed: u64,
    /// Tensor backend.
    #[serde(default = "default_backend")]
    pub backend: BackendKind,
    /// Float precision of the tensors.
    #[serde(default)]
    pub precision: Precision,
    /// Which rasterizer composites every render of the run (`fused`, the default, or
    /// `tensor`, the readable specification).
    #[serde(default)]
    pub rasterizer: Rasterizer,
    /// The most memory (GB, 10⁹ bytes) the run may plan to use: sizes whose estimated peak
    /// exceeds it are refused before any work. Default: 75 % of the physical memory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_memory_gb: Option<f64>,
    /// Where the Gaussians come from.
    pub scene: SceneConfig,
    /// How queries become per-Gaussian channels.
    #[serde(default)]
    pub targets: TargetsConfig,
    /// The queries, one time window each, in order.
    pub queries: Vec<QueryConfig>,
    /// The optimisation camera.
    #[serde(default)]
    pub camera: CameraConfig,
    /// Trajectory model. Without `[trajectory]`: [`first_try_model`].
    #[serde(default = "first_try_model")]
    pub trajectory: TrajectoryModel,
    /// Costs and weights. Without a `[costs]` table: [`CostsConfig::first_try`] (the paper's
    /// four, clearance and motion limits derived from the scene, visibility).
    #[serde(default = "CostsConfig::first_try")]
    pub costs: CostsConfig,
    /// Trajectory optimiser.
    #[serde(default)]
    pub optimiser: TrajectoryOptions,
    /// Starting point.
    #[serde(default)]
    pub start: StartConfig,
    /// Outputs.
    #[serde(default)]
    pub output: OutputConfig,
    /// Single-pose optimisation (`splatraj pose`).
    #[serde(default)]
    pub pose: PoseConfig,
    /// SGLD sampling (`splatraj pose --sgld`).
    #[serde(default)]
    pub sgld: SgldOptions,
    /// Rendering shortcuts of the optimisation passes (trajectory, pose, SGLD), exact by
    /// default; frames and metrics are always rendered exactly. `stop_transmittance`: a pixel
    /// stops before T would fall below it (exact: 1e-4; larger stops earlier); `min_opacity`:
    /// Gaussians with a lower opacity are left out (exact: 0). Their cost in accuracy is
    /// measured by `splatraj study` (docs/results.md).
    #[serde(default, skip_serializing_if = "Approximations::is_exact")]
    pub approximations: Approximations,
    /// `splatraj study`: the variants to run and how to judge them
    /// ([`crate::study::StudyConfig`]).
    #[serde(default, skip_serializing_if = "crate::study::StudyConfig::is_default")]
    pub study: crate::study::StudyConfig,
    /// Folder that relative input paths are resolved against: the config file's folder when
    /// loaded by [`Config::load`], else the working directory. Not part of the file.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The file it was loaded from (for messages); empty when built in code.
    #[serde(skip)]
    pub path: PathBuf,
}

/// RBF centres per window of a config without `[trajectory]`, chosen on the first-try
/// captures (docs/results.md, "First try on real captures").
pub const FIRST_TRY_CENTRES_PER_WINDOW: usize = 4;

/// The trajectory model of a config without `[trajectory]`: RBF with
/// [`FIRST_TRY_CENTRES_PER_WINDOW`] centres per window, normalised to a partition of unity so
/// that the path's ends hold their poses (`splatraj_traj::trajectory::rbf`).
pub fn first_try_model() -> TrajectoryModel {
    TrajectoryModel::Rbf(splatraj_traj::trajectory::Rbf {
        normalisation: splatraj_traj::trajectory::RbfNormalisation::PartitionOfUnity,
        ..splatraj_traj::trajectory::Rbf::new(1, FIRST_TRY_CENTRES_PER_WINDOW, None)
    })
}

fn default_backend() -> BackendKind {
    BackendKind::Flex
}

/// `[scene]`: a file or the built-in demo room (exactly one of `path` and `demo`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneConfig {
    /// Scene file (INRIA PLY, compressed PLY, SPZ).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// The built-in demo room.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub demo: Option<DemoSceneConfig>,
    /// Label sidecar (Segments.ai JSON or a JSON array of ids).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<PathBuf>,
    /// Drop invalid Gaussians (with a warning) instead of stopping.
    pub drop_invalid: bool,
    /// World up; by default guessed from the scene (the demo's is +z).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
}

/// `[scene.demo]`: the demo room's generator settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemoSceneConfig {
    /// Number of Gaussians.
    pub gaussians: usize,
    /// Generator seed.
    pub seed: u64,
}

impl Default for DemoSceneConfig {
    fn default() -> Self {
        let d = splatraj_scene::demo::DemoConfig::default();
        Self {
            gaussians: d.gaussians,
            seed: d.seed,
        }
    }
}

/// `[[queries]]`: one thing to look at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QueryConfig {
    /// The query (label name, phrase, region name), or a name for a `mask` target.
    pub text: String,
    /// Share of the frame the object should cover; default `[camera] target_ratio`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_ratio: Option<f64>,
    /// A per-Gaussian 0/1 mask (`.npy`, one value per Gaussian) used instead of the source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<PathBuf>,
    /// A shot preset for this window (orbit, dolly; trajectory runs): its start and its cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shot: Option<ShotSpec>,
}

/// `[camera]`: the optimisation camera (pinhole, principal point at the centre unless given).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Horizontal field of view, degrees (used unless `fx` is given).
    pub fov_x: f64,
    /// Focal lengths and principal point in pixels (all four, or none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fx: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fy: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cx: Option<f64>,
    /// See `fx`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cy: Option<f64>,
    /// Default target ratio r_t of every query.
    pub target_ratio: f64,
    /// How each query's working distance (the prior radius, the distance at which its object
    /// covers r_t) is found: `measured` (default) or `box`.
    pub working_distance: WorkingDistance,
}

/// How a query's working distance is found (`[camera] working_distance`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorkingDistance {
    /// Estimated from the object's box, then measured on renders of the object alone from ten
    /// directions and corrected (`splatraj_traj::optimise::calibrated_radius`); a prior
    /// `radius` in `[costs.prior]` is kept as given.
    #[default]
    Measured,
    /// Estimated from the object's box alone (Cauchy's mean silhouette): what runs did before
    /// measuring, and what the tuned demo configs keep.
    Box,
}

/// Width of the default optimisation camera, pixels: enough to resolve an object covering
/// 2 % of the frame (about 11 × 11 pixels), few enough for a step in well under a second on
/// 2 cores.
pub const DEFAULT_CAMERA_WIDTH: usize = 96;
/// Height of the default optimisation camera: the default output's 16:9.
pub const DEFAULT_CAMERA_HEIGHT: usize = 54;

impl Default for CameraConfig {
    /// [`DEFAULT_CAMERA_WIDTH`] × [`DEFAULT_CAMERA_HEIGHT`] (the output's 16:9), 60°
    /// horizontal, r_t = 0.15.
    fn default() -> Self {
        Self {
            width: DEFAULT_CAMERA_WIDTH,
            height: DEFAULT_CAMERA_HEIGHT,
            fov_x: 60.0,
            fx: None,
            fy: None,
            cx: None,
            cy: None,
            target_ratio: DEFAULT_TARGET_RATIO,
            working_distance: WorkingDistance::Measured,
        }
    }
}

impl CameraConfig {
    /// The intrinsics at the configured size.
    pub fn intrinsics(&self) -> Result<Intrinsics> {
        if self.width == 0 || self.height == 0 {
            bail!(
                "`camera.width` and `camera.height` must be ≥ 1, got {}×{}",
                self.width,
                self.height
            );
        }
        if !(self.target_ratio > 0.0 && self.target_ratio <= 1.0) {
            bail!(
                "`camera.target_ratio` = {} must be in (0, 1]",
                self.target_ratio
            );
        }
        match (self.fx, self.fy, self.cx, self.cy) {
            (Some(fx), Some(fy), Some(cx), Some(cy)) => {
                Intrinsics::new(fx, fy, cx, cy, self.width, self.height)
                    .context("`camera.fx`/`fy`/`cx`/`cy`")
            }
            (None, None, None, None) => {
                if !(self.fov_x > 0.0 && self.fov_x < 180.0) {
                    bail!(
                        "`camera.fov_x` = {} must be in (0, 180) degrees",
                        self.fov_x
                    );
                }
                Intrinsics::from_fov_x(self.fov_x, self.width, self.height)
                    .context("`camera.fov_x`")
            }
            _ => bail!("`camera`: give all of fx, fy, cx, cy, or none of them (then fov_x)"),
        }
    }
}

/// How starting poses are drawn when no `pose` or `trajectory` is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartKind {
    /// Each window starts from the viewpoint a search finds where its object shows, unhidden
    /// and framed, with short moves between windows (`splatraj_traj::optimise::views`);
    /// restarts try other viewpoints.
    #[default]
    Search,
    /// Each window starts at a camera looking at its object from its prior radius, all from
    /// one side (restarts jitter the azimuth by up to ±`jitter` degrees).
    Objects,
    /// Seeded random cameras in the scene looking at its centre (`spread`).
    Random,
}

/// `[start]`: where the optimisation starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StartConfig {
    /// Object-facing or random starts.
    pub kind: StartKind,
    /// Objects: azimuth jitter of restarts after the first, degrees (≥ 0).
    pub jitter: f64,
    /// Objects: elevation of the view above the horizontal, degrees, in (−90, 90); a flat
    /// scene seen from its front wants a steep one.
    pub elevation: f64,
    /// Random starts: camera centres within `spread` × the scene's half-extent of its centre
    /// (see `splatraj_traj::optimise::start`), in (0, 1].
    pub spread: f64,
    /// Independent random starts; the best result is kept (≥ 1).
    pub restarts: usize,
    /// How the start travels between consecutive windows: `auto` (default: `planned` when
    /// `[costs.clearance]` is on, else `straight`), `planned` (around the geometry: a grid
    /// search keeping the clearance margin, for joins whose straight way does not; see
    /// `splatraj_traj::optimise::route`) or `straight`. Gradient descent alone cannot take a
    /// path that crosses a wall around it; a planned start can.
    pub route: RouteKind,
    /// A fixed start pose Φ = [ω, c] (instead of random starts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<[f64; 6]>,
    /// A path to start from, re-fitted to `[trajectory]`: an earlier run's `trajectory.json`, or
    /// another tool's camera file (nerfstudio `camera_path.json`, COLMAP `images.txt`, INRIA
    /// `cameras.json`, SuperSplat `settings.json`; see `docs/interchange.md`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<PathBuf>,
}

impl StartConfig {
    /// How object starts look at their objects.
    pub fn object_view(&self) -> ObjectView {
        ObjectView {
            elevation_degrees: self.elevation,
            jitter_degrees: self.jitter,
        }
    }

    /// The random-start distribution.
    pub fn distribution(&self) -> StartDistribution {
        StartDistribution {
            spread: self.spread,
        }
    }
}

impl Default for StartConfig {
    fn default() -> Self {
        Self {
            kind: StartKind::Search,
            jitter: ObjectView::default().jitter_degrees,
            elevation: ObjectView::default().elevation_degrees,
            spread: StartDistribution::default().spread,
            restarts: 1,
            route: RouteKind::Auto,
            pose: None,
            trajectory: None,
        }
    }
}

/// Overlay of the target's mask on the output frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaskOverlay {
    /// Plain RGB frames.
    #[default]
    None,
    /// The current window's object tinted.
    Tint,
}

/// What a run whose verdict fails on some window does after writing its folder
/// (`splatraj_traj::metrics::verdict`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VerdictPolicy {
    /// Warn and exit with status 3, so that scripts notice (the default).
    #[default]
    Fail,
    /// Warn, and exit 0 (a study's variants, smoke runs).
    Warn,
}

/// `[output]`: what is written and where.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Folder that holds `<name>/<timestamp>/` run folders (relative to the working
    /// directory, unlike input paths).
    pub runs_dir: PathBuf,
    /// Frames rendered along the whole trajectory (0: none), at evenly spaced times over
    /// [0, 1]; ignored when `seconds` is given. Default: `fps ×` the duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    /// Frame rate of `video.mp4` and of the exports (`exports/<format>/`), frames per second.
    pub fps: f64,
    /// Length of the video in seconds: when given, `fps × seconds` frames (rounded) are
    /// rendered instead of `frames`. Default: `frames / fps` when `frames` is given, else
    /// [`SECONDS_PER_QUERY`] per query.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Mask overlay on the frames.
    pub mask_overlay: MaskOverlay,
    /// What a failed verdict does: `fail` (exit status 3, the default) or `warn`.
    pub verdict: VerdictPolicy,
    /// Poses written to `trajectory.json` (evenly spaced over [0, 1]).
    pub trajectory_samples: usize,
    /// Samples per window for the metrics.
    pub metric_samples: usize,
    /// Samples of the whole trajectory for LDJ.
    pub ldj_samples: usize,
}

/// Seconds of video per query when neither `frames` nor `seconds` is given: long enough to
/// see an object and the move to the next, short enough that three parts make a 9 s clip.
pub const SECONDS_PER_QUERY: f64 = 3.0;

impl Default for OutputConfig {
    /// 1280 × 720 at 30 fps, [`SECONDS_PER_QUERY`] per query, plain frames (the report's
    /// keyframes tint the object).
    fn default() -> Self {
        Self {
            runs_dir: PathBuf::from("runs"),
            frames: None,
            fps: 30.0,
            seconds: None,
            width: 1280,
            height: 720,
            mask_overlay: MaskOverlay::None,
            verdict: VerdictPolicy::Fail,
            trajectory_samples: 201,
            metric_samples: 16,
            ldj_samples: splatraj_traj::metrics::DEFAULT_LDJ_SAMPLES,
        }
    }
}

impl OutputConfig {
    /// Frames to render for `queries` windows: `fps × seconds` (rounded, at least 1) when
    /// `seconds` is given, else `frames`, else `fps ×` [`SECONDS_PER_QUERY`] per query.
    pub fn frame_count(&self, queries: usize) -> usize {
        match (self.seconds, self.frames) {
            (Some(s), _) => ((self.fps * s).round() as usize).max(1),
            (None, Some(frames)) => frames,
            (None, None) => ((self.fps * self.duration(queries)).round() as usize).max(1),
        }
    }

    /// Duration of the whole path in seconds for `queries` windows: `seconds`, else
    /// `frames / fps` (when `frames` ≥ 1), else [`SECONDS_PER_QUERY`] per query.
    pub fn duration(&self, queries: usize) -> f64 {
        match (self.seconds, self.frames) {
            (Some(s), _) => s,
            (None, Some(frames)) if frames > 0 => frames as f64 / self.fps,
            _ => SECONDS_PER_QUERY * queries.max(1) as f64,
        }
    }

    /// Checks the counts and sizes; errors name the key.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            bail!("`output.width` and `output.height` must be ≥ 1");
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            bail!("`output.fps` = {} must be a positive number", self.fps);
        }
        if let Some(s) = self.seconds
            && !(s.is_finite() && s > 0.0)
        {
            bail!("`output.seconds` = {s} must be a positive number");
        }
        if self.trajectory_samples < 2 {
            bail!("`output.trajectory_samples` must be ≥ 2");
        }
        if self.metric_samples == 0 {
            bail!("`output.metric_samples` must be ≥ 1");
        }
        if self.ldj_samples < splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES {
            bail!(
                "`output.ldj_samples` must be ≥ {}",
                splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES
            );
        }
        Ok(())
    }
}

/// The paper's single-pose ablations: which image costs join the prior.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Ablation {
    /// Every cost of `[costs]` as configured.
    Full,
    /// The prior alone.
    Prior,
    /// Prior and TCE.
    PriorTce,
    /// Prior and TRE.
    PriorTre,
    /// Prior, TCE and TRE.
    PriorTceTre,
}

impl Ablation {
    /// Every ablation, in the order of the paper's table.
    pub const ALL: [Ablation; 5] = [
        Ablation::Full,
        Ablation::Prior,
        Ablation::PriorTce,
        Ablation::PriorTre,
        Ablation::PriorTceTre,
    ];

    /// The name used in configs and on the command line (`prior-tce`, …).
    pub fn name(self) -> &'static str {
        match self {
            Ablation::Full => "full",
            Ablation::Prior => "prior",
            Ablation::PriorTce => "prior-tce",
            Ablation::PriorTre => "prior-tre",
            Ablation::PriorTceTre => "prior-tce-tre",
        }
    }

    /// The costs of `config` restricted to this ablation: TCE and TRE on or off as named, the
    /// prior on (with its configured weights, or the defaults), upright as configured.
    pub fn apply(self, config: &CostsConfig) -> CostsConfig {
        let (tce, tre) = match self {
            Ablation::Full => return config.clone(),
            Ablation::Prior => (false, false),
            Ablation::PriorTce => (true, false),
            Ablation::PriorTre => (false, true),
            Ablation::PriorTceTre => (true, true),
        };
        CostsConfig {
            tce: tce.then(|| config.tce.clone().unwrap_or_default()),
            tre: tre.then(|| config.tre.clone().unwrap_or_default()),
            prior: Some(config.prior.clone().unwrap_or_default()),
            // Every other cost (upright, custom, …) as configured.
            ..config.clone()
        }
    }
}

impl std::str::FromStr for Ablation {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ablation::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Ablation::ALL.iter().map(|a| a.name()).collect();
                format!(
                    "unknown ablation `{s}`: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// `[pose]`: single-pose optimisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    /// Which costs (the paper's Table I ablations).
    pub ablation: Ablation,
    /// Which query of `[[queries]]` to frame (0-based).
    pub query: usize,
    /// Adam settings (`[pose.optimiser]`).
    pub optimiser: SinglePoseOptions,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            ablation: Ablation::Full,
            query: 0,
            optimiser: SinglePoseOptions::default(),
        }
    }
}

impl Config {
    /// Reads `path` (and the files it `extends`), applies `overrides` (`key=value`), and
    /// checks the result with the built-in costs only.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Config> {
        Self::load_with(path, overrides, &Extensions::default())
    }

    /// [`Config::load`] for a config that may name the costs, trajectory models and target
    /// sources registered in `extensions`.
    pub fn load_with(path: &Path, overrides: &[String], extensions: &Extensions) -> Result<Config> {
        let mut value = read_table(path, 0)?;
        write_first_try_tables(&mut value, overrides)?;
        let mut set_keys = Vec::with_capacity(overrides.len());
        for o in overrides {
            set_keys.push((apply_override(&mut value, o)?, o.as_str()));
        }
        let mut config: Config = deserialize_table(value).map_err(|(key, message)| {
            // A key an override set, a key below it, or the table holding it (a tagged table
            // like `[trajectory]` reports its own name) is the option's fault, not the file's.
            let set_by = set_keys.iter().rev().find(|(k, _)| {
                key == *k
                    || key.starts_with(&format!("{k}."))
                    || (!key.is_empty() && k.starts_with(&format!("{key}.")))
            });
            match set_by {
                Some((_, o)) => anyhow::anyhow!("--set {o}: `{key}`: {message}"),
                None => anyhow::anyhow!("config {}: {}", path.display(), at_key(&key, &message)),
            }
        })?;
        config.base_dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf();
        config.path = path.to_path_buf();
        config
            .validate_with(extensions)
            .with_context(|| format!("config {}", path.display()))?;
        Ok(config)
    }

    /// A config from TOML text (no `extends`), checked with `extensions`; relative paths are
    /// resolved against `base_dir`.
    pub fn from_toml(text: &str, base_dir: &Path, extensions: &Extensions) -> Result<Config> {
        let table: toml::Table = toml::from_str(text)
            .map_err(|e| anyhow::anyhow!("config is not valid TOML: {}", e.message().trim_end()))?;
        let mut config: Config = deserialize_table(table)
            .map_err(|(key, message)| anyhow::anyhow!("config: {}", at_key(&key, &message)))?;
        config.base_dir = base_dir.to_path_buf();
        config.validate_with(extensions).context("config")?;
        Ok(config)
    }

    /// `p` resolved against [`Config::base_dir`] (absolute paths unchanged).
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base_dir.join(p)
        }
    }

    /// The scene file, resolved (`None` for the demo room).
    pub fn scene_file(&self) -> Option<PathBuf> {
        self.scene.path.as_deref().map(|p| self.resolve(p))
    }

    /// Range checks that serde cannot express, with the built-in costs only; errors name the
    /// key.
    pub fn validate(&self) -> Result<()> {
        self.validate_with(&Extensions::default())
    }

    /// [`Config::validate`] for a config that may name the costs, models and sources
    /// registered in `extensions`.
    pub fn validate_with(&self, extensions: &Extensions) -> Result<()> {
        if self.name.is_empty()
            || self
                .name
                .chars()
                .any(|c| !(c.is_alphanumeric() || "-_.".contains(c)))
        {
            bail!(
                "`name` = {:?} must be non-empty and use only letters, digits, '-', '_', '.'",
                self.name
            );
        }
        match (&self.scene.path, &self.scene.demo) {
            (Some(_), Some(_)) => bail!("`scene`: give `path` or `demo`, not both"),
            (None, None) => bail!("`scene`: give `path` (a scene file) or `demo = {{}}`"),
            _ => {}
        }
        if let Some(up) = self.scene.up
            && !(up.iter().all(|v| v.is_finite()) && up.iter().any(|v| *v != 0.0))
        {
            bail!("`scene.up` = {up:?} must be finite and non-zero");
        }
        if let Some(gb) = self.max_memory_gb
            && !(gb.is_finite() && gb > 0.0)
        {
            bail!("`max_memory_gb` = {gb} must be finite and > 0");
        }
        if self.queries.is_empty() {
            bail!("`queries`: at least one `[[queries]]` table is needed");
        }
        for (i, q) in self.queries.iter().enumerate() {
            if let Some(r) = q.target_ratio
                && !(r > 0.0 && r <= 1.0)
            {
                bail!("`queries.{i}.target_ratio` = {r} must be in (0, 1]");
            }
            if let Some(shot) = &q.shot
                && let Err(e) = shot.validate()
            {
                bail!("`queries.{i}.shot.{}` {}", e.field, e.reason);
            }
        }
        if self.start.route == RouteKind::Planned && self.costs.clearance.is_none() {
            bail!(
                "`start.route` = \"planned\" routes around the geometry the clearance cost \
                 keeps clear of: add `[costs.clearance]` (with its `margin`), or use \"auto\""
            );
        }
        self.camera.intrinsics()?;
        self.costs
            .build_with(&extensions.costs)
            .map_err(anyhow::Error::msg)?;
        self.trajectory
            .build_with(self.queries.len(), &extensions.models)
            .and_then(|model| model.basis().validate())
            .map_err(|e| anyhow::anyhow!("`trajectory`: {e}"))?;
        if let splatraj_semantic::SourceKind::Custom(name) = &self.targets.source
            && !extensions.sources.contains(name)
        {
            bail!(
                "`targets.source` = \"custom.{name}\" names no registered target source \
                 (registered: {})",
                match extensions.sources.names() {
                    n if n.is_empty() => "none".to_string(),
                    n => n.join(", "),
                }
            );
        }
        self.optimiser
            .validate()
            .map_err(|e| anyhow::anyhow!("`optimiser`: {e}"))?;
        if self.start.restarts == 0 {
            bail!("`start.restarts` must be ≥ 1");
        }
        if !(self.start.spread > 0.0 && self.start.spread <= 1.0) {
            bail!("`start.spread` = {} must be in (0, 1]", self.start.spread);
        }
        if !(self.start.jitter.is_finite() && self.start.jitter >= 0.0) {
            bail!(
                "`start.jitter` = {} must be finite and ≥ 0 degrees",
                self.start.jitter
            );
        }
        if self.start.elevation.is_nan() || self.start.elevation.abs() >= 90.0 {
            bail!(
                "`start.elevation` = {} must be in (−90, 90) degrees",
                self.start.elevation
            );
        }
        if self.start.pose.is_some() && self.start.trajectory.is_some() {
            bail!("`start`: give `pose` or `trajectory`, not both");
        }
        if let Some(p) = self.start.pose {
            splatraj_render::camera_file::check_pose_range(&p)
                .map_err(|e| anyhow::anyhow!("`start.pose`: {e}"))?;
        }
        self.output.validate()?;
        self.pose
            .optimiser
            .validate()
            .map_err(|e| anyhow::anyhow!("`pose.optimiser`: {e}"))?;
        if self.pose.query >= self.queries.len() {
            bail!(
                "`pose.query` = {} but there are {} queries (0-based)",
                self.pose.query,
                self.queries.len()
            );
        }
        self.sgld
            .validate()
            .map_err(|e| anyhow::anyhow!("`sgld`: {e}"))?;
        self.approximations
            .check()
            .map_err(|e| match e.split_once(' ') {
                Some((key, rest)) => anyhow::anyhow!("`approximations.{key}` {rest}"),
                None => anyhow::anyhow!("`approximations`: {e}"),
            })?;
        self.study.validate().map_err(anyhow::Error::msg)?;
        Ok(())
    }
}

/// Writes the first-try `[costs]` and `[trajectory]` into a config that leaves them out, when
/// an override edits them: `--set costs.motion.weight=0` or `--set
/// trajectory.centres_per_window=4` then tunes the set the config runs with, instead of
/// becoming the only cost (a `[costs]` table lists exactly the costs that are on) or a model
/// without its `kind`.
fn write_first_try_tables(value: &mut toml::Table, overrides: &[String]) -> Result<()> {
    let edits = |table: &str| {
        overrides
            .iter()
            .any(|o| o.trim_start().starts_with(&format!("{table}.")))
    };
    if !value.contains_key("costs") && edits("costs") {
        let defaults = toml::Value::try_from(CostsConfig::first_try())
            .context("the default `[costs]` as TOML")?;
        value.insert("costs".into(), defaults);
    }
    // A new `kind` is a new model: its own keys, not the first-try RBF's.
    let new_kind = overrides.iter().any(|o| {
        let key = o.split_once('=').map_or(o.as_str(), |(k, _)| k).trim();
        key == "trajectory" || key == "trajectory.kind"
    });
    if !value.contains_key("trajectory") && edits("trajectory") && !new_kind {
        let defaults = toml::Value::try_from(first_try_model())
            .context("the default `[trajectory]` as TOML")?;
        value.insert("trajectory".into(), defaults);
    }
    Ok(())
}

/// Deserialises the whole config, or says at which key (dotted, list entries by index:
/// `queries.0.text`, as `--set` writes it; empty at the top level) and what went wrong.
fn deserialize_table(table: toml::Table) -> Result<Config, (String, String)> {
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let key = e
            .path()
            .iter()
            .map(|segment| match segment {
                serde_path_to_error::Segment::Seq { index } => index.to_string(),
                other => other.to_string(),
            })
            .collect::<Vec<_>>()
            .join(".");
        (key, e.into_inner().message().trim_end().to_string())
    })
}

/// "`key`: message", or the message alone at the top level.
fn at_key(key: &str, message: &str) -> String {
    if key.is_empty() || key == "?" {
        message.to_string()
    } else {
        format!("`{key}`: {message}")
    }
}

/// How many `extends` a config may chain (a cycle ends here with an error).
const MAX_EXTENDS: usize = 8;

/// Reads a config file as a TOML table, merged over the file its `extends` key names.
///
/// `extends = "demo.toml"` (relative to this file) loads that config first; this file's keys
/// then replace its values, tables merging key by key (so a variant config states only what
/// differs; see [`merge`]). The `extends` key itself is not part of the schema.
fn read_table(path: &Path, depth: usize) -> Result<toml::Table> {
    if depth > MAX_EXTENDS {
        bail!(
            "config {}: more than {MAX_EXTENDS} nested `extends` (a cycle?)",
            path.display()
        );
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    let mut table: toml::Table = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("config {} is not valid TOML: {e}", path.display()))?;
    match table.remove("extends") {
        None => Ok(table),
        Some(toml::Value::String(base)) => {
            let dir = path.parent().unwrap_or(Path::new("."));
            let mut merged = read_table(&dir.join(&base), depth + 1)
                .with_context(|| format!("`extends` of {}", path.display()))?;
            merge(&mut merged, table);
            Ok(merged)
        }
        Some(other) => bail!(
            "config {}: `extends` must be a file name, got {other}",
            path.display()
        ),
    }
}

/// Merges `over` into `base`: tables recursively, anything else replaced. A table whose
/// `kind` differs from the base's (`[trajectory] kind = "waypoint"` over an RBF) replaces it
/// whole: the other keys belonged to the old kind.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o))
                if o.get("kind").is_none_or(|k| Some(k) == b.get("kind")) =>
            {
                merge(b, o)
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Sets `key=value` in the TOML table and returns the key; the value is parsed as TOML (a bare
/// word that is not valid TOML is taken as a string, so `--set queries.0.text=lamp` works).
/// Numeric path segments index arrays (`queries.0.text`). An empty value, or one that starts
/// like a TOML number, list, table or quoted string but does not parse, is an error naming
/// the option.
pub fn apply_override(root: &mut toml::Table, assignment: &str) -> Result<String> {
    apply_assignment(root, assignment, "--set")
}

/// [`apply_override`] for another command-line `option` (errors name it).
pub fn apply_assignment(root: &mut toml::Table, assignment: &str, option: &str) -> Result<String> {
    let Some((key, raw)) = assignment.split_once('=') else {
        bail!("{option} {assignment}: expected KEY=VALUE");
    };
    let key = key.trim();
    if key.is_empty() {
        bail!("{option} {assignment}: no key before `=` (expected KEY=VALUE)");
    }
    let raw = raw.trim();
    if raw.is_empty() {
        bail!("{option} {assignment}: no value after `=` (a string needs quotes: {key}=\"\")");
    }
    let value: toml::Value = match toml::from_str::<toml::Table>(&format!("v = {raw}")) {
        Ok(mut t) => t.remove("v").expect("just parsed"),
        Err(e)
            if raw.starts_with(['[', '{', '"', '\'', '+', '-', '.'])
                || raw.starts_with(|c: char| c.is_ascii_digit()) =>
        {
            bail!(
                "{option} {assignment}: `{raw}` is not a valid TOML value ({}; a string needs \
                 quotes: {key}='\"{raw}\"')",
                e.message().trim_end()
            )
        }
        Err(_) => toml::Value::String(raw.to_string()),
    };
    let parts: Vec<&str> = key.split('.').map(str::trim).collect();
    if parts.iter().any(|p| p.is_empty()) {
        bail!("{option} {assignment}: empty key segment in `{key}`");
    }
    let mut tree = toml::Value::Table(std::mem::take(root));
    let assignment = format!("{option} {assignment}");
    let result = set_path(&mut tree, &parts, 0, value, &assignment);
    if let toml::Value::Table(t) = tree {
        *root = t;
    }
    result.map(|()| parts.join("."))
}

/// Sets `parts[depth..]` below `node` to `value`, creating tables on the way.
fn set_path(
    node: &mut toml::Value,
    parts: &[&str],
    depth: usize,
    value: toml::Value,
    key: &str,
) -> Result<()> {
    let part = parts[depth];
    let here = parts[..=depth].join(".");
    let last = depth + 1 == parts.len();
    let child = match node {
        toml::Value::Table(t) => {
            if last {
                t.insert(part.to_string(), value);
                return Ok(());
            }
            t.entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        }
        toml::Value::Array(a) => {
            let i: usize = part
                .parse()
                .with_context(|| format!("{key}: `{here}` must index a list (0-based)"))?;
            let len = a.len();
            let slot = a
                .get_mut(i)
                .with_context(|| format!("{key}: `{here}` is out of range ({len} entries)"))?;
            if last {
                *slot = value;
                return Ok(());
            }
            slot
        }
        _ => bail!(
            "{key}: `{}` is a value, not a table",
            parts[..depth].join(".")
        ),
    };
    set_path(child, parts, depth + 1, value, key)
}
