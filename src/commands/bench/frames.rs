//! `splatraj bench frames`: a run's output frames timed per part.

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::outputs::path_render::FrameSchedule;
use splatraj_render::backend::BackendKind;
use splatraj_render::render::Rasterizer;

use super::FramingArgs;

/// Arguments of `splatraj bench frames`.
#[derive(Debug, Args)]
pub struct BenchFramesArgs {
    /// Real scene to time too (default: `biker.compressed.ply` in `$SPLATRAJ_DATA` or
    /// `/work/shared/data`, when there).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Time no real scene.
    #[arg(long, conflicts_with = "scene")]
    no_scene: bool,
    /// Gaussians of the demo scene (0: no demo rows).
    #[arg(long, default_value_t = 1_000_000)]
    gaussians: usize,
    /// Frame sizes: WIDTHxHEIGHT, 720p or 1080p.
    #[arg(long, value_delimiter = ',', default_values = ["720p", "1080p"], value_parser = parse_size)]
    sizes: Vec<(usize, usize)>,
    /// Frames timed per row, spread over the video (the video's own count times it whole).
    #[arg(long, default_value_t = 8)]
    frames: usize,
    /// Length of the video, seconds.
    #[arg(long, default_value_t = 9.0)]
    seconds: f64,
    /// Frames per second of the video.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Schedules to time: sequential (one frame at a time, the reference), pipelined,
    /// pipelined:BATCH (poses a pass) or pipelined:BATCH:GROUPS (and the video's groups of
    /// pictures encoded at once; default: half the cores).
    #[arg(long, value_delimiter = ',', default_values = ["sequential", "pipelined"], value_parser = FrameSchedule::from_str)]
    schedule: Vec<FrameSchedule>,
    /// SH degree the scenes are brought to, 0 to 3 (a higher one adds zero coefficients: the
    /// same pictures at that degree's cost; real captures mostly hold 3); default: as built
    /// or read (the demo holds 1).
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=3))]
    sh_degree: Option<u8>,
    /// Compositing: fused or tensor.
    #[arg(long, default_value = "fused", value_parser = Rasterizer::from_str)]
    rasterizer: Rasterizer,
    /// Tensor backend, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    #[command(flatten)]
    framing: FramingArgs,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

fn parse_size(text: &str) -> Result<(usize, usize), String> {
    splatraj::experiment::bench::frames::parse_size(text).map_err(|e| e.to_string())
}

/// `splatraj bench frames`: the timing is the library's (`splatraj::experiment::bench::frames`);
/// this picks the real scene and prints.
pub(super) fn run(args: &BenchFramesArgs) -> Result<()> {
    use splatraj::experiment::bench::frames::{FramesBench, run_frames};
    let scene = match (&args.scene, args.no_scene) {
        (Some(path), _) => Some(path.clone()),
        (None, true) => None,
        (None, false) => splatraj::experiment::bench::frames::default_scene(),
    };
    let bench = FramesBench {
        backend: args.backend,
        demo_gaussians: (args.gaussians > 0).then_some(args.gaussians),
        scene,
        sizes: args.sizes.clone(),
        frames: args.frames,
        seconds: args.seconds,
        fps: args.fps,
        schedules: args.schedule.clone(),
        rasterizer: args.rasterizer,
        object: args.framing.object.clone(),
        target_ratio: args.framing.target_ratio,
        fov: args.framing.fov,
        sh_degree: args.sh_degree,
    };
    let report = run_frames(&bench, &mut |row| eprintln!("timing {row} …"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}
