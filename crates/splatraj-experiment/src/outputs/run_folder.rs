//! The run folder of `splatraj run` beyond its single files: checking that it can be made,
//! resuming a stopped run in it, cleaning what a killed process left, and the `metrics.json`
//! that closes it.
//!
//! A run stopped by SIGKILL or a second Ctrl-C leaves `config.toml`, `checkpoint.json` and
//! maybe temporary `*.partial` files; [`resumable`] reads such a folder back and
//! [`remove_partial_files`] clears the temporaries. A finished run writes `metrics.json` with
//! `run.stop = "finished"` and drops its checkpoint ([`remove_checkpoint`]).

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use serde::Serialize;
use splatraj_render::backend::Hardware;
use splatraj_render::counters::Counts;
use splatraj_scene::atomic::is_partial_file;
use splatraj_traj::metrics::{Smoothness, WindowMetrics};

use crate::config::Config;
use crate::optimise::checkpoint::{CHECKPOINT_FILE, Checkpoint};
use crate::{Evaluation, Experiment, RunStop, TrajectoryRun};

/// `metrics.json`.
#[derive(Debug, Serialize)]
pub struct MetricsFile {
    /// Per-window metrics.
    pub windows: Vec<WindowMetrics>,
    /// Log dimensionless jerk of the whole path.
    pub ldj: Smoothness,
    /// Samples LDJ was computed on.
    pub ldj_samples: usize,
    /// How the optimisation went.
    pub run: RunReport,
}

impl MetricsFile {
    /// The file of an evaluated run.
    pub fn new(evaluation: Evaluation, ldj_samples: usize, run: RunReport) -> Self {
        let Evaluation { windows, ldj } = evaluation;
        MetricsFile {
            windows,
            ldj,
            ldj_samples,
            run,
        }
    }
}

/// How the optimisation went (`metrics.json`'s `run`).
#[derive(Debug, Clone, Serialize)]
pub struct RunReport {
    /// Scene name.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Gaussians the optimisation rendered: the coarse copy's when `optimise_gaussians` made
    /// one, else the scene's.
    pub optimised_gaussians: usize,
    /// Why the optimisation ended.
    pub stop: RunStop,
    /// Restarts that ran.
    pub restarts_run: usize,
    /// The restart whose trajectory was kept.
    pub best_restart: usize,
    /// Its best step.
    pub best_step: usize,
    /// Its best sampled loss.
    pub best_total: f64,
    /// Steps over all restarts.
    pub iterations_run: usize,
    /// Steps skipped for a non-finite gradient.
    pub skipped_steps: usize,
    /// Optimisation wall time.
    pub optimisation_s: f64,
    /// Optimisation wall time per step.
    pub per_iteration_ms: f64,
    /// Metrics wall time.
    pub metrics_s: f64,
    /// Frames, video and exports wall time.
    pub frames_s: f64,
    /// The whole run's wall time.
    pub total_s: f64,
    /// Peak resident memory of the run's process so far (VmHWM), MB; None where the system
    /// does not report it.
    pub peak_memory_mb: Option<f64>,
    /// Backend and precision.
    pub backend: String,
    /// What the run computed on ([`Hardware`]): a GPU by name, an emulated one, or the CPU.
    pub device: String,
    /// What each stage asked of the device: kernel launches, reads and uploads (docs/gpu.md
    /// "Counters"; launches are counted on a GPU only).
    pub counts: StageCounts,
}

/// The device counters of a run's stages.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StageCounts {
    /// The preparation: reading the scene, grounding the queries, the start views' search.
    pub preparation: Counts,
    /// The optimisation (its starts and every step).
    pub optimisation: Counts,
    /// The metrics.
    pub metrics: Counts,
    /// The frames (video and exports included).
    pub frames: Counts,
}

/// Wall times of the stages after the optimisation, and every stage's device counters.
#[derive(Debug, Clone, Copy)]
pub struct StageTimes {
    /// Metrics.
    pub metrics: Duration,
    /// Frames, video and exports.
    pub frames: Duration,
    /// The whole run so far.
    pub total: Duration,
    /// The stages' device counters.
    pub counts: StageCounts,
}

