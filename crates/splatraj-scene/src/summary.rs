//! What `scene info` reports about a loaded scene: counts, bounds, the up guess, labels,
//! features and other properties, as one serialisable value (the command prints it as text or
//! JSON; a library user gets the same figures).

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;

use crate::formats::{LoadedScene, SceneFormat};
use crate::scene::{Bounds, Scene};
use crate::up_axis::{UpGuess, guess_up_axis};

/// What `scene info` reports about a scene file.
#[derive(Debug, Serialize)]
pub struct SceneInfo {
    /// The file read.
    pub file: String,
    /// Its format.
    pub format: SceneFormat,
    /// Gaussians kept.
    pub gaussians: usize,
    /// Gaussians dropped as invalid.
    pub dropped_invalid: usize,
    /// SH degree.
    pub sh_degree: u8,
    /// Bounds of the centres.
    pub bounds: Option<Bounds>,
    /// Bounds of the centres between the 2% and 98% quantiles (ignores floaters).
    pub robust_bounds: Option<Bounds>,
    /// Mean opacity.
    pub opacity_mean: f32,
    /// The up-axis guess.
    pub up_guess: Option<UpGuess>,
    /// Labels, when the scene has them.
    pub labels: Option<LabelInfo>,
    /// Feature vectors, when the scene has them.
    pub features: Option<FeatureInfo>,
    /// Names of the other per-Gaussian properties.
    pub other_properties: Vec<String>,
}

/// Labels of a scene.
#[derive(Debug, Serialize)]
pub struct LabelInfo {
    /// Where the labels came from.
    pub source: String,
    /// Gaussians per label id, with the id's name when known.
    pub counts: BTreeMap<i32, LabelCount>,
}

/// Gaussians of one label id.
#[derive(Debug, Serialize)]
pub struct LabelCount {
    /// Gaussians kept.
    pub gaussians: usize,
    /// The id's name, when known.
    pub name: Option<String>,
}

/// Feature vectors of a scene.
#[derive(Debug, Serialize)]
pub struct FeatureInfo {
    /// Length of each vector.
    pub dim: usize,
    /// Name of the first column.
    pub first: String,
    /// Name of the last column.
    pub last: String,
}

impl SceneInfo {
    /// Reads the scene at `path` and summarises it (`splatraj scene info`'s one call).
    pub fn read(path: &Path, options: &crate::ReadOptions) -> crate::Result<Self> {
        Ok(Self::new(path, &crate::read_scene(path, options)?))
    }

    /// The summary of `loaded`, read from `path`.
    pub fn new(path: &Path, loaded: &LoadedScene) -> Self {
        let scene: &Scene = &loaded.scene;
        let extras = &scene.extras;
        SceneInfo {
            file: path.display().to_string(),
            format: loaded.format,
            gaussians: scene.len(),
            dropped_invalid: loaded.dropped,
            sh_degree: scene.sh_degree,
            bounds: scene.bounds(),
            robust_bounds: scene.robust_bounds(0.02),
            opacity_mean: scene.opacities.iter().sum::<f32>() / scene.len().max(1) as f32,
            up_guess: guess_up_axis(scene),
            labels: extras.labels.as_ref().map(|labels| LabelInfo {
                source: labels.source.clone(),
                counts: labels
                    .counts()
                    .into_iter()
                    .map(|(id, gaussians)| {
                        let name = labels.names.get(&id).cloned();
                        (id, LabelCount { gaussians, name })
                    })
                    .collect(),
            }),
            features: extras.features.as_ref().map(|f| FeatureInfo {
                dim: f.dim,
                first: f.names.first().cloned().unwrap_or_default(),
                last: f.names.last().cloned().unwrap_or_default(),
            }),
            other_properties: extras.properties.iter().map(|p| p.name.clone()).collect(),
        }
    }
}

impl SceneInfo {
    /// `splatraj scene info`'s text: the summary as aligned lines.
    pub fn text(&self) -> String {
        let info = self;
        let fmt3 = |v: [f32; 3]| format!("[{:.3}, {:.3}, {:.3}]", v[0], v[1], v[2]);
        let fmt_bounds = |b: &Option<Bounds>| match b {
            Some(b) => format!("min {} max {}", fmt3(b.min), fmt3(b.max)),
            None => "none (empty scene)".into(),
        };
        let mut out = format!(
            "file:            {}\nformat:          {:?}\nGaussians:       {}\nSH degree:       {}\n\
                 bounds:          {}\nrobust bounds:   {} (2%-98% quantiles)\nmean opacity:    {:.3}\n",
            info.file,
            info.format,
            info.gaussians,
            info.sh_degree,
            fmt_bounds(&info.bounds),
            fmt_bounds(&info.robust_bounds),
            info.opacity_mean,
        );
        if info.dropped_invalid > 0 {
            out += &format!("dropped invalid: {}\n", info.dropped_invalid);
        }
        if let Some(up) = &info.up_guess {
            out += &format!(
                "up (guess):      {} (raw {}, confidence {:.2}, from {:?}); set `up` in the config to override\n",
                fmt3(up.up),
                fmt3(up.raw),
                up.confidence,
                up.method
            );
        }
        match &info.labels {
            Some(labels) => {
                out += &format!("labels:          from {}\n", labels.source);
                for (id, count) in &labels.counts {
                    let name = count.name.as_deref().unwrap_or("-");
                    out += &format!("  {id:>6}  {:>9} Gaussians  {name}\n", count.gaussians);
                }
            }
            None => out += "labels:          none\n",
        }
        match &info.features {
            Some(f) => {
                out += &format!(
                    "features:        {} per Gaussian ({} … {})\n",
                    f.dim, f.first, f.last
                )
            }
            None => out += "features:        none\n",
        }
        if !info.other_properties.is_empty() {
            out += &format!("other properties: {}\n", info.other_properties.join(", "));
        }
        out
    }
}
