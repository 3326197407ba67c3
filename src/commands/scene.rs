//! `splatraj scene …`: inspect, convert and generate scene files.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::Result;
use clap::Subcommand;
use splatraj::experiment::picking::query::parse_direction;
use splatraj::experiment::picking::views_page::{
    ViewsPageOptions, ViewsPageRequest, write_views_page,
};
use splatraj::experiment::prepare::scene_files::{
    MaskSidecarRequest, convert_scene, lift_masks_to_sidecar, write_demo_scene,
};
use splatraj::lift::{LiftStage, MaskOptions};
use splatraj_render::backend::BackendKind;
use splatraj_scene::demo::DemoConfig;
use splatraj_scene::summary::SceneInfo;
use splatraj_scene::{InvalidPolicy, SceneFormat};

use indicatif::ProgressBar;

use crate::cli::{MemoryArgs, ReadArgs, progress_bar};

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
    /// Write one self-contained HTML page of renders around (and inside) the scene, each with
    /// its camera and depth, where a click picks a part: its 3D point, a ball to size, the
    /// Gaussians inside and the `[targets]` lines to paste into a config.
    Views(ViewsArgs),
}

/// Arguments of `scene views`.
#[derive(Debug, clap::Args)]
pub struct ViewsArgs {
    /// Scene file (INRIA PLY, compressed PLY, SPZ, SOG …).
    scene: PathBuf,
    /// The page to write (HTML; written whole or not at all).
    #[arg(long, default_value = "views.html")]
    out: PathBuf,
    /// Views to render (the planner may keep fewer when fewer show something).
    #[arg(long, default_value_t = ViewsPageOptions::default().views)]
    views: usize,
    /// Side of each square view, pixels.
    #[arg(long, default_value_t = ViewsPageOptions::default().size)]
    size: usize,
    /// World up of the scene, `X,Y,Z` (e.g. `0,-1,0` for y-down captures); by default guessed.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    up: Option<String>,
    /// Most Gaussian centres the page carries to count what a ball holds; beyond, an even
    /// sample, and the counts are estimates scaled from it (the page says so).
    #[arg(long, default_value_t = ViewsPageOptions::default().max_centres)]
    max_centres: usize,
    /// Tensor backend: flex (CPU), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    #[command(flatten)]
    read: ReadArgs,
    #[command(flatten)]
    memory: MemoryArgs,
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
            read,
        } => {
            let converted = convert_scene(&input, &output, format, &read.options())?;
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
        SceneCommand::LiftMasks(args) => lift_masks(args)?,
        SceneCommand::Views(args) => views(args)?,
    }
    Ok(())
}

/// One progress bar for a lift's stages, and the callback that draws them on it (the stage's
/// name as its message).
fn stage_bar() -> (ProgressBar, impl Fn(LiftStage, usize, usize)) {
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
fn warn_dropped(path: &Path, dropped: usize) {
    if dropped > 0 {
        eprintln!(
            "warning: {}: dropped {dropped} invalid Gaussians",
            path.display()
        );
    }
}

/// `scene lift-masks`: parses, lifts and writes with the library, prints a summary.
fn lift_masks(args: LiftMasksArgs) -> Result<()> {
    let device = args.backend.device()?;
    let request = MaskSidecarRequest {
        scene: args.scene,
        cameras: args.cameras,
        masks: args.masks,
        out: args.out,
        options: MaskOptions {
            min_share: args.min_share,
            neighbours: args.neighbours,
            ..MaskOptions::default()
        },
        invalid: if args.drop_invalid {
            InvalidPolicy::Drop
        } else {
            InvalidPolicy::Reject
        },
    };
    let (bar, progress) = stage_bar();
    let (lift, dropped) = lift_masks_to_sidecar(&request, &device, &progress)?;
    bar.finish_and_clear();
    warn_dropped(&request.scene, dropped);
    print!("{}", lift.summary_text());
    eprintln!(
        "wrote {} ({} Gaussians labelled)",
        request.out.display(),
        lift.labels.ids.iter().filter(|&&id| id != 0).count()
    );
    Ok(())
}

/// `scene views`: parses, writes the page with the library, prints a summary.
fn views(args: ViewsArgs) -> Result<()> {
    let request = ViewsPageRequest {
        options: ViewsPageOptions {
            views: args.views,
            size: args.size,
            up: args
                .up
                .as_deref()
                .map(|up| parse_direction(up, "--up"))
                .transpose()?,
            max_centres: args.max_centres,
            ..ViewsPageOptions::default()
        },
        read: args.read.options(),
        scene: args.scene,
        out: args.out,
        max_memory_gb: args.memory.max_memory,
    };
    let device = args.backend.device()?;
    let (bar, progress) = stage_bar();
    let written = write_views_page(&request, &device, &progress)?;
    bar.finish_and_clear();
    warn_dropped(&request.scene, written.dropped);
    for line in written.summary(&request.out) {
        eprintln!("{line}");
    }
    Ok(())
}
