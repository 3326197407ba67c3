//! `splatraj report RUN_DIR [--scene FILE]`: rebuilds a run folder's `report.html` from its
//! files, with the scene's points under the path views (the scene its `config.toml` names,
//! found as `run_scene` says, or `--scene`). The work is the library's
//! ([`splatraj::experiment::outputs::run_report`], as at the end of `splatraj run`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::outputs::run_report::{run_scene, write_run_report};

use crate::cli::ReadArgs;

/// Arguments of `splatraj report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The run folder.
    run: PathBuf,
    /// The run's scene, when the file its config names cannot be found from here.
    #[arg(long)]
    scene: Option<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
}

/// Runs `splatraj report`.
pub fn run(args: ReportArgs) -> Result<()> {
    if !args.run.is_dir() {
        anyhow::bail!("{} is not a run folder", args.run.display());
    }
    let scene = match &args.scene {
        Some(path) => args.read.load_to_render(path)?.scene,
        None => run_scene(&args.run)?,
    };
    let path = write_run_report(&args.run, Some(&scene))?;
    println!("{}", path.display());
    Ok(())
}
