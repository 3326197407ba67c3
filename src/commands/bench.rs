//! `splatraj bench render`: time the object-mask pass, forward and forward + backward.
//!
//! Each configuration (scene, resolution, pruning) runs in a fresh child process of this
//! binary (hidden `--one` flag), so that the peak memory it reports (VmHWM of
//! /proc/self/status, a process-wide high-water mark) belongs to that configuration alone.
//! The loss is TCE + TRE of the mask, as in the optimiser. The camera frames one object so
//! that it covers about the target ratio of the frame: the distance comes from the object's
//! size and the field of view, then two corrections from measured coverage (coverage ∝ 1/d²).

use std::path::PathBuf;
use std::process::Command;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, Subcommand};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{DeviceScene, Pruning};
use splatraj_scene::demo::{DEMO_VIEWPOINT, DemoConfig, demo_layout, demo_scene};
use splatraj_scene::{ReadOptions, Scene, guess_up_axis, read_scene};
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;

use super::render::{
    DtypeArg, forward_backward, forward_loss, mask_request, median_ms, pose_tensor,
};

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
    /// Internal: run one configuration (`demo:N:RES:PRUNING` or `scene:RES:PRUNING`) in this
    /// process and print its result as one JSON line.
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
}

impl Config {
    fn spec(&self) -> String {
        let pruning = pruning_name(self.pruning);
        match self.source {
            Source::Demo(n) => format!("demo:{n}:{}:{pruning}", self.resolution),
            Source::File => format!("scene:{}:{pruning}", self.resolution),
        }
    }

    fn parse(spec: &str) -> Result<Self> {
        let parts: Vec<&str> = spec.split(':').collect();
        let bad = || anyhow!("--one {spec:?}: expected demo:N:RES:PRUNING or scene:RES:PRUNING");
        let (source, rest) = match parts.as_slice() {
            ["demo", n, rest @ ..] => (Source::Demo(n.parse().map_err(|_| bad())?), rest),
            ["scene", rest @ ..] => (Source::File, rest),
            _ => return Err(bad()),
        };
        let [resolution, pruning] = rest else {
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
        })
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
                configs.push(Config {
                    source: source.clone(),
                    resolution,
                    pruning,
                });
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
         {} cores, target coverage {:.2}\n",
        report.backend,
        report.dtype,
        report.repeats,
        report.rayon_threads,
        report.cores,
        report.target_ratio
    );
    out += &format!(
        "{:<24} {:>9} {:>5} {:>7} {:>8} {:>9} {:>10} {:>13} {:>8} {:>8} {:>8}\n",
        "scene",
        "gaussians",
        "res",
        "pruning",
        "object",
        "coverage",
        "fwd ms",
        "fwd+bwd ms",
        "setup MB",
        "peak MB",
        "cpu/wall"
    );
    let mb = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.0}"));
    for row in &report.rows {
        if let Some(why) = &row.skipped {
            out += &format!(
                "{:<24} {:>9} {:>5} {:>7}   skipped ({why})\n",
                row.scene, row.gaussians, row.resolution, row.pruning
            );
            continue;
        }
        out += &format!(
            "{:<24} {:>9} {:>5} {:>7} {:>8} {:>9.3} {:>10.1} {:>13.1} {:>8} {:>8} {:>8}\n",
            row.scene,
            row.gaussians,
            row.resolution,
            row.pruning,
            row.object_gaussians,
            row.coverage,
            row.forward_ms,
            row.forward_backward_ms,
            mb(row.setup_peak_mb),
            mb(row.peak_mb),
            row.cpu_per_wall.map_or("-".into(), |v| format!("{v:.2}")),
        );
    }
    out
}

/// A scene, its object mask and a camera framing the object.
struct Setup {
    name: String,
    scene: Scene,
    mask: Vec<f32>,
    pose: Pose,
}

