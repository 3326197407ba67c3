//! Camera trajectories for splatraj: what the optimiser minimises and how.
//!
//! Today it holds the trajectory models ([`trajectory`]: RBF, waypoint and polynomial bases
//! behind the `Basis` trait, one burn Module `Trajectory` mapping times to poses Φ(t)), the
//! smoothness metric LDJ ([`metrics`]), and the costs of DESIGN.md ([`costs`]: target centring
//! and target ratio errors on rendered masks `[B, H, W]`, uprightness and the decaying prior on
//! poses, each behind the `Cost` trait with its config weight and summed by `WeightedCosts`;
//! plus the bounding-box IoU metric), and single-pose optimisation ([`optimise`]: Φ optimised
//! directly with Adam through the renderer, the paper's Table I setting). Still to come
//! (issue 4): trajectory optimisation with stratified time samples, SGLD, per-window metrics and
//! the `run`/`pose` commands. It renders only by calling `splatraj-render`; it does not read
//! scenes or pick objects.

pub mod costs;
pub mod metrics;
pub mod optimise;
pub mod trajectory;
