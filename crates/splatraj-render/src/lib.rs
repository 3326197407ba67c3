//! Rendering of Gaussian scenes for splatraj.
//!
//! This crate holds the camera model and the renderers: the differentiable rasterizer (host
//! decisions and binning; projection, SH colours and compositing each as one fused burn op
//! with its own backward, or as burn tensor ops, their readable specification), an
//! independent brute-force f64 reference renderer (the yardstick for tests and a CPU preview),
//! the backend choice for burn tensors, and the lifting of per-pixel values onto the Gaussians
//! through the rasterizer's backward ([`lift`]). It does not read files or pick objects: it
//! takes a [`splatraj_scene::Scene`] and per-Gaussian channels from the crates before it in the
//! pipeline.

#![warn(missing_docs)]

pub mod adapters;
pub mod alpha_reach;
pub mod backend;
pub mod bitset;
pub mod camera;
pub mod composite_rules;
pub mod counters;
/// The single-camera JSON file (`splatraj render --camera`), from `splatraj-camera`.
pub use splatraj_camera::camera_file;
pub mod decide;
pub mod focus;
pub mod fused;
pub mod heaviest_first;
pub mod host;
pub mod images;
pub mod joined_rows;
pub mod lift;
pub mod orbit;
pub mod pass_size;
pub mod project;
pub mod rasterize;
pub mod reference;
pub mod render;
pub mod rodrigues;
pub mod rows;
pub mod sh;
pub mod stages;
#[cfg(test)]
mod test_random;
pub mod tile_grid;
pub mod tiles;
