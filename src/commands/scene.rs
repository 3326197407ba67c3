//! `splatraj scene …`: inspect, convert and generate scene files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{Context, Result, bail};
use clap::Subcommand;
use serde::Serialize;
use splatraj::lift::mask_files::{MaskCoding, MaskLift, lift_mask_files};
use splatraj::lift::{LiftStage, MaskOptions};
use splatraj_render::backend::BackendKind;
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::formats::{LoadedScene, check_output_target, write_label_sidecar};
use splatraj_scene::{
    Bounds, InvalidPolicy, ReadOptions, Scene, SceneFormat, UpGuess, guess_up_axis,
    write_inria_ply, write_scene,
};

use crate::cli::{ReadArgs, progress_bar};

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
    /// Convert any readable scene to INRIA binary PLY (with labels and other extras),
    /// PlayCanvas compressed PLY or Niantic SPZ, chosen by the output's name or `--format`.
    Convert {
        /// Input scene file.
        input: PathBuf,
        /// Output file (written whole or not at all): `.ply` (INRIA), `.compressed.ply` or
        /// `.spz`.
        output: PathBuf,
        /// Output format, whatever the output's name: inria-ply, compressed-ply or spz.
        #[arg(long, value_parser = parse_output_format)]
        format: Option<SceneFormat>,
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
    /// Lift 2D label masks (a segmenter's PNGs, one per camera) onto the Gaussians and write
    /// them as a label sidecar that `--labels` reads (docs/open-vocabulary.md).
    LiftMasks(LiftMasksArgs),
}

/// Arguments of `scene lift-masks`.
#[derive(Debug, clap::Args)]
pub struct LiftMasksArgs {
    /// Scene file (INRIA PLY, compressed PLY or SPZ).
    #[arg(long)]
    scene: PathBuf,
    /// The capture's cameras: INRIA cameras.json, COLMAP images.txt (cameras.txt beside it),
    /// nerfstudio transforms.json or camera_path.json.
    #[arg(long)]
    cameras: PathBuf,
    /// Folder of PNG masks named after the cameras' images (frame_0001.png for
    /// images/frame_0001.jpg): grey values are label ids, or colours are labels (black = none).
    #[arg(long)]
    masks: PathBuf,
    /// Label sidecar to write (JSON; written whole or not at all).
    #[arg(long)]
    out: PathBuf,
    /// The least share of a Gaussian's blending weight its object must hold, in (0, 1].
    #[arg(long, default_value_t = MaskOptions::default().min_share)]
    min_share: f32,
    /// Nearest Gaussians asked by one left without an object (0: no consensus pass).
    #[arg(long, default_value_t = MaskOptions::default().neighbours)]
    neighbours: usize,
    /// Drop Gaussians with invalid values with a warning, instead of stopping with an error.
    #[arg(long)]
    drop_invalid: bool,
    /// Tensor backend: flex (CPU), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
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
            format,
            read,
        } => {
            // Decided before reading, so a wrong name fails at once.
            let format = match format {
                Some(format) => {
                    // An explicit format may name any file, but not one whose name says
                    // another format: that file would mislead whoever opens it by its name.
                    if let Some(named) = SceneFormat::from_extension(&output)
                        && named != format
                    {
                        bail!(
                            "{}: the name says {} ({}) but --format is {}; rename the output \
                             or drop --format",
                            output.display(),
                            named.name(),
                            named.extension(),
                            format.name()
                        );
                    }
                    format
                }
                None => SceneFormat::for_output(&output)?,
            };
            check_output_target(&output)?;
            let loaded = read.load(&input)?;
            warn_dropped_extras(&loaded.scene, format);
            write_scene(&loaded.scene, &output, format)?;
            eprintln!(
                "wrote {} Gaussians (SH degree {}) to {} ({})",
                loaded.scene.len(),
                loaded.scene.sh_degree,
                output.display(),
                format.name()
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
        SceneCommand::LiftMasks(args) => lift_masks(&args)?,
    }
    Ok(())
}

/// `--format` of `scene convert`: a format splatraj writes.
fn parse_output_format(name: &str) -> std::result::Result<SceneFormat, String> {
    let names: Vec<&str> = SceneFormat::WRITABLE.iter().map(|f| f.name()).collect();
    match SceneFormat::from_name(name) {
        Some(format) if SceneFormat::WRITABLE.contains(&format) => Ok(format),
        Some(_) => Err(format!(
            "splatraj reads {name} but does not write it (it writes {})",
            names.join(", ")
        )),
        None => Err(format!(
            "unknown format '{name}' (splatraj writes {})",
            names.join(", ")
        )),
    }
}

