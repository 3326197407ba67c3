//! Camera trajectories for splatraj: what the optimiser minimises and how.
//!
//! It holds the trajectory models ([`trajectory`]: RBF, waypoint and polynomial bases behind
//! the `Basis` trait, one burn Module `Trajectory` mapping times to poses Φ(t)), the costs of
//! docs/conventions.md ([`costs`]: target centring and target ratio errors on rendered masks `[B,
//! H, W]`, uprightness and the decaying prior on poses, each behind the `Cost` trait with its
//! config weight and summed by `WeightedCosts`; plus the bounding-box IoU metric), the optimisers
//! ([`optimise`]: burn's Adam on a trajectory's weights over stratified samples of every query
//! window, batched single-pose Adam for restarts, SGLD chains for pose posterior samples, and the
//! starting poses), and the metrics ([`metrics`]: per-window TCE, TRE, IoU and visibility on a
//! fixed time grid, LDJ smoothness). It renders only by calling `splatraj-render`; it does not read
//! scenes or configs, pick objects, or write files: the `splatraj` CLI does that.

#![warn(missing_docs)]

pub mod clearance;
pub mod costs;
pub mod metrics;
pub mod optimise;
pub mod pacing;
pub mod shots;
pub mod trajectory;
pub mod transitions;
