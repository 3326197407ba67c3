//! What the commands share on the command line: scene-reading flags, the progress bar and
//! the Ctrl-C flag. (Pipeline work lives in the library crates; commands do not import each
//! other.)

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use splatraj::experiment::optimise::observer::{Flow, Observer, Progress};
use splatraj_scene::{InvalidPolicy, ReadOptions};

/// Options shared by the subcommands that read a scene.
#[derive(Debug, Args)]
pub struct ReadArgs {
    /// Ground-truth label sidecar (SuperSplat/Segments.ai JSON, or a JSON array of ids).
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Drop Gaussians with invalid values (NaN, zero scale, zero quaternion) with a warning,
    /// instead of stopping with an error.
    #[arg(long)]
    drop_invalid: bool,
}

/// What `--drop-invalid` asks for: drop invalid Gaussians with a warning, or stop with an error.
pub fn invalid_policy(drop_invalid: bool) -> InvalidPolicy {
    if drop_invalid {
        InvalidPolicy::Drop
    } else {
        InvalidPolicy::Reject
    }
}

impl ReadArgs {
    /// The scene reader's options these flags ask for.
    pub fn options(&self) -> ReadOptions {
        ReadOptions {
            invalid: invalid_policy(self.drop_invalid),
            labels: self.labels.clone(),
        }
    }
}

/// Set by the first Ctrl-C or SIGTERM ([`install_stop_handler`]).
static INTERRUPTED: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// Set by Ctrl-C (or SIGTERM): an observer that reads it stops the optimisation at the end of
/// the current step, once the library honours stop requests ([`splatraj_scene::stop::honour`],
/// from the moment its run folder exists).
pub fn interrupt_flag() -> Arc<AtomicBool> {
    INTERRUPTED
        .get_or_init(|| Arc::new(AtomicBool::new(false)))
        .clone()
}

/// Installs the one signal handler of the process (`main`, before any command). The first
/// Ctrl-C or SIGTERM sets [`interrupt_flag`] and asks every loop of the library to stop at its
/// next whole step ([`splatraj_scene::stop`]: optimisation steps, frames, study runs,
/// benchmark children); a second one quits at once, after removing the temporary files of
/// writes in progress (files already written are whole, the others are not there; a run's
/// checkpoint keeps its best trajectory).
/// Work that does not check for requests ([`splatraj_scene::stop::honour`]) ends at the first.
pub fn install_stop_handler() {
    let flag = interrupt_flag();
    let on_signal = move || {
        if flag.swap(true, Ordering::SeqCst) || !splatraj_scene::stop::honoured() {
            splatraj_scene::atomic::remove_partial_files_and_exit(EXIT_INTERRUPTED.into());
        }
        splatraj_scene::stop::request();
    };
    if let Err(e) = ctrlc::set_handler(on_signal) {
        tracing::warn!("Ctrl-C will not stop the work cleanly: {e}");
    }
}

/// Checks `RAYON_NUM_THREADS` before the worker threads start: a value that is not a number
/// is refused (rayon would ignore it silently), and a count whose stacks cannot fit the memory
/// limit too (rayon would start them until the system refuses one, and abort).
pub fn check_worker_threads() -> anyhow::Result<()> {
    let Some(value) = std::env::var_os("RAYON_NUM_THREADS") else {
        return Ok(());
    };
    let text = value.to_string_lossy();
    let threads: usize = text.trim().parse().map_err(|_| {
        anyhow::anyhow!(
            "the environment variable RAYON_NUM_THREADS = {text:?} is not a thread count (a \
             whole number; 0 or unset: one per core)"
        )
    })?;
    splatraj_experiment::resources::check_threads("RAYON_NUM_THREADS", threads)
}

/// Exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells expect).
pub const EXIT_INTERRUPTED: u8 = 130;

/// Stack of each rayon worker: commands run on one (`main`), so it gets a main thread's usual
/// 8 MiB rather than rayon's 2 MiB default.
pub const WORKER_STACK_BYTES: usize = 8 << 20;

/// Exit status of a run that finished and wrote its folder, but whose verdict failed on some
/// window (an object not shown as asked: docs/first-try.md). 1 stays "error", 130 "stopped".
pub const EXIT_VERDICT: u8 = 3;

/// How a command that wrote whole files still ends with a status of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// Stopped by Ctrl-C after writing what it had ([`EXIT_INTERRUPTED`]).
    Interrupted,
    /// A run whose folder is whole but whose verdict failed ([`EXIT_VERDICT`]).
    VerdictFailed,
}

