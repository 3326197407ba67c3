//! The `splatraj` command line.

mod cli;
mod commands;

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use splatraj_scene::allocation::ReportingAllocator;

/// Every burn tensor op allocates a fresh buffer. glibc's allocator hands large freed buffers
/// back to the OS and the next op faults them in again, zeroed: on a 150k-Gaussian mask pass
/// that was two thirds of the projection's time (`bench render`'s stage table: 16.8 → 5.8 ms,
/// fwd + bwd 111 → 95 ms on one thread) for about 50 MB more resident memory. mimalloc (a
/// maintained allocator, C built by its crate) keeps and reuses them. Only the binary sets it:
/// programs using the library choose their own allocator.
/// Wrapped so that a refused allocation ends with a message and status 1, not an abort
/// ([`splatraj_scene::allocation`]).
#[global_allocator]
static ALLOCATOR: ReportingAllocator<mimalloc::MiMalloc> = ReportingAllocator(mimalloc::MiMalloc);

// mimalloc's C API (in the library its crate builds; the crate declares it only behind a
// feature that needs one more dependency).
unsafe extern "C" {
    fn mi_option_set(option: std::ffi::c_int, value: std::ffi::c_long);
}

/// `mi_option_purge_delay` (position 15 of `mi_option_e` in mimalloc 2 and 3).
const MI_OPTION_PURGE_DELAY: std::ffi::c_int = 15;

/// Tells mimalloc to keep the memory freed buffers held instead of handing it back to the OS
/// ("purging" it) 10–100 ms later. Left on, a 6 M-Gaussian demo run purged 29 GiB in 10
/// steps and faulted it in again zeroed: a perf profile put 23 % of a step in the kernel's page
/// clearing, and a step took 4.3 s against 3.3 s without purging (peak resident memory 4.3
/// against 5.1 GiB: freed memory stays resident until reused). A longer delay (1 s) purged as
/// much.
fn keep_freed_memory() {
    // SAFETY: a setter of one integer option, valid at any time (mimalloc reads it per purge).
    unsafe { mi_option_set(MI_OPTION_PURGE_DELAY, -1) }
}

/// Camera trajectories that show named objects in 3D Gaussian Splatting scenes.
#[derive(Debug, Parser)]
#[command(name = "splatraj", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Inspect, convert or generate scene files.
    #[command(subcommand)]
    Scene(commands::scene::SceneCommand),
    /// Render one camera of a scene: RGB and object mask, optionally costs and pose gradient.
    Render(commands::render::RenderArgs),
    /// Show what a query selects (labels, region or language features) and picture it.
    Query(commands::query::QueryArgs),
    /// Optimise a camera trajectory showing each query in turn, and render it (TOML config).
    Run(commands::run::RunArgs),
    /// Optimise one camera pose framing one query (ablations, restarts, SGLD samples).
    Pose(commands::pose::PoseArgs),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(commands::bench::BenchCommand),
    /// Measure what accuracy costs in time: variants of one experiment, each optimised and
    /// judged by one fixed evaluation (`study merge` joins shards).
    Study(commands::study::StudyArgs),
    /// CLIP text embeddings of phrases, written as a phrase table (.safetensors or .json).
    EncodeText(commands::encode_text::EncodeTextArgs),
    /// Write a run's trajectory as another tool's camera file (nerfstudio, COLMAP, INRIA,
    /// SuperSplat).
    Export(commands::export::ExportArgs),
    /// Render any camera path (a run's trajectory.json, or a nerfstudio, COLMAP, INRIA or
    /// SuperSplat camera file) to frames and an MP4 video.
    RenderPath(commands::render_path::RenderPathArgs),
    /// Rebuild a run folder's report.html from its files.
    Report(commands::report::ReportArgs),
    /// List what this machine can compute on: the CPU's threads and wgpu's adapters, with the
    /// CUBECL_WGPU_DEFAULT_DEVICE value that picks each.
    Devices(commands::devices::DevicesArgs),
}

/// What the work planned, for the message of an allocation that fails anyway: the largest
/// stage of the last memory plan that passed.
fn planned_memory() -> String {
    let mut words = String::new();
    splatraj_experiment::resources::with_last_checked_peak(|peak| {
        if let Some((stage, limit)) = peak {
            words = format!(
                "The plan for this work estimated at most {} for {}, under the limit of {} \
                 ({}); this input needed more.",
                splatraj_experiment::resources::show_bytes(stage.bytes),
                stage.what,
                splatraj_experiment::resources::show_bytes(limit.bytes),
                limit.source_words()
            );
        }
    });
    words
}

fn main() -> ExitCode {
    keep_freed_memory();
    splatraj_scene::allocation::end_failed_allocations_cleanly(planned_memory);
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        // Colour codes only on a terminal: a redirected log stays plain text.
        .with_ansi(std::io::stderr().is_terminal())
        .without_time()
        .init();
    // A bug must still end with one readable paragraph, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("error: internal error (a bug in splatraj, please report it): {info}");
    }));

    let cli = Cli::parse();
    cli::install_lift_progress();
    cli::install_stop_handler();
    // Threads: RAYON_NUM_THREADS, else one per core (rayon's rule).
    if let Err(error) = cli::check_worker_threads() {
        eprintln!("error: {}", message(&error));
        return ExitCode::FAILURE;
    }
    if let Err(error) = rayon::ThreadPoolBuilder::new()
        .stack_size(cli::WORKER_STACK_BYTES)
        .build_global()
    {
        eprintln!("error: cannot start the worker threads: {error}");
        return ExitCode::FAILURE;
    }
    // The command runs on a worker of rayon's pool, not on the main thread: a parallel loop
    // started from outside the pool hands its work over and sleeps until a worker wakes it,
    // and a mask pass starts about twenty of them (decide, bin, the compositing kernels, burn's
    // ops). On the demo's pruned pass that was a tenth of the time on two threads.
    let result = rayon::scope(|_| match cli.command {
        Command::Scene(command) => commands::scene::run(command),
        Command::Render(args) => commands::render::run(args),
        Command::Query(args) => commands::query::run(args),
        Command::Run(args) => commands::run::run(args),
        Command::Pose(args) => commands::pose::run(args),
        Command::Bench(command) => commands::bench::run(command),
        Command::Study(args) => commands::study::run(args),
        Command::Export(args) => commands::export::run(args),
        Command::RenderPath(args) => commands::render_path::run(args),
        Command::Report(args) => commands::report::run(args),
        Command::EncodeText(args) => commands::encode_text::run(args),
        Command::Devices(args) => commands::devices::run(args),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            if let Some(ended) = error.downcast_ref::<cli::Ended>() {
                eprintln!("{ended}");
                ExitCode::from(ended.status())
            } else if let Some(stopped) = error.downcast_ref::<splatraj_scene::stop::Stopped>() {
                // Work cut short by Ctrl-C or SIGTERM: what was written is whole.
                eprintln!("{stopped}");
                ExitCode::from(cli::EXIT_INTERRUPTED)
            } else {
                eprintln!("error: {}", message(&error));
                ExitCode::FAILURE
            }
        }
    }
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message already
/// holds (an I/O error shown by the error that wraps it would otherwise print twice).
fn message(error: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in error.chain() {
        let cause = cause.to_string();
        if text.contains(&cause) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&cause);
    }
    text
}
