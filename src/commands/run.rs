//! `splatraj run CONFIG.toml`: optimise a trajectory that shows each query in turn, then write
//! the run folder (resolved config, trajectory, frames, metrics, history).
//!
//! Order of work: read and check everything (config, scene, targets) before any folder is
//! made; optimise from each start (a progress bar shows iteration, cost and time left; Ctrl-C
//! or `optimiser.time_limit_s` stops early and keeps the best so far); then evaluate the
//! per-window metrics on a fixed time grid at the output resolution, LDJ, and render frames.
//! The work is the library's ([`splatraj::experiment::Experiment`]); this file draws progress
//! and writes files.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use serde::Serialize;
use splatraj::experiment::config::{Config, MaskOverlay};
use splatraj::experiment::outputs::{
    FrameSpec, create_run_dir, write_bytes, write_csv, write_frames, write_json,
};
use splatraj::experiment::records::trajectory_history;
use splatraj::experiment::{Evaluation, Experiment, TrajectoryRun};
use splatraj_traj::metrics::{Smoothness, WindowMetrics};
use splatraj_traj::optimise::StopReason;
use splatraj_traj::optimise::sampling::window_of;
use splatraj_traj::trajectory::uniform_times;

use crate::cli::{bar_observer, interrupt_flag, progress_bar};

/// Arguments of `splatraj run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Experiment config (TOML).
    config: PathBuf,
    /// Override a config value, e.g. `--set optimiser.iterations=50` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Check the config, scene and queries, print what would run, and stop.
    #[arg(long)]
    check: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// `metrics.json`.
#[derive(Debug, Serialize)]
struct MetricsFile {
    windows: Vec<WindowMetrics>,
    ldj: Smoothness,
    ldj_samples: usize,
    run: RunReport,
}

/// How the optimisation went.
#[derive(Debug, Serialize)]
struct RunReport {
    scene: String,
    gaussians: usize,
    stop: StopReason,
    restarts_run: usize,
    best_restart: usize,
    best_step: usize,
    best_total: f64,
    iterations_run: usize,
    skipped_steps: usize,
    optimisation_s: f64,
    per_iteration_ms: f64,
    metrics_s: f64,
    frames_s: f64,
    total_s: f64,
    backend: String,
}

/// Runs `splatraj run`.
pub fn run(args: RunArgs) -> Result<()> {
    let started = Instant::now();
    let config = Config::load(&args.config, &args.set)?;
    let experiment = Experiment::prepare(&config)?;
    print_plan(&experiment);
    if args.check {
        return Ok(());
    }
    // Checked before the folder exists: the costs and starts build.
    experiment.costs()?;
    let restarts = experiment.start_trajectories()?.len();

    let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
    eprintln!("run folder: {}", dir.display());
    write_bytes(
        &dir.join("config.toml"),
        toml::to_string(&config)?.as_bytes(),
    )?;

    let bar = progress_bar((config.optimiser.iterations * restarts) as u64, args.quiet);
    let run = experiment.run_trajectory(&mut bar_observer(&bar, interrupt_flag()))?;
    bar.finish_and_clear();
    if run.stop == StopReason::Interrupted {
        eprintln!("stopped early: writing the best trajectory so far");
    }
    let (header, rows) = trajectory_history(&run, experiment.windows.len());
    write_csv(&dir.join("history.csv"), &header, &rows)?;
    let trajectory = experiment.trajectory(&run.best().best)?;
    write_json(
        &dir.join("trajectory.json"),
        &experiment.trajectory_file(&trajectory)?,
    )?;

    let metrics_started = Instant::now();
    let evaluation = experiment.evaluate(&trajectory)?;
    let metrics_s = metrics_started.elapsed().as_secs_f64();

    let frames_started = Instant::now();
    let n = experiment.windows.len();
    let frame_times = uniform_times(config.output.frames);
    let specs: Vec<FrameSpec> = frame_times
        .iter()
        .zip(trajectory.poses_at(&frame_times))
        .map(|(&t, pose)| FrameSpec {
            pose,
            tint: (config.output.mask_overlay == MaskOverlay::Tint)
                .then(|| experiment.windows[window_of(t, n)].mask.as_slice()),
        })
        .collect();
    let frame_bar = progress_bar(specs.len() as u64, args.quiet);
    frame_bar.set_message("frames");
    write_frames(
        &experiment.plain_scene(),
        (&experiment.output_intrinsics()?, config.rasterizer),
        &specs,
        &dir.join("frames"),
        &mut |done| frame_bar.set_position(done as u64),
    )?;
    frame_bar.finish_and_clear();
    let frames_s = frames_started.elapsed().as_secs_f64();

    let report = run_report(&experiment, &run, [metrics_s, frames_s], started);
    print_summary(&evaluation, &report);
    let Evaluation { windows, ldj } = evaluation;
    let ldj_samples = config.output.ldj_samples;
    write_json(
        &dir.join("metrics.json"),
        &MetricsFile {
            windows,
            ldj,
            ldj_samples,
            run: report,
        },
    )?;
    println!("{}", dir.display());
    Ok(())
}

fn run_report(
    experiment: &Experiment,
    run: &TrajectoryRun,
    [metrics_s, frames_s]: [f64; 2],
    started: Instant,
) -> RunReport {
    let best = run.best();
    let optimisation_s = run.elapsed.as_secs_f64();
    let iterations_run = run.iterations_run();
    let config = &experiment.config;
    RunReport {
        scene: experiment.scene_name.clone(),
        gaussians: experiment.scene.len(),
        stop: run.stop,
        restarts_run: run.results.len(),
        best_restart: run.best,
        best_step: best.best_step,
        best_total: best.best_total,
        iterations_run,
        skipped_steps: run.results.iter().map(|r| r.skipped_steps).sum(),
        optimisation_s,
        per_iteration_ms: 1e3 * optimisation_s / iterations_run.max(1) as f64,
        metrics_s,
        frames_s,
        total_s: started.elapsed().as_secs_f64(),
        backend: format!("{:?} {:?}", config.backend, config.precision),
    }
}

fn print_plan(experiment: &Experiment) {
    eprintln!(
        "scene: {} ({} Gaussians), up {:?} ({}), backend {:?}, rasterizer {:?}",
        experiment.scene_name,
        experiment.scene.len(),
        experiment.up.up,
        experiment.up.source.name(),
        experiment.config.backend,
        experiment.config.rasterizer
    );
    for (i, w) in experiment.windows.iter().enumerate() {
        let c = w.context.object_centre;
        eprintln!(
            "query {i}: {:?} → {} Gaussians, centre [{:.3}, {:.3}, {:.3}], prior radius {:.3}, target ratio {}",
            w.name,
            experiment.selected[i],
            c[0],
            c[1],
            c[2],
            w.context.prior_radius,
            w.context.target_ratio
        );
    }
}

fn print_summary(evaluation: &Evaluation, report: &RunReport) {
    eprintln!("window  query                  TCE     TRE     IoU   visible");
    for w in &evaluation.windows {
        eprintln!(
            "{:>6}  {:<20} {:>7.4} {:>7.4} {:>7.3}   {:.0}%",
            w.window,
            w.name,
            w.tce,
            w.tre,
            w.iou,
            100.0 * w.visible_fraction
        );
    }
    let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    eprintln!(
        "LDJ positional {}, angular {}; {} iterations in {:.1} s ({:.0} ms each), total {:.1} s",
        show(evaluation.ldj.positional),
        show(evaluation.ldj.angular),
        report.iterations_run,
        report.optimisation_s,
        report.per_iteration_ms,
        report.total_s
    );
}
