//! `splatraj scene …`: inspect, convert and generate scene files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Subcommand;
use serde::Serialize;
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::formats::LoadedScene;
use splatraj_scene::{Bounds, Scene, SceneFormat, UpGuess, guess_up_axis, write_inria_ply};

use crate::cli::ReadArgs;

/// The `scene` subcommands.
#[derive(Debug, Subcommand)]
pub enum SceneCommand {
    /// Print what a scene file holds: count, SH degree, bounds, extras, up-axis guess.
    Info {
        /// Scene file (INRIA PLY, compressed PLY or SPZ).
        file: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Convert any readable scene to INRIA binary PLY (with labels and other extras).
    Convert {
        /// Input scene file.
        input: PathBuf,
        /// Output `.ply` file (written whole or not at all).
        output: PathBuf,
        #[command(flatten)]
        read: ReadArgs,
    },
    /// Write the built-in procedural demo scene (a labelled tabletop room) as INRIA PLY.
    Demo {
        /// Output `.ply` file.
        #[arg(long)]
        out: PathBuf,
        /// Random seed (same seed, same scene).
        #[arg(long, default_value_t = DemoConfig::default().seed)]
        seed: u64,
        /// Number of Gaussians (50 000 – 200 000 intended).
        #[arg(long, default_value_t = DemoConfig::default().gaussians)]
        gaussians: usize,
    },
}

/// Runs one `scene` subcommand.
pub fn run(command: SceneCommand) -> Result<()> {
    match command {
        SceneCommand::Info { file, read, json } => {
            let loaded = read.load(&file)?;
            let info = SceneInfo::new(&file, &loaded);
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                print!("{}", info.to_text());
            }
        }
        SceneCommand::Convert {
            input,
            output,
            read,
        } => {
            let loaded = read.load(&input)?;
            write_inria_ply(&loaded.scene, &output)?;
            eprintln!(
                "wrote {} Gaussians (SH degree {}) to {}",
                loaded.scene.len(),
                loaded.scene.sh_degree,
                output.display()
            );
        }
        SceneCommand::Demo {
            out,
            seed,
            gaussians,
        } => {
            let scene = demo_scene(&DemoConfig { seed, gaussians })?;
            write_inria_ply(&scene, &out)?;
            eprintln!(
                "wrote the demo scene ({} Gaussians, seed {seed}) to {}",
                scene.len(),
                out.display()
            );
        }
    }
    Ok(())
}

/// What `scene info` reports.
#[derive(Debug, Serialize)]
struct SceneInfo {
    file: String,
    format: SceneFormat,
    gaussians: usize,
    dropped_invalid: usize,
    sh_degree: u8,
    bounds: Option<Bounds>,
    /// Bounds of the centres between the 2% and 98% quantiles (ignores floaters).
    robust_bounds: Option<Bounds>,
    opacity_mean: f32,
    up_guess: Option<UpGuess>,
    labels: Option<LabelInfo>,
    features: Option<FeatureInfo>,
    other_properties: Vec<String>,
}

#[derive(Debug, Serialize)]
struct LabelInfo {
    source: String,
    /// Gaussians per label id, with the id's name when known.
    counts: BTreeMap<i32, LabelCount>,
}

#[derive(Debug, Serialize)]
struct LabelCount {
    gaussians: usize,
    name: Option<String>,
}

#[derive(Debug, Serialize)]
struct FeatureInfo {
    dim: usize,
    first: String,
    last: String,
}

impl SceneInfo {
    fn new(path: &Path, loaded: &LoadedScene) -> Self {
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

    fn to_text(&self) -> String {
        let fmt3 = |v: [f32; 3]| format!("[{:.3}, {:.3}, {:.3}]", v[0], v[1], v[2]);
        let fmt_bounds = |b: &Option<Bounds>| match b {
            Some(b) => format!("min {} max {}", fmt3(b.min), fmt3(b.max)),
            None => "none (empty scene)".into(),
        };
        let mut out = format!(
            "file:            {}\nformat:          {:?}\nGaussians:       {}\nSH degree:       {}\n\
             bounds:          {}\nrobust bounds:   {} (2%-98% quantiles)\nmean opacity:    {:.3}\n",
            self.file,
            self.format,
            self.gaussians,
            self.sh_degree,
            fmt_bounds(&self.bounds),
            fmt_bounds(&self.robust_bounds),
            self.opacity_mean,
        );
        if self.dropped_invalid > 0 {
            out += &format!("dropped invalid: {}\n", self.dropped_invalid);
        }
        if let Some(up) = &self.up_guess {
            out += &format!(
                "up (guess):      {} (raw {}, confidence {:.2}, from {:?}); set `up` in the config to override\n",
                fmt3(up.up),
                fmt3(up.raw),
                up.confidence,
                up.method
            );
        }
        match &self.labels {
            Some(labels) => {
                out += &format!("labels:          from {}\n", labels.source);
                for (id, count) in &labels.counts {
                    let name = count.name.as_deref().unwrap_or("-");
                    out += &format!("  {id:>6}  {:>9} Gaussians  {name}\n", count.gaussians);
                }
            }
            None => out += "labels:          none\n",
        }
        match &self.features {
            Some(f) => {
                out += &format!(
                    "features:        {} per Gaussian ({} … {})\n",
                    f.dim, f.first, f.last
                )
            }
            None => out += "features:        none\n",
        }
        if !self.other_properties.is_empty() {
            out += &format!("other properties: {}\n", self.other_properties.join(", "));
        }
        out
    }
}
