//! [`Experiment`]: a config made concrete. [`Experiment::prepare`] reads and checks every
//! input (scene, world up, one target per query, its time window and prior radius) before
//! anything runs or any file is written, so a bad file or query fails with nothing written.

use anyhow::{Context, Result, bail};
use burn::tensor::{DType, Device};
use splatraj_render::camera::Intrinsics;
use splatraj_render::counters::{self, Counts};
use splatraj_render::render::DeviceScene;
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::{InvalidPolicy, ReadOptions, ResolvedUp, Scene, read_scene};
use splatraj_semantic::{Relevancy, Scoring, Target, read_mask_file, select};
use splatraj_traj::clearance::{Occupancy, OccupancySpec};
use splatraj_traj::costs::{OrAuto, QueryContext, WeightedCosts, default_prior_radius};
use splatraj_traj::optimise::{Candidate, WindowTarget};
use splatraj_traj::trajectory::TrajectoryModel;
use splatraj_traj::transitions::JoinKind;

use crate::config::Config;
use crate::extensions::Extensions;
use crate::prepare::memo::Memo;

/// A setting derived from the scene because the config left it `"auto"` (or out).
#[derive(Debug, Clone, PartialEq)]
pub struct Derived {
    /// Its config key.
    pub key: &'static str,
    /// The value now in the config.
    pub value: f64,
    /// How it was derived, in words.
    pub why: String,
}

/// A coarse copy of the scene and each window's mask on it (`optimise_gaussians`; built and
/// read in [`crate::prepare::optimised_scene`]).
#[derive(Debug)]
pub struct CoarseCopy {
    /// The merged scene.
    pub scene: Scene,
    /// Each window's mask over the merged Gaussians.
    pub masks: Vec<Vec<f32>>,
}

/// Everything loaded and checked for a run of one config.
#[derive(Debug)]
pub struct Experiment {
    /// The config it was prepared from.
    pub config: Config,
    /// The registries its costs, model and target source are built from.
    pub extensions: Extensions,
    /// The scene on the host.
    pub scene: Scene,
    /// Where it came from (a path, or `demo (…)`).
    pub scene_name: String,
    /// World up (unit length) and where it came from.
    pub up: ResolvedUp,
    /// Centre and half-extent of the scene's robust bounding box (random starts).
    pub bounds: ([f64; 3], [f64; 3]),
    /// One target per query, in order: its window's object mask and cost context.
    pub windows: Vec<WindowTarget>,
    /// The `[trajectory]` model for the windows, built once (a custom model from
    /// [`Extensions::models`](crate::Extensions::models)): the starts, the memory plan and the
    /// run all use this one.
    pub model: TrajectoryModel,
    /// The selected Gaussians of each query (counts for the report).
    pub selected: Vec<usize>,
    /// What grounding said about each query (a selection file's matched share), for the plan.
    pub notes: Vec<Vec<String>>,
    /// Each query's object box as (centre, half extent): its robust extent around its centre.
    pub boxes: Vec<([f64; 3], [f64; 3])>,
    /// The settings that were `"auto"` in the config and were derived from the scene, in the
    /// order they were resolved (`config` holds the values).
    pub derived: Vec<Derived>,
    /// The plain device (frames, metrics); [`Experiment::autodiff_scene`] wraps it.
    pub device: Device,
    /// Float dtype of every tensor.
    pub dtype: DType,
    /// The optimisation camera.
    pub intrinsics: Intrinsics,
    /// The clearance cost's occupancy, built on first use per spec ([`Experiment::occupancy`]):
    /// start planning, the optimisation and the metrics all ask for it, and on a 3M-Gaussian
    /// scene each k-d tree build took seconds.
    pub(crate) occupancy_memo: Memo<OccupancySpec, Occupancy>,
    /// The view search's choice for all windows, per restart, keyed by what else the search
    /// reads ([`Experiment::searched_views`]): `run` checks the starts before it runs them,
    /// and each search renders hundreds of views.
    pub(crate) views_memo: Memo<String, Vec<Vec<Candidate>>>,
    /// What each join of windows becomes (`[output] transitions`), judged once
    /// ([`Experiment::joins`]): the starts, the run's model and the plan all ask for it.
    pub(crate) joins_memo: Memo<String, Vec<JoinKind>>,
    /// The scene on the plain device, uploaded once ([`Experiment::plain_scene`]): the start
    /// search, the metrics and the frames render it (a 6M-Gaussian capture is ~1.5 GB to copy).
    pub(crate) scene_memo: Memo<(), DeviceScene>,
    /// Each window's object alone on the plain device, keyed by its Gaussians' indices
    /// ([`Experiment::object_alone`]; how many are kept: `alone_scenes_kept`).
    pub(crate) alone_memo: Memo<Vec<u32>, DeviceScene>,
    /// The coarse copy the optimisation renders instead of `scene`, when `optimise_gaussians`
    /// asks for one ([`Experiment::optimisation_scene`]).
    pub coarse: Option<CoarseCopy>,
    /// When [`Experiment::prepare`] started: a run's total time counts from here.
    pub prepared_at: std::time::Instant,
    /// The device counters then: a run's preparation counts from here (`run.counts`).
    pub prepared_counts: Counts,
}