/// A command that ends with [`Ending`]'s status: `main` prints the message and exits with it.
#[derive(Debug)]
pub struct Ended {
    /// How it ended.
    pub how: Ending,
    /// What to tell the user.
    pub message: String,
}

impl Ended {
    /// Stopped by Ctrl-C.
    pub fn interrupted(message: String) -> Self {
        Self {
            how: Ending::Interrupted,
            message,
        }
    }

    /// The verdict failed.
    pub fn verdict_failed(message: String) -> Self {
        Self {
            how: Ending::VerdictFailed,
            message,
        }
    }

    /// The process's exit status.
    pub fn status(&self) -> u8 {
        match self.how {
            Ending::Interrupted => EXIT_INTERRUPTED,
            Ending::VerdictFailed => EXIT_VERDICT,
        }
    }
}

impl std::fmt::Display for Ended {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Ended {}

/// `--max-memory GB` of the commands that render or optimise.
#[derive(Debug, Args)]
pub struct MemoryArgs {
    /// The most memory (GB) the work may plan to use; sizes whose estimated peak is above are
    /// refused before any work (default: `max_memory_gb` of the config, else 75 % of RAM).
    #[arg(long, value_name = "GB")]
    pub max_memory: Option<f64>,
}

impl MemoryArgs {
    /// The config's `max_memory_gb` it sets (none when not given); errors name the option
    /// when the value is not a positive number.
    pub fn max_memory_gb(&self) -> anyhow::Result<Option<f64>> {
        match self.max_memory {
            Some(gb) if !(gb.is_finite() && gb > 0.0) => {
                anyhow::bail!("--max-memory {gb} must be a finite number of GB > 0")
            }
            gb => Ok(gb),
        }
    }
}

/// A progress bar on stderr (hidden when `quiet` or when stderr is not a terminal).
pub fn progress_bar(len: u64, quiet: bool) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if quiet {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise} < {eta_precise}] {bar:30} {pos}/{len} {msg}",
        )
        .expect("valid template"),
    );
    bar
}

/// Draws the phases of building a lifted field (choosing views, rendering and encoding views,
/// lifting) as one progress bar each on stderr, for every lift the command starts (a `lifted`
/// source is built from a config, so it cannot be handed a bar directly).
pub fn install_lift_progress() {
    use splatraj::lift::LiftStage;
    // One bar per phase: planning, rendering, encoding and lifting follow each other.
    let current: Mutex<Option<(LiftStage, ProgressBar)>> = Mutex::new(None);
    splatraj::lift::progress::install(Arc::new(move |stage, done, total| {
        let mut current = current.lock().unwrap_or_else(|e| e.into_inner());
        if current.as_ref().map(|c| c.0) != Some(stage) {
            if let Some((_, bar)) = current.take() {
                bar.finish();
            }
            let bar = progress_bar(total as u64, false);
            bar.set_message(stage.name());
            *current = Some((stage, bar));
        }
        if let Some((_, bar)) = current.as_ref() {
            // Views are encoded two at a time: never draw the bar backwards.
            bar.set_position(bar.position().max(done as u64));
            if done >= total {
                bar.finish();
            }
        }
    }));
}

/// An observer that draws `bar` and stops once Ctrl-C set `interrupted`.
pub fn bar_observer(bar: &ProgressBar, interrupted: Arc<AtomicBool>) -> impl Observer + '_ {
    move |p: &Progress| {
        match *p {
            Progress::Trajectory {
                restart,
                restarts,
                step,
                steps,
                total,
                best,
            } => {
                bar.set_position((restart * steps + step + 1) as u64);
                bar.set_message(format!(
                    "start {}/{restarts}  cost {total:.4}  best {best:.4}",
                    restart + 1
                ));
            }
            Progress::Pose { step, best, .. } => {
                bar.set_position(step as u64 + 1);
                bar.set_message(format!("best {best:.4}"));
            }
            Progress::Frame { done, .. } => bar.set_position(done as u64),
            // Each command draws its phases its own way.
            Progress::Phase(_) => {}
        }
        if interrupted.load(Ordering::SeqCst) {
            Flow::Stop
        } else {
            Flow::Continue
        }
    }
}

/// Float precision on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DtypeArg {
    /// 32-bit floats.
    F32,
    /// 64-bit floats (CPU backends).
    F64,
}

impl DtypeArg {
    /// The render precision.
    pub fn precision(self) -> splatraj_render::backend::Precision {
        match self {
            DtypeArg::F32 => splatraj_render::backend::Precision::F32,
            DtypeArg::F64 => splatraj_render::backend::Precision::F64,
        }
    }
}
