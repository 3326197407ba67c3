//! `splatraj render-path SCENE PATH_FILE --out DIR`: renders any camera path to frames and a
//! video, headless, with a progress bar — `ns-render` for a bare `.ply`/`.spz`.
//!
//! The path is a run folder or its `trajectory.json` (evaluated from its model at fps × seconds
//! times, by default the run's own frames), or another tool's camera file (nerfstudio
//! `camera_path.json`, COLMAP `images.txt`, INRIA `cameras.json`, SuperSplat `settings.json`),
//! whose frames are rendered as they are. SCENE is a scene file, or an experiment config
//! whose scene and queries are used: then each frame's metrics for its window's object go to
//! `frame_metrics.csv`, and `--mask-overlay tint` tints it. The work is the library's
//! ([`splatraj::experiment::outputs::path_render`], as `splatraj run` renders its frames); this file
//! parses, reads and shows progress.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::{Result, bail};
use burn::tensor::DType;
use clap::Args;
use splatraj::experiment::config::MaskOverlay;
use splatraj::experiment::outputs::camera_paths::{FrameRequest, PathFile, SceneMismatch};
use splatraj::experiment::outputs::path_render::{PathRender, Video, render_path_to};
use splatraj::experiment::outputs::records::SceneRecord;
use splatraj::experiment::{Config, Experiment};
use splatraj_render::backend::BackendKind;
use splatraj_render::render::{DeviceScene, Rasterizer};

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

/// Whether `path` is an experiment config (a TOML table with `[scene]`) rather than a scene.
fn is_config(path: &Path) -> bool {
    splatraj_scene::input::read_text(path)
        .ok()
        .and_then(|text| toml::from_str::<toml::Table>(&text).ok())
        .is_some_and(|table| table.contains_key("scene"))
}

/// Runs `splatraj render-path`.
pub fn run(args: RenderPathArgs) -> Result<()> {
    // Every input is read and checked before anything is rendered or written.
    let config = is_config(&args.scene);
    if !config && !args.set.is_empty() {
        bail!("--set needs an experiment config as SCENE, not a scene file");
    }
    if !config && args.mask_overlay == MaskOverlay::Tint {
        bail!(
            "--mask-overlay tint needs the objects to tint: give an experiment config (TOML) \
             with its queries as SCENE instead of {}",
            args.scene.display()
        );
    }
    let path = PathFile::read(&args.path)?;
    let frames = path.frames(&FrameRequest {
        fps: args.fps,
        seconds: args.seconds,
        width: args.width,
        height: args.height,
    })?;
    let video = if args.no_video {
        Video::None
    } else {
        Video::Mp4
    };
    let experiment = if config {
        Some(Experiment::prepare(&Config::load(&args.scene, &args.set)?)?)
    } else {
        None
    };
    if let (Some(e), PathFile::Trajectory(t)) = (&experiment, &path) {
        t.check_windows(e.windows.len())?;
        t.check_scene(&SceneRecord::of(e), args.scene_mismatch)?;
    }
    let (scene, objects, rasterizer) = match &experiment {
        Some(e) => (
            e.plain_scene(),
            e.path_objects(),
            args.rasterizer.unwrap_or(e.config.rasterizer),
        ),
        None => {
            let loaded = args.read.load_to_render(&args.scene)?;
            if let PathFile::Trajectory(t) = &path {
                let given = SceneRecord {
                    name: args.scene.display().to_string(),
                    gaussians: loaded.scene.len(),
                };
                t.check_scene(&given, args.scene_mismatch)?;
            }
            let device = args.backend.device()?;
            (
                DeviceScene::new(&loaded.scene, &device, DType::F32),
                Vec::new(),
                args.rasterizer.unwrap_or_default(),
            )
        }
    };
    eprintln!(
        "path: {} → {} frames at {} fps, {}×{}",
        path.describe(),
        frames.poses.len(),
        frames.fps,
        frames.cameras[0].width,
        frames.cameras[0].height
    );
    let job = PathRender {
        frames: &frames,
        objects,
        overlay: args.mask_overlay,
        rasterizer,
        video,
    };
    let bar = progress_bar(frames.poses.len() as u64, args.quiet);
    bar.set_message("frames");
    let rendered = render_path_to(&scene, &job, &args.out, &mut |done| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    if !rendered.metrics.is_empty() {
        let mean = |f: fn(&splatraj::experiment::outputs::path_render::FrameMetrics) -> f64| {
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