/// Runs one configuration in this process.
fn run_one(args: &BenchRenderArgs, config: &Config) -> Result<Row> {
    let device = args.backend.device()?;
    let autodiff = device.clone().autodiff();
    let dtype = args.dtype.precision().dtype();
    let target = args.target_ratio;
    let intrinsics = Intrinsics::from_fov_x(args.fov, config.resolution, config.resolution)?;
    // Camera placement is calibrated at 64² so every resolution sees the same view.
    let calibration = Intrinsics::from_fov_x(args.fov, 64, 64)?;

    let setup = match config.source {
        Source::Demo(n) => demo_setup(args, n, &calibration, &device)?,
        Source::File => {
            let path = args
                .scene
                .as_ref()
                .ok_or_else(|| anyhow!("--one scene:… needs --scene"))?;
            file_setup(args, path, &calibration, &device)?
        }
    };
    let plain_scene = DeviceScene::new(&setup.scene, &device, dtype);
    let ad_scene = DeviceScene::new(&setup.scene, &autodiff, dtype);
    let request = mask_request(intrinsics, setup.mask.clone(), config.pruning);
    let setup_peak_mb = peak_mb();

    // Warm-up (first-call allocations), which also gives the costs reported.
    let result = forward_backward(&ad_scene, &setup.pose, &request, target, &autodiff, dtype)?;
    forward_loss(&plain_scene, &setup.pose, &request, target, &device, dtype)?;

    let cpu_before = cpu_seconds();
    let wall = Instant::now();
    let forward_ms = median_ms(args.repeats, || {
        forward_loss(&plain_scene, &setup.pose, &request, target, &device, dtype).map(|_| ())
    })?;
    let forward_backward_ms = median_ms(args.repeats, || {
        forward_backward(&ad_scene, &setup.pose, &request, target, &autodiff, dtype).map(|_| ())
    })?;
    let wall_s = wall.elapsed().as_secs_f64();
    let cpu_per_wall = match (cpu_before, cpu_seconds()) {
        (Some(a), Some(b)) if wall_s > 0.0 => Some((b - a) / wall_s),
        _ => None,
    };

    Ok(Row {
        scene: setup.name,
        gaussians: setup.scene.len(),
        resolution: config.resolution,
        pruning: pruning_name(config.pruning).into(),
        object_gaussians: setup.mask.iter().filter(|&&m| m != 0.0).count(),
        coverage: result.coverage,
        tce: result.tce,
        tre: result.tre,
        forward_ms,
        forward_backward_ms,
        setup_peak_mb,
        peak_mb: peak_mb(),
        cpu_per_wall,
        rayon_threads: rayon::current_num_threads(),
        skipped: None,
    })
}

/// Measured coverage of `mask` from `pose` (forward only, pruned, at the calibration size).
fn measure_coverage(
    scene: &Scene,
    mask: &[f32],
    pose: &Pose,
    intrinsics: &Intrinsics,
    device: &burn::tensor::Device,
) -> Result<f64> {
    let dtype = burn::tensor::DType::F32;
    let uploaded = DeviceScene::new(scene, device, dtype);
    let request = mask_request(*intrinsics, mask.to_vec(), Pruning::ObjectOnly);
    let out =
        splatraj_render::render::render(&uploaded, pose_tensor(pose, device, dtype), &request)?;
    let sum = super::render::host(out.images.sum())?[0];
    Ok(sum / (intrinsics.width * intrinsics.height) as f64)
}

/// Distance at which a silhouette of `area` m² covers `ratio` of a frame.
fn framing_distance(area: f64, ratio: f64, k: &Intrinsics) -> f64 {
    // Pixel area = area · fx · fy / d², frame = W · H.
    (area * k.fx * k.fy / (ratio * (k.width * k.height) as f64)).sqrt()
}

