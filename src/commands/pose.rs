//! `splatraj pose CONFIG.toml`: one camera pose that frames one query (the paper's Table I),
//! with its ablations, restarts and SGLD posterior samples.
//!
//! The same config as `splatraj run`; `[pose]` picks the query and the ablation, and
//! `[pose.optimiser]` holds Adam's settings. Restarts run as one batch (one batched render per
//! step). `--sgld CHAINS` then runs that many Langevin chains from the best pose and writes
//! the kept samples. Outputs go to a fresh `runs/<name>/<timestamp>/`: `config.toml`,
//! `pose.json` (best pose and every start's result), `history.csv`, `metrics.json` (TCE, TRE,
//! IoU of the best pose at the output resolution), `frame.png`, and with `--sgld`
//! `sgld_samples.csv`. Ctrl-C during the optimisation stops it and keeps each start's best.
//! The work, and every file, is the library's, one call
//! ([`splatraj::experiment::process::run_pose_experiment`]); this file parses, draws progress
//! and prints.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::config::Ablation;
use splatraj::experiment::optimise::observer::{Flow, Observer, Phase, Progress};
use splatraj::experiment::process::{PoseRequest, run_pose_experiment};

use crate::cli::{Ended, MemoryArgs, bar_observer, interrupt_flag, progress_bar};

/// Arguments of `splatraj pose`.
#[derive(Debug, Args)]
pub struct PoseArgs {
    /// Experiment config (TOML).
    config: PathBuf,
    /// Override a config value, e.g. `--set pose.query=1` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Which costs join the prior (overrides `pose.ablation`): full, prior, prior-tce,
    /// prior-tre or prior-tce-tre.
    #[arg(long, value_parser = parse_ablation)]
    ablation: Option<Ablation>,
    /// Independent random starts, optimised together; the best is kept (overrides
    /// `start.restarts`).
    #[arg(long)]
    restarts: Option<usize>,
    /// After optimising, run this many SGLD chains from the best pose and write the samples.
    #[arg(long, value_name = "CHAINS")]
    sgld: Option<usize>,
    #[command(flatten)]
    memory: MemoryArgs,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn parse_ablation(s: &str) -> Result<Ablation, String> {
    s.parse()
}

/// Runs `splatraj pose`.
pub fn run(args: PoseArgs) -> Result<()> {
    let request = PoseRequest {
        config: &args.config,
        set: &args.set,
        ablation: args.ablation,
        restarts: args.restarts,
        max_memory_gb: args.memory.max_memory_gb()?,
        sgld: args.sgld,
    };
    let mut progress = PoseProgress {
        bar: progress_bar(0, args.quiet),
        interrupted: interrupt_flag(),
    };
    let outcome = run_pose_experiment(&request, &mut progress)?;
    progress.bar.finish_and_clear();
    if outcome.interrupted {
        eprintln!("stopped by Ctrl-C: wrote the best pose so far");
    }
    eprintln!("{}", outcome.summary());
    println!("{}", outcome.dir.display());
    if outcome.interrupted {
        return Err(Ended::interrupted(format!(
            "interrupted: {} holds the best pose so far",
            outcome.dir.display()
        ))
        .into());
    }
    Ok(())
}

/// The bar of a pose run, with the library's lines (the query's plan, the folder) and the
/// switch to SGLD.
struct PoseProgress {
    bar: indicatif::ProgressBar,
    interrupted: std::sync::Arc<std::sync::atomic::AtomicBool>,
}

impl Observer for PoseProgress {
    fn progress(&mut self, progress: &Progress) -> Flow {
        match *progress {
            Progress::Phase(Phase::Optimisation { steps }) => {
                self.bar.set_length(steps as u64);
                Flow::Continue
            }
            Progress::Phase(Phase::Sgld { chains }) => {
                self.bar.finish_and_clear();
                eprintln!("SGLD, {chains} chains");
                Flow::Continue
            }
            _ => bar_observer(&self.bar, self.interrupted.clone()).progress(progress),
        }
    }

    fn line(&mut self, line: &str) {
        eprintln!("{line}");
    }
}
