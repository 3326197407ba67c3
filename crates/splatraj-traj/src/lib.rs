//! Camera trajectories for splatraj: what the optimiser minimises and how.
//!
//! Today it holds the trajectory models ([`trajectory`]: RBF, waypoint and polynomial bases
//! behind the `Basis` trait, one burn Module `Trajectory` mapping times to poses Φ(t)), the
//! smoothness metric LDJ ([`metrics`]), and the costs of DESIGN.md ([`costs`]: target centring
//! and target ratio errors on rendered masks `[B, H, W]`, uprightness and the decaying prior on
//! poses, each behind the `Cost` trait with its config weight and summed by `WeightedCosts`;
//! plus the bounding-box IoU metric). Still to come (issue 4): the optimisers (Adam, SGLD), the
//! per-window metrics and the run itself. It does not render (that is `splatraj-render`), read scenes or pick objects.

pub mod costs;
pub mod metrics;
pub mod trajectory;