fn demo_setup(
    args: &BenchRenderArgs,
    gaussians: usize,
    calibration: &Intrinsics,
    device: &burn::tensor::Device,
) -> Result<Setup> {
    let layout = demo_layout();
    let object = layout
        .iter()
        .find(|o| o.name.eq_ignore_ascii_case(args.object.trim()))
        .ok_or_else(|| {
            anyhow!(
                "--object {:?} is not a demo object; available: {}",
                args.object,
                layout.iter().map(|o| o.name).collect::<Vec<_>>().join(", ")
            )
        })?;
    let scene = demo_scene(&DemoConfig {
        gaussians,
        ..DemoConfig::default()
    })?;
    let ids = &scene
        .extras
        .labels
        .as_ref()
        .ok_or_else(|| anyhow!("the demo scene has no labels"))?
        .ids;
    let mask: Vec<f32> = ids
        .iter()
        .map(|&id| if id == object.id { 1.0 } else { 0.0 })
        .collect();
    let centre = DVec3::from_array(object.center.map(f64::from));
    let size = object.size.map(f64::from);
    // Silhouette ≈ a disc whose radius is half the geometric mean of the box's edges.
    let radius = 0.5 * (size[0] * size[1] * size[2]).cbrt();
    let area = std::f64::consts::PI * radius * radius;
    // View from the demo's standing viewpoint, the way a person would look at the object.
    let direction = (DVec3::from_array(DEMO_VIEWPOINT.map(f64::from)) - centre).normalize();
    let mut distance = framing_distance(area, args.target_ratio, calibration);
    let pose_at = |d: f64| Pose::look_at(centre + direction * d, centre, DVec3::Z);
    for _ in 0..2 {
        let coverage = measure_coverage(&scene, &mask, &pose_at(distance)?, calibration, device)?;
        tracing::debug!(distance, coverage, "camera distance calibration");
        if coverage > 0.0 {
            distance *= (coverage / args.target_ratio).sqrt();
        }
    }
    Ok(Setup {
        name: "demo".into(),
        pose: pose_at(distance)?,
        scene,
        mask,
    })
}

fn file_setup(
    args: &BenchRenderArgs,
    path: &std::path::Path,
    calibration: &Intrinsics,
    device: &burn::tensor::Device,
) -> Result<Setup> {
    let scene = read_scene(path, &ReadOptions::default())?.scene;
    let bounds = scene
        .robust_bounds(0.02)
        .ok_or_else(|| anyhow!("{} holds no Gaussian", path.display()))?;
    let centre = DVec3::from_array(bounds.center().map(f64::from));
    let up = guess_up_axis(&scene).map_or(DVec3::Z, |g| DVec3::from_array(g.up.map(f64::from)));
    // As the preview example: outside the robust bounds' sphere, 30° around up, 25° above.
    let half = DVec3::from_array(bounds.size().map(f64::from)).length() * 0.5;
    let (tan_x, _) = calibration.tan_half_fov();
    let distance = half.max(1e-3) / tan_x.atan().sin();
    let helper = if up.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let e1 = (helper - up * helper.dot(up)).normalize();
    let e2 = up.cross(e1);
    let (az, el) = (30f64.to_radians(), 25f64.to_radians());
    let direction = (e1 * az.cos() + e2 * az.sin()) * el.cos() + up * el.sin();
    let pose = Pose::look_at(centre + direction * distance, centre, up)?;
    // The object: Gaussians within ρ of the centre, ρ sized for the target coverage, then
    // corrected from measured coverage (real scenes are not uniformly dense).
    let mut rho = framing_distance(1.0, args.target_ratio, calibration).recip() * distance
        / std::f64::consts::PI.sqrt();
    let sphere = |rho: f64| -> Vec<f32> {
        scene
            .means
            .iter()
            .map(|m| {
                let d = DVec3::from_array(m.map(f64::from)) - centre;
                if d.length() <= rho { 1.0 } else { 0.0 }
            })
            .collect()
    };
    for _ in 0..4 {
        let coverage = measure_coverage(&scene, &sphere(rho), &pose, calibration, device)?;
        tracing::debug!(rho, coverage, distance, "object sphere calibration");
        let factor = if coverage > 0.0 {
            (args.target_ratio / coverage).sqrt().clamp(0.5, 2.0)
        } else {
            2.0
        };
        rho *= factor;
    }
    let mask = sphere(rho);
    Ok(Setup {
        name: path
            .file_name()
            .map_or_else(|| "scene".into(), |n| n.to_string_lossy().into_owned()),
        scene,
        mask,
        pose,
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