/// The smallest working distance, as a share of the scene's diagonal: a millimetre in a
/// kilometre-wide capture.
pub const MIN_DISTANCE_OF_DIAGONAL: f64 = 1e-6;

/// The largest working distance, as a multiple of the scene's diagonal: a whole capture seen
/// small from far outside it.
pub const MAX_DISTANCE_OF_DIAGONAL: f64 = 100.0;

impl Experiment {
    /// Loads the scene, resolves world up and grounds every query, with the built-in costs.
    pub fn prepare(config: &Config) -> Result<Self> {
        Self::prepare_with(config, &Extensions::default())
    }

    /// [`Experiment::prepare`] for a config that may use the costs, trajectory models and
    /// target sources of `extensions`.
    pub fn prepare_with(config: &Config, extensions: &Extensions) -> Result<Self> {
        let (prepared_at, prepared_counts) = (std::time::Instant::now(), counters::snapshot());
        let mut experiment = Self::prepare_on(config, extensions, load_scene(config)?)?;
        experiment.prepared_at = prepared_at;
        experiment.prepared_counts = prepared_counts;
        Ok(experiment)
    }

    /// [`Experiment::prepare_with`] on the scene of `config.scene` already read, with its name
    /// ([`load_scene`]): configs that share `[scene]` read it once.
    pub fn prepare_on(
        config: &Config,
        extensions: &Extensions,
        (scene, scene_name): (Scene, String),
    ) -> Result<Self> {
        let (prepared_at, prepared_counts) = (std::time::Instant::now(), counters::snapshot());
        if scene.is_empty() {
            bail!("scene {scene_name} has no Gaussians");
        }
        let up = crate::prepare::scene_up::scene_up(config, &scene)
            .with_context(|| format!("config {}", config.path.display()))?;
        let bounds = scene
            .robust_bounds(0.02)
            .or_else(|| scene.bounds())
            .context("the scene's bounds are not finite")?;
        let centre: [f64; 3] =
            std::array::from_fn(|i| 0.5 * (bounds.min[i] + bounds.max[i]) as f64);
        let half: [f64; 3] = std::array::from_fn(|i| 0.5 * (bounds.max[i] - bounds.min[i]) as f64);
        let device = config.backend.device_for(config.precision.dtype())?;
        let intrinsics = config.camera.intrinsics()?;
        // One window per query (grounding keeps their order and count).
        let model = config
            .trajectory
            .build_with(config.queries.len(), &extensions.models)
            .context("`trajectory`")?;
        let mut experiment = Experiment {
            config: config.clone(),
            extensions: extensions.clone(),
            scene,
            scene_name,
            up,
            bounds: (centre, half),
            windows: Vec::new(),
            model,
            selected: Vec::new(),
            notes: Vec::new(),
            boxes: Vec::new(),
            derived: Vec::new(),
            device,
            dtype: config.precision.dtype(),
            intrinsics,
            occupancy_memo: Memo::default(),
            views_memo: Memo::default(),
            joins_memo: Memo::default(),
            scene_memo: Memo::default(),
            alone_memo: Memo::default(),
            coarse: None,
            prepared_at,
            prepared_counts,
        };
        // Grounding checks its own memory (a lifted field's views); what comes after renders at
        // the camera's size.
        experiment.ground_queries()?;
        experiment.alone_memo = Memo::keeping(experiment.alone_scenes_kept());
        experiment
            .preparation_memory()
            .check(experiment.memory_limit()?, crate::resources::RAISE_LIMIT)?;
        if experiment.config.camera.working_distance == crate::config::WorkingDistance::Measured {
            experiment.measure_working_distances()?;
        }
        experiment.derive_from_scene()?;
        // The dolly zooms' zoom is r/r_w: checkable now that the working radii are known.
        experiment
            .check_shot_zoom()
            .with_context(|| format!("config {}", config.path.display()))?;
        experiment.build_coarse_copy()?;
        Ok(experiment)
    }

