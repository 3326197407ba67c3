//! `lifted`: free-text queries on any scene, through a language field lifted from its own renders.
//!
//! The source holds the CLIP text tower (for queries) and, until the field exists, the path of
//! the weights (the image tower is loaded only to build a field, not when the cache has it).
//! The field is built on the first query of a scene, or read from the cache, and kept in memory
//! for the next ones. Relevancy is LERF's, as for `features` sources: for each Gaussian, the
//! minimum over canonical negatives n of `σ(τ·(cos(f, q) − cos(f, n)))`; a Gaussian no view
//! showed scores 0 (it had no vote).

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use burn::tensor::{DType, Device};
use serde::{Deserialize, Serialize};
use splatraj_render::render::DeviceScene;
use splatraj_scene::Scene;
use splatraj_semantic::SemanticError;
use splatraj_semantic::image_encoder::{ImageEncoder, ImageEncoderOptions};
use splatraj_semantic::sources::{Relevancy, Scoring, SourceConfig, SourceContext, TargetSource};
use splatraj_semantic::text_encoder::{Activation, TextEncoder, TextEncoderOptions};
use splatraj_semantic::vectors::{self, DEFAULT_NEGATIVES, DEFAULT_TEMPERATURE};

use crate::cache::{self, Fnv};
use crate::cameras::{NamedView, read_views};
use crate::error::{LiftError, Result};
use crate::field::{FieldOptions, LiftedField, encode_photos, encode_views};
use crate::progress::Progress;
use crate::views::{ViewOptions, plan_views};

/// Bumped whenever what a field holds for the same inputs changes (view planning, ClearCLIP,
/// the subspace, the lifting), so that old caches are rebuilt rather than trusted.
pub const FIELD_VERSION: u32 = 1;

/// The name configs use: `[targets] source = "lifted"`.
pub const LIFTED: &str = "lifted";

/// `[targets.lifted]`: the weights, the views and how the field is built and cached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiftedConfig {
    /// The open_clip (or OpenAI) CLIP file holding both towers.
    pub weights: PathBuf,
    /// The towers' MLP activation when no `open_clip_config.json` says it.
    #[serde(default)]
    pub activation: Option<Activation>,
    /// How views are planned.
    #[serde(default)]
    pub views: ViewOptions,
    /// How views are rendered, encoded and lifted.
    #[serde(default)]
    pub field: FieldOptions,
    /// World up for planning views; `None` guesses it from the scene.
    #[serde(default)]
    pub up: Option<[f64; 3]>,
    /// The capture's cameras (INRIA `cameras.json`, COLMAP `images.txt`, nerfstudio
    /// `transforms.json` or `camera_path.json`) to lift from instead of planned views.
    #[serde(default)]
    pub cameras: Option<PathBuf>,
    /// With `cameras`: the folder of the capture's real photos, matched to the cameras by image
    /// name, encoded instead of renders (the features then see the real scene; the lifting still
    /// goes through renders from those cameras).
    #[serde(default)]
    pub photos: Option<PathBuf>,
    /// Folder of the field cache; `None`: no cache (the field lives as long as the source).
    #[serde(default)]
    pub cache_dir: Option<PathBuf>,
    /// Canonical negative phrases.
    #[serde(default = "default_negatives")]
    pub negatives: Vec<String>,
    /// Temperature τ of the relevancy.
    #[serde(default = "default_temperature")]
    pub temperature: f32,
}

fn default_negatives() -> Vec<String> {
    DEFAULT_NEGATIVES.iter().map(|s| s.to_string()).collect()
}

fn default_temperature() -> f32 {
    DEFAULT_TEMPERATURE
}

impl LiftedConfig {
    /// A config with defaults for everything but the weights file.
    pub fn new(weights: PathBuf) -> Self {
        LiftedConfig {
            weights,
            activation: None,
            views: ViewOptions::default(),
            field: FieldOptions::default(),
            up: None,
            cameras: None,
            photos: None,
            cache_dir: None,
            negatives: default_negatives(),
            temperature: default_temperature(),
        }
    }
}

