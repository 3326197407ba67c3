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
//! The work, and every file, is the library's ([`splatraj::experiment::process`]).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::Experiment;
use splatraj::experiment::config::{Ablation, Config};
use splatraj::experiment::optimise::observer::{Flow, Observer, Phase, Progress};
use splatraj::experiment::process::RunFolder;

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
    let max_memory_gb = args.memory.max_memory_gb()?;
    // Low to high: the file, --set, the options (typed fields, checked with the rest).
    let config = Config::load_edited(&args.config, &args.set, |config| {
        if let Some(a) = args.ablation {
            config.pose.ablation = a;
        }
        if let Some(r) = args.restarts {
            config.start.restarts = r;
        }
        if max_memory_gb.is_some() {
            config.max_memory_gb = max_memory_gb;
        }
    })?;
    let experiment = Experiment::prepare(&config)?;
    let plan = experiment.check_pose_run(args.sgld)?;
    let index = config.pose.query;
    let window = &experiment.windows[index];
    eprintln!(
        "query {:?}: {} Gaussians, {} start(s), costs {:?}",
        window.name,
        experiment.selected[index],
        experiment.pose_starts()?.len(),
        experiment.pose_costs()?.names()
    );
    // Ctrl-C is honoured before the run folder exists (as `run` does): a signal in between
    // would end the process at once and leave an empty folder.
    let interrupted = interrupt_flag();
    let folder = RunFolder::create(&experiment)?;
    eprintln!("run folder: {}", folder.dir().display());

    let bar = progress_bar(plan.steps as u64, args.quiet);
    let mut observer = |p: &Progress| {
        if let Progress::Phase(Phase::Sgld { chains }) = *p {
            bar.finish_and_clear();
            eprintln!("SGLD, {chains} chains");
            return Flow::Continue;
        }
        bar_observer(&bar, interrupted.clone()).progress(p)
    };
    let outcome = experiment.run_pose_in(&folder, args.sgld, &mut observer)?;
    bar.finish_and_clear();
    if outcome.interrupted {
        eprintln!("stopped by Ctrl-C: wrote the best pose so far");
    }
    let (metrics, pose) = (&outcome.metrics.metrics, &outcome.pose);
    eprintln!(
        "best pose {:?}\nTCE {}  TRE {:.4}  IoU {:.3}  visible {}  ({:.1} s, {:.0} ms/iteration for {} start(s))",
        pose.pose,
        metrics
            .tce
            .map_or("undefined (never in view)".to_string(), |t| format!(
                "{t:.4}"
            )),
        metrics.tre,
        metrics.iou,
        metrics.visible,
        pose.optimisation_s,
        pose.per_iteration_ms,
        pose.starts.len()
    );
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