    /// Replaces each window's working distance (prior radius, estimated from its box) by the
    /// one measured on renders of its object alone
    /// ([`splatraj_traj::optimise::calibrated_radius`]), when the config leaves the prior's
    /// `radius` to the windows.
    fn measure_working_distances(&mut self) -> Result<()> {
        if self
            .config
            .costs
            .prior
            .as_ref()
            .is_some_and(|p| p.radius.is_some())
        {
            return Ok(());
        }
        for i in 0..self.windows.len() {
            let alone = self.object_alone(i);
            let context = &self.windows[i].context;
            let measured = splatraj_traj::optimise::calibrated_radius(
                &alone,
                context.object_centre,
                context.prior_radius,
                context.target_ratio,
                self.up.up,
                &self.intrinsics,
                self.config.rasterizer,
            )
            .with_context(|| format!("`queries.{i}`: measuring its working distance"))?;
            self.windows[i].context.prior_radius = measured;
        }
        Ok(())
    }

    /// Refuses a working distance out of proportion to the scene (outside
    /// [`MIN_DISTANCE_OF_DIAGONAL`, `MAX_DISTANCE_OF_DIAGONAL`] × its diagonal): it comes from a
    /// camera or a target ratio no view can satisfy (a field of view near 180°, a ratio near
    /// 0), and every size derived from it (margin, speed, the start's route) would follow it.
    fn check_working_distances(&self, diagonal: f64) -> Result<()> {
        let (low, high) = (
            MIN_DISTANCE_OF_DIAGONAL * diagonal,
            MAX_DISTANCE_OF_DIAGONAL * diagonal,
        );
        for (i, window) in self.windows.iter().enumerate() {
            let distance = window.context.prior_radius;
            if !(distance >= low && distance <= high) {
                bail!(
                    "`queries.{i}` ({:?}): its working distance {distance:.3e} is out of \
                     proportion to the scene (diagonal {diagonal:.3}; between {low:.3e} and \
                     {high:.3e} expected); check `camera.fov_x` (now {:?}°) and the query's \
                     target ratio (now {:?})",
                    window.name,
                    self.config.camera.fov_x,
                    window.context.target_ratio
                );
            }
        }
        Ok(())
    }

