//! `splatraj scene …`: inspect, convert and generate scene files; `lift-masks` and `views`
//! in their own files. Each subcommand parses, makes one library call and prints.

pub mod lift_masks;
pub mod views;

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Subcommand;
use indicatif::ProgressBar;
use splatraj::experiment::prepare::scene_files::{convert_scene, write_demo_scene};
use splatraj::lift::LiftStage;
use splatraj_scene::SceneFormat;
use splatraj_scene::demo::DemoConfig;
use splatraj_scene::summary::SceneInfo;

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
        /// SH degree to write, 0 to 3: a lower one drops the finer view-dependent colour (a
        /// smaller file), a higher one adds zero coefficients; default: the input's.
        #[arg(long, value_parser = clap::value_parser!(u8).range(0..=3))]
        sh_degree: Option<u8>,
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
    LiftMasks(lift_masks::LiftMasksArgs),
    /// Write one self-contained HTML page of renders around (and inside) the scene, each with
    /// its camera and depth, where a click picks a part: its 3D point, a ball to size, the
    /// Gaussians inside and the `[targets]` lines to paste into a config.
    Views(views::ViewsArgs),
}

/// Runs one `scene` subcommand.
pub fn run(command: SceneCommand) -> Result<()> {
    match command {
        SceneCommand::Info { file, read, json } => {
            let info = SceneInfo::read(&file, &read.options())?;
            warn_dropped(&file, info.dropped_invalid);
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                print!("{}", info.text());
            }
        }
        SceneCommand::Convert {
            input,
            output,
            format,
            sh_degree,
            read,
        } => {
            let converted = convert_scene(&input, &output, format, sh_degree, &read.options())?;
            warn_dropped(&input, converted.loaded.dropped);
            for line in converted.summary(&output) {
                eprintln!("{line}");
            }
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
        SceneCommand::LiftMasks(args) => lift_masks::run(args)?,
        SceneCommand::Views(args) => views::run(args)?,
    }
    Ok(())
}

/// One progress bar for a lift's stages, and the callback that draws them on it (the stage's
/// name as its message).
pub(super) fn stage_bar() -> (ProgressBar, impl Fn(LiftStage, usize, usize)) {
    let bar = progress_bar(0, false);
    let drawn = bar.clone();
    let progress = move |stage: LiftStage, done: usize, total: usize| {
        drawn.set_message(stage.name());
        drawn.set_length(total as u64);
        drawn.set_position(done as u64);
    };
    (bar, progress)
}

/// The warning for Gaussians dropped as invalid while reading `path`.
pub(super) fn warn_dropped(path: &Path, dropped: usize) {
    if dropped > 0 {
        eprintln!(
            "warning: {}: dropped {dropped} invalid Gaussians",
            path.display()
        );
    }
}
