//! Metrics to report, not to optimise (docs/conventions.md "Metrics").
//!
//! - [`ldj()`](ldj()): smoothness of a whole trajectory (log dimensionless jerk) on the camera
//!   centre and on the rotation vector;
//! - [`window`]: per query window TCE, TRE, bounding-box IoU and visibility, on a fixed grid.

pub mod ldj;
pub mod path;
pub mod window;

pub use ldj::{DEFAULT_LDJ_SAMPLES, Smoothness, ldj, pose_ldj, trajectory_ldj};
pub use path::{ClearanceMetrics, MotionMetrics, PathMetrics, path_metrics};
pub use window::{WindowMetrics, WindowObject, window_metrics};
