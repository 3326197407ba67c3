//! `splatraj bench step`: what one optimisation step of a config costs with its windows in one
//! render call ([`StepPasses::Shared`], the costs that batch run once) and with a call per
//! window ([`StepPasses::PerWindow`]), on the config's backend: the wall time per step and,
//! per step, the kernel launches, reads back, uploads and render calls
//! ([`splatraj_render::counters`]). It is the instrument of docs/gpu.md's "One pass a step":
//! on a GPU it says whether the shared step wins and by how much, which lavapipe's counts can
//! only suggest.
//!
//! Each variant runs `steps` steps from the config's first start after one untimed step (the
//! kernels compile and tune on first use). The time is the timed call's wall time over its
//! steps, its last read included: a step's own timing cannot be used, because on a GPU a
//! step's backward is only queued, and the device is waited for by the next step's read (the
//! last step's by the read after the loop). A median of the steps' own timings left the
//! backward out entirely with `--steps 1` (lavapipe, guitar: 2.5 s a step against 22 s).

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use serde::Serialize;
use splatraj_render::backend::Hardware;
use splatraj_render::counters::{self, Counts};
use splatraj_render::stages;
use splatraj_traj::optimise::{Flow, StepPasses, optimise_trajectory};

use crate::config::Config;
use crate::optimise::trajectory_run::TrajectoryOptimisation;
use crate::prepare::experiment::Experiment;

/// One variant's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepRow {
    /// `shared` or `per-window`.
    pub passes: &'static str,
    /// What the steps ran on ([`Hardware`]): a GPU by name, an emulated one, or the CPU.
    pub device: String,
    /// Wall time of the timed steps over their number, ms: every wait for the device included.
    pub ms_per_step: f64,
    /// Per step: launches, reads, uploads, bytes, render calls.
    pub counts: Counts,
    /// Steps timed.
    pub steps: usize,
    /// The best sampled loss the steps reached (the variants optimise alike).
    pub best_total: f64,
    /// Launches per step by kernel name, most first (empty on the CPU backends): what is left
    /// to merge.
    pub launch_names: Vec<(String, u64)>,
    /// Mean ms per step in each render stage ([`splatraj_render::stages`]), pipeline order:
    /// where a step's time goes (on a GPU the stages' times are indicative only).
    pub stages_ms: Vec<(&'static str, f64)>,
}

/// Runs `steps` optimisation steps of the trajectory of the config at `path` (with `set`'s
/// overrides) with each way of sharing render calls, after one untimed step each.
pub fn run_step_bench(path: &Path, set: &[String], steps: usize) -> Result<Vec<StepRow>> {
    let config = Config::load(path, set)?;
    let experiment = Experiment::prepare(&config)?;
    let experiment = &experiment;
    let optimisation = TrajectoryOptimisation::new(experiment)?;
    let start = optimisation
        .starts
        .first()
        .ok_or_else(|| anyhow::anyhow!("the config makes no start trajectory"))?;
    let device = Hardware::of(&experiment.device).to_string();
    let mut rows = Vec::new();
    for (passes, name) in [
        (StepPasses::PerWindow, "per-window"),
        (StepPasses::Shared, "shared"),
    ] {
        let problem = optimisation.problem(&optimisation.costs, passes);
        let mut options = experiment.config.optimiser.clone();
        options.time_limit_s = None;
        options.iterations = 1;
        optimise_trajectory(&problem, start, &options, 0, &mut |_| Flow::Continue)?;
        options.iterations = steps.max(1);
        counters::tally_launch_names(true);
        let before = counters::snapshot();
        stages::reset();
        let started = Instant::now();
        let result = optimise_trajectory(&problem, start, &options, 0, &mut |_| Flow::Continue)?;
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let counts = counters::snapshot()
            .since(&before)
            .per(options.iterations as u64);
        let launch_names = counters::launch_names()
            .into_iter()
            .map(|(name, n)| (name, n / options.iterations as u64))
            .collect();
        counters::tally_launch_names(false);
        let stages_ms = stages::ms_per(options.iterations)
            .iter()
            .map(|&(stage, ms)| (stage.name(), ms))
            .collect();
        rows.push(StepRow {
            passes: name,
            device: device.clone(),
            ms_per_step: ms / options.iterations as f64,
            counts,
            steps: options.iterations,
            best_total: result.best_total,
            launch_names,
            stages_ms,
        });
    }
    Ok(rows)
}

/// The rows as a table.
pub fn step_table(rows: &[StepRow]) -> String {
    let mut out = rows.first().map_or_else(String::new, |r| {
        format!("optimisation steps on {}\n", r.device)
    });
    out += &format!(
        "{:<11} {:>9} {:>9} {:>6} {:>8} {:>9} {:>8} {:>9} {:>9} {:>12}\n",
        "passes",
        "ms/step",
        "launches",
        "reads",
        "uploads",
        "KB up",
        "renders",
        "k pairs",
        "k rows",
        "best loss"
    );
    for r in rows {
        let c = &r.counts;
        let _ = writeln!(
            out,
            "{:<11} {:>9.1} {:>9} {:>6} {:>8} {:>9.1} {:>8} {:>9.1} {:>9.1} {:>12.6}",
            r.passes,
            r.ms_per_step,
            c.launches,
            c.reads,
            c.uploads,
            c.bytes_up as f64 / 1024.0,
            c.renders,
            c.pairs as f64 / 1e3,
            c.rows as f64 / 1e3,
            r.best_total
        );
    }
    for r in rows {
        let stages: Vec<String> = r
            .stages_ms
            .iter()
            .map(|(name, ms)| format!("{name} {ms:.1}"))
            .collect();
        let _ = writeln!(
            out,
            "{} ms a step by stage: {}",
            r.passes,
            stages.join(", ")
        );
    }
    for r in rows.iter().filter(|r| !r.launch_names.is_empty()) {
        let top: Vec<String> = r
            .launch_names
            .iter()
            .take(8)
            .map(|(name, n)| format!("{n} {name}"))
            .collect();
        let _ = writeln!(out, "{} launches a step: {}", r.passes, top.join(", "));
    }
    out
}
