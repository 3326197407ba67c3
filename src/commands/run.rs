//! `splatraj run CONFIG.toml`: optimise a trajectory that shows each query in turn, then write
//! the run folder (resolved config, trajectory, frames, metrics, history).
//!
//! Order of work: read and check everything (config, scene, targets) before any folder is
//! made; optimise from each start (a progress bar shows iteration, cost and time left; Ctrl-C
//! or `optimiser.time_limit_s` stops early and keeps the best so far); then evaluate the
//! per-window metrics on a fixed time grid at the output resolution, LDJ, and render frames.
//! The work is the library's ([`splatraj::experiment::Experiment`]); this file draws progress
//! and writes files.
//!
//! Nothing is lost: the estimated peak memory is checked against the limit before any work
//! (`--check` runs the same checks, reads every input and tests that the runs folder is
//! writable); the best trajectory so far is checkpointed to `checkpoint.json` every few seconds
//! while optimising, so SIGKILL or a second Ctrl-C loses seconds of work, and `splatraj run
//! --resume RUN_DIR` continues such a run in its folder. A run stopped by Ctrl-C writes its
//! files for the best trajectory so far and exits 130.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Result, bail};
use clap::Args;
use splatraj::experiment::config::{Config, VerdictPolicy};
use splatraj::experiment::outputs::{create_run_dir, write_bytes, write_csv, write_json};
use splatraj::experiment::records::trajectory_history;
use splatraj::experiment::resources::RAISE_LIMIT;
use splatraj::experiment::run_folder::{
    MetricsFile, RunReport, StageTimes, check_writable, remove_checkpoint, remove_partial_files,
    resumable,
};
use splatraj::experiment::{Evaluation, Experiment, RunOptions, RunStop};

use crate::cli::{Ended, MemoryArgs, bar_observer, interrupt_flag, progress_bar};

/// Arguments of `splatraj run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Experiment config (TOML).
    #[arg(required_unless_present = "resume")]
    config: Option<PathBuf>,
    /// Continue a run that was interrupted or killed, in its folder (reads its `config.toml`
    /// and `checkpoint.json`).
    #[arg(long, value_name = "RUN_DIR", conflicts_with = "config")]
    resume: Option<PathBuf>,
    /// Override a config value, e.g. `--set optimiser.iterations=50` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    #[command(flatten)]
    memory: MemoryArgs,
    /// Check the config, scene, queries, start, masks, memory and runs folder, print what
    /// would run, and stop.
    #[arg(long)]
    check: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Runs `splatraj run`.
