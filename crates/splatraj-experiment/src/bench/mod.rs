//! `splatraj bench render` as a library: the configurations (scene, resolution, pruning,
//! rasterizer), one configuration timed in this process ([`run_one`]: the mask pass through the
//! optimiser's loss path, [`crate::optimise::probe`], on the scenes of [`crate::bench::scenes`]), the
//! rows and the report with its table, including the fused rasterizer's speed-up over the
//! tensor one. The command runs each configuration in a child process of its own so that the
//! peak memory a row reports (VmHWM, a process-wide high-water mark) is that configuration's.
//!
//! **This folder** is the benchmarks: the mask pass (here), output frames ([`frames`]), scale
//! ([`scale`], on the demo scenes of [`scenes`]), an optimisation step's render calls
//! ([`step`]), what a launch, a read and an upload cost ([`launches`]) and the first-try
//! quality figures ([`quality`]).

pub mod frames;
pub mod launches;
pub mod quality;
pub mod scale;
pub mod scenes;
pub mod step;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::DType;
use serde::{Deserialize, Serialize};
use splatraj_render::backend::{BackendKind, Hardware};
use splatraj_render::camera::Intrinsics;
use splatraj_render::counters::{self, Counts};
use splatraj_render::render::{Pruning, Rasterizer};
use splatraj_render::stages;

use crate::bench::scenes::{demo_bench_scene, file_bench_scene};
use crate::optimise::probe::{MaskProbe, median_ms};
use crate::resources::peak_mb;
use crate::resources::{MemoryLimit, RenderWork};

/// Which scene a configuration renders.
#[derive(Debug, Clone, PartialEq)]
pub enum BenchSource {
    /// The demo scene with this many Gaussians.
    Demo(usize),
    /// The real scene of [`BenchSettings::scene`].
    File,
}

/// One benchmark configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchConfig {
    /// The scene.
    pub source: BenchSource,
    /// Square image size, pixels.
    pub resolution: usize,
    /// Object-pruned or full mask pass.
    pub pruning: Pruning,
    /// Which compositing.
    pub rasterizer: Rasterizer,
}

/// What every configuration of one benchmark shares.
#[derive(Debug, Clone)]
pub struct BenchSettings {
    /// Tensor backend.
    pub backend: BackendKind,
    /// Float dtype.
    pub dtype: DType,
    /// Timed runs per measurement (the median is reported), after one untimed warm-up.
    pub repeats: usize,
    /// Demo object the camera frames.
    pub object: String,
    /// Share of the frame the object should cover (also TRE's target).
    pub target_ratio: f64,
    /// Horizontal field of view, degrees.
    pub fov: f64,
    /// The real scene, if any (its object: a sphere of Gaussians at its centre).
    pub scene: Option<PathBuf>,
}

impl BenchConfig {
    /// The configuration as `demo:N:RES:PRUNING:RASTERIZER` or `scene:RES:PRUNING:RASTERIZER`
    /// (what the command hands a child process).
    pub fn spec(&self) -> String {
        let pruning = pruning_name(self.pruning);
        let rasterizer = rasterizer_name(self.rasterizer);
        match self.source {
            BenchSource::Demo(n) => format!("demo:{n}:{}:{pruning}:{rasterizer}", self.resolution),
            BenchSource::File => format!("scene:{}:{pruning}:{rasterizer}", self.resolution),
        }
    }

