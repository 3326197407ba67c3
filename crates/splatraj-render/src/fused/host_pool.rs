//! The host work of the GPU ops (the lists and row tables converted for upload, the backward's
//! slots ordered by row, the host kernels of an f64 pass) on a rayon pool of its own.
//!
//! burn's fusion backend runs a queued op later, on its device thread, while the thread that
//! queued it waits for that device thread (a read, a flush). The command runs on a worker of
//! rayon's global pool (`src/main.rs`), so with one worker (`RAYON_NUM_THREADS=1`, a one-core
//! machine) a parallel loop the device thread handed to the global pool waited for the only
//! worker, which waited for the device thread: the process hung at its first mask pass. The
//! pool here never waits for burn's fusion, so its workers are always free for the device
//! thread.

use std::sync::OnceLock;

use rayon::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};

/// Runs `work` (which may use rayon's parallel iterators) on the pool for the device thread's
/// host work, as many threads as the global pool has.
pub(crate) fn run<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    static POOL: OnceLock<Option<ThreadPool>> = OnceLock::new();
    let pool = POOL.get_or_init(|| {
        ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(|i| format!("splatraj-device-host-{i}"))
            .build()
            .ok()
    });
    match pool {
        Some(pool) => pool.install(work),
        // No threads could be started for it: the global pool then, which hangs only where its
        // every worker waits on the device.
        None => work(),
    }
}

/// `values` as the i32s the kernels index with, converted on [`run`]'s pool (a step's lists
/// hold about a million entries).
pub(crate) fn i32s(values: &[u32]) -> Vec<i32> {
    run(|| values.par_iter().map(|&v| v as i32).collect())
}