/// Says which of the scene's extras the output format has no place for.
fn warn_dropped_extras(scene: &Scene, format: SceneFormat) {
    if format == SceneFormat::InriaPly {
        return;
    }
    let extras = &scene.extras;
    let mut dropped = Vec::new();
    if extras.labels.is_some() {
        dropped.push("labels".to_string());
    }
    if let Some(features) = &extras.features {
        dropped.push(format!("{} feature channels", features.dim));
    }
    dropped.extend(extras.properties.iter().map(|p| format!("'{}'", p.name)));
    if !dropped.is_empty() {
        eprintln!(
            "warning: {} cannot hold {}; they are not written (INRIA .ply keeps them)",
            format.name(),
            dropped.join(", ")
        );
    }
}

/// Most neighbours `--neighbours` may ask.
const MAX_NEIGHBOURS: usize = 64;

/// `scene lift-masks`: parses, lifts with the library, writes the sidecar and prints a summary.
fn lift_masks(args: &LiftMasksArgs) -> Result<()> {
    if !(args.min_share > 0.0 && args.min_share <= 1.0) {
        bail!("--min-share {} must be in (0, 1]", args.min_share);
    }
    if args.neighbours > MAX_NEIGHBOURS {
        bail!(
            "--neighbours {} must be at most {MAX_NEIGHBOURS}",
            args.neighbours
        );
    }
    // Written last, after minutes of work: refuse a target that would destroy the scene.
    if let (Ok(out), Ok(scene)) = (args.out.canonicalize(), args.scene.canonicalize())
        && out == scene
    {
        bail!("--out {} is the scene file itself", args.out.display());
    }
    let device = args.backend.device()?;
    let loaded = splatraj_scene::read_scene(
        &args.scene,
        &ReadOptions {
            invalid: if args.drop_invalid {
                InvalidPolicy::Drop
            } else {
                InvalidPolicy::Reject
            },
            labels: None,
        },
    )?;
    if loaded.dropped > 0 {
        eprintln!(
            "warning: {}: dropped {} invalid Gaussians",
            args.scene.display(),
            loaded.dropped
        );
    }
    let scene = loaded.scene;
    let bar = progress_bar(0, false);
    bar.set_message(LiftStage::Lift.name());
    let drawn = bar.clone();
    let progress = move |_: LiftStage, done: usize, total: usize| {
        drawn.set_length(total as u64);
        drawn.set_position(done as u64);
    };
    let options = MaskOptions {
        min_share: args.min_share,
        neighbours: args.neighbours,
    };
    let lift = lift_mask_files(
        &scene,
        &args.cameras,
        &args.masks,
        &options,
        &device,
        &progress,
    )?;
    bar.finish_and_clear();
    let labels = lift.scene_labels(args.out.display().to_string());
    write_label_sidecar(&args.out, &labels)
        .with_context(|| format!("cannot write the labels to {}", args.out.display()))?;
    print!("{}", lift_summary(&lift));
    eprintln!(
        "wrote {} ({} Gaussians labelled)",
        args.out.display(),
        lift.labels.ids.iter().filter(|&&id| id != 0).count()
    );
    Ok(())
}

/// What `scene lift-masks` prints: cameras used, the labels with their Gaussians, the unseen
/// share.
fn lift_summary(lift: &MaskLift) -> String {
    let cameras = lift.masked.len() + lift.unmasked.len();
    let mut out = format!("cameras:    {} of {cameras} with a mask", lift.masked.len());
    if !lift.unmasked.is_empty() {
        let shown: Vec<&str> = lift.unmasked.iter().take(5).map(String::as_str).collect();
        out += &format!(
            " ({} skipped: {}{})",
            lift.unmasked.len(),
            shown.join(", "),
            if lift.unmasked.len() > shown.len() {
                ", …"
            } else {
                ""
            }
        );
    }
    out += &format!(
        "\nmasks:      {}\n",
        match lift.coding {
            MaskCoding::Grey => "grey (values are label ids)".to_string(),
            MaskCoding::Colour => format!("colour-coded ({} colours)", lift.legend.len()),
        }
    );
    let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
    for &id in &lift.labels.ids {
        *counts.entry(id).or_insert(0) += 1;
    }
    let found: Vec<i32> = lift
        .labels
        .labels
        .iter()
        .copied()
        .filter(|&l| l != 0)
        .collect();
    out += &format!("labels:     {} in the masks\n", found.len());
    let names: BTreeMap<i32, String> = lift.legend.iter().map(|e| (e.id, e.name())).collect();
    for id in &found {
        out += &format!(
            "  {id:>6}  {:>9} Gaussians  {}\n",
            counts.get(id).copied().unwrap_or(0),
            names.get(id).map_or("-", String::as_str)
        );
    }
    let n = lift.labels.ids.len().max(1) as f64;
    out += &format!(
        "unlabelled: {} Gaussians ({:.1} %)\nunseen:     {:.1} % of the Gaussians (no masked \
         camera shows them)\n",
        counts.get(&0).copied().unwrap_or(0),
        100.0 * counts.get(&0).copied().unwrap_or(0) as f64 / n,
        100.0 * lift.unseen_share()
    );
    out
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
