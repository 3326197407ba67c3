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
//! # lens = "fixed"        # or "zoom": a zoom s(t) optimised with the pose, bounded by
//! # zoom_range = [0.5, 2.0]  # [min, max] of s (0 < min < 1 < max; docs/conventions.md "The lens")
//!
//! [trajectory]             # kind = "rbf" | "waypoint" | "polynomial" and its parameters,
//!                          # or kind = "custom.<name>" and [trajectory.custom.<name>]: a
//!                          # model registered in `Extensions` (as `source = "custom.<name>"`
//!                          # and [targets.custom.<name>] for a target source)
//! [costs]                  # tce, tre, upright, prior, clearance (margin, sigma, min_opacity),
//!                          # motion (max_speed, max_acceleration, max_angular_speed,
//!                          # max_orbit_speed, even_speed), visibility (tolerance)
//!                          # tables; without `[costs]` the first-try set (all of them,
//!                          # margin and speed "auto": derived from the scene;
//!                          # `--set costs.<cost>.<key>=…` edits that set);
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
//! # optimise_gaussians = "auto"  # (top level) the optimisation renders a coarse copy of at most
//! #                          # this many Gaussians (neighbours merged): "auto" (1 M for larger
//! #                          # scenes), "all" or a number; metrics and frames use the scene itself
//! [approximations]         # optimisation renders only: stop_transmittance, min_opacity (exact by default)
//! [study]                  # `splatraj study`: factors, design, seeds, quality, evaluation
//! [sgld]                   # `splatraj pose --sgld`: Langevin settings
//! ```
//!
//! Unknown keys are errors (every table denies them), as are out-of-range values; both name
//! the key. `--set key=value` edits the parsed TOML before it is checked, so an override is
//! checked exactly like the file (`--set optimiser.iterations=50`, `--set queries.0.text=lamp`).
//! Relative paths are relative to the config file's folder ([`Config::base_dir`]).
//!
//! This module tree is the bottom of the crate: the schema (one file per table), [`load`]
//! (the file read once as a [`ConfigFile`], `extends`), [`first_try`] (the tables an override
//! of a left-out `[costs]` or `[trajectory]` edits), [`overrides`] (`--set`, parsed once) and
//! [`validate`] (range checks, each a [`ConfigError`] naming the key) import nothing of the
//! crate but [`crate::extensions`] (the registries a config may name), so anything can read a
//! config without the runs.

pub mod camera;
pub mod first_try;
pub mod load;
pub mod optimise_gaussians;
pub mod output;
pub mod overrides;
pub mod pose;
pub mod queries;
pub mod scene;
pub mod start;
pub mod study;
pub mod validate;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
pub use splatraj_config::ConfigError;
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::rasterize::Approximations;
use splatraj_render::render::Rasterizer;
use splatraj_semantic::TargetsConfig;
use splatraj_traj::costs::CostsConfig;
use splatraj_traj::optimise::{SgldOptions, TrajectoryOptions};
use splatraj_traj::trajectory::TrajectoryModel;

pub use camera::{
    CameraConfig, DEFAULT_CAMERA_HEIGHT, DEFAULT_CAMERA_WIDTH, LensKind, WorkingDistance,
};
pub use load::ConfigFile;
pub use optimise_gaussians::{AUTO_OPTIMISE_GAUSSIANS, OptimiseGaussians};
pub use output::{MaskOverlay, OutputConfig, SECONDS_PER_QUERY, VerdictPolicy};
pub use overrides::{Override, apply_assignment, apply_override};
pub use pose::{Ablation, PoseConfig};
pub use queries::QueryConfig;
pub use scene::{DemoSceneConfig, SceneConfig};
pub use start::{StartConfig, StartKind};
pub use study::StudyConfig;

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
    /// What the optimisation passes render: the scene itself (`"all"`) or a coarse copy of at
    /// most this many Gaussians; `"auto"` (default): a copy of 1 M for larger scenes. Metrics,
    /// verdicts and frames always render the scene itself ([`OptimiseGaussians`]).
    #[serde(default, skip_serializing_if = "OptimiseGaussians::is_auto")]
    pub optimise_gaussians: OptimiseGaussians,
    /// `splatraj study`: the variants to run and how to judge them
    /// ([`StudyConfig`]).
    #[serde(default, skip_serializing_if = "StudyConfig::is_default")]
    pub study: StudyConfig,
    /// Folder that relative input paths are resolved against: the config file's folder when
    /// loaded by [`Config::load`], else the working directory. Not part of the file.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The file it was loaded from (for messages); empty when built in code.
    #[serde(skip)]
    pub path: PathBuf,
}

/// How a config file names a `[targets]` key in errors: `targets.<key>`.
pub fn targets_key(key: &str) -> String {
    format!("targets.{key}")
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

impl Config {
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
}
