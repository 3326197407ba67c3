//! `splatraj bench scale` and `bench first-try`: whole configs run with `splatraj run` in child
//! processes; the runs and their figures are the library's, this parses and prints.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;

/// Arguments of `splatraj bench scale`.
#[derive(Debug, Args)]
pub struct BenchScaleArgs {
    /// Config to run; its scene must be the demo's (`[scene] demo = …`).
    #[arg(long, default_value = "configs/demo.toml")]
    config: PathBuf,
    /// Demo scene sizes, in Gaussians.
    #[arg(long, value_delimiter = ',', default_values_t = [1_000_000usize, 3_000_000, 6_000_000, 10_000_000])]
    sizes: Vec<usize>,
    /// Optimisation steps per run (0: the config's own).
    #[arg(long, default_value_t = 10)]
    iterations: usize,
    #[command(flatten)]
    runs: ChildRunArgs,
}

/// What the benches that run whole configs (`splatraj run` in child processes) share.
#[derive(Debug, Args)]
pub struct ChildRunArgs {
    /// Override a config value in every run, e.g. `--set output.width=320` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Folder of the run folders (default: a fresh one under the system's temporary folder).
    #[arg(long)]
    runs_dir: Option<PathBuf>,
    /// Print one JSON array instead of a table.
    #[arg(long)]
    json: bool,
}

impl ChildRunArgs {
    /// `--runs-dir`, or a fresh folder named `splatraj-{bench}-{pid}` in the temporary folder.
    fn runs_dir(&self, bench: &str) -> PathBuf {
        self.runs_dir.clone().unwrap_or_else(|| {
            std::env::temp_dir().join(format!("splatraj-{bench}-{}", std::process::id()))
        })
    }
}

/// `splatraj bench scale`: the runs and their figures are the library's
/// (`splatraj::experiment::bench::scale`); this prints them.
pub(super) fn scale(args: &BenchScaleArgs) -> Result<()> {
    use splatraj::experiment::bench::scale::{ScaleBench, run_scale, scale_table};
    let bench = ScaleBench {
        config: args.config.clone(),
        sizes: args.sizes.clone(),
        iterations: (args.iterations > 0).then_some(args.iterations),
        set: args.runs.set.clone(),
        runs_dir: args.runs.runs_dir("scale"),
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let (rows, failures) = run_scale(&exe, &bench, &mut |size| {
        eprintln!("running {} at {size} Gaussians …", bench.config.display())
    })?;
    if args.runs.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print!("{}", scale_table(&rows));
        println!("run folders: {}", bench.runs_dir.display());
    }
    if !failures.is_empty() {
        bail!("{} size(s) failed: {}", failures.len(), failures.join("; "));
    }
    Ok(())
}

/// Arguments of `splatraj bench first-try`.
#[derive(Debug, Args)]
pub struct BenchFirstTryArgs {
    /// Configs to run (default: every `.toml` in `configs/first-try/`).
    configs: Vec<PathBuf>,
    #[command(flatten)]
    runs: ChildRunArgs,
}

/// `splatraj bench first-try`: the runs and their figures are the library's
/// (`splatraj::experiment::bench::quality`); this prints them.
pub(super) fn first_try(args: &BenchFirstTryArgs) -> Result<()> {
    use splatraj::experiment::bench::quality::{
        FIRST_TRY_CONFIGS, FirstTryBench, configs_in, quality_table, run_first_try,
    };
    let bench = FirstTryBench {
        configs: if args.configs.is_empty() {
            configs_in(std::path::Path::new(FIRST_TRY_CONFIGS))?
        } else {
            args.configs.clone()
        },
        set: args.runs.set.clone(),
        runs_dir: args.runs.runs_dir("first-try"),
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let runs = run_first_try(&exe, &bench, &mut |config| {
        eprintln!("running {} …", config.display())
    })?;
    if args.runs.json {
        println!("{}", serde_json::to_string_pretty(&runs)?);
    } else {
        print!("{}", quality_table(&runs));
        println!("run folders: {}", bench.runs_dir.display());
    }
    Ok(())
}

/// Arguments of `splatraj bench step`.
#[derive(Debug, Args)]
pub struct BenchStepArgs {
    /// Config whose optimisation step is measured (its backend, scene, windows and costs).
    #[arg(long, default_value = "configs/demo.toml")]
    config: PathBuf,
    /// Steps timed per variant (after one untimed step).
    #[arg(long, default_value_t = 10)]
    steps: usize,
    /// Override a config value, e.g. `--set backend="wgpu"` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Print one JSON array instead of a table.
    #[arg(long)]
    json: bool,
}

/// `splatraj bench step`: the steps and their counts are the library's
/// (`splatraj::experiment::bench::step`); this prints them.
pub(super) fn step(args: &BenchStepArgs) -> Result<()> {
    use splatraj::experiment::bench::step::{run_step_bench, step_table};
    let rows = run_step_bench(&args.config, &args.set, args.steps)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print!("{}", step_table(&rows));
    }
    Ok(())
}
