//! Optimisers: what moves the camera parameters downhill on the costs of [`crate::costs`].
//!
//! Today it holds the single-pose optimiser ([`single_pose`]): Φ itself, six numbers, is the
//! parameter, as in the paper's Table I ablation. Still to come (issue 4): Adam on trajectory
//! Modules over stratified time samples, and SGLD chains for posterior samples of one pose.

pub mod single_pose;

pub use single_pose::{
    HistoryRow, OptimiseError, SinglePoseOptions, SinglePoseResult, optimise_single_pose,
};
