//! Stratified sampling of times inside the query windows.
//!
//! Query i of n owns the window T_i = [i/n, (i+1)/n] (0-based i; docs/conventions.md "Optimisation
//! problem"). Each step estimates ∫_{T_i} L dt from S samples: the window is cut into S equal
//! strata and one time is drawn uniformly inside each. Stratifying keeps every part of the
//! window represented at every step (plain uniform sampling can leave half a window unseen for
//! several steps), so the estimate's variance is lower for the same render cost, and it is
//! still unbiased.

use rand::Rng;

// Which window a time is in is the trajectory's own split of t (its shots are runs of
// windows, `trajectory::cuts`): one rule for the samples, the frames and the shots.
pub use crate::trajectory::cuts::{window_bounds, window_of};

/// `per_window` stratified times inside window `index` of `windows`, ascending.
///
/// With an RNG each time is drawn uniformly in its stratum; with `None` it sits at the
/// stratum's middle (the fixed grid used for metrics).
pub fn stratified_times(
    index: usize,
    windows: usize,
    per_window: usize,
    rng: Option<&mut dyn rand::RngCore>,
) -> Vec<f64> {
    let (start, end) = window_bounds(index, windows);
    let width = (end - start) / per_window.max(1) as f64;
    let mut offsets: Box<dyn FnMut() -> f64> = match rng {
        Some(rng) => Box::new(move || rng.random::<f64>()),
        None => Box::new(|| 0.5),
    };
    (0..per_window)
        .map(|s| start + (s as f64 + offsets()) * width)
        .collect()
}
