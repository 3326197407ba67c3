//! `splatraj scene views`: the page of views where a click picks a part (the library's
//! `write_views_page`).

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::Result;
use splatraj::experiment::picking::query::parse_direction;
use splatraj::experiment::picking::views_page::{
    ViewsPageOptions, ViewsPageRequest, write_views_page,
};
use splatraj_render::backend::BackendKind;

use super::{stage_bar, warn_dropped};
use crate::cli::{MemoryArgs, ReadArgs};

/// Arguments of `scene views`.
#[derive(Debug, clap::Args)]
pub struct ViewsArgs {
    /// Scene file (INRIA PLY, compressed PLY, SPZ, SOG …).
    scene: PathBuf,
    /// The page to write (HTML; written whole or not at all).
    #[arg(long, default_value = "views.html")]
    out: PathBuf,
    /// Views to render (the planner may keep fewer when fewer show something).
    #[arg(long, default_value_t = ViewsPageOptions::default().views)]
    views: usize,
    /// Side of each square view, pixels.
    #[arg(long, default_value_t = ViewsPageOptions::default().size)]
    size: usize,
    /// World up of the scene, `X,Y,Z` (e.g. `0,-1,0` for y-down captures); by default guessed.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    up: Option<String>,
    /// Most Gaussian centres the page carries to count what a ball holds; beyond, an even
    /// sample, and the counts are estimates scaled from it (the page says so).
    #[arg(long, default_value_t = ViewsPageOptions::default().max_centres)]
    max_centres: usize,
    /// Tensor backend: flex (CPU), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    #[command(flatten)]
    read: ReadArgs,
    #[command(flatten)]
    memory: MemoryArgs,
}

/// `scene views`: parses, writes the page with the library, prints a summary.
pub fn run(args: ViewsArgs) -> Result<()> {
    let request = ViewsPageRequest {
        options: ViewsPageOptions {
            views: args.views,
            size: args.size,
            up: args
                .up
                .as_deref()
                .map(|up| parse_direction(up, "--up"))
                .transpose()?,
            max_centres: args.max_centres,
            ..ViewsPageOptions::default()
        },
        read: args.read.options(),
        scene: args.scene,
        out: args.out,
        max_memory_gb: args.memory.max_memory,
    };
    let device = args.backend.device()?;
    let (bar, progress) = stage_bar();
    let written = write_views_page(&request, &device, &progress)?;
    bar.finish_and_clear();
    warn_dropped(&request.scene, written.dropped);
    for line in written.summary(&request.out) {
        eprintln!("{line}");
    }
    Ok(())
}
