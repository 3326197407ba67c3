//! `splatraj bench render`: time the object-mask pass, forward and forward + backward, with
//! each rasterizer; `bench first-try` runs the first-try configs; `bench frames` times a run's
//! output frames; `bench scale` runs a config whole at several demo scene sizes.
//!
//! Each configuration (scene, resolution, pruning, rasterizer) runs in a fresh child process
//! of this binary (hidden `--one` flag), so that the peak memory it reports (VmHWM of
//! /proc/self/status, a process-wide high-water mark) belongs to that configuration alone.
//! The configurations, the timing of one, the rows and the table are
//! `splatraj::experiment::bench` (the loss is TCE + TRE of the mask through the optimiser's own
//! loss path); this file parses, spawns the children and prints. Per configuration the table
//! gives, for each rasterizer, ms and ns per pixel–Gaussian pair (time / (tile–Gaussian pairs ×
//! 256)), and the fused rasterizer's speed-up over the tensor one.

use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, Subcommand};
use splatraj::experiment::bench::{
    BenchConfig, BenchSettings, RenderBenchGrid, run_one, run_render_bench,
};
use splatraj::experiment::path_render::FrameSchedule;
use splatraj_render::backend::BackendKind;
use splatraj_render::render::Rasterizer;
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;

use crate::cli::DtypeArg;

/// The `bench` subcommands.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Time the mask pass (render + TCE + TRE), forward and forward + backward, on demo scenes
    /// of several sizes (and optionally a real scene), pruned and unpruned.
    Render(BenchRenderArgs),
    /// Run minimal first-try configs (default: `configs/first-try/*.toml`) as a new user
    /// would, each with `splatraj run` in a child process, and tabulate each window's verdict,
    /// framing, visible and hidden shares, clearance, turn per frame, wobble and the time.
    FirstTry(BenchFirstTryArgs),
    /// Time a run's output frames (render RGB + object mask, metrics, PNG, H.264) at 720p and
    /// 1080p on the demo scene and a real one, per frame and for a whole video.
    Frames(BenchFramesArgs),
    /// Run a config (default: the demo's) whole on the demo scene at several sizes, each in a
    /// child process, and tabulate the time per step, each stage's time and the peak memory.
    Scale(BenchScaleArgs),
}

/// Arguments of `splatraj bench scale`.
#[derive(Debug, Args)]
pub struct BenchScaleArgs {
    /// Config to run; its scene must be the demo's (`[scene] demo = …`).
    #[arg(long, default_value = "configs/demo.toml")]
    config: PathBuf,
    /// Demo scene sizes, in Gaussians.
    #[arg(long, value_delimiter = ',', default_values_t = [1_000_000usize, 3_000_000, 6_000_000, 10_000_000])]
    sizes: Vec<usize>,
    /// Optimisation steps per run (0: the config's own).
    #[arg(long, default_value_t = 10)]
    iterations: usize,
    #[command(flatten)]
    runs: ChildRunArgs,
}

/// What the benches that run whole configs (`splatraj run` in child processes) share.
#[derive(Debug, Args)]
pub struct ChildRunArgs {
    /// Override a config value in every run, e.g. `--set output.width=320` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Folder of the run folders (default: a fresh one under the system's temporary folder).
    #[arg(long)]
    runs_dir: Option<PathBuf>,
    /// Print one JSON array instead of a table.
    #[arg(long)]
    json: bool,
}

impl ChildRunArgs {
    /// `--runs-dir`, or a fresh folder named `splatraj-{bench}-{pid}` in the temporary folder.
    fn runs_dir(&self, bench: &str) -> PathBuf {
        self.runs_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("splatraj-{bench}-{}", std::process::id()))
        })
    }
}