pub fn run(args: RunArgs) -> Result<()> {
    let started = Instant::now();
    let mut overrides = args.set.clone();
    overrides.extend(args.memory.overrides());
    let (config, resume) = match (&args.resume, &args.config) {
        (Some(dir), _) => {
            let (config, checkpoint) = resumable(dir, &overrides)?;
            eprintln!(
                "resuming {}: restart {}/{} at step {}/{}, best sampled loss so far {:.4}",
                dir.display(),
                checkpoint.restart + 1,
                checkpoint.restarts,
                checkpoint.steps_done,
                checkpoint.steps,
                checkpoint.best_total
            );
            (config, Some((dir.clone(), checkpoint)))
        }
        (None, Some(path)) => (Config::load(path, &overrides)?, None),
        (None, None) => bail!("give a config file, or --resume RUN_DIR"),
    };
    let experiment = Experiment::prepare(&config)?;
    // Everything that can fail before the work is checked before any folder exists: the costs,
    // the starts (reading `start.trajectory`), the memory, the runs folder.
    experiment.costs()?;
    let memory = experiment.trajectory_memory()?;
    memory.check(experiment.memory_limit()?, RAISE_LIMIT)?;
    let restarts = experiment.start_trajectories()?.len();
    if resume.is_none() {
        check_writable(&config.output.runs_dir.join(&config.name))?;
    }
    print_plan(&experiment);
    if args.check {
        if let Some(peak) = memory.peak() {
            eprintln!(
                "check passed; peak memory about {} ({})",
                splatraj::experiment::resources::show_bytes(peak.bytes),
                peak.what
            );
        }
        return Ok(());
    }

    let dir = match &resume {
        Some((dir, _)) => {
            remove_partial_files(dir)?;
            dir.clone()
        }
        None => {
            let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
            // The config as run: every `"auto"` replaced by what was derived from the scene.
            write_bytes(
                &dir.join("config.toml"),
                toml::to_string(&experiment.config)?.as_bytes(),
            )?;
            dir
        }
    };
    eprintln!("run folder: {}", dir.display());

    let bar = progress_bar((config.optimiser.iterations * restarts) as u64, args.quiet);
    let options = RunOptions {
        checkpoint_dir: Some(&dir),
        resume: resume.as_ref().map(|(_, c)| c),
    };
    let run = experiment.run_trajectory_with(options, &mut bar_observer(&bar, interrupt_flag()))?;
    bar.finish_and_clear();
    match run.stop {
        RunStop::Interrupted => eprintln!("stopped by Ctrl-C: writing the best trajectory so far"),
        RunStop::TimeLimit => {
            eprintln!("`optimiser.time_limit_s` reached: writing the best trajectory so far")
        }
        RunStop::Finished => {}
    }
    let (header, rows) = trajectory_history(&run, experiment.windows.len());
    write_csv(&dir.join("history.csv"), &header, &rows)?;
    let trajectory = experiment.trajectory(&run.best().best)?;
    write_json(
        &dir.join("trajectory.json"),
        &experiment.trajectory_file(&trajectory)?,
    )?;

    // Metrics and verdicts, frames, video and exports.
    let frame_count = config.output.frame_count(experiment.windows.len());
    let frame_bar = progress_bar(frame_count as u64, args.quiet);
    frame_bar.set_message("metrics, frames");
    let outputs = experiment.write_outputs(&trajectory, &dir, &mut |done| {
        frame_bar.set_position(done as u64)
    })?;
    frame_bar.finish_and_clear();
    let evaluation = outputs.evaluation;
    let times = StageTimes {
        metrics: outputs.metrics,
        frames: outputs.frames,
        total: started.elapsed(),
    };

    let report = RunReport::new(&experiment, &run, times);
    print_summary(&evaluation, &report);
    let (problems, failing) = (evaluation.problems(), evaluation.failing());
    for problem in &problems {
        eprintln!("warning: {problem}");
    }
    write_json(
        &dir.join("metrics.json"),
        &MetricsFile::new(evaluation, config.output.ldj_samples, report),
    )?;
    experiment.write_report(&dir)?;
    println!("{}", dir.display());
    match run.stop {
        // A finished run needs no checkpoint; a stopped one keeps it for --resume.
        RunStop::Finished => remove_checkpoint(&dir)?,
        RunStop::TimeLimit => {}
        RunStop::Interrupted => {
            return Err(Ended::interrupted(format!(
                "interrupted: {} holds the best trajectory so far; `splatraj run --resume {}` \
                 continues the optimisation",
                dir.display(),
                dir.display()
            ))
            .into());
        }
    }
    if problems.is_empty() || config.output.verdict == VerdictPolicy::Warn {
        Ok(())
    } else {
        Err(Ended::verdict_failed(format!(
            "verdict: {} of {} windows do not show their object as asked (see the warnings \
             above, `metrics.json`'s `verdict` and {}); exit status {}",
            failing,
            experiment.windows.len(),
            dir.join("report.html").display(),
            crate::cli::EXIT_VERDICT
        ))
        .into())
    }
}

fn print_plan(experiment: &Experiment) {
    eprintln!(
        "scene: {} ({} Gaussians), backend {:?}, rasterizer {:?}",
        experiment.scene_name,
        experiment.scene.len(),
        experiment.config.backend,
        experiment.config.rasterizer
    );
    eprintln!("{}", experiment.up.describe());
    if experiment.up.doubtful() {
        eprintln!(
            "warning: the up guess is unsure; if the frames come out tilted, set `scene.up` \
             (y-down captures: [0, -1, 0]; z-up: [0, 0, 1])"
        );
    }
    for d in &experiment.derived {
        eprintln!(
            "derived from the scene: {} = {:.4} ({})",
            d.key, d.value, d.why
        );
    }
    // The search already ran for the start check (`start_trajectories`), which caches it.
    let views = experiment.start_views().ok().flatten();
    for (i, w) in experiment.windows.iter().enumerate() {
        if let Some(view) = views.as_ref().and_then(|v| v.get(i)) {
            eprintln!(
                "query {i}: starts from azimuth {:.0}°, elevation {:.0}°, distance {:.3}: {:.0} % \
                 of it visible there",
                view.azimuth_degrees,
                view.elevation_degrees,
                view.distance,
                100.0 * view.visible_share
            );
        }
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
    eprintln!(
        "window  query                  TCE     TRE   in view  visible  hidden  clearance  verdict"
    );
    for w in &evaluation.windows {
        // An object never in view has no framing error: show a dash, not the empty mask's 0.
        let tce = w
            .framing
            .tce_in_view
            .map_or("      -".to_string(), |t| format!("{t:>7.4}"));
        let clearance = w
            .path
            .as_ref()
            .and_then(|p| p.clearance.as_ref())
            .map_or("-".to_string(), |c| format!("{:.3}", c.min_clearance));
        let verdict = match &w.verdict {
            Some(v) if v.pass => "ok".to_string(),
            Some(v) => format!("FAIL ({})", v.failed().join(", ")),
            None => "-".to_string(),
        };
        eprintln!(
            "{:>6}  {:<20} {} {:>7.4}  {:>6.0}%  {:>6.0}%  {:>5.0}%  {:>9}  {}",
            w.window,
            w.name,
            tce,
            w.tre,
            100.0 * w.visible_fraction,
            100.0 * (1.0 - w.occlusion.mean_occluded),
            100.0 * w.occlusion.hidden_fraction,
            clearance,
            verdict
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