impl SourceConfig for LiftedConfig {
    fn init(&self, context: &SourceContext) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
        let mut config = self.clone();
        config.weights = context.resolve(&self.weights);
        config.cache_dir = self.cache_dir.as_ref().map(|d| context.resolve(d));
        config.cameras = self.cameras.as_ref().map(|d| context.resolve(d));
        config.photos = self.photos.as_ref().map(|d| context.resolve(d));
        Ok(Box::new(LiftedSource::new(config, context.device.clone())?))
    }
}

/// The `lifted` target source (see the module docs).
pub struct LiftedSource {
    config: LiftedConfig,
    text: TextEncoder,
    device: Device,
    /// The capture's cameras instead of planned views, with their photos when given.
    cameras: Option<Vec<NamedView>>,
    /// The field of the last scene queried, with its cache key.
    field: Mutex<Option<(String, Arc<LiftedField>)>>,
    progress: Option<Arc<Progress>>,
}

impl std::fmt::Debug for LiftedSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiftedSource")
            .field("config", &self.config)
            .field("cameras", &self.cameras.as_ref().map(Vec::len))
            .finish()
    }
}

impl LiftedSource {
    /// Loads the text tower, reads the capture's cameras when given and checks the options.
    pub fn new(config: LiftedConfig, device: Device) -> Result<Self> {
        config.views.check("targets.lifted.views")?;
        config.field.check("targets.lifted.field")?;
        if !(config.temperature.is_finite() && config.temperature > 0.0) {
            return Err(LiftError::option(
                "targets.temperature",
                format!("{} must be finite and > 0", config.temperature),
            ));
        }
        if config.negatives.is_empty() {
            return Err(LiftError::option(
                "targets.negatives",
                "at least one canonical negative phrase is needed",
            ));
        }
        if let Some(up) = config.up {
            let length = up.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !(up.iter().all(|v| v.is_finite()) && length > 1e-9 && length.is_finite()) {
                return Err(LiftError::option(
                    "targets.lifted.up",
                    format!("{up:?} is not a direction: three finite numbers, not all 0"),
                ));
            }
        }
        if config.photos.is_some() && config.cameras.is_none() {
            return Err(LiftError::option(
                "targets.lifted.photos",
                "photos need the cameras they were taken with (targets.lifted.cameras)",
            ));
        }
        let cameras = config.cameras.as_deref().map(read_views).transpose()?;
        if let (Some(dir), Some(cameras)) = (&config.photos, &cameras) {
            photos_of(dir, cameras)?;
        }
        // Keyed by the table's own name for the file, so the caller can name it as the user
        // set it (`text_encoder` in `[targets]`).
        let text = TextEncoder::from_file(
            &config.weights,
            TextEncoderOptions {
                activation: config.activation,
                heads: None,
            },
            &device,
        )
        .map_err(|e| LiftError::Semantic(e.in_key("weights")))?;
        Ok(LiftedSource {
            config,
            text,
            device,
            cameras,
            field: Mutex::new(None),
            progress: None,
        })
    }

    /// Reports progress of building a field through `progress`.
    pub fn with_progress(mut self, progress: Arc<Progress>) -> Self {
        self.progress = Some(progress);
        self
    }

    /// The cache key of `scene`'s field under this source's settings.
    pub fn key(&self, scene: &Scene) -> Result<String> {
        let mut hash = Fnv::default();
        cache::hash_scene(&mut hash, scene);
        let settings = serde_json::json!({
            "views": self.config.views,
            "field": self.config.field,
            "up": self.config.up,
            "activation": self.config.activation,
            "cameras": self.cameras.as_ref().map(|c| c.iter().map(|v| (&v.name, v.view.pose.0, [v.view.intrinsics.fx, v.view.intrinsics.fy, v.view.intrinsics.cx, v.view.intrinsics.cy, v.view.intrinsics.width as f64, v.view.intrinsics.height as f64])).collect::<Vec<_>>()),
        });
        hash.bytes(settings.to_string().as_bytes());
        hash.bytes(&FIELD_VERSION.to_le_bytes());
        if let (Some(dir), Some(cameras)) = (&self.config.photos, &self.cameras) {
            for photo in photos_of(dir, cameras)? {
                cache::hash_file_identity(&mut hash, &photo)?;
            }
        }
        cache::hash_file_identity(&mut hash, &self.config.weights)?;
        // open_clip_config.json beside the weights sets the towers' heads and activation.
        let beside = self
            .config
            .weights
            .with_file_name(splatraj_semantic::text_encoder::OPEN_CLIP_CONFIG);
        if beside.is_file() {
            cache::hash_file_identity(&mut hash, &beside)?;
        }
        Ok(hash.hex())
    }