/// `splatraj bench scale`: the runs and their figures are the library's
/// (`splatraj::experiment::bench_scale`); this prints them.
fn scale(args: &BenchScaleArgs) -> Result<()> {
    use splatraj::experiment::bench_scale::{ScaleBench, run_scale, scale_table};
    let bench = ScaleBench {
        config: args.config.clone(),
        sizes: args.sizes.clone(),
        iterations: (args.iterations > 0).then_some(args.iterations),
        set: args.runs.set.clone(),
        runs_dir: args.runs.runs_dir("scale"),
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let (rows, failures) = run_scale(&exe, &bench, &mut |size| {
        eprintln!("running {} at {size} Gaussians …", bench.config.display())
    })?;
    if args.runs.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print!("{}", scale_table(&rows));
        println!("run folders: {}", bench.runs_dir.display());
    }
    if !failures.is_empty() {
        bail!("{} size(s) failed: {}", failures.len(), failures.join("; "));
    }
    Ok(())
}

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
    /// Schedules to time: sequential (one frame at a time, the reference), pipelined or
    /// pipelined:BATCH.
    #[arg(long, value_delimiter = ',', default_values = ["sequential", "pipelined"], value_parser = FrameSchedule::from_str)]
    schedule: Vec<FrameSchedule>,
    /// Compositing: fused or tensor.
    #[arg(long, default_value = "fused", value_parser = Rasterizer::from_str)]
    rasterizer: Rasterizer,
    /// Tensor backend, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Demo object the camera frames.
    #[arg(long, default_value = "red mug")]
    object: String,
    /// Share of the frame the object covers at the first frame.
    #[arg(long, default_value_t = DEFAULT_TARGET_RATIO)]
    target_ratio: f64,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

fn parse_size(text: &str) -> Result<(usize, usize), String> {
    splatraj::experiment::bench_frames::parse_size(text).map_err(|e| e.to_string())
}

