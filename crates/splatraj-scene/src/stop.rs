//! A process-wide request to stop, set by a signal handler (Ctrl-C, SIGTERM) and read by every
//! long loop at its next whole step: an optimisation step, a frame, a study run, a benchmark
//! configuration.
//!
//! Work that checks for requests says so first ([`honour`]); a signal handler ends work that
//! does not at once. It is process-wide because a signal is. Loops that must finish what an earlier request
//! asked for (a run stopped while optimising still writes its frames) compare
//! [`requests`] with the count when they began ([`Since`]), so only a request that came
//! during them stops them.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Stop requests so far.
static REQUESTS: AtomicU64 = AtomicU64::new(0);

/// Whether the work under way stops at a request ([`honour`]); otherwise a signal handler
/// should end the process at once.
static HONOURED: AtomicBool = AtomicBool::new(false);

/// Declares that the work from now on checks for stop requests at its boundaries (called by
/// each loop that does, before it starts).
pub fn honour() {
    HONOURED.store(true, Ordering::SeqCst);
}

/// Whether some loop declared that it stops at a request ([`honour`]).
pub fn honoured() -> bool {
    HONOURED.load(Ordering::SeqCst)
}

/// Asks every loop to stop at its next boundary (safe to call from a signal handler thread).
pub fn request() {
    REQUESTS.fetch_add(1, Ordering::SeqCst);
}

/// Stop requests so far.
pub fn requests() -> u64 {
    REQUESTS.load(Ordering::SeqCst)
}

/// Whether a stop was ever requested.
pub fn requested() -> bool {
    requests() > 0
}

/// The stop requests from a point on: a loop that began at [`Since::now`] stops when
/// [`Since::stopped`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Since(u64);

impl Since {
    /// From now.
    pub fn now() -> Self {
        Since(requests())
    }

    /// Whether a stop was requested since.
    pub fn stopped(self) -> bool {
        requests() > self.0
    }

    /// A boundary of work: [`Stopped`] saying what stands (`what`) when a stop was requested
    /// since, else nothing.
    pub fn stop_point(self, what: impl FnOnce() -> String) -> Result<(), Stopped> {
        if self.stopped() {
            return Err(Stopped { what: what() });
        }
        Ok(())
    }
}

/// The error of work cut short by a stop request, naming what was done.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stopped {
    /// What was stopped and what stands (e.g. "frames: 12 of 300 written, no video").
    pub what: String,
}

impl std::fmt::Display for Stopped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "stopped by a signal: {}", self.what)
    }
}

impl std::error::Error for Stopped {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loop_sees_only_the_requests_made_since_it_began() {
        let before = Since::now();
        request();
        let after = Since::now();
        assert!(before.stopped());
        assert!(!after.stopped());
        assert!(requested());
        assert!(
            Stopped {
                what: "frames".into()
            }
            .to_string()
            .contains("frames")
        );
    }
}
