//! What a pass costs besides arithmetic: kernel launches, reads back to the host (each a wait
//! for the device on a GPU) and bytes moved each way, counted process-wide.
//!
//! On a GPU these counts, not the arithmetic, set the floor of a small pass: a launch costs a
//! few microseconds whatever it computes, and a read waits for everything queued before it.
//! So they are counted, not guessed: `bench render --json` reports them per pass and
//! `RUST_LOG=splatraj_render=debug` per render, and tests hold them to what the design
//! promises (one read per optimisation step, launches that do not grow with the batch, a scene
//! uploaded once).
//!
//! - **Reads** are the reads splatraj's own code makes ([`crate::host::to_host`], the poses a
//!   render's host decisions need): on a GPU each one is a synchronisation. The host kernels
//!   of the CPU backends read their inputs in memory; that is not counted.
//! - **Uploads** are the host values splatraj sends per pass (poses, sample times, tile lists,
//!   indices, mask values); **scene uploads** count whole scenes ([`crate::render::DeviceScene`]).
//! - **Launches** are every kernel the GPU backend issues, burn's own ops included, counted by
//!   CubeCL's launch observer ([`watch_launches`]); zero on the CPU backends, which launch none.
//!
//! A process-wide tally because passes run deep inside loops that should not thread a counter
//! through; read it as the difference of two [`snapshot`]s around the work to measure, on a
//! process doing nothing else (tests that count run in their own test binary).

use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};

/// Counts since the process started (or between two snapshots, by [`Counts::since`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Kernel launches on a GPU backend (0 on the CPU backends).
    pub launches: u64,
    /// Reads back to the host.
    pub reads: u64,
    /// Bytes read back.
    pub bytes_down: u64,
    /// Uploads of per-pass values.
    pub uploads: u64,
    /// Bytes uploaded.
    pub bytes_up: u64,
    /// Whole scenes uploaded.
    pub scene_uploads: u64,
    /// Render passes ([`crate::render::render_at`] calls): an optimisation step makes one,
    /// whatever its windows.
    #[serde(default)]
    pub renders: u64,
    /// Tile–Gaussian pairs composited: the compositing's work.
    #[serde(default)]
    pub pairs: u64,
    /// Packed rows projected and handed to compositing (each pose's Gaussians, summed over
    /// the poses, [`crate::rows`]): the host copies, footprints and gradients of a pass grow
    /// with it.
    #[serde(default)]
    pub rows: u64,
    /// Work items of the GPU compositing forwards (a workgroup each): a work tile, or a
    /// segment of a long tile list where a backward follows (`fused/segments.rs`); 0 on the
    /// CPU backends, whose host kernels take whole lists.
    #[serde(default)]
    pub segments: u64,
}

impl Counts {
    /// Each count divided by `passes` (rounded down): per pass, over a run of equal passes.
    pub fn per(&self, passes: u64) -> Counts {
        let p = passes.max(1);
        Counts {
            launches: self.launches / p,
            reads: self.reads / p,
            bytes_down: self.bytes_down / p,
            uploads: self.uploads / p,
            bytes_up: self.bytes_up / p,
            scene_uploads: self.scene_uploads / p,
            renders: self.renders / p,
            pairs: self.pairs / p,
            rows: self.rows / p,
            segments: self.segments / p,
        }
    }

    /// What happened between `earlier` and `self`.
    pub fn since(&self, earlier: &Counts) -> Counts {
        Counts {
            launches: self.launches - earlier.launches,
            reads: self.reads - earlier.reads,
            bytes_down: self.bytes_down - earlier.bytes_down,
            uploads: self.uploads - earlier.uploads,
            bytes_up: self.bytes_up - earlier.bytes_up,
            scene_uploads: self.scene_uploads - earlier.scene_uploads,
            renders: self.renders - earlier.renders,
            pairs: self.pairs - earlier.pairs,
            rows: self.rows - earlier.rows,
            segments: self.segments - earlier.segments,
        }
    }
}

static LAUNCHES: AtomicU64 = AtomicU64::new(0);
static READS: AtomicU64 = AtomicU64::new(0);
static BYTES_DOWN: AtomicU64 = AtomicU64::new(0);
static UPLOADS: AtomicU64 = AtomicU64::new(0);
static BYTES_UP: AtomicU64 = AtomicU64::new(0);
static SCENE_UPLOADS: AtomicU64 = AtomicU64::new(0);
static RENDERS: AtomicU64 = AtomicU64::new(0);
static PAIRS: AtomicU64 = AtomicU64::new(0);
static ROWS: AtomicU64 = AtomicU64::new(0);
static SEGMENTS: AtomicU64 = AtomicU64::new(0);

