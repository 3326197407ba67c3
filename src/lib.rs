//! splatraj: camera trajectories that show named objects in 3D Gaussian Splatting scenes.
//!
//! This package is the command-line tool and a thin facade over the pipeline's crates:
//! [`scene`] (files, data model, demo scene) → [`semantic`] (query → the object's Gaussians)
//! → [`render`] (camera, rasterizer) → [`lift`] (language fields and labels lifted from the
//! scene's own renders) → [`traj`] (trajectory models, costs, optimisers,
//! metrics) → [`experiment`] (the config schema, [`experiment::Experiment`]: prepare, run,
//! evaluate, write). Library users can depend on the crates directly.

#![warn(missing_docs)]

pub use splatraj_experiment as experiment;
pub use splatraj_experiment::config;
pub use splatraj_lift as lift;
pub use splatraj_render as render;
pub use splatraj_scene as scene;
pub use splatraj_semantic as semantic;
pub use splatraj_traj as traj;
