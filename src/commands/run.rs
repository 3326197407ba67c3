//! `splatraj run CONFIG.toml`: optimise a trajectory that shows each query in turn, then write
//! the run folder (resolved config, trajectory, frames, metrics, history).
//!
//! Order of work: read and check everything (config, scene, targets) before any folder is
//! made; optimise from each start (a progress bar shows iteration, cost and time left; Ctrl-C
//! or `optimiser.time_limit_s` stops early and keeps the best so far); then evaluate the
//! per-window metrics on a fixed time grid at the output resolution, LDJ, and render frames.
//! The work, and every file, is the library's, one call
//! ([`splatraj::experiment::process::run_trajectory_experiment`]); this file parses, draws
//! progress and prints.
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
use splatraj::experiment::RunStop;
use splatraj::experiment::optimise::observer::{Flow, Observer, Phase, Progress};
use splatraj::experiment::process::{
    RunSource, TrajectoryEnd, TrajectoryRequest, run_trajectory_experiment,
};

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
    let max_memory_gb = args.memory.max_memory_gb()?;
    let source = match (&args.resume, &args.config) {
        (Some(dir), _) => RunSource::Resume {
            dir,
            set: &args.set,
        },
        (None, Some(path)) => RunSource::Config {
            path,
            set: &args.set,
        },
        (None, None) => bail!("give a config file, or --resume RUN_DIR"),
    };
    let request = TrajectoryRequest {
        source,
        max_memory_gb,
        check_only: args.check,
    };
    let mut progress = RunProgress::new(args.quiet);
    let outcome = match run_trajectory_experiment(&request, &mut progress)? {
        TrajectoryEnd::Checked(plan) => {
            if let Some(line) = plan.check_line() {
                eprintln!("{line}");
            }
            return Ok(());
        }
        TrajectoryEnd::Ran(outcome) => outcome,
    };
    progress.finish();
    for line in outcome.summary_lines() {
        eprintln!("{line}");
    }
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
    if !outcome.verdict_fails() {
        Ok(())
    } else {
        Err(Ended::verdict_failed(format!(
            "verdict: {} of {} windows do not show their object as asked (see the warnings \
             above, `metrics.json`'s `verdict` and {}); exit status {}",
            outcome.failing,
            outcome.evaluation.windows.len(),
            dir.join("report.html").display(),
            crate::cli::EXIT_VERDICT
        ))
        .into())
    }
}

/// The bars of a run: the optimisation's, then the outputs' (metrics, frames), with the
/// library's lines (the plan, the folder) and the reason a stopped optimisation ended.
struct RunProgress {
    bar: ProgressBar,
    quiet: bool,
    interrupted: Arc<AtomicBool>,
}

impl RunProgress {
    fn new(quiet: bool) -> Self {
        RunProgress {
            bar: progress_bar(0, quiet),
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
        if let Progress::Phase(Phase::Optimisation { steps }) = *progress {
            self.bar.set_length(steps as u64);
            return Flow::Continue;
        }
        if let Progress::Phase(Phase::Outputs { frames, stop }) = *progress {
            self.bar.finish_and_clear();
            match stop {
                RunStop::Interrupted => eprintln!(
                    "stopped by Ctrl-C: writing the metrics and {frames} frames of the best \
                     trajectory so far; Ctrl-C again quits now (the checkpoint stays for \
                     `--resume`)"
                ),
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

    fn line(&mut self, line: &str) {
        eprintln!("{line}");
    }
}
