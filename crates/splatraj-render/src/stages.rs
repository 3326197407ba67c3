//! Where rendering time goes: wall time per stage, summed over every render in this process
//! since the last [`reset`].
//!
//! A process-wide clock because renders run deep inside optimisation loops that should not
//! have to thread a timer through; `splatraj study` and `bench` read it around the work they
//! measure. On the CPU backends the stages run eagerly, so the times are what each stage
//! costs; on GPU backends kernels are queued asynchronously and the times are indicative.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// A stage of a render (forward) or of its compositing backward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Host decisions: cull, screen position, radius, depth.
    Decide,
    /// Tile binning and depth order.
    Bin,
    /// Differentiable projection, SH colour and channel values (burn tensor ops).
    Project,
    /// Compositing forward.
    Composite,
    /// Compositing backward (the fused op's hand-written backward; the tensor path's backward
    /// is part of burn's autodiff and is not separated).
    CompositeBackward,
    /// Projection backward (the fused projection's hand-written backward; the tensor
    /// projection's is part of burn's autodiff and is not separated).
    ProjectBackward,
}

impl Stage {
    /// Every stage, in pipeline order.
    pub const ALL: [Stage; 6] = [
        Stage::Decide,
        Stage::Bin,
        Stage::Project,
        Stage::Composite,
        Stage::CompositeBackward,
        Stage::ProjectBackward,
    ];

    /// Short name for tables (`decide`, `bin`, `project`, `composite`, `composite_backward`,
    /// `project_backward`).
    pub fn name(self) -> &'static str {
        match self {
            Stage::Decide => "decide",
            Stage::Bin => "bin",
            Stage::Project => "project",
            Stage::Composite => "composite",
            Stage::CompositeBackward => "composite_backward",
            Stage::ProjectBackward => "project_backward",
        }
    }
}

static NANOS: [AtomicU64; Stage::ALL.len()] = [const { AtomicU64::new(0) }; Stage::ALL.len()];

/// Adds `elapsed` to `stage`'s total.
pub fn add(stage: Stage, elapsed: Duration) {
    NANOS[stage as usize].fetch_add(elapsed.as_nanos() as u64, Ordering::Relaxed);
}

/// Total time per stage since the last [`reset`], in [`Stage::ALL`] order.
pub fn totals() -> [(Stage, Duration); Stage::ALL.len()] {
    Stage::ALL.map(|s| {
        (
            s,
            Duration::from_nanos(NANOS[s as usize].load(Ordering::Relaxed)),
        )
    })
}

/// Milliseconds per unit in each stage since the last [`reset`], [`Stage::ALL`] order: the
/// totals divided by `units` (the passes, frames or steps measured).
pub fn ms_per(units: usize) -> [(Stage, f64); Stage::ALL.len()] {
    totals().map(|(stage, total)| (stage, 1e3 * total.as_secs_f64() / units.max(1) as f64))
}

/// Sets every total to zero.
pub fn reset() {
    for n in &NANOS {
        n.store(0, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn totals_sum_what_was_added_per_stage() {
        // Other tests in this binary may render concurrently: compare differences.
        let before = totals();
        add(Stage::Bin, Duration::from_micros(1500));
        add(Stage::Bin, Duration::from_micros(500));
        let after = totals();
        let bin = Stage::Bin as usize;
        assert!(after[bin].1 - before[bin].1 >= Duration::from_millis(2));
        assert_eq!(Stage::ALL.map(|s| s as usize), [0, 1, 2, 3, 4, 5]);
    }
}
