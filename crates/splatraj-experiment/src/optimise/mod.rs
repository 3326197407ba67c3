//! The optimisation stage: the paper's trajectory optimisation with restarts
//! ([`trajectory_run`]), the single-pose ablations and SGLD ([`pose_run`]), the checkpoint that
//! lets a stopped run continue ([`checkpoint`]), the progress reports that may stop them
//! ([`observer`]), and one object's loss at one camera through the same path ([`probe`]).

pub mod checkpoint;
pub mod observer;
pub mod pose_run;
pub mod probe;
pub mod trajectory_run;