impl RunReport {
    /// The report of `run` of `experiment`.
    pub fn new(experiment: &Experiment, run: &TrajectoryRun, times: StageTimes) -> Self {
        let best = run.best();
        let optimisation_s = run.elapsed.as_secs_f64();
        let iterations_run = run.iterations_run();
        let config = &experiment.config;
        RunReport {
            scene: experiment.scene_name.clone(),
            gaussians: experiment.scene.len(),
            optimised_gaussians: experiment.optimisation_scene().len(),
            stop: run.stop,
            restarts_run: run.results.len(),
            best_restart: run.best,
            best_step: best.best_step,
            best_total: best.best_total,
            iterations_run,
            skipped_steps: run.results.iter().map(|r| r.skipped_steps).sum(),
            optimisation_s,
            per_iteration_ms: 1e3 * optimisation_s / iterations_run.max(1) as f64,
            metrics_s: times.metrics.as_secs_f64(),
            frames_s: times.frames.as_secs_f64(),
            total_s: times.total.as_secs_f64(),
            peak_memory_mb: crate::resources::peak_mb(),
            backend: format!("{:?} {:?}", config.backend, config.precision),
            device: Hardware::of(&experiment.device).to_string(),
            counts: times.counts,
        }
    }
}

/// The config and checkpoint of a run folder to resume: its resolved `config.toml` (with
/// `overrides`), its inputs resolved against the original config's folder.
pub fn resumable(dir: &Path, overrides: &[String]) -> Result<(Config, Checkpoint)> {
    if !dir.is_dir() {
        bail!("--resume {}: not a run folder", dir.display());
    }
    if finished(&dir.join("metrics.json")) {
        bail!("--resume {}: this run already finished", dir.display());
    }
    let checkpoint = Checkpoint::read(dir)?;
    let mut config = Config::load(&dir.join("config.toml"), overrides)?;
    config.base_dir = checkpoint.base_dir.clone();
    Ok((config, checkpoint))
}

/// Whether `metrics.json` says its run finished.
fn finished(metrics: &Path) -> bool {
    splatraj_scene::input::read_text(metrics)
        .ok()
        .and_then(|text| serde_json::from_str::<serde_json::Value>(&text).ok())
        .is_some_and(|v| v["run"]["stop"] == "finished")
}

/// Fails unless files can be created in `dir` (or, when it does not exist yet, in the
/// nearest folder above it that does).
pub fn check_writable(dir: &Path) -> Result<()> {
    // The nearest path that exists must be a folder: a file there (the runs folder itself, or
    // a folder above it) could never hold the run.
    if let Some(blocking) = dir
        .ancestors()
        .find(|p| !p.as_os_str().is_empty() && std::fs::symlink_metadata(p).is_ok())
        .filter(|p| !p.is_dir())
    {
        bail!(
            "`output.runs_dir`: {} cannot be made: {} is not a folder",
            dir.display(),
            blocking.display()
        );
    }
    let existing = dir
        .ancestors()
        .find(|p| p.as_os_str().is_empty() || p.is_dir())
        .map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        })
        .unwrap_or(Path::new("."));
    let probe = existing.join(format!(".splatraj-write-test.{}", std::process::id()));
    std::fs::File::create(&probe).with_context(|| {
        format!(
            "the runs folder {} is not writable (cannot create a file in {}); set \
             `output.runs_dir`",
            dir.display(),
            existing.display()
        )
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Removes the temporary files a killed process left in a run folder (and its `frames/`).
pub fn remove_partial_files(dir: &Path) -> Result<()> {
    for folder in [dir.to_path_buf(), dir.join("frames"), dir.join("keyframes")] {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            if is_partial_file(&entry.file_name().to_string_lossy()) {
                std::fs::remove_file(entry.path())
                    .with_context(|| format!("cannot remove {}", entry.path().display()))?;
            }
        }
    }
    Ok(())
}

/// Removes the checkpoint of a finished run (it would only invite a needless `--resume`).
pub fn remove_checkpoint(dir: &Path) -> Result<()> {
    let checkpoint = dir.join(CHECKPOINT_FILE);
    if checkpoint.exists() {
        std::fs::remove_file(&checkpoint)
            .with_context(|| format!("cannot remove {}", checkpoint.display()))?;
    }
    Ok(())
}
