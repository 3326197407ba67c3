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
//! The work is the library's ([`splatraj::experiment::Experiment`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use splatraj::experiment::config::{Ablation, Config, MaskOverlay};
use splatraj::experiment::outputs::{
    FrameSpec, create_run_dir, frame_png, write_bytes, write_csv, write_json,
};
use splatraj::experiment::records::{PoseFile, pose_history, sgld_samples};
use splatraj::experiment::resources::RAISE_LIMIT;
use splatraj::experiment::{Experiment, Posterior};
use splatraj_traj::metrics::WindowMetrics;
use splatraj_traj::optimise::StopReason;

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

/// `metrics.json` of a pose run.
#[derive(Debug, Serialize)]
struct PoseMetrics {
    metrics: WindowMetrics,
    sgld: Option<SgldSummary>,
}

/// Spread of the SGLD samples.
#[derive(Debug, Serialize)]
struct SgldSummary {
    chains: usize,
    samples: usize,
    /// Mean and standard deviation of each pose component over the samples.
    mean: [f64; 6],
    std: [f64; 6],
    skipped_updates: usize,
    seconds: f64,
}

impl From<&Posterior> for SgldSummary {
    fn from(p: &Posterior) -> Self {
        SgldSummary {
            chains: p.chains,
            samples: p.samples.len(),
            mean: p.mean,
            std: p.std,
            skipped_updates: p.skipped_updates,
            seconds: p.elapsed.as_secs_f64(),
        }
    }
}

/// Runs `splatraj pose`.
pub fn run(args: PoseArgs) -> Result<()> {
    let mut overrides = args.set.clone();
    if let Some(a) = args.ablation {
        overrides.push(format!(
            "pose.ablation={}",
            toml::Value::try_from(a).context("ablation")?
        ));
    }
    if let Some(r) = args.restarts {
        overrides.push(format!("start.restarts={r}"));
    }
    overrides.extend(args.memory.overrides());
    let config = Config::load(&args.config, &overrides)?;
    if args.sgld == Some(0) {
        anyhow::bail!("--sgld needs at least one chain");
    }
    let experiment = Experiment::prepare(&config)?;
    experiment
        .pose_memory(args.sgld.unwrap_or(0))
        .check(experiment.memory_limit()?, RAISE_LIMIT)?;
    let index = config.pose.query;
    let window = &experiment.windows[index];
    let costs = experiment.pose_costs()?;
    let starts = experiment.pose_starts()?;
    eprintln!(
        "query {:?}: {} Gaussians, {} start(s), costs {:?}",
        window.name,
        experiment.selected[index],
        starts.len(),
        costs.names()
    );

    let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
    eprintln!("run folder: {}", dir.display());
    write_bytes(
        &dir.join("config.toml"),
        toml::to_string(&config)?.as_bytes(),
    )?;

    let bar = progress_bar(config.pose.optimiser.iterations as u64, args.quiet);
    let run = experiment.optimise_pose(&mut bar_observer(&bar, interrupt_flag()))?;
    bar.finish_and_clear();
    let interrupted = run.stop() == StopReason::Interrupted;
    if interrupted {
        eprintln!("stopped by Ctrl-C: writing the best pose so far");
    }
    let (header, rows) = pose_history(&run.results);
    write_csv(&dir.join("history.csv"), &header, &rows)?;
    let best = run.best();

    let sgld = match args.sgld {
        Some(chains) => {
            let bar = progress_bar(1, args.quiet);
            bar.set_message(format!("SGLD, {chains} chains"));
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let posterior = experiment.sample_posterior(best.pose, chains)?;
            bar.finish_and_clear();
            let (header, rows) = sgld_samples(&posterior);
            write_csv(&dir.join("sgld_samples.csv"), &header, &rows)?;
            Some(SgldSummary::from(&posterior))
        }
        None => None,
    };
    let pose_file = PoseFile::new(&experiment, &run);
    write_json(&dir.join("pose.json"), &pose_file)?;

    let metrics = experiment.evaluate_pose(best.pose)?;
    eprintln!(
        "best pose {:?}\nTCE {:.4}  TRE {:.4}  IoU {:.3}  visible {}  ({:.1} s, {:.0} ms/iteration for {} start(s))",
        best.pose.0,
        metrics.tce,
        metrics.tre,
        metrics.iou,
        metrics.visible,
        pose_file.optimisation_s,
        pose_file.per_iteration_ms,
        starts.len()
    );
    let tint = (config.output.mask_overlay == MaskOverlay::Tint).then_some(window.mask.as_slice());
    let camera = (&experiment.output_intrinsics()?, config.rasterizer);
    let png = frame_png(
        &experiment.plain_scene(),
        camera,
        &FrameSpec {
            pose: best.pose.0,
            tint,
        },
    )?;
    write_bytes(&dir.join("frame.png"), &png)?;
    write_json(&dir.join("metrics.json"), &PoseMetrics { metrics, sgld })?;
    println!("{}", dir.display());
    if interrupted {
        return Err(Ended::interrupted(format!(
            "interrupted: {} holds the best pose so far",
            dir.display()
        ))
        .into());
    }
    Ok(())
}
