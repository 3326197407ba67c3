//! A whole experiment through the library alone, as `splatraj run` does it: the same run
//! folder, file for file.
//!
//! `cargo run --release --example library_run -- CONFIG [--set KEY=VALUE]...`

use anyhow::{Context, Result, bail};
use splatraj::experiment::optimise::observer::{Flow, Progress};
use splatraj::experiment::process::RunFolder;
use splatraj::experiment::{Config, Experiment};

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let config_path = args
        .next()
        .context("usage: library_run CONFIG [--set KEY=VALUE]...")?;
    let mut overrides = Vec::new();
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--set" => overrides.push(args.next().context("--set needs KEY=VALUE")?),
            other => bail!("unknown argument {other:?}"),
        }
    }
    let config = Config::load(std::path::Path::new(&config_path), &overrides)?;
    let experiment = Experiment::prepare(&config)?;
    let plan = experiment.check_trajectory_run(false)?;
    let folder = RunFolder::create(&experiment)?;
    let mut observer = |p: &Progress| {
        if let Progress::Trajectory { restart, step, .. } = *p
            && step % 50 == 0
        {
            eprintln!("restart {restart}, step {step} of {} in all", plan.steps);
        }
        Flow::Continue
    };
    let outcome = experiment.run_trajectory_in(&folder, &mut observer)?;
    for problem in &outcome.problems {
        eprintln!("warning: {problem}");
    }
    println!("{}", outcome.dir.display());
    Ok(())
}
