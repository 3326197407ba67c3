//! `splatraj render-path SCENE PATH_FILE --out DIR`: renders any camera path to frames and a
//! video, headless, with a progress bar — `ns-render` for a bare `.ply`/`.spz`.
//!
//! The path is a run folder or its `trajectory.json` (evaluated from its model at fps × seconds
//! times, by default the run's own frames), or another tool's camera file (nerfstudio
//! `camera_path.json`, COLMAP `images.txt`, INRIA `cameras.json`, SuperSplat `settings.json`),
//! whose frames are rendered as they are. SCENE is a scene file, or an experiment config
//! whose scene and queries are used: then each frame's metrics for its window's object go to
//! `frame_metrics.csv`, and `--mask-overlay tint` tints it. The work is the library's
//! ([`splatraj::experiment::outputs::path_job`]: one call that reads, checks and renders, as
//! `splatraj run` renders its frames); this file parses, calls it and shows progress.

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::config::MaskOverlay;
use splatraj::experiment::frame_metrics::FrameMetrics;
use splatraj::experiment::outputs::camera_paths::{FrameRequest, SceneMismatch};
use splatraj::experiment::outputs::path_job::{PathJob, PathPlan, SceneArgument, render_path_job};
use splatraj::experiment::outputs::path_render::Video;
use splatraj_render::backend::BackendKind;
use splatraj_render::render::Rasterizer;

use crate::cli::{ReadArgs, progress_bar};

/// Arguments of `splatraj render-path`.
#[derive(Debug, Args)]
pub struct RenderPathArgs {
    /// Scene file (INRIA PLY, compressed PLY or SPZ), or an experiment config (TOML) whose
    /// scene and queries are used.
    scene: PathBuf,
    /// Camera path: a run folder or trajectory.json, a nerfstudio camera_path.json, COLMAP
    /// images.txt, INRIA cameras.json or SuperSplat settings.json.
    path: PathBuf,
    /// Output folder for frames/, video.mp4 and frame_metrics.csv (created if missing).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    read: ReadArgs,
    /// Override a value of the config given as SCENE (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Frame width in pixels (rescales the path's cameras; alone, keeps the aspect ratio).
    #[arg(long)]
    width: Option<usize>,
    /// Frame height in pixels (rescales the path's cameras; alone, keeps the aspect ratio).
    #[arg(long)]
    height: Option<usize>,
    /// Frames per second of the video; default: the file's, the run's `output.fps`, else 30.
    #[arg(long)]
    fps: Option<f64>,
    /// Length in seconds of a trajectory.json's render (fps × seconds frames); default: the
    /// run's frame count, else 5 s. Another tool's file keeps its own frames.
    #[arg(long)]
    seconds: Option<f64>,
    /// Tint each window's object (needs a config as SCENE), or none.
    #[arg(long, default_value = "none", value_parser = parse_overlay)]
    mask_overlay: MaskOverlay,
    /// PNG frames only, no video.mp4.
    #[arg(long)]
    no_video: bool,
    /// Tensor backend for a scene file: flex (CPU, default), ndarray or wgpu (a config says its
    /// own).
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Compositing: fused or tensor; default: the config's, else fused.
    #[arg(long, value_parser = Rasterizer::from_str)]
    rasterizer: Option<Rasterizer>,
    /// A trajectory.json made on another scene (another Gaussian count) than SCENE's: refuse
    /// it, or allow it (rendered with a warning).
    #[arg(long, default_value = "refuse", value_parser = SceneMismatch::from_str)]
    scene_mismatch: SceneMismatch,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn parse_overlay(s: &str) -> Result<MaskOverlay, String> {
    match s {
        "none" => Ok(MaskOverlay::None),
        "tint" => Ok(MaskOverlay::Tint),
        other => Err(format!("unknown mask overlay {other:?} (none or tint)")),
    }
}

/// Runs `splatraj render-path`.
pub fn run(args: RenderPathArgs) -> Result<()> {
    let job = PathJob {
        scene: SceneArgument {
            path: &args.scene,
            set: &args.set,
            read: args.read.options(),
            backend: args.backend,
        },
        path: &args.path,
        frames: FrameRequest {
            fps: args.fps,
            seconds: args.seconds,
            width: args.width,
            height: args.height,
        },
        overlay: args.mask_overlay,
        rasterizer: args.rasterizer,
        scene_mismatch: args.scene_mismatch,
        video: if args.no_video {
            Video::None
        } else {
            Video::Mp4
        },
    };
    let bar = progress_bar(0, args.quiet);
    let mut announce = |plan: &PathPlan| {
        if plan.dropped > 0 {
            eprintln!(
                "warning: {}: dropped {} invalid Gaussians",
                args.scene.display(),
                plan.dropped
            );
        }
        eprintln!(
            "path: {} → {} frames at {} fps, {}×{} on {}",
            plan.description, plan.frames, plan.fps, plan.width, plan.height, plan.hardware
        );
        if let Some(warning) = plan.hardware.warning() {
            eprintln!("warning: {warning}");
        }
        bar.set_length(plan.frames as u64);
        bar.set_message("frames");
    };
    let rendered = render_path_job(&job, &args.out, &mut announce, &mut |done| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    if !rendered.metrics.is_empty() {
        let mean = |f: fn(&FrameMetrics) -> f64| {
            rendered.metrics.iter().map(f).sum::<f64>() / rendered.metrics.len() as f64
        };
        eprintln!(
            "mean over frames: TCE {} (frames in view), TRE {:.4}, coverage {:.3}",
            rendered
                .mean_tce_in_view()
                .map_or("undefined (never in view)".to_string(), |t| format!(
                    "{t:.4}"
                )),
            mean(|m| m.tre),
            mean(|m| m.coverage)
        );
    }
    if let Some(video) = &rendered.video {
        eprintln!("video: {}", video.display());
    }
    println!("{}", args.out.display());
    Ok(())
}
