//! `splatraj report RUN_DIR [--scene FILE]`: rebuilds a run folder's `report.html` from its
//! files, with the scene's points under the path views (the scene its `config.toml` names,
//! found as `run_scene` says, or `--scene`). The work is the library's, one call
//! ([`splatraj::experiment::outputs::run_report::rebuild_run_report`], the report as at the end
//! of `splatraj run`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use splatraj::experiment::outputs::run_report::rebuild_run_report;

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
    let read = args.read.options();
    let scene = args.scene.as_deref().map(|path| (path, &read));
    let rebuilt = rebuild_run_report(&args.run, scene)?;
    if let (Some(path), dropped @ 1..) = (&args.scene, rebuilt.dropped) {
        eprintln!(
            "warning: {}: dropped {dropped} invalid Gaussians",
            path.display()
        );
    }
    println!("{}", rebuilt.path.display());
    Ok(())
}
