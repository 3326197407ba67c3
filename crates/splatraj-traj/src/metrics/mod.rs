//! Metrics to report, not to optimise (docs/conventions.md "Metrics").
//!
//! - [`ldj()`](ldj()): smoothness of a whole trajectory (log dimensionless jerk) on the camera
//!   centre and on the rotation vector;
//! - [`window`]: per query window TCE, TRE, bounding-box IoU, visibility and occlusion, on a
//!   fixed grid;
//! - [`path`]: per window clearance and motion peaks on a dense grid;
//! - [`shot`]: per window with a shot preset, the deviation from what the shot asks;
//! - [`verdict`](mod@verdict): per window, whether it shows its object as a viewer expects;
//! - [`wobble`](mod@wobble): the part of the framing error along t faster than about 1 Hz.

pub mod ldj;
pub mod path;
pub mod shot;
pub mod verdict;
pub mod window;
pub mod wobble;

pub use ldj::{DEFAULT_LDJ_SAMPLES, Smoothness, ldj, pose_ldj, trajectory_ldj};
pub use path::{ClearanceMetrics, MotionMetrics, PathMetrics, path_metrics, shot_path_metrics};
pub use shot::{Deviation, ShotMetrics, ZoomFrame, ZoomHold, shot_metrics, zoom_hold};
pub use verdict::{Check, CheckKind, Verdict, verdict};
pub use window::{
    Framing, LensSamples, Occlusion, WindowMetrics, WindowObject, ZoomAt, window_metrics,
    window_metrics_zoomed,
};
pub use wobble::wobble;
