//! `splatraj export`: a run's trajectory as another tool's camera file (nerfstudio
//! `camera_path.json`, COLMAP `cameras.txt` + `images.txt`, INRIA `cameras.json`, SuperSplat
//! `settings.json`; formats and axes in `docs/interchange.md`).
//!
//! The trajectory is evaluated from the model and weights of `trajectory.json` at fps × seconds
//! evenly spaced times over t ∈ [0, 1] (by default the run's own frames: its `output.fps` and
//! frame count; a custom model, which needs its registry, falls back to the densely sampled
//! poses the file holds). The cameras are the run's frame camera (`output_intrinsics`),
//! rescaled by `--width`/`--height`. Each file is written whole or not at all. The work is the
//! library's ([`splatraj::experiment::outputs::camera_paths::export_run`]), as for the exports every run writes.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::outputs::camera_paths::{ExportRequest, FrameRequest, export_run};
use splatraj_camera_paths::Format;

/// Arguments of `splatraj export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// A run folder (holding trajectory.json) or a trajectory.json.
    input: PathBuf,
    /// nerfstudio, colmap, inria or supersplat.
    #[arg(long, value_parser = parse_format)]
    format: Format,
    /// Frames per second; default: the run's `output.fps`, else 30.
    #[arg(long)]
    fps: Option<f64>,
    /// Length in seconds (fps × seconds frames); default: the run's frame count, else 5 s.
    #[arg(long)]
    seconds: Option<f64>,
    /// Image width in pixels (rescales the run's frame camera; alone, keeps the aspect ratio).
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels (rescales the run's frame camera; alone, keeps the aspect ratio).
    #[arg(long)]
    height: Option<usize>,
    /// Output folder (created if missing); default: `exports/<format>/` beside trajectory.json.
    #[arg(long)]
    out: Option<PathBuf>,
}

fn parse_format(s: &str) -> Result<Format, String> {
    s.parse()
}

/// Runs `splatraj export`.
pub fn run(args: ExportArgs) -> Result<()> {
    let exported = export_run(&ExportRequest {
        input: args.input,
        format: args.format,
        frames: FrameRequest {
            fps: args.fps,
            seconds: args.seconds,
            width: args.width,
            height: args.height,
        },
        out: args.out,
    })?;
    let frames = &exported.frames;
    let camera = frames.cameras[0];
    eprintln!(
        "wrote {} to {} ({} frames, {} fps, {}×{})",
        exported.files.join(", "),
        exported.dir.display(),
        frames.poses.len(),
        frames.fps,
        camera.width,
        camera.height
    );
    println!("{}", exported.dir.display());
    Ok(())
}