    /// The field of `scene`: kept from the last query, read from the cache, or built.
    pub fn field(&self, scene: &Scene) -> Result<Arc<LiftedField>> {
        let key = self.key(scene)?;
        let mut kept = self.field.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, field)) = kept.as_ref()
            && *k == key
        {
            return Ok(field.clone());
        }
        let path = self
            .config
            .cache_dir
            .as_ref()
            .map(|dir| cache::cache_path(dir, &key));
        let cached = match &path {
            Some(p) => match cache::read(p, &key, scene.len()) {
                Ok(found) => found,
                Err(e) => {
                    tracing::warn!("ignoring the lifted-field cache: {e}");
                    None
                }
            },
            None => None,
        };
        let field = match cached {
            Some(field) => field,
            None => {
                let field = self.build(scene)?;
                if let Some(p) = &path
                    && let Err(e) = cache::write(p, &key, &field)
                {
                    tracing::warn!("could not cache the lifted field: {e}");
                }
                field
            }
        };
        let field = Arc::new(field);
        *kept = Some((key, field.clone()));
        Ok(field)
    }

    /// Plans views (or takes the given cameras), loads the image tower and lifts.
    fn build(&self, scene: &Scene) -> Result<LiftedField> {
        let silent = crate::progress::silent;
        let installed = crate::progress::installed();
        let progress: &Progress = match (&self.progress, &installed) {
            (Some(p), _) | (None, Some(p)) => p.as_ref(),
            (None, None) => &silent,
        };
        let started = std::time::Instant::now();
        let autodiff = self.device.clone().autodiff();
        let device_scene = DeviceScene::new(scene, &autodiff, DType::F32);
        let views = match &self.cameras {
            Some(views) => views.iter().map(|v| v.view).collect(),
            None => {
                let up = splatraj_scene::up_axis::resolve_up(self.config.up, false, scene).up;
                let plan = plan_views(
                    scene,
                    &device_scene,
                    up,
                    &self.config.views,
                    self.config.field.render_size,
                    progress,
                )?;
                tracing::info!(
                    "lifting from {} views ({} offered, {} dropped as buried or empty); they \
                     show {:.0} % of the Gaussians",
                    plan.views.len(),
                    plan.offered,
                    plan.dropped,
                    100.0 * plan.seen_share
                );
                plan.views
            }
        };
        let planned = started.elapsed();
        let image = ImageEncoder::from_file(
            &self.config.weights,
            ImageEncoderOptions {
                activation: self.config.activation,
                dense_size: self.config.field.render_size,
                ..ImageEncoderOptions::default()
            },
            &self.device,
        )?;
        let loaded = started.elapsed();
        let dense = match (&self.config.photos, &self.cameras) {
            (Some(dir), Some(cameras)) => {
                let photos: Vec<(PathBuf, crate::views::View)> = photos_of(dir, cameras)?
                    .into_iter()
                    .zip(cameras.iter().map(|c| c.view))
                    .collect();
                encode_photos(&photos, &image, progress)?
            }
            _ => encode_views(&device_scene, &views, &image, &self.config.field, progress)?,
        };
        let encoded = started.elapsed();
        let field = LiftedField::lift(&device_scene, &views, &dense, &self.config.field, progress)?;
        let lifted = started.elapsed();
        tracing::info!(
            plan_s = planned.as_secs_f64(),
            load_image_tower_s = (loaded - planned).as_secs_f64(),
            render_and_encode_s = (encoded - loaded).as_secs_f64(),
            lift_s = (lifted - encoded).as_secs_f64(),
            explained = field.explained(),
            voted = field
                .weights
                .iter()
                .filter(|&&w| w >= crate::MIN_WEIGHT)
                .count() as f64
                / scene.len().max(1) as f64,
            "lifted field of {} Gaussians from {} views",
            scene.len(),
            views.len()
        );
        Ok(field)
    }

    /// The unit text embedding of `phrase`.
    fn text_unit(&self, phrase: &str) -> Result<Vec<f32>> {
        let v = self.text.encode(&[phrase])?.values;
        Ok(vectors::unit(&v, || {
            format!("the text embedding of {phrase:?}")
        })?)
    }
}

