//! Camera trajectories for splatraj: what the optimiser minimises and how.
//!
//! This crate will hold the trajectory models (RBF, waypoint, polynomial), the costs behind a
//! common trait, the optimisers (Adam, SGLD) and the metrics (TCE, TRE, IoU, LDJ). Today it
//! holds the two image costs of DESIGN.md as plain differentiable burn tensor functions on
//! rendered mask images `[B, H, W]`: [`costs::tce`] (target centring error) and [`costs::tre`]
//! (target ratio error). It does not render (that is `splatraj-render`, which produces the mask
//! images), read scenes or pick objects; it only turns images into scalars per sample, on
//! whatever device and dtype the images live on, differentiably when that device is autodiff.

pub mod costs;
pub mod metrics;
pub mod trajectory;
