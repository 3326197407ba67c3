//! `splatraj export`: a run's trajectory as another tool's camera file (nerfstudio
//! `camera_path.json`, COLMAP `cameras.txt` + `images.txt`, INRIA `cameras.json`, SuperSplat
//! `settings.json`; formats and axes in `docs/interchange.md`).
//!
//! The trajectory is evaluated from the model and weights of `trajectory.json` at fps × seconds
//! evenly spaced times over t ∈ [0, 1] (a custom model, which needs its registry, falls back to
//! the densely sampled poses the file holds). The cameras are the run's frame camera
//! (`output_intrinsics`), rescaled by `--width`/`--height`. Each file is written whole or not
//! at all.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Deserialize;
use splatraj::experiment::outputs::write_bytes;
use splatraj::traj::optimise::sampling::window_of;
use splatraj::traj::trajectory::{Basis, TrajectoryRecord, uniform_times};
use splatraj_render::camera::Intrinsics;
use splatraj_render::camera_file::resize;
use splatraj_report::supersplat::Focus;
use splatraj_report::{CameraPath, ExportOptions, Format, Pinhole};

/// Frames when neither `--seconds` nor the run's `output.frames` says.
const DEFAULT_SECONDS: f64 = 5.0;

/// Arguments of `splatraj export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// A run folder (holding trajectory.json) or a trajectory.json.
    input: PathBuf,
    /// nerfstudio, colmap, inria or supersplat.
    #[arg(long, value_parser = parse_format)]
    format: Format,
    /// Frames per second.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Length in seconds (fps × seconds frames); default: the run's `output.frames` at --fps,
    /// else 5 s.
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

/// What export reads of `trajectory.json` besides the model and weights.
#[derive(Debug, Deserialize)]
struct TrajectoryExtras {
    output_intrinsics: Intrinsics,
    #[serde(default)]
    windows: Vec<WindowCentre>,
    #[serde(default)]
    poses: Vec<SampledPose>,
}

#[derive(Debug, Deserialize)]
struct WindowCentre {
    object_centre: [f64; 3],
}

#[derive(Debug, Deserialize)]
struct SampledPose {
    pose: [f64; 6],
}

/// Runs `splatraj export`.
pub fn run(args: ExportArgs) -> Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps {} must be a positive number", args.fps);
    }
    let file = if args.input.is_dir() {
        args.input.join("trajectory.json")
    } else {
        args.input.clone()
    };
    let folder = file.parent().unwrap_or(Path::new(".")).to_path_buf();
    let text = std::fs::read_to_string(&file)
        .with_context(|| format!("cannot read the trajectory {}", file.display()))?;
    let record: TrajectoryRecord = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not a trajectory.json (needs `model` and `weights`)",
            file.display()
        )
    })?;
    let extras: TrajectoryExtras = serde_json::from_str(&text)
        .with_context(|| format!("{}: no frame camera (`output_intrinsics`)", file.display()))?;
    let seconds = match args.seconds {
        Some(s) if s.is_finite() && s > 0.0 => s,
        Some(s) => bail!("--seconds {s} must be a positive number"),
        None => run_frames(&folder).map_or(DEFAULT_SECONDS, |n| n as f64 / args.fps),
    };
    let count = ((args.fps * seconds).round() as usize).max(1);
    let intrinsics = resize(&extras.output_intrinsics, args.width, args.height)?;
    let camera = Pinhole {
        fx: intrinsics.fx,
        fy: intrinsics.fy,
        cx: intrinsics.cx,
        cy: intrinsics.cy,
        width: intrinsics.width,
        height: intrinsics.height,
    };

    let (times, poses) = if record.model.validate().is_ok() {
        let times = uniform_times(count);
        (times.clone(), evaluate(&record, &times))
    } else {
        eprintln!(
            "note: model {} is not built in: exporting the {} poses sampled in {}",
            record.model.name(),
            extras.poses.len(),
            file.display()
        );
        let poses: Vec<[f64; 6]> = extras.poses.iter().map(|p| p.pose).collect();
        (uniform_times(poses.len()), poses)
    };
    if poses.is_empty() {
        bail!("{}: no poses to export", file.display());
    }
    let path = CameraPath::from_phis(&poses, camera, args.fps);
    let focus = if extras.windows.is_empty() {
        Focus::Distance(1.0)
    } else {
        // Each frame's target at the distance of the object its window shows.
        Focus::PerFrame(
            times
                .iter()
                .zip(&poses)
                .map(|(&t, pose)| {
                    let o = extras.windows[window_of(t, extras.windows.len())].object_centre;
                    let d = (0..3).map(|k| (o[k] - pose[3 + k]).powi(2)).sum::<f64>();
                    d.sqrt().max(1e-3)
                })
                .collect(),
        )
    };
    let options = ExportOptions {
        fps: args.fps,
        focus,
        ..ExportOptions::default()
    };
    let files = splatraj_report::export(&path, args.format, &options)?;

    let out = args
        .out
        .unwrap_or_else(|| folder.join("exports").join(args.format.name()));
    std::fs::create_dir_all(&out)
        .with_context(|| format!("cannot create the output folder {}", out.display()))?;
    for (name, contents) in &files {
        write_bytes(&out.join(name), contents.as_bytes())?;
    }
    let names: Vec<&str> = files.iter().map(|f| f.0).collect();
    eprintln!(
        "wrote {} to {} ({} frames, {} fps, {}×{})",
        names.join(", "),
        out.display(),
        poses.len(),
        args.fps,
        camera.width,
        camera.height
    );
    println!("{}", out.display());
    Ok(())
}

/// Φ(t) = Ψ(t)·W on the host.
fn evaluate(record: &TrajectoryRecord, times: &[f64]) -> Vec<[f64; 6]> {
    let k = record.model.count();
    record
        .model
        .matrix(times)
        .chunks_exact(k)
        .map(|row| {
            let mut pose = [0.0; 6];
            for (psi, w) in row.iter().zip(&record.weights) {
                for (p, wj) in pose.iter_mut().zip(w) {
                    *p += psi * wj;
                }
            }
            pose
        })
        .collect()
}

/// The frame count of the run in `folder` (`output.frames` of its config.toml), if any.
fn run_frames(folder: &Path) -> Option<usize> {
    let text = std::fs::read_to_string(folder.join("config.toml")).ok()?;
    let config: toml::Value = toml::from_str(&text).ok()?;
    let frames = config.get("output")?.get("frames")?.as_integer()?;
    usize::try_from(frames).ok().filter(|&n| n > 0)
}