    /// The configuration of a [`BenchConfig::spec`].
    pub fn parse(spec: &str) -> Result<Self> {
        let parts: Vec<&str> = spec.split(':').collect();
        let bad = || {
            anyhow!(
                "--one {spec:?}: expected demo:N:RES:PRUNING:RASTERIZER or \
                 scene:RES:PRUNING:RASTERIZER"
            )
        };
        let (source, rest) = match parts.as_slice() {
            ["demo", n, rest @ ..] => (BenchSource::Demo(n.parse().map_err(|_| bad())?), rest),
            ["scene", rest @ ..] => (BenchSource::File, rest),
            _ => return Err(bad()),
        };
        let [resolution, pruning, rasterizer] = rest else {
            return Err(bad());
        };
        Ok(BenchConfig {
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

    /// Every combination of `sources`, `resolutions`, both prunings and `rasterizers`, in
    /// that nesting order; an error when there is none.
    pub fn all(
        sources: &[BenchSource],
        resolutions: &[usize],
        rasterizers: &[Rasterizer],
    ) -> Result<Vec<BenchConfig>> {
        if let Some(r) = resolutions.iter().find(|&&r| r == 0) {
            bail!("--resolutions: {r} is not a valid image size");
        }
        let mut configs = Vec::new();
        for source in sources {
            for &resolution in resolutions {
                for pruning in [Pruning::ObjectOnly, Pruning::None] {
                    for &rasterizer in rasterizers {
                        configs.push(BenchConfig {
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
        Ok(configs)
    }

    /// Skipped unless asked for: an unpruned 256² render of a demo scene above 300k Gaussians
    /// (300k at 256² take ~3 s per forward + backward on 2 cores, 15 s with repeats).
    pub fn is_slow(&self) -> bool {
        matches!(self.source, BenchSource::Demo(n) if n > 300_000)
            && self.resolution >= 256
            && self.pruning == Pruning::None
    }

    /// The row of a configuration that did not run, saying `why`.
    pub fn skipped_row(&self, settings: &BenchSettings, why: &str) -> BenchRow {
        BenchRow {
            scene: source_name(&self.source, settings),
            gaussians: match self.source {
                BenchSource::Demo(n) => n,
                BenchSource::File => 0,
            },
            resolution: self.resolution,
            pruning: pruning_name(self.pruning).into(),
            rasterizer: rasterizer_name(self.rasterizer).into(),
            pairs: 0,
            object_gaussians: 0,
            coverage: f64::NAN,
            tce: f64::NAN,
            tre: f64::NAN,
            grad_pose: Vec::new(),
            forward_ms: f64::NAN,
            forward_backward_ms: f64::NAN,
            setup_peak_mb: None,
            peak_mb: None,
            cpu_per_wall: None,
            rayon_threads: 0,
            device: String::new(),
            stages_ms: Vec::new(),
            counts: Counts::default(),
            launch_names: Vec::new(),
            skipped: Some(why.into()),
        }
    }
}

/// `fused` or `tensor`.
pub fn rasterizer_name(rasterizer: Rasterizer) -> &'static str {
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

fn source_name(source: &BenchSource, settings: &BenchSettings) -> String {
    match source {
        BenchSource::Demo(_) => "demo".into(),
        BenchSource::File => settings
            .scene
            .as_ref()
            .and_then(|p| p.file_name())
            .map_or_else(|| "scene".into(), |n| n.to_string_lossy().into_owned()),
    }
}

/// One row of the benchmark table (one configuration; a child process prints it as JSON).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BenchRow {
    /// Scene name (`demo` or the file name).
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Square image size, pixels.
    pub resolution: usize,
    /// `object` or `none`.
    pub pruning: String,
    /// `fused` or `tensor`.
    pub rasterizer: String,
    /// Tile–Gaussian pairs of the pass (× 256: pixel–Gaussian pairs).
    pub pairs: usize,
    /// Gaussians in the object mask.
    pub object_gaussians: usize,
    /// Measured mask mean (share of the frame the object covers).
    pub coverage: f64,
    /// TCE of the warm-up pass.
    pub tce: f64,
    /// TRE of the warm-up pass.
    pub tre: f64,
    /// d(TCE + TRE)/dΦ of the warm-up pass (what `scripts/gpu_check.sh` compares across
    /// backends).
    #[serde(default)]
    pub grad_pose: Vec<f64>,
    /// Median ms of mask render + TCE + TRE (plain device).
    pub forward_ms: f64,
    /// Median ms of mask render + TCE + TRE + backward (autodiff device).
    pub forward_backward_ms: f64,
    /// Process peak resident memory after building/loading the scene, placing the camera
    /// (a few 64² forward renders) and uploading, before any timed pass (MB).
    pub setup_peak_mb: Option<f64>,
    /// Process peak resident memory at the end (MB).
    pub peak_mb: Option<f64>,
    /// CPU time / wall time during the timed runs (≈ cores kept busy).
    pub cpu_per_wall: Option<f64>,
    /// Threads of rayon's global pool in the child.
    pub rayon_threads: usize,
    /// What the child ran on ([`Hardware`]): a GPU by name, an emulated one, or the CPU.
    #[serde(default)]
    pub device: String,
    /// Mean ms per forward + backward pass in each render stage (`splatraj_render::stages`
    /// names), then `other`: the rest of the pass (the projection's autodiff backward, costs).
    #[serde(default)]
    pub stages_ms: Vec<(String, f64)>,
    /// Per forward + backward pass: kernel launches (GPU backends), reads back to the host,
    /// uploads and bytes each way (`splatraj_render::counters`).
    #[serde(default)]
    pub counts: Counts,
    /// The kernels launched in those passes by name, most first, per pass (GPU backends).
    #[serde(default)]
    pub launch_names: Vec<(String, u64)>,
    /// Why the configuration was not run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

/// Everything the benchmark reports (`bench render --json`).
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Tensor backend.
    pub backend: String,
    /// Float dtype.
    pub dtype: String,
    /// Timed runs per measurement.
    pub repeats: usize,
    /// Threads of rayon's global pool.
    pub rayon_threads: usize,
    /// Cores available.
    pub cores: usize,
    /// Share of the frame the object should cover.
    pub target_ratio: f64,
    /// One row per configuration.
    pub rows: Vec<BenchRow>,
}

impl BenchReport {
    /// The human-readable table, then the fused speed-ups.
    pub fn table(&self) -> String {
        let report = self;
        // The children's: a row that was skipped has none.
        let device = report
            .rows
            .iter()
            .find(|r| !r.device.is_empty())
            .map_or_else(String::new, |r| format!(" on {}", r.device));
        let mut out = format!(
            "mask pass (render + TCE + TRE), backend {}{device}, {}, median of {}, rayon pool {} \
             threads on {} cores, target coverage {:.2}; ns/pair = time / (tile–Gaussian pairs × \
             256)\n",
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
        out += &stage_table(&report.rows);
        let speedups = speedups(&report.rows);
        if !speedups.is_empty() {
            out += "fused speed-up over tensor (fwd, fwd+bwd):\n";
            for (key, fwd, bwd) in speedups {
                out += &format!("  {key}: {fwd:.2}×, {bwd:.2}×\n");
            }
        }
        out
    }
}

/// Where a forward + backward pass spends its time, one line per timed row (ms per pass).
fn stage_table(rows: &[BenchRow]) -> String {
    let Some(names) = rows.iter().find(|r| !r.stages_ms.is_empty()) else {
        return String::new();
    };
    let mut out = format!(
        "{:<20} {:>9} {:>4} {:>7} {:>7}",
        "stages, ms/pass", "gaussians", "res", "pruning", "raster"
    );
    for (name, _) in &names.stages_ms {
        out += &format!(" {name:>9}");
    }
    out += &format!(
        " | {:>8} {:>5} {:>7} {:>9} {:>9}\n",
        "launches", "reads", "uploads", "KB up", "KB down"
    );
    for row in rows.iter().filter(|r| !r.stages_ms.is_empty()) {
        out += &format!(
            "{:<20} {:>9} {:>4} {:>7} {:>7}",
            row.scene, row.gaussians, row.resolution, row.pruning, row.rasterizer
        );
        for (_, ms) in &row.stages_ms {
            out += &format!(" {ms:>9.1}");
        }
        let c = &row.counts;
        out += &format!(
            " | {:>8} {:>5} {:>7} {:>9.1} {:>9.1}\n",
            c.launches,
            c.reads,
            c.uploads,
            c.bytes_up as f64 / 1024.0,
            c.bytes_down as f64 / 1024.0
        );
    }
    // Where a GPU pass's launches go: the kernels launched most, per pass.
    for row in rows.iter().filter(|r| !r.launch_names.is_empty()) {
        let most: Vec<String> = row
            .launch_names
            .iter()
            .take(8)
            .map(|(name, n)| format!("{n}× {name}"))
            .collect();
        out += &format!(
            "launches, {} {} {}² {} {}: {}\n",
            row.scene,
            row.gaussians,
            row.resolution,
            row.pruning,
            row.rasterizer,
            most.join(", ")
        );
    }
    out
}

/// For each configuration timed with both rasterizers: tensor time / fused time.
pub fn speedups(rows: &[BenchRow]) -> Vec<(String, f64, f64)> {
    let key = |r: &BenchRow| {
        format!(
            "{} {} {}² {}",
            r.scene, r.gaussians, r.resolution, r.pruning
        )
    };
    fn timed<'a>(rows: &'a [BenchRow], name: &'static str) -> impl Iterator<Item = &'a BenchRow> {
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

/// Runs one configuration in this process: builds its scene and camera, warms up, then times
/// the mask pass forward and forward + backward.
pub fn run_one(args: &BenchSettings, config: &BenchConfig) -> Result<BenchRow> {
    let dtype = args.dtype;
    let device = args.backend.device_for(dtype)?;
    let intrinsics = Intrinsics::from_fov_x(args.fov, config.resolution, config.resolution)?;
    // Camera placement is calibrated at 64² so every resolution sees the same view.
    let calibration = Intrinsics::from_fov_x(args.fov, 64, 64)?;
    let ratio = args.target_ratio;
    let setup = match config.source {
        BenchSource::Demo(n) => demo_bench_scene(&args.object, n, ratio, &calibration, &device)?,
        BenchSource::File => {
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
    // The stage clock is process-wide and each row runs in its own child, so only this
    // configuration's passes are on it.
    stages::reset();
    counters::tally_launch_names(true);
    let counted = counters::snapshot();
    let pass = Instant::now();
    let forward_backward_ms = median_ms(args.repeats, || {
        probe.forward_backward(&setup.pose).map(|_| ())
    })?;
    let counts = counters::snapshot()
        .since(&counted)
        .per(args.repeats.max(1) as u64);
    let launch_names = counters::launch_names()
        .into_iter()
        .map(|(name, n)| (name, n / args.repeats.max(1) as u64))
        .collect();
    counters::tally_launch_names(false);
    let per_pass = |d: std::time::Duration| 1e3 * d.as_secs_f64() / args.repeats.max(1) as f64;
    let mut stages_ms: Vec<(String, f64)> = stages::ms_per(args.repeats)
        .iter()
        .map(|&(stage, ms)| (stage.name().to_string(), ms))
        .collect();
    let staged: f64 = stages_ms.iter().map(|(_, ms)| ms).sum();
    stages_ms.push(("other".into(), per_pass(pass.elapsed()) - staged));
    let wall_s = wall.elapsed().as_secs_f64();
    let cpu_per_wall = match (cpu_before, cpu_seconds()) {
        (Some(a), Some(b)) if wall_s > 0.0 => Some((b - a) / wall_s),
        _ => None,
    };
    Ok(BenchRow {
        scene: setup.name,
        gaussians: setup.scene.len(),
        resolution: config.resolution,
        pruning: pruning_name(config.pruning).into(),
        rasterizer: rasterizer_name(config.rasterizer).into(),
        pairs: result.stats.map_or(0, |s| s.pairs),
        object_gaussians: setup.mask.iter().filter(|&&m| m != 0.0).count(),
        coverage: result.coverage.unwrap_or(0.0),
        tce: result.term("tce"),
        tre: result.term("tre"),
        grad_pose: result.grad_pose.clone().unwrap_or_default(),
        forward_ms,
        forward_backward_ms,
        setup_peak_mb,
        peak_mb: peak_mb(),
        cpu_per_wall,
        rayon_threads: rayon::current_num_threads(),
        device: Hardware::of(&device).to_string(),
        stages_ms,
        counts,
        launch_names,
        skipped: None,
    })
}

/// User + system CPU time of this process, seconds (from /proc/self/stat, 100 ticks/s).
pub fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line, 12 and 13 after ") ".
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Which configurations `bench render` runs.
#[derive(Debug, Clone)]
pub struct RenderBenchGrid {
    /// Demo scene sizes, in Gaussians (none: the real scene only).
    pub sizes: Vec<usize>,
    /// Square image sizes, in pixels.
    pub resolutions: Vec<usize>,
    /// Rasterizers timed on every configuration.
    pub rasterizers: Vec<Rasterizer>,
    /// Threads of each child's rayon pool (`None`: one per core).
    pub threads: Option<usize>,
    /// Run the slow configurations too.
    pub all: bool,
}

/// Errors, before any child starts, on a `--fov` that is no field of view, or when the
/// configurations of one resolution of `grid` cannot fit in memory or would take too long:
/// each times `--repeats` forwards and forward + backward passes after one warm-up of each,
/// all from flags (a scene file's size is checked when read).
fn check_render_bench_work(
    settings: &BenchSettings,
    grid: &RenderBenchGrid,
    configs: &[BenchConfig],
) -> Result<()> {
    Intrinsics::from_fov_x(settings.fov, 64, 64)
        .with_context(|| format!("--fov {}", settings.fov))?;
    let gaussians = grid.sizes.iter().copied().max().unwrap_or(0);
    for &resolution in &grid.resolutions {
        let runs = configs
            .iter()
            .filter(|c| c.resolution == resolution && (grid.all || !c.is_slow()))
            .count();
        let passes = 2.0 * (1.0 + settings.repeats as f64);
        RenderWork {
            what: format!(
                "`--repeats` = {} × {runs} configurations of up to {gaussians} demo Gaussians \
                 (--sizes) at `--resolutions`",
                settings.repeats
            ),
            renders: passes * runs as f64,
            at_once: 1,
            size: (resolution, resolution),
            gaussians,
            gradient: true,
            float_bytes: settings.dtype.size(),
        }
        .check(MemoryLimit::new(None)?, "")?;
    }
    Ok(())
}

/// Runs every configuration of `grid` in its own child process of `exe` (`splatraj bench
/// render --one SPEC`), so each peak memory is its own; `progress` hears each start and
/// failure. Returns the report and the failures (each also a skipped row).
pub fn run_render_bench(
    exe: &std::path::Path,
    settings: &BenchSettings,
    grid: &RenderBenchGrid,
    progress: &mut dyn FnMut(String),
) -> Result<(BenchReport, Vec<String>)> {
    if settings.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    let mut sources: Vec<BenchSource> = grid.sizes.iter().map(|&n| BenchSource::Demo(n)).collect();
    if settings.scene.is_some() {
        sources.push(BenchSource::File);
    }
    let configs = BenchConfig::all(&sources, &grid.resolutions, &grid.rasterizers)?;
    check_render_bench_work(settings, grid, &configs)?;
    // Fail early, before spawning children, on an uncompiled backend or missing scene.
    settings.backend.device_for(settings.dtype)?;
    if let Some(path) = &settings.scene
        && !path.is_file()
    {
        bail!("--scene {}: no such file", path.display());
    }
    let dtype = if settings.dtype == DType::F64 {
        "f64"
    } else {
        "f32"
    };
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    splatraj_scene::stop::honour();
    for (i, config) in configs.iter().enumerate() {
        if splatraj_scene::stop::requested() {
            return Err(splatraj_scene::stop::Stopped {
                what: format!("{i} of {} configurations measured", configs.len()),
            }
            .into());
        }
        if config.is_slow() && !grid.all {
            rows.push(config.skipped_row(settings, "slow; run with --all"));
            continue;
        }
        progress(format!("[{}/{}] {}", i + 1, configs.len(), config.spec()));
        let mut child = std::process::Command::new(exe);
        child.args(["bench", "render", "--one", &config.spec()]);
        child.args(["--repeats", &settings.repeats.to_string()]);
        child.args(["--backend", &settings.backend.to_string()]);
        child.args(["--dtype", dtype]);
        child.args(["--rasterizer", rasterizer_name(config.rasterizer)]);
        child.args(["--object", &settings.object]);
        child.args(["--target-ratio", &settings.target_ratio.to_string()]);
        child.args(["--fov", &settings.fov.to_string()]);
        if let Some(threads) = grid.threads {
            child.args(["--threads", &threads.to_string()]);
        }
        if let Some(scene) = &settings.scene {
            child.arg("--scene").arg(scene);
        }
        let output = crate::children::output_until_stopped(
            &mut child,
            &format!("the benchmark process of {}", config.spec()),
        )?;
        let stdout = String::from_utf8_lossy(&output.stdout);
        let parsed = stdout
            .lines()
            .last()
            .and_then(|line| serde_json::from_str::<BenchRow>(line).ok());
        match (output.status.success(), parsed) {
            (true, Some(row)) => rows.push(row),
            _ => {
                let err = String::from_utf8_lossy(&output.stderr).trim().to_string();
                progress(format!("  failed: {err}"));
                failures.push(format!("{}: {err}", config.spec()));
                rows.push(config.skipped_row(settings, "failed"));
            }
        }
    }
    let report = BenchReport {
        backend: settings.backend.to_string(),
        dtype: dtype.to_string(),
        repeats: settings.repeats,
        rayon_threads: grid.threads.unwrap_or_else(rayon::current_num_threads),
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        target_ratio: settings.target_ratio,
        rows,
    };
    Ok((report, failures))
}

/// Runs `bench` on a rayon pool of `threads` workers (checked first, `--threads`), entered
/// once so the measured passes start their parallel loops from inside it, as `run` does;
/// `None` runs it where it is (on the global pool).
pub fn in_thread_pool<T: Send>(
    threads: Option<usize>,
    stack_bytes: usize,
    bench: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    let Some(threads) = threads else {
        return bench();
    };
    crate::resources::check_threads("--threads", threads)?;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(stack_bytes)
        .build()
        .map_err(|e| anyhow!("cannot set up {threads} rayon threads: {e}"))?
        .install(bench)
}
