//! Metrics to report, not to optimise (DESIGN.md "Metrics").
//!
//! Today: the smoothness of a whole trajectory, [`ldj()`](ldj()) (log dimensionless jerk) on the
//! camera centre and on the rotation vector. The per-window image metrics (TCE, TRE, IoU) will
//! join here.

pub mod ldj;

pub use ldj::{DEFAULT_LDJ_SAMPLES, Smoothness, ldj, pose_ldj, trajectory_ldj};
