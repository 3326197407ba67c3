//! What `run` and `pose` share: the scene, the device, world up and one target per query.
//!
//! Every input is read and checked here, before any optimisation starts or any output folder
//! exists, so a bad file or query ends the command with nothing written.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use burn::tensor::{DType, Device};
use splatraj::config::Config;
use splatraj_render::camera::Intrinsics;
use splatraj_render::render::DeviceScene;
use splatraj_scene::demo::{DEMO_UP, DemoConfig, demo_scene};
use splatraj_scene::{InvalidPolicy, ReadOptions, Scene, guess_up_axis, read_scene};
use splatraj_semantic::{Relevancy, Scoring, Target, select};
use splatraj_traj::costs::{QueryContext, default_prior_radius};
use splatraj_traj::optimise::WindowTarget;

use super::render::read_mask;

/// Everything loaded and checked for a run.
pub struct Prepared {
    /// The scene on the host.
    pub scene: Scene,
    /// Where it came from (a path, or `demo`).
    pub scene_name: String,
    /// World up (unit length) and where it came from.
    pub up: [f64; 3],
    /// `config`, `demo`, `guess` or `default`.
    pub up_from: &'static str,
    /// Centre and half-extent of the scene's robust bounding box (random starts).
    pub bounds: ([f64; 3], [f64; 3]),
    /// One target per query, in order.
    pub windows: Vec<WindowTarget>,
    /// The selected Gaussians of each query (counts for the report).
    pub selected: Vec<usize>,
    /// The plain device (frames, metrics); `autodiff_scene` wraps it for optimisation.
    pub device: Device,
    /// Float dtype of every tensor.
    pub dtype: DType,
    /// The optimisation camera.
    pub intrinsics: Intrinsics,
}

impl Prepared {
    /// The scene on the autodiff device (for optimisation).
    pub fn autodiff_scene(&self) -> DeviceScene {
        DeviceScene::new(&self.scene, &self.device.clone().autodiff(), self.dtype)
    }

    /// The scene on the plain device (for frames and metrics).
    pub fn plain_scene(&self) -> DeviceScene {
        DeviceScene::new(&self.scene, &self.device, self.dtype)
    }

    /// Window `i`'s object alone (its Gaussians only), on the plain device.
    pub fn object_alone(&self, i: usize) -> DeviceScene {
        let keep: Vec<bool> = self.windows[i].mask.iter().map(|&m| m != 0.0).collect();
        let mut alone = self.scene.clone();
        alone.retain(&keep);
        DeviceScene::new(&alone, &self.device, self.dtype)
    }
}

/// Resolves `p` against the config file's folder.
pub fn resolve(base: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

/// Loads the scene, picks world up and grounds every query (see the module docs).
pub fn prepare(config: &Config, config_path: &Path) -> Result<Prepared> {
    let base = config_path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let (scene, scene_name) = load_scene(config, base)?;
    if scene.is_empty() {
        bail!("scene {scene_name} has no Gaussians");
    }
    let (up, up_from) = match (config.scene.up, &config.scene.demo) {
        (Some(up), _) => (up, "config"),
        (None, Some(_)) => (DEMO_UP.map(f64::from), "demo"),
        (None, None) => match guess_up_axis(&scene) {
            Some(g) => (g.up.map(f64::from), "guess"),
            None => {
                tracing::warn!(
                    "could not guess world up for {scene_name}; using +z (set scene.up)"
                );
                ([0.0, 0.0, 1.0], "default")
            }
        },
    };
    let norm = up.iter().map(|v| v * v).sum::<f64>().sqrt();
    let up = up.map(|v| v / norm);
    let bounds = scene
        .robust_bounds(0.02)
        .or_else(|| scene.bounds())
        .context("the scene's bounds are not finite")?;
    let centre: [f64; 3] = std::array::from_fn(|i| 0.5 * (bounds.min[i] + bounds.max[i]) as f64);
    let half: [f64; 3] = std::array::from_fn(|i| 0.5 * (bounds.max[i] - bounds.min[i]) as f64);

    let device = config.backend.device()?;
    let dtype = config.precision.dtype();
    let intrinsics = config.camera.intrinsics()?;
    let (tx, ty) = intrinsics.tan_half_fov();
    let (fov_x, fov_y) = (2.0 * tx.atan(), 2.0 * ty.atan());

    let selection = config
        .targets
        .selection()
        .map_err(|e| anyhow::anyhow!("config {}: {e}", config_path.display()))?;
    let needs_source = config.queries.iter().any(|q| q.mask.is_none());
    let source = if needs_source {
        Some(
            config
                .targets
                .build(base, &device)
                .map_err(|e| anyhow::anyhow!("config {}: {e}", config_path.display()))?,
        )
    } else {
        None
    };
    let mut windows = Vec::with_capacity(config.queries.len());
    let mut selected = Vec::with_capacity(config.queries.len());
    for (i, query) in config.queries.iter().enumerate() {
        let target: Target = match (&query.mask, &source) {
            (Some(mask), _) => {
                let path = resolve(base, mask);
                let values = read_mask(&path, scene.len())?;
                let relevancy = Relevancy {
                    name: query.text.clone(),
                    values,
                    scoring: Scoring::Mask { cluster: false },
                };
                select(&scene, &query.text, &relevancy, &selection)
                    .with_context(|| format!("`queries.{i}.mask` ({})", path.display()))?
            }
            (None, Some(source)) => {
                splatraj_semantic::find_target(source.as_ref(), &scene, &query.text, &selection)
                    .with_context(|| format!("`queries.{i}.text` = {:?}", query.text))?
            }
            (None, None) => unreachable!("a source is built whenever a query has no mask"),
        };
        let target_ratio = query.target_ratio.unwrap_or(config.camera.target_ratio);
        let extent = target.extent.map(f64::from);
        let prior_radius = default_prior_radius(extent, fov_x, fov_y, target_ratio)
            .or_else(|_| {
                // A single Gaussian (or a flat point set) has no extent to frame: fall back
                // to its scale in the scene.
                default_prior_radius([half[0] * 0.05; 3], fov_x, fov_y, target_ratio)
            })
            .with_context(|| format!("`queries.{i}`: prior radius"))?;
        selected.push(target.count);
        windows.push(WindowTarget {
            name: query.text.clone(),
            mask: target.mask,
            context: QueryContext {
                object_centre: target.centre.map(f64::from),
                prior_radius,
                world_up: up,
                target_ratio,
            },
        });
    }
    Ok(Prepared {
        scene,
        scene_name,
        up,
        up_from,
        bounds: (centre, half),
        windows,
        selected,
        device,
        dtype,
        intrinsics,
    })
}

fn load_scene(config: &Config, base: &Path) -> Result<(Scene, String)> {
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
    let path = resolve(
        base,
        config
            .scene
            .path
            .as_deref()
            .expect("validated: path or demo"),
    );
    let options = ReadOptions {
        invalid: if config.scene.drop_invalid {
            InvalidPolicy::Drop
        } else {
            InvalidPolicy::Reject
        },
        labels: config.scene.labels.as_ref().map(|l| resolve(base, l)),
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