    /// Replaces the config's `"auto"` settings by values derived from the scene and the
    /// queries' working distances, and records them in [`Experiment::derived`].
    fn derive_from_scene(&mut self) -> Result<()> {
        let radii: Vec<f64> = self
            .windows
            .iter()
            .map(|w| w.context.prior_radius)
            .collect();
        let smallest = radii.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = radii.iter().sum::<f64>() / radii.len().max(1) as f64;
        let diagonal = 2.0 * glam::DVec3::from(self.bounds.1).length();
        self.check_working_distances(diagonal)?;
        // A margin wider than the scene puts every view inside it: the cost would push the
        // camera out of the scene, and the verdict would fail every window.
        if let Some(clearance) = &self.config.costs.clearance
            && let OrAuto::Value(margin) = clearance.margin
            && (margin > diagonal || margin.is_nan())
        {
            bail!(
                "`costs.clearance.margin` = {margin:?} is larger than the scene's diagonal \
                 ({diagonal:.3}): every view would be inside the margin; give it in scene units \
                 or leave it \"auto\""
            );
        }
        if let Some(clearance) = &mut self.config.costs.clearance
            && clearance.margin.is_auto()
        {
            let margin = splatraj_traj::costs::auto_margin(smallest, diagonal);
            if !(margin.is_finite() && margin > 0.0) {
                bail!(
                    "`costs.clearance.margin` = \"auto\": the scene's size and the working \
                     distances give no margin ({margin}); give `margin` in scene units"
                );
            }
            clearance.margin = OrAuto::Value(margin);
            self.derived.push(Derived {
                key: "costs.clearance.margin",
                value: margin,
                why: format!(
                    "{} × the smallest working distance ({smallest:.3}), at most {} × the \
                     scene's diagonal ({diagonal:.3})",
                    splatraj_traj::costs::clearance::AUTO_MARGIN_OF_RADIUS,
                    splatraj_traj::costs::clearance::AUTO_MARGIN_OF_SCENE
                ),
            });
        }
        let window_seconds =
            self.config.output.duration(self.windows.len()) / self.windows.len().max(1) as f64;
        // The camera's way between two windows' views is at most the objects' distance plus
        // both working distances.
        let largest_travel = self
            .windows
            .windows(2)
            .map(|w| {
                glam::DVec3::from(w[0].context.object_centre)
                    .distance(glam::DVec3::from(w[1].context.object_centre))
                    + w[0].context.prior_radius
                    + w[1].context.prior_radius
            })
            .fold(0.0, f64::max);
        if let Some(motion) = &mut self.config.costs.motion
            && motion.max_speed == Some(OrAuto::Auto)
        {
            let speed = splatraj_traj::costs::auto_max_speed(mean, largest_travel, window_seconds);
            motion.max_speed = Some(OrAuto::Value(speed));
            self.derived.push(Derived {
                key: "costs.motion.max_speed",
                value: speed,
                why: format!(
                    "{} mean working distances ({mean:.3}) per second, or the longest pan \
                     between views ({largest_travel:.3}) in {} of a {window_seconds:.1} s window \
                     at the eased pan's peak",
                    splatraj_traj::costs::motion::AUTO_SPEED_RADII_PER_SECOND,
                    splatraj_traj::costs::motion::AUTO_SPEED_JOIN_SHARE
                ),
            });
        }
        Ok(())
    }

    /// One target per query: from its mask file or the `[targets]` source.
    fn ground_queries(&mut self) -> Result<()> {
        let config = &self.config;
        let at = || format!("config {}", config.path.display());
        let selection = config
            .targets
            .selection()
            .map_err(|e| anyhow::anyhow!("{}: {e}", at()))?;
        let source = if config.queries.iter().any(|q| q.mask.is_none()) {
            Some(
                crate::prepare::grounding::build_source(
                    config,
                    self.scene.len(),
                    &self.device,
                    &self.extensions,
                    &crate::config::targets_key,
                )
                .map_err(|e| anyhow::anyhow!("{}: {e:#}", at()))?,
            )
        } else {
            None
        };
        let (tx, ty) = self.intrinsics.tan_half_fov();
        let (fov_x, fov_y) = (2.0 * tx.atan(), 2.0 * ty.atan());
        let half = self.bounds.1;
        for (i, query) in config.queries.iter().enumerate() {
            let group = query.shot.as_ref().map_or(&[][..], |s| s.group_objects());
            let target: Target = match (&query.mask, &source) {
                (Some(_), _) if !group.is_empty() => {
                    bail!("`queries.{i}`: a group shot frames its `shot.objects`; leave out `mask`")
                }
                (None, Some(source)) if !group.is_empty() => {
                    crate::prepare::grounding::group_target(
                        source.as_ref(),
                        &self.scene,
                        group,
                        &selection,
                    )
                    .with_context(|| format!("`queries.{i}.shot.objects`"))?
                }
                (Some(mask), _) => {
                    let path = config.resolve(mask);
                    let values = read_mask_file(&path, self.scene.len())?;
                    let relevancy = Relevancy {
                        name: query.text.clone(),
                        values,
                        scoring: Scoring::Mask { cluster: false },
                        notes: Vec::new(),
                    };
                    select(&self.scene, &query.text, &relevancy, &selection)
                        .with_context(|| format!("`queries.{i}.mask` ({})", path.display()))?
                }
                (None, Some(source)) => splatraj_semantic::find_target(
                    source.as_ref(),
                    &self.scene,
                    &query.text,
                    &selection,
                )
                .with_context(|| format!("`queries.{i}.text` = {:?}", query.text))?,
                (None, None) => unreachable!("a source is built whenever a query has no mask"),
            };
            // Doubts about the grounding (e.g. a selection spread implausibly thin) are the
            // user's to judge: show them, they do not stop the run.
            for warning in &target.warnings {
                tracing::warn!("`queries.{i}`: {warning}");
            }
            let target_ratio = query.target_ratio.unwrap_or(config.camera.target_ratio);
            let extent = target.extent.map(f64::from);
            let prior_radius = default_prior_radius(extent, fov_x, fov_y, target_ratio)
                .or_else(|_| {
                    // A single Gaussian (or a flat point set) has no extent to frame: fall
                    // back to its scale in the scene.
                    default_prior_radius([half[0] * 0.05; 3], fov_x, fov_y, target_ratio)
                })
                .with_context(|| format!("`queries.{i}`: prior radius"))?;
            self.selected.push(target.count);
            self.notes.push(target.notes.clone());
            let half = target.extent.map(|e| 0.5 * f64::from(e));
            self.boxes.push((target.centre.map(f64::from), half));
            self.windows.push(WindowTarget {
                name: query.text.clone(),
                mask: target.mask,
                context: QueryContext {
                    object_centre: target.centre.map(f64::from),
                    prior_radius,
                    world_up: self.up.up,
                    target_ratio,
                },
            });
        }
        Ok(())
    }

