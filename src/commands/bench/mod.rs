//! `splatraj bench render`: time the object-mask pass, forward and forward + backward, with
//! each rasterizer; `bench first-try` runs the first-try configs; `bench frames` times a run's
//! output frames; `bench scale` runs a config whole at several demo scene sizes; `bench step`
//! measures one optimisation step with its windows in one render call and in one each; `bench
//! launches` times what a launch, a read and an upload cost on a backend.
//!
//! Each configuration (scene, resolution, pruning, rasterizer) runs in a fresh child process
//! of this binary (hidden `--one` flag), so that the peak memory it reports (VmHWM of
//! /proc/self/status, a process-wide high-water mark) belongs to that configuration alone.
//! The configurations, the timing of one, the rows and the table are
//! `splatraj::experiment::bench` (the loss is TCE + TRE of the mask through the optimiser's own
//! loss path); this file parses, spawns the children and prints. Per configuration the table
//! gives, for each rasterizer, ms and ns per pixel–Gaussian pair (time / (tile–Gaussian pairs ×
//! 256)), and the fused rasterizer's speed-up over the tensor one.

mod frames;
mod render;
mod runs;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use splatraj_render::backend::BackendKind;
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;

pub use frames::BenchFramesArgs;
pub use render::BenchRenderArgs;
pub use runs::{BenchFirstTryArgs, BenchScaleArgs, BenchStepArgs};

/// The `bench` subcommands.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Time the mask pass (render + TCE + TRE), forward and forward + backward, on demo scenes
    /// of several sizes (and optionally a real scene), pruned and unpruned.
    Render(BenchRenderArgs),
    /// Run minimal first-try configs (default: `configs/first-try/*.toml`) as a new user
    /// would, each with `splatraj run` in a child process, and tabulate each window's verdict,
    /// framing, framed share, visible and hidden shares, clearance, turn and orbit per frame,
    /// wobble and the time.
    FirstTry(BenchFirstTryArgs),
    /// Time a run's output frames (render RGB + object mask, metrics, PNG, H.264) at 720p and
    /// 1080p on the demo scene and a real one, per frame and for a whole video.
    Frames(BenchFramesArgs),
    /// Run a config (default: the demo's) whole on the demo scene at several sizes, each in a
    /// child process, and tabulate the time per step, each stage's time and the peak memory.
    Scale(BenchScaleArgs),
    /// Time one optimisation step of a config (default: the demo's) with its windows in one
    /// render call and in a call per window, with the kernel launches, reads, uploads and
    /// render calls of a step.
    Step(BenchStepArgs),
    /// Time what one kernel launch, one read back and one upload cost on a backend, apart
    /// from any arithmetic (on a GPU: the floor of a step's ~120 launches and its read).
    Launches(BenchLaunchesArgs),
}

/// Arguments of `splatraj bench launches`.
#[derive(Debug, Args)]
pub struct BenchLaunchesArgs {
    /// Tensor backend, among those compiled in.
    #[arg(long, default_value = "flex")]
    backend: BackendKind,
    /// Iterations of each probe (after as many untimed).
    #[arg(long, default_value_t = 1000)]
    iterations: usize,
    /// Print one JSON array instead of a table.
    #[arg(long)]
    json: bool,
}

/// How the benches' camera frames the demo object (`bench frames`, `bench render`).
#[derive(Debug, Args)]
pub struct FramingArgs {
    /// Demo object the camera frames.
    #[arg(long, default_value = "red mug")]
    object: String,
    /// Share of the frame the object should cover (also TRE's target).
    #[arg(long, default_value_t = DEFAULT_TARGET_RATIO)]
    target_ratio: f64,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
}

/// Runs one `bench` subcommand.
pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::FirstTry(args) => runs::first_try(&args),
        BenchCommand::Frames(args) => frames::run(&args),
        BenchCommand::Scale(args) => runs::scale(&args),
        BenchCommand::Render(args) => render::run(&args),
        BenchCommand::Step(args) => runs::step(&args),
        BenchCommand::Launches(args) => launches(&args),
    }
}

/// `splatraj bench launches`: the probes are the library's
/// (`splatraj::experiment::bench::launches`); this prints them.
fn launches(args: &BenchLaunchesArgs) -> Result<()> {
    use splatraj::experiment::bench::launches::{launch_table, run_launch_bench};
    let rows =
        run_launch_bench(args.backend, args.iterations).context("`bench launches --iterations`")?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print!("{}", launch_table(args.backend, &rows));
    }
    Ok(())
}
