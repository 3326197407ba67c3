//! `splatraj bench render`: time the object-mask pass, forward and forward + backward, with
//! each rasterizer.
//!
//! Each configuration (scene, resolution, pruning, rasterizer) runs in a fresh child process
//! of this binary (hidden `--one` flag), so that the peak memory it reports (VmHWM of
//! /proc/self/status, a process-wide high-water mark) belongs to that configuration alone.
//! The loss is TCE + TRE of the mask through the optimiser's own loss path
//! (`splatraj::experiment::probe`). The scenes and cameras are
//! `splatraj::experiment::bench_scenes`. Per configuration the table gives, for each
//! rasterizer, ms and ns per pixel–Gaussian pair (time / (tile–Gaussian pairs × 256)), and the
//! fused rasterizer's speed-up over the tensor one.

use std::path::PathBuf;
use std::process::Command;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, Subcommand};
use serde::{Deserialize, Serialize};
use splatraj::experiment::bench_scenes::{demo_bench_scene, file_bench_scene};
use splatraj::experiment::probe::{MaskProbe, median_ms};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::Intrinsics;
use splatraj_render::render::{Pruning, Rasterizer};
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;

use crate::cli::DtypeArg;

/// The `bench` subcommands.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Time the mask pass (render + TCE + TRE), forward and forward + backward, on demo scenes
    /// of several sizes (and optionally a real scene), pruned and unpruned.
    Render(BenchRenderArgs),
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
    /// Threads of rayon's global pool (default: rayon's choice, one per core).
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
        BenchCommand::Render(args) => {
            if let Some(threads) = args.threads {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build_global()
                    .map_err(|e| anyhow!("cannot set up {threads} rayon threads: {e}"))?;
            }
            match &args.one {
                Some(spec) => {
                    let row = run_one(&args, &Config::parse(spec)?)?;
                    println!("{}", serde_json::to_string(&row)?);
                    Ok(())
                }
                None => run_all(&args),
            }
        }
    }
}

/// Which scene a configuration renders.
#[derive(Debug, Clone, PartialEq)]
enum Source {
    /// The demo scene with this many Gaussians.
    Demo(usize),
    /// The file given with --scene.
    File,
}

/// One benchmark configuration.
#[derive(Debug, Clone, PartialEq)]
struct Config {
    source: Source,
    resolution: usize,
    pruning: Pruning,
    rasterizer: Rasterizer,
}

impl Config {
    fn spec(&self) -> String {
        let pruning = pruning_name(self.pruning);
        let rasterizer = rasterizer_name(self.rasterizer);
        match self.source {
            Source::Demo(n) => format!("demo:{n}:{}:{pruning}:{rasterizer}", self.resolution),
            Source::File => format!("scene:{}:{pruning}:{rasterizer}", self.resolution),
        }
    }

    fn parse(spec: &str) -> Result<Self> {
        let parts: Vec<&str> = spec.split(':').collect();
        let bad = || {
            anyhow!(
                "--one {spec:?}: expected demo:N:RES:PRUNING:RASTERIZER or \
                 scene:RES:PRUNING:RASTERIZER"
            )
        };
        let (source, rest) = match parts.as_slice() {
            ["demo", n, rest @ ..] => (Source::Demo(n.parse().map_err(|_| bad())?), rest),
            ["scene", rest @ ..] => (Source::File, rest),
            _ => return Err(bad()),
        };
        let [resolution, pruning, rasterizer] = rest else {
            return Err(bad());
        };
        Ok(Config {
            source,
            resolution: resolution.parse().map_err(|_| bad())?,
            pruning: match *pruning {
                "object" => Pruning::ObjectOnly,
                "none" => Pruning::None,
                _ => return Err(bad()),
            },
            rasterizer: rasterizer.parse().map_err(|_| bad())?,
        })
    }
}

fn rasterizer_name(rasterizer: Rasterizer) -> &'static str {
    match rasterizer {
        Rasterizer::Fused => "fused",
        Rasterizer::Tensor => "tensor",
    }
}

fn pruning_name(pruning: Pruning) -> &'static str {
    match pruning {
        Pruning::ObjectOnly => "object",
        Pruning::None => "none",
    }
}