    /// The costs of `[costs]` (built-in and registered ones).
    pub fn costs(&self) -> Result<WeightedCosts> {
        self.config
            .costs
            .build_with(&self.extensions.costs)
            .map_err(anyhow::Error::msg)
    }

    /// The scene on the plain device (the start search, metrics and frames), uploaded on the
    /// first call and shared by the later ones.
    pub fn plain_scene(&self) -> DeviceScene {
        self.scene_memo.get_or_insert((), || {
            DeviceScene::new(&self.scene, &self.device, self.dtype)
        })
    }

    /// Window `i`'s object alone (its Gaussians only), on the plain device: uploaded on the
    /// first call for those Gaussians and shared by the later ones.
    pub fn object_alone(&self, i: usize) -> DeviceScene {
        let keep: Vec<bool> = self.windows[i].mask.iter().map(|&m| m != 0.0).collect();
        let indices: Vec<u32> = (0..keep.len() as u32)
            .filter(|&g| keep[g as usize])
            .collect();
        self.alone_memo.get_or_insert(indices, || {
            DeviceScene::new(&self.scene.subset(&keep), &self.device, self.dtype)
        })
    }

    /// How many objects alone [`Experiment::object_alone`] keeps on the device: every window's
    /// while together they hold no more Gaussians than the scene (the memory plans count one
    /// scene's worth of such copies), else one at a time, as each is asked for.
    fn alone_scenes_kept(&self) -> usize {
        let together: usize = self
            .windows
            .iter()
            .map(|w| w.mask.iter().filter(|&&m| m != 0.0).count())
            .sum();
        if together <= self.scene.len() {
            self.windows.len()
        } else {
            1
        }
    }

    /// The output camera: the optimisation camera at `[output]`'s size.
    pub fn output_intrinsics(&self) -> Result<Intrinsics> {
        Ok(self
            .intrinsics
            .rescaled(self.config.output.width, self.config.output.height)?)
    }
}

/// The scene of `[scene]` (a file, read as configured, or the demo room) and its name for
/// messages (the path, or `demo (…)`).
pub fn load_scene(config: &Config) -> Result<(Scene, String)> {
    if let Some(demo) = &config.scene.demo {
        let scene = demo_scene(&DemoConfig {
            seed: demo.seed,
            gaussians: demo.gaussians,
        })
        .context("`scene.demo`")?;
        return Ok((
            scene,
            format!("demo (seed {}, {} Gaussians)", demo.seed, demo.gaussians),
        ));
    }
    let path = config.resolve(
        config
            .scene
            .path
            .as_deref()
            .context("`scene`: give `path` (a scene file) or `demo = {}`")?,
    );
    let options = ReadOptions {
        invalid: if config.scene.drop_invalid {
            InvalidPolicy::Drop
        } else {
            InvalidPolicy::Reject
        },
        labels: config.scene.labels.as_ref().map(|l| config.resolve(l)),
    };
    let loaded = read_scene(&path, &options)?;
    if loaded.dropped > 0 {
        tracing::warn!(
            "dropped {} invalid Gaussians from {}",
            loaded.dropped,
            path.display()
        );
    }
    Ok((loaded.scene, path.display().to_string()))
}
