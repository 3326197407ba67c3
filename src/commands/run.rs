//! `splatraj run CONFIG.toml`: optimise a trajectory that shows each query in turn, then write
//! the run folder (resolved config, trajectory, frames, metrics, history).
//!
//! Order of work: read and check everything (config, scene, targets) before any folder is
//! made; optimise from each start (a progress bar shows iteration, cost and time left; Ctrl-C
//! or `optimiser.time_limit_s` stops early and keeps the best so far); then evaluate the
//! per-window metrics on a fixed time grid at the output resolution, LDJ, and render frames.
//! The work, and every file, is the library's ([`splatraj::experiment::process`]); this file
//! parses, draws progress and prints.
//!
//! Nothing is lost: the estimated peak memory is checked against the limit before any work
//! (`--check` runs the same checks, reads every input and tests that the runs folder is
//! writable); the best trajectory so far is checkpointed to `checkpoint.json` every few seconds
//! while optimising, so SIGKILL or a second Ctrl-C loses seconds of work, and `splatraj run
//! --resume RUN_DIR` continues such a run in its folder. A run stopped by Ctrl-C writes its
//! files for the best trajectory so far and exits 130.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Result, bail};
use clap::Args;
use indicatif::ProgressBar;
use splatraj::experiment::config::{Config, VerdictPolicy};
use splatraj::experiment::observer::{Flow, Observer, Phase, Progress};
use splatraj::experiment::process::RunFolder;
use splatraj::experiment::run_folder::{RunReport, resumable};
use splatraj::experiment::{Evaluation, Experiment, RunStop};

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
    let mut overrides = args.set.clone();
    overrides.extend(args.memory.overrides());
    let (config, checkpoint) = match (&args.resume, &args.config) {
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
            (config, Some(checkpoint))
        }
        (None, Some(path)) => (Config::load(path, &overrides)?, None),
        (None, None) => bail!("give a config file, or --resume RUN_DIR"),
    };
    let experiment = Experiment::prepare(&config)?;
    let plan = experiment.check_trajectory_run(checkpoint.is_some())?;
    print_plan(&experiment);
    if args.check {
        if let Some(peak) = plan.memory.peak() {
            eprintln!(
                "check passed; peak memory about {} ({})",
                splatraj::experiment::resources::show_bytes(peak.bytes),
                peak.what
            );
        }
        return Ok(());
    }
    let folder = match (&args.resume, checkpoint) {
        (Some(dir), Some(checkpoint)) => RunFolder::resume(dir, checkpoint)?,
        _ => RunFolder::create(&experiment)?,
    };
    eprintln!("run folder: {}", folder.dir().display());

    let mut progress = RunProgress::new(plan.steps as u64, args.quiet);
    let outcome = experiment.run_trajectory_in(&folder, &mut progress)?;
    progress.finish();
    print_summary(&outcome.evaluation, &outcome.report);
    for problem in &outcome.problems {
        eprintln!("warning: {problem}");
    }
    let dir = &outcome.dir;
    println!("{}", dir.display());
    if outcome.stop == RunStop::Interrupted {
        return Err(Ended::interrupted(format!(
            "interrupted: {} holds the best trajectory so far; `splatraj run --resume {}` \
             continues the optimisation",
            dir.display(),
            dir.display()
        ))
        .into());
    }
    if outcome.problems.is_empty() || config.output.verdict == VerdictPolicy::Warn {
        Ok(())
    } else {
        Err(Ended::verdict_failed(format!(
            "verdict: {} of {} windows do not show their object as asked (see the warnings \
             above, `metrics.json`'s `verdict` and {}); exit status {}",
            outcome.failing,
            experiment.windows.len(),
            dir.join("report.html").display(),
            crate::cli::EXIT_VERDICT
        ))
        .into())
    }
}

/// The bars of a run: the optimisation's, then the outputs' (metrics, frames), with the
/// reason a stopped optimisation ended.
struct RunProgress {
    bar: ProgressBar,
    quiet: bool,
    interrupted: Arc<AtomicBool>,
}

impl RunProgress {
    fn new(steps: u64, quiet: bool) -> Self {
        RunProgress {
            bar: progress_bar(steps, quiet),
            quiet,
            interrupted: interrupt_flag(),
        }
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl Observer for RunProgress {
    fn progress(&mut self, progress: &Progress) -> Flow {
        if let Progress::Phase(Phase::Outputs { frames, stop }) = *progress {
            self.bar.finish_and_clear();
            match stop {
                RunStop::Interrupted => {
                    eprintln!("stopped by Ctrl-C: writing the best trajectory so far")
                }
                RunStop::TimeLimit => {
                    eprintln!(
                        "`optimiser.time_limit_s` reached: writing the best trajectory so far"
                    )
                }
                RunStop::Finished => {}
            }
            self.bar = progress_bar(frames as u64, self.quiet);
            self.bar.set_message("metrics, frames");
            return Flow::Continue;
        }
        bar_observer(&self.bar, self.interrupted.clone()).progress(progress)
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
