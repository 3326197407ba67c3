//! Gaussian Splatting scenes as plain Rust data.
//!
//! This crate holds the scene model ([`Scene`], a struct of arrays of activated values), the
//! readers for the files users have (INRIA 3DGS PLY in binary and ASCII, PlayCanvas/SuperSplat
//! compressed PLY, Niantic SPZ, PlayCanvas SOG, antimatter15 `.splat`, GaussianSplats3D
//! `.ksplat`, label sidecars), writers of INRIA PLY, compressed PLY and SPZ, validation with clear
//! errors, a guess of the scene's up axis and up from the capture's cameras' rotations, coarser
//! copies of a scene (neighbours merged) and the procedural demo scene; and the program-wide
//! plumbing every crate shares: whole-or-nothing file writes, stop requests, and an allocation
//! failure that ends with a message instead of an abort. It does not render, select objects or
//! depend on burn: those live in the crates further down the pipeline.

#![warn(missing_docs)]

pub mod allocation;
pub mod atomic;
pub mod cameras_up;
pub mod coarse;
pub mod demo;
pub mod error;
pub mod formats;
pub mod input;
pub mod scene;
pub mod stop;
pub mod summary;
pub mod up_axis;
pub mod validate;

pub use cameras_up::{CamerasUp, CamerasUpError, cameras_up};
pub use error::{Result, SceneError};
pub use formats::{
    ReadOptions, SceneFormat, read_scene, write_compressed_ply, write_inria_ply, write_scene,
    write_spz,
};
pub use scene::{Bounds, Extras, Features, Labels, NamedProperty, SH_C0, Scene};
pub use up_axis::{
    ResolvedUp, UpCandidate, UpCandidates, UpGuess, UpSource, guess_up_axis, resolve_up,
    up_candidates,
};
pub use validate::InvalidPolicy;