/// One row of the benchmark table.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Row {
    scene: String,
    gaussians: usize,
    resolution: usize,
    pruning: String,
    rasterizer: String,
    /// Tile–Gaussian pairs of the pass (× 256: pixel–Gaussian pairs).
    pairs: usize,
    /// Gaussians in the object mask.
    object_gaussians: usize,
    /// Measured mask mean (share of the frame the object covers).
    coverage: f64,
    tce: f64,
    tre: f64,
    /// Median ms of mask render + TCE + TRE (plain device).
    forward_ms: f64,
    /// Median ms of mask render + TCE + TRE + backward (autodiff device).
    forward_backward_ms: f64,
    /// Process peak resident memory after building/loading the scene, placing the camera
    /// (a few 64² forward renders) and uploading, before any timed pass (MB).
    setup_peak_mb: Option<f64>,
    /// Process peak resident memory at the end (MB).
    peak_mb: Option<f64>,
    /// CPU time / wall time during the timed runs (≈ cores kept busy).
    cpu_per_wall: Option<f64>,
    /// Threads of rayon's global pool in the child.
    rayon_threads: usize,
    /// Why the configuration was not run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    skipped: Option<String>,
}

/// Everything the benchmark reports.
#[derive(Debug, Serialize)]
struct Report {
    backend: String,
    dtype: String,
    repeats: usize,
    rayon_threads: usize,
    cores: usize,
    target_ratio: f64,
    rows: Vec<Row>,
}

