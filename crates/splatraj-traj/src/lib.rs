//! Camera trajectories for splatraj: what the optimiser minimises and how.
//!
//! Today it holds the trajectory models ([`trajectory`]: RBF, waypoint and polynomial bases
//! behind the `Basis` trait, one burn Module `Trajectory` mapping times to poses Φ(t)), the
//! smoothness metric LDJ ([`metrics`]), and the two image costs of DESIGN.md as differentiable
//! tensor functions on rendered mask images `[B, H, W]` ([`costs`]: target centring error and
//! target ratio error). Still to come (issue 4): the costs behind a common trait with weights
//! (upright, prior, IoU), the optimisers (Adam, SGLD), the per-window metrics and the run
//! itself. It does not render (that is `splatraj-render`), read scenes or pick objects.

pub mod costs;
pub mod metrics;
pub mod trajectory;