/// `splatraj bench frames`: the timing is the library's (`splatraj::experiment::bench_frames`);
/// this picks the real scene and prints.
fn frames(args: &BenchFramesArgs) -> Result<()> {
    use splatraj::experiment::bench_frames::{FramesBench, run_frames};
    let scene = match (&args.scene, args.no_scene) {
        (Some(path), _) => Some(path.clone()),
        (None, true) => None,
        (None, false) => splatraj::experiment::bench_frames::default_scene(),
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
        object: args.object.clone(),
        target_ratio: args.target_ratio,
        fov: args.fov,
    };
    let report = run_frames(&bench, &mut |row| eprintln!("timing {row} …"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}

/// Arguments of `splatraj bench first-try`.
#[derive(Debug, Args)]
pub struct BenchFirstTryArgs {
    /// Configs to run (default: every `.toml` in `configs/first-try/`).
    configs: Vec<PathBuf>,
    #[command(flatten)]
    runs: ChildRunArgs,
}

/// `splatraj bench first-try`: the runs and their figures are the library's
/// (`splatraj::experiment::quality`); this prints them.
fn first_try(args: &BenchFirstTryArgs) -> Result<()> {
    use splatraj::experiment::quality::{
        FIRST_TRY_CONFIGS, FirstTryBench, configs_in, quality_table, run_first_try,
    };
    let bench = FirstTryBench {
        configs: if args.configs.is_empty() {
            configs_in(std::path::Path::new(FIRST_TRY_CONFIGS))?
        } else {
            args.configs.clone()
        },
        set: args.runs.set.clone(),
        runs_dir: args.runs.runs_dir("first-try"),
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let runs = run_first_try(&exe, &bench, &mut |config| {
        eprintln!("running {} …", config.display())
    })?;
    if args.runs.json {
        println!("{}", serde_json::to_string_pretty(&runs)?);
    } else {
        print!("{}", quality_table(&runs));
        println!("run folders: {}", bench.runs_dir.display());
    }
    Ok(())
}

/// Arguments of `splatraj bench render`.
#[derive(Debug, Args)]
pub struct BenchRenderArgs {
    /// Also benchmark this real scene (the object is a sphere of Gaussians around its centre).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Demo scene sizes, in Gaussians.
    #[arg(long, value_delimiter = ',', default_values_t = [10_000usize, 100_000, 300_000])]
    sizes: Vec<usize>,
    /// Skip the demo scenes (with --scene: benchmark the real scene only).
    #[arg(long)]
    no_demo: bool,
    /// Square image sizes, in pixels.
    #[arg(long, value_delimiter = ',', default_values_t = [64usize, 128, 256])]
    resolutions: Vec<usize>,
    /// Timed runs per measurement (the median is reported), after one untimed warm-up.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Threads of the rayon pool the passes run in (default: rayon's choice, one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// Tensor backend, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Float precision.
    #[arg(long, value_enum, default_value_t = DtypeArg::F32)]
    dtype: DtypeArg,
    /// Rasterizers to time on every configuration (fused, tensor).
    #[arg(long, value_delimiter = ',', default_values = ["fused", "tensor"], value_parser = Rasterizer::from_str)]
    rasterizer: Vec<Rasterizer>,
    /// Demo object the camera frames.
    #[arg(long, default_value = "red mug")]
    object: String,
    /// Share of the frame the object should cover (also TRE's target).
    #[arg(long, default_value_t = DEFAULT_TARGET_RATIO)]
    target_ratio: f64,
    /// Horizontal field of view, degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f64,
    /// Run every configuration, including unpruned 256² renders of demo scenes above 300k
    /// Gaussians (skipped by default as slow).
    #[arg(long)]
    all: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Internal: run one configuration (`demo:N:RES:PRUNING:RASTERIZER` or
    /// `scene:RES:PRUNING:RASTERIZER`) in this process and print its result as one JSON line.
    #[arg(long, hide = true)]
    one: Option<String>,
}

/// Runs one `bench` subcommand.
pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::FirstTry(args) => first_try(&args),
        BenchCommand::Frames(args) => frames(&args),
        BenchCommand::Scale(args) => scale(&args),
        BenchCommand::Render(args) => {
            let bench = || match &args.one {
                Some(spec) => {
                    // A child of `bench render`: it must not outlive its parent.
                    splatraj::experiment::children::exit_with_parent();
                    let row = run_one(&settings(&args), &BenchConfig::parse(spec)?)?;
                    println!("{}", serde_json::to_string(&row)?);
                    Ok(())
                }
                None => run_all(&args),
            };
            let Some(threads) = args.threads else {
                return bench(); // already on a worker of the global pool (`main`)
            };
            splatraj::experiment::resources::check_threads("--threads", threads)?;
            // A pool of that size (the global one already runs this command), entered once so
            // the measured passes start their parallel loops from inside it, as `run` does.
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .stack_size(crate::cli::WORKER_STACK_BYTES)
                .build()
                .map_err(|e| anyhow!("cannot set up {threads} rayon threads: {e}"))?
                .install(bench)
        }
    }
}

/// What every configuration shares, from the arguments.
fn settings(args: &BenchRenderArgs) -> BenchSettings {
    BenchSettings {
        backend: args.backend,
        dtype: args.dtype.precision().dtype(),
        repeats: args.repeats,
        object: args.object.clone(),
        target_ratio: args.target_ratio,
        fov: args.fov,
        scene: args.scene.clone(),
    }
}

fn run_all(args: &BenchRenderArgs) -> Result<()> {
    let grid = RenderBenchGrid {
        sizes: if args.no_demo {
            Vec::new()
        } else {
            args.sizes.clone()
        },
        resolutions: args.resolutions.clone(),
        rasterizers: args.rasterizer.clone(),
        threads: args.threads,
        all: args.all,
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let started = Instant::now();
    let (report, failures) = run_render_bench(&exe, &settings(args), &grid, &mut |event| {
        eprintln!("{event}")
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
        println!(
            "cpu/wall: CPU time over wall time of the timed runs (about the cores kept busy); \
             burn's flex backend runs kernels on rayon only when burn is built with its `rayon` \
             feature, while tile binning always uses the rayon pool.\ntotal {:.1} s",
            started.elapsed().as_secs_f64()
        );
    }
    if !failures.is_empty() {
        bail!(
            "{} configuration(s) failed: {}",
            failures.len(),
            failures.join("; ")
        );
    }
    Ok(())
}