impl TargetSource for LiftedSource {
    fn kind(&self) -> &'static str {
        LIFTED
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> splatraj_semantic::Result<Relevancy> {
        let field = self.field(scene)?;
        if field.len() != scene.len() {
            return Err(SemanticError::Mismatch(format!(
                "the lifted field has {} Gaussians, the scene {}",
                field.len(),
                scene.len()
            )));
        }
        if field.subspace.dim != self.text.dim() {
            return Err(SemanticError::Mismatch(format!(
                "the lifted field has features of length {} but the text tower of {} makes {}",
                field.subspace.dim,
                self.config.weights.display(),
                self.text.dim()
            )));
        }
        let query_cos = field.cosines(&self.text_unit(query)?);
        let negative_cos = self
            .config
            .negatives
            .iter()
            .map(|n| Ok(field.cosines(&self.text_unit(n)?)))
            .collect::<Result<Vec<_>>>()?;
        let tau = self.config.temperature;
        let values = query_cos
            .iter()
            .enumerate()
            .map(|(i, q)| match q {
                None => 0.0,
                Some(q) => negative_cos
                    .iter()
                    .filter_map(|n| n[i].map(|c| vectors::pair_softmax(*q, c, tau)))
                    .fold(1.0f32, f32::min),
            })
            .collect();
        Ok(Relevancy {
            name: query.trim().to_string(),
            values,
            scoring: Scoring::Graded,
            notes: Vec::new(),
        })
    }
}

impl From<LiftError> for SemanticError {
    fn from(e: LiftError) -> Self {
        match e {
            LiftError::Semantic(e) => e,
            LiftError::Option { key, reason } => SemanticError::option(key, reason),
            other => SemanticError::MissingData {
                source_kind: LIFTED,
                detail: other.to_string(),
            },
        }
    }
}

/// The default cache folder of a scene file: `<folder>/<file name>.splatraj-lifted/`.
pub fn default_cache_dir(scene_path: &Path) -> PathBuf {
    let name = scene_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    scene_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(format!("{name}.splatraj-lifted"))
}

/// The photo of each camera in `dir`, matched by image stem (any image extension).
fn photos_of(dir: &Path, cameras: &[NamedView]) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| LiftError::file(dir, e))?;
    let mut by_stem = std::collections::BTreeMap::new();
    for entry in entries {
        let path = entry.map_err(|e| LiftError::file(dir, e))?.path();
        if let Some(name) = path.file_name().and_then(|n| n.to_str()) {
            by_stem.insert(crate::cameras::image_stem(name).to_string(), path.clone());
        }
    }
    let mut missing = Vec::new();
    let photos: Vec<PathBuf> = cameras
        .iter()
        .filter_map(|c| {
            let found = by_stem.get(c.stem()).cloned();
            if found.is_none() {
                missing.push(c.name.clone());
            }
            found
        })
        .collect();
    if !missing.is_empty() {
        return Err(LiftError::file(
            dir,
            format!(
                "no photo for {} of {} cameras ({}{}): each camera's image must be here under its \
                 name",
                missing.len(),
                cameras.len(),
                missing
                    .iter()
                    .take(5)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", "),
                if missing.len() > 5 { ", …" } else { "" }
            ),
        ));
    }
    Ok(photos)
}
