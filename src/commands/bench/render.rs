//! `splatraj bench render`: the mask pass timed per configuration, each in a child process
//! (hidden `--one`).

use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use splatraj::experiment::bench::{
    BenchConfig, BenchSettings, RenderBenchGrid, run_one, run_render_bench,
};
use splatraj_render::backend::BackendKind;
use splatraj_render::render::Rasterizer;

use super::FramingArgs;
use crate::cli::DtypeArg;

/// Arguments of `splatraj bench render`.
#[derive(Debug, Args)]
pub struct BenchRenderArgs {
    /// Also benchmark this real scene (the object is a sphere of Gaussians around its centre).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Demo scene sizes, in Gaussians.
    #[arg(long, value_delimiter = ',', default_values_t = [10_000usize, 100_000, 300_000])]
    sizes: Vec<usize>,
    /// Skip the demo scenes (with --scene: benchmark the real scene only).
    #[arg(long)]
    no_demo: bool,
    /// Square image sizes, in pixels.
    #[arg(long, value_delimiter = ',', default_values_t = [64usize, 128, 256])]
    resolutions: Vec<usize>,
    /// Timed runs per measurement (the median is reported), after one untimed warm-up.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Threads of the rayon pool the passes run in (default: rayon's choice, one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// Tensor backend, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Float precision.
    #[arg(long, value_enum, default_value_t = DtypeArg::F32)]
    dtype: DtypeArg,
    /// Rasterizers to time on every configuration (fused, tensor).
    #[arg(long, value_delimiter = ',', default_values = ["fused", "tensor"], value_parser = Rasterizer::from_str)]
    rasterizer: Vec<Rasterizer>,
    #[command(flatten)]
    framing: FramingArgs,
    /// Run every configuration, including unpruned 256² renders of demo scenes above 300k
    /// Gaussians (skipped by default as slow).
    #[arg(long)]
    all: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Internal: run one configuration (`demo:N:RES:PRUNING:RASTERIZER` or
    /// `scene:RES:PRUNING:RASTERIZER`) in this process and print its result as one JSON line.
    #[arg(long, hide = true)]
    one: Option<String>,
}

/// Runs `bench render`: every configuration in a child process, or (`--one`) the one this
/// child was given.
pub(super) fn run(args: &BenchRenderArgs) -> Result<()> {
    let bench = || match &args.one {
        Some(spec) => {
            // A child of `bench render`: it must not outlive its parent.
            splatraj::experiment::children::exit_with_parent();
            let row = run_one(&settings(args), &BenchConfig::parse(spec)?)?;
            println!("{}", serde_json::to_string(&row)?);
            Ok(())
        }
        None => run_all(args),
    };
    // `None`: already on a worker of the global pool (`main`).
    splatraj::experiment::bench::in_thread_pool(args.threads, crate::cli::WORKER_STACK_BYTES, bench)
}

/// What every configuration shares, from the arguments.
fn settings(args: &BenchRenderArgs) -> BenchSettings {
    BenchSettings {
        backend: args.backend,
        dtype: args.dtype.precision().dtype(),
        repeats: args.repeats,
        object: args.framing.object.clone(),
        target_ratio: args.framing.target_ratio,
        fov: args.framing.fov,
        scene: args.scene.clone(),
    }
}

fn run_all(args: &BenchRenderArgs) -> Result<()> {
    let grid = RenderBenchGrid {
        sizes: if args.no_demo {
            Vec::new()
        } else {
            args.sizes.clone()
        },
        resolutions: args.resolutions.clone(),
        rasterizers: args.rasterizer.clone(),
        threads: args.threads,
        all: args.all,
    };
    let exe = std::env::current_exe().context("cannot find the splatraj binary to re-run")?;
    let started = Instant::now();
    let (report, failures) = run_render_bench(&exe, &settings(args), &grid, &mut |event| {
        eprintln!("{event}")
    })?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
        println!(
            "cpu/wall: CPU time over wall time of the timed runs (about the cores kept busy); \
             burn's flex backend runs kernels on rayon only when burn is built with its `rayon` \
             feature, while tile binning always uses the rayon pool.\ntotal {:.1} s",
            started.elapsed().as_secs_f64()
        );
    }
    if !failures.is_empty() {
        bail!(
            "{} configuration(s) failed: {}",
            failures.len(),
            failures.join("; ")
        );
    }
    Ok(())
}