fn run_all(args: &BenchRenderArgs) -> Result<()> {
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    if let Some(r) = args.resolutions.iter().find(|&&r| r == 0) {
        bail!("--resolutions: {r} is not a valid image size");
    }
    // Fail early, before spawning children, on an uncompiled backend or missing scene.
    args.backend.device()?;
    if let Some(path) = &args.scene
        && !path.is_file()
    {
        bail!("--scene {}: no such file", path.display());
    }
    let mut configs = Vec::new();
    let mut sources: Vec<Source> = Vec::new();
    if !args.no_demo {
        sources.extend(args.sizes.iter().map(|&n| Source::Demo(n)));
    }
    if args.scene.is_some() {
        sources.push(Source::File);
    }
    for source in &sources {
        for &resolution in &args.resolutions {
            for pruning in [Pruning::ObjectOnly, Pruning::None] {
                for &rasterizer in &args.rasterizer {
                    configs.push(Config {
                        source: source.clone(),
                        resolution,
                        pruning,
                        rasterizer,
                    });
                }
            }
        }
    }
    if configs.is_empty() {
        bail!("nothing to benchmark: give demo --sizes or --scene FILE");
    }

    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let started = Instant::now();
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for (i, config) in configs.iter().enumerate() {
        // 300k Gaussians at 256² unpruned take ~3 s per forward + backward on 2 cores (15 s
        // with repeats), affordable in the default run; larger scenes at 256² are not.
        let slow = matches!(config.source, Source::Demo(n) if n > 300_000)
            && config.resolution >= 256
            && config.pruning == Pruning::None;
        if slow && !args.all {
            rows.push(skipped_row(config, args, "slow; run with --all"));
            continue;
        }
        eprintln!("[{}/{}] {}", i + 1, configs.len(), config.spec());
        let mut child = Command::new(&exe);
        child.args(["bench", "render", "--one", &config.spec()]);
        child.args(["--repeats", &args.repeats.to_string()]);
        child.args(["--backend", &args.backend.to_string()]);
        child.args(["--dtype", &format!("{:?}", args.dtype).to_lowercase()]);
        child.args(["--rasterizer", rasterizer_name(config.rasterizer)]);
        child.args(["--object", &args.object]);
        child.args(["--target-ratio", &args.target_ratio.to_string()]);
        child.args(["--fov", &args.fov.to_string()]);
        if let Some(threads) = args.threads {
            child.args(["--threads", &threads.to_string()]);
        }
        if let Some(scene) = &args.scene {
            child.arg("--scene").arg(scene);
        }
        let output = child.output().context("cannot start a benchmark process")?;
        let stdout = String::from_utf8_lossy(&output.stdout);
        let parsed = stdout
            .lines()
            .last()
            .and_then(|line| serde_json::from_str::<Row>(line).ok());
        match (output.status.success(), parsed) {
            (true, Some(row)) => rows.push(row),
            _ => {
                let err = String::from_utf8_lossy(&output.stderr).trim().to_string();
                eprintln!("  failed: {err}");
                failures.push(format!("{}: {err}", config.spec()));
                rows.push(skipped_row(config, args, "failed"));
            }
        }
    }
    let report = Report {
        backend: args.backend.to_string(),
        dtype: format!("{:?}", args.dtype).to_lowercase(),
        repeats: args.repeats,
        rayon_threads: args.threads.unwrap_or_else(rayon::current_num_threads),
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        target_ratio: args.target_ratio,
        rows,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", table(&report));
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

fn skipped_row(config: &Config, args: &BenchRenderArgs, why: &str) -> Row {
    Row {
        scene: source_name(&config.source, args),
        gaussians: match config.source {
            Source::Demo(n) => n,
            Source::File => 0,
        },
        resolution: config.resolution,
        pruning: pruning_name(config.pruning).into(),
        rasterizer: rasterizer_name(config.rasterizer).into(),
        pairs: 0,
        object_gaussians: 0,
        coverage: f64::NAN,
        tce: f64::NAN,
        tre: f64::NAN,
        forward_ms: f64::NAN,
        forward_backward_ms: f64::NAN,
        setup_peak_mb: None,
        peak_mb: None,
        cpu_per_wall: None,
        rayon_threads: 0,
        skipped: Some(why.into()),
    }
}

fn source_name(source: &Source, args: &BenchRenderArgs) -> String {
    match source {
        Source::Demo(_) => "demo".into(),
        Source::File => args
            .scene
            .as_ref()
            .and_then(|p| p.file_name())
            .map_or_else(|| "scene".into(), |n| n.to_string_lossy().into_owned()),
    }
}

fn table(report: &Report) -> String {
    let mut out = format!(
        "mask pass (render + TCE + TRE), backend {}, {}, median of {}, rayon pool {} threads on \
         {} cores, target coverage {:.2}; ns/pair = time / (tile–Gaussian pairs × 256)\n",
        report.backend,
        report.dtype,
        report.repeats,
        report.rayon_threads,
        report.cores,
        report.target_ratio
    );
    out += &format!(
        "{:<20} {:>9} {:>4} {:>7} {:>7} {:>7} {:>6} {:>9} {:>8} {:>11} {:>9} {:>7} {:>7} {:>6}\n",
        "scene",
        "gaussians",
        "res",
        "pruning",
        "raster",
        "object",
        "cover",
        "pairs",
        "fwd ms",
        "fwd+bwd ms",
        "ns/pair",
        "setupMB",
        "peakMB",
        "cpu/w"
    );
    let mb = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.0}"));
    let ns = |ms: f64, pairs: usize| 1e6 * ms / (pairs.max(1) as f64 * 256.0);
    for row in &report.rows {
        if let Some(why) = &row.skipped {
            out += &format!(
                "{:<20} {:>9} {:>4} {:>7} {:>7}   skipped ({why})\n",
                row.scene, row.gaussians, row.resolution, row.pruning, row.rasterizer
            );
            continue;
        }
        out += &format!(
            "{:<20} {:>9} {:>4} {:>7} {:>7} {:>7} {:>6.3} {:>9} {:>8.1} {:>11.1} {:>4.2}/{:<4.2} {:>7} {:>7} {:>6}\n",
            row.scene,
            row.gaussians,
            row.resolution,
            row.pruning,
            row.rasterizer,
            row.object_gaussians,
            row.coverage,
            row.pairs,
            row.forward_ms,
            row.forward_backward_ms,
            ns(row.forward_ms, row.pairs),
            ns(row.forward_backward_ms, row.pairs),
            mb(row.setup_peak_mb),
            mb(row.peak_mb),
            row.cpu_per_wall.map_or("-".into(), |v| format!("{v:.2}")),
        );
    }
    let speedups = speedups(&report.rows);
    if !speedups.is_empty() {
        out += "fused speed-up over tensor (fwd, fwd+bwd):\n";
        for (key, fwd, bwd) in speedups {
            out += &format!("  {key}: {fwd:.2}×, {bwd:.2}×\n");
        }
    }
    out
}

/// For each configuration timed with both rasterizers: tensor time / fused time.
fn speedups(rows: &[Row]) -> Vec<(String, f64, f64)> {
    let key = |r: &Row| {
        format!(
            "{} {} {}² {}",
            r.scene, r.gaussians, r.resolution, r.pruning
        )
    };
    fn timed<'a>(rows: &'a [Row], name: &'static str) -> impl Iterator<Item = &'a Row> {
        rows.iter()
            .filter(move |r| r.skipped.is_none() && r.rasterizer == name)
    }
    timed(rows, "fused")
        .filter_map(|f| {
            let t = timed(rows, "tensor").find(|t| key(t) == key(f))?;
            Some((
                key(f),
                t.forward_ms / f.forward_ms,
                t.forward_backward_ms / f.forward_backward_ms,
            ))
        })
        .collect()
}

/// Runs one configuration in this process.
fn run_one(args: &BenchRenderArgs, config: &Config) -> Result<Row> {
    let device = args.backend.device()?;
    let dtype = args.dtype.precision().dtype();
    let intrinsics = Intrinsics::from_fov_x(args.fov, config.resolution, config.resolution)?;
    // Camera placement is calibrated at 64² so every resolution sees the same view.
    let calibration = Intrinsics::from_fov_x(args.fov, 64, 64)?;
    let ratio = args.target_ratio;
    let setup = match config.source {
        Source::Demo(n) => demo_bench_scene(&args.object, n, ratio, &calibration, &device)?,
        Source::File => {
            let path = args
                .scene
                .as_ref()
                .ok_or_else(|| anyhow!("--one scene:… needs --scene"))?;
            file_bench_scene(path, ratio, &calibration, &device)?
        }
    };
    let mut probe = MaskProbe::new(
        &setup.scene,
        (&device, dtype),
        setup.mask.clone(),
        ratio,
        intrinsics,
        config.rasterizer,
    )?;
    probe.prune = config.pruning == Pruning::ObjectOnly;
    let setup_peak_mb = peak_mb();

    // Warm-up (first-call allocations), which also gives the costs reported.
    let result = probe.forward_backward(&setup.pose)?;
    probe.forward(&setup.pose)?;

    let cpu_before = cpu_seconds();
    let wall = Instant::now();
    let forward_ms = median_ms(args.repeats, || probe.forward(&setup.pose).map(|_| ()))?;
    let forward_backward_ms = median_ms(args.repeats, || {
        probe.forward_backward(&setup.pose).map(|_| ())
    })?;
    let wall_s = wall.elapsed().as_secs_f64();
    let cpu_per_wall = match (cpu_before, cpu_seconds()) {
        (Some(a), Some(b)) if wall_s > 0.0 => Some((b - a) / wall_s),
        _ => None,
    };
    let term = |name: &str| {
        result
            .terms
            .iter()
            .find(|t| t.0 == name)
            .map_or(f64::NAN, |t| t.2)
    };
    Ok(Row {
        scene: setup.name,
        gaussians: setup.scene.len(),
        resolution: config.resolution,
        pruning: pruning_name(config.pruning).into(),
        rasterizer: rasterizer_name(config.rasterizer).into(),
        pairs: result.stats.map_or(0, |s| s.pairs),
        object_gaussians: setup.mask.iter().filter(|&&m| m != 0.0).count(),
        coverage: result.coverage.unwrap_or(0.0),
        tce: term("tce"),
        tre: term("tre"),
        forward_ms,
        forward_backward_ms,
        setup_peak_mb,
        peak_mb: peak_mb(),
        cpu_per_wall,
        rayon_threads: rayon::current_num_threads(),
        skipped: None,
    })
}

/// Process peak resident set (VmHWM), MB; None where /proc is missing.
fn peak_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// User + system CPU time of this process, seconds (from /proc/self/stat, 100 ticks/s).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line, 12 and 13 after ") ".
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