/// The counts so far.
pub fn snapshot() -> Counts {
    let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
    Counts {
        launches: load(&LAUNCHES),
        reads: load(&READS),
        bytes_down: load(&BYTES_DOWN),
        uploads: load(&UPLOADS),
        bytes_up: load(&BYTES_UP),
        scene_uploads: load(&SCENE_UPLOADS),
        renders: load(&RENDERS),
        pairs: load(&PAIRS),
        rows: load(&ROWS),
        segments: load(&SEGMENTS),
    }
}

/// A read of `bytes` back to the host.
pub fn read(bytes: usize) {
    READS.fetch_add(1, Ordering::Relaxed);
    BYTES_DOWN.fetch_add(bytes as u64, Ordering::Relaxed);
}

/// An upload of `bytes` of per-pass values.
pub fn upload(bytes: usize) {
    UPLOADS.fetch_add(1, Ordering::Relaxed);
    BYTES_UP.fetch_add(bytes as u64, Ordering::Relaxed);
    tracing::trace!(bytes, "upload");
}

/// A render pass.
pub fn render() {
    RENDERS.fetch_add(1, Ordering::Relaxed);
}

/// A pass's compositing work: `pairs` tile–Gaussian pairs over `rows` packed rows.
pub fn composite(pairs: usize, rows: usize) {
    PAIRS.fetch_add(pairs as u64, Ordering::Relaxed);
    ROWS.fetch_add(rows as u64, Ordering::Relaxed);
}

/// A GPU compositing forward working in `segments` workgroups.
pub fn segments(segments: usize) {
    SEGMENTS.fetch_add(segments as u64, Ordering::Relaxed);
}

/// A whole scene of `bytes` uploaded.
pub fn scene_upload(bytes: usize) {
    SCENE_UPLOADS.fetch_add(1, Ordering::Relaxed);
    upload(bytes);
}

/// Counts every kernel the GPU backend launches from now on (idempotent; a relaxed atomic
/// increment per launch). Called when a wgpu device is first made; without the `wgpu`
/// feature there is nothing to watch.
pub fn watch_launches() {
    #[cfg(feature = "wgpu")]
    gpu::watch();
}

/// Also tallies the launches by kernel name from now on (a lock per launch: for `bench` and
/// diagnosis, not for runs), or stops and forgets the tally.
pub fn tally_launch_names(on: bool) {
    let mut names = NAMES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    *names = on.then(std::collections::HashMap::new);
    TALLYING.store(on, Ordering::Relaxed);
}

/// The launches by kernel name since [`tally_launch_names`] was turned on, most first.
pub fn launch_names() -> Vec<(String, u64)> {
    let names = NAMES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    // Kernels that differ only in their generic arguments count as one.
    let mut merged = std::collections::BTreeMap::<String, u64>::new();
    for (name, &count) in names.iter().flatten() {
        *merged.entry(short_kernel_name(name)).or_default() += count;
    }
    let mut out: Vec<(String, u64)> = merged.into_iter().collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    out
}

/// A kernel's name without its module path and generic arguments.
fn short_kernel_name(name: &str) -> String {
    let base = name.split('<').next().unwrap_or(name);
    base.rsplit("::").next().unwrap_or(base).to_string()
}

/// Whether [`NAMES`] is on: checked before taking its lock, so that an ordinary run's launches
/// cost one relaxed atomic increment and load, no lock.
static TALLYING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

static NAMES: std::sync::Mutex<Option<std::collections::HashMap<&'static str, u64>>> =
    std::sync::Mutex::new(None);

/// Records one launch of `kernel`.
#[cfg_attr(not(feature = "wgpu"), allow(dead_code))]
fn launched(kernel: &'static str) {
    LAUNCHES.fetch_add(1, Ordering::Relaxed);
    // Each launch in order (`RUST_LOG=splatraj_render::counters=trace`): where a pass's
    // launches come from, which the tallies by name do not say (docs/gpu.md).
    tracing::trace!(kernel = short_kernel_name(kernel), "launch");
    if !TALLYING.load(Ordering::Relaxed) {
        return;
    }
    let mut names = NAMES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(names) = names.as_mut() {
        *names.entry(kernel).or_default() += 1;
    }
}

#[cfg(feature = "wgpu")]
mod gpu {
    use std::sync::{Arc, OnceLock};

    use burn_cubecl::cubecl::logging::{LaunchObservation, LaunchObserver};

    struct CountLaunches;

    impl LaunchObserver for CountLaunches {
        fn launched(&self, kernel: &'static str) {
            super::launched(kernel);
        }
    }

    /// The observation lives as long as the process: CubeCL keeps one observer slot.
    static WATCHING: OnceLock<LaunchObservation> = OnceLock::new();

    pub(super) fn watch() {
        WATCHING.get_or_init(|| LaunchObservation::new(Arc::new(CountLaunches)));
    }
}
