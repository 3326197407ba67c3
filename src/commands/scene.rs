//! `splatraj scene …`: inspect, convert and generate scene files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{Result, bail};
use clap::Subcommand;
use splatraj::experiment::scene_files::{
    MaskSidecarRequest, convert_scene, lift_masks_to_sidecar, write_demo_scene,
};
use splatraj::lift::mask_files::{MaskCoding, MaskLift};
use splatraj::lift::{LiftStage, MaskOptions};
use splatraj_render::backend::BackendKind;
use splatraj_scene::demo::DemoConfig;
use splatraj_scene::summary::SceneInfo;
use splatraj_scene::{Bounds, InvalidPolicy, SceneFormat};

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
        #[arg(long, value_parser = SceneFormat::writable_from_name)]
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
                print!("{}", info_text(&info));
            }
        }
        SceneCommand::Convert {
            input,
            output,
            format,
            read,
        } => {
            let converted = convert_scene(&input, &output, format, &read.options())?;
            let (scene, format) = (&converted.loaded.scene, converted.format);
            warn_dropped(&input, converted.loaded.dropped);
            if !converted.dropped_extras.is_empty() {
                eprintln!(
                    "warning: {} cannot hold {}; they are not written (INRIA .ply keeps them)",
                    format.name(),
                    converted.dropped_extras.join(", ")
                );
            }
            eprintln!(
                "wrote {} Gaussians (SH degree {}) to {} ({})",
                scene.len(),
                scene.sh_degree,
                output.display(),
                format.name()
            );
        }
        SceneCommand::Demo {
            out,
            seed,
            gaussians,
        } => {
            let scene = write_demo_scene(&DemoConfig { seed, gaussians }, &out)?;
            eprintln!(
                "wrote the demo scene ({} Gaussians, seed {seed}) to {}",
                scene.len(),
                out.display()
            );
        }
        SceneCommand::LiftMasks(args) => lift_masks(args)?,
    }
    Ok(())
}

/// The warning for Gaussians dropped as invalid while reading `path`.
fn warn_dropped(path: &Path, dropped: usize) {
    if dropped > 0 {
        eprintln!(
            "warning: {}: dropped {dropped} invalid Gaussians",
            path.display()
        );
    }
}

/// Most neighbours `--neighbours` may ask.
const MAX_NEIGHBOURS: usize = 64;

/// `scene lift-masks`: parses, lifts and writes with the library, prints a summary.
fn lift_masks(args: LiftMasksArgs) -> Result<()> {
    if !(args.min_share > 0.0 && args.min_share <= 1.0) {
        bail!("--min-share {} must be in (0, 1]", args.min_share);
    }
    if args.neighbours > MAX_NEIGHBOURS {
        bail!(
            "--neighbours {} must be at most {MAX_NEIGHBOURS}",
            args.neighbours
        );
    }
    let device = args.backend.device()?;
    let request = MaskSidecarRequest {
        scene: args.scene,
        cameras: args.cameras,
        masks: args.masks,
        out: args.out,
        options: MaskOptions {
            min_share: args.min_share,
            neighbours: args.neighbours,
        },
        invalid: if args.drop_invalid {
            InvalidPolicy::Drop
        } else {
            InvalidPolicy::Reject
        },
    };
    let bar = progress_bar(0, false);
    bar.set_message(LiftStage::Lift.name());
    let drawn = bar.clone();
    let progress = move |_: LiftStage, done: usize, total: usize| {
        drawn.set_length(total as u64);
        drawn.set_position(done as u64);
    };
    let (lift, dropped) = lift_masks_to_sidecar(&request, &device, &progress)?;
    bar.finish_and_clear();
    warn_dropped(&request.scene, dropped);
    print!("{}", lift_summary(&lift));
    eprintln!(
        "wrote {} ({} Gaussians labelled)",
        request.out.display(),
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

/// `scene info`'s text.
fn info_text(info: &SceneInfo) -> String {
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
