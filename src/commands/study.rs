//! `splatraj study CONFIG.toml`: what accuracy costs in time. Runs variants of one experiment
//! (`--vary KEY=V1,V2`, the `[study]` table, `--preset table1|table2`, or the default sweep of
//! every accuracy-for-time knob), each measured the same way, and writes the study folder
//! (`study.csv`, `study.json`, `frontier.svg`, `summary.md`). `splatraj study merge DIR...`
//! joins the folders of `--shard K/N` runs into one study.
//!
//! Each run goes to a child process of this binary (hidden `--one RUN`), so that the peak
//! memory it reports (VmHWM, a process-wide high-water mark) is its own and no run's
//! allocations slow the next; `--in-process` runs them here instead (no memory figure). Before
//! the first run the plan is checked whole (`--dry-run` stops after the check). The plan, the
//! check, the measuring and the files are `splatraj::experiment::study`, one call each
//! (`run_study`, a child's `measure_one`, `merge_into`); this file parses, shows progress and
//! prints.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use splatraj::experiment::Extensions;
use splatraj::experiment::study::plan::PlanOptions;
use splatraj::experiment::study::{
    Factor, Preset, RunPlace, Shard, StudyEnd, StudyNews, StudyRequest, measure_one, merge_into,
    run_study,
};

/// Arguments of `splatraj study`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct StudyArgs {
    #[command(subcommand)]
    command: Option<StudyCommand>,
    #[command(flatten)]
    run: StudyRunArgs,
}

/// `splatraj study merge`.
#[derive(Debug, Subcommand)]
pub enum StudyCommand {
    /// Join the study folders of a study's shards (`--shard K/N`) into one study.
    Merge(MergeArgs),
}

/// Arguments of `splatraj study merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The shards' study folders.
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Folder of the merged study.
    #[arg(long)]
    out: PathBuf,
}

/// Arguments of a study run.
#[derive(Debug, Args)]
pub struct StudyRunArgs {
    /// Experiment config (TOML).
    config: Option<PathBuf>,
    /// Override a config value of every variant and of the evaluation (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// A factor: a config key and its values, e.g. `optimiser.iterations=50,100` or
    /// `camera={width=64,height=48},{width=256,height=192}` (repeatable; replaces `[study]`'s).
    #[arg(long, value_name = "KEY=V1,V2,...")]
    vary: Vec<String>,
    /// Every combination of the factors' values (default: one factor at a time).
    #[arg(long)]
    grid: bool,
    /// Repeats of every variant (seeds `seed`, `seed + 1`, …); starts of a single-pose study.
    #[arg(long)]
    seeds: Option<usize>,
    /// The paper's tables: table1 (single-pose ablations) or table2 (trajectory models).
    #[arg(long, value_parser = parse_preset)]
    preset: Option<Preset>,
    /// Run only the K-th of N slices of the runs (1-based), e.g. a Slurm array task.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    shard: Option<Shard>,
    /// Study folder (default: `<output.runs_dir>/<name>-study/<timestamp>/`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run every variant in this process (no per-run peak memory).
    #[arg(long)]
    in_process: bool,
    /// Print the plan (variants and runs), check it as the study checks it before its first
    /// run (every variant's config, scene, queries, memory and time; the evaluation's sizes;
    /// the study folder), and stop without running any.
    #[arg(long)]
    dry_run: bool,
    /// No progress lines.
    #[arg(long)]
    quiet: bool,
    /// Internal: run one run of the plan here and print its rows as one JSON line.
    #[arg(long, hide = true)]
    one: Option<usize>,
}

fn parse_preset(s: &str) -> Result<Preset, String> {
    s.parse()
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    s.parse()
}

/// Runs `splatraj study`.
pub fn run(args: StudyArgs) -> Result<()> {
    match args.command {
        Some(StudyCommand::Merge(merge)) => run_merge(&merge),
        None => run_study_command(&args.run),
    }
}

fn run_merge(args: &MergeArgs) -> Result<()> {
    let dirs: Vec<&Path> = args.dirs.iter().map(PathBuf::as_path).collect();
    let study = merge_into(&dirs, &args.out)?;
    eprintln!("{}", study.merged_line(dirs.len()));
    println!("{}", args.out.display());
    Ok(())
}

fn plan_options(args: &StudyRunArgs) -> Result<PlanOptions> {
    Ok(PlanOptions {
        set: args.set.clone(),
        vary: args
            .vary
            .iter()
            .map(|v| Factor::parse(v))
            .collect::<Result<_>>()?,
        grid: args.grid,
        seeds: args.seeds,
        preset: args.preset,
    })
}

fn run_study_command(args: &StudyRunArgs) -> Result<()> {
    let Some(config) = &args.config else {
        bail!("give a config file (splatraj study CONFIG.toml), or `splatraj study merge DIR...`");
    };
    let extensions = Extensions::default();
    let options = plan_options(args)?;
    if let Some(index) = args.one {
        let rows = measure_one(config, &options, index, &extensions)?;
        println!("{}", serde_json::to_string(&rows)?);
        return Ok(());
    }
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let request = StudyRequest {
        config,
        options: &options,
        shard: args.shard,
        out: args.out.as_deref(),
        place: if args.in_process {
            RunPlace::InProcess
        } else {
            RunPlace::Child { exe: &exe }
        },
    };
    let mut tell = |news: StudyNews<'_>| match news {
        StudyNews::Line(line) | StudyNews::Failed(line) => eprintln!("{line}"),
        StudyNews::Row(line) if !args.quiet => eprintln!("{line}"),
        StudyNews::Row(_) => {}
    };
    let outcome = match run_study(
        &request,
        args.dry_run,
        &extensions,
        std::env::args(),
        &mut tell,
    )? {
        StudyEnd::Checked => return Ok(()),
        StudyEnd::Conducted(outcome) => outcome,
    };
    let (dir, study) = (&outcome.dir, &outcome.study);
    if let Some(line) = study.cheapest_line() {
        eprintln!("{line}");
    }
    println!("{}", dir.display());
    let failed = study.failures.len();
    if failed > 0 {
        bail!(
            "{failed} run(s) failed (listed in {})",
            dir.join("summary.md").display()
        );
    }
    Ok(())
}
