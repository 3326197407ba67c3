//! Helpers shared by the trajectory crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use splatraj_scene::Scene;

/// Opaque (0.99), axis-aligned, black Gaussians at `means` with `scales`.
pub fn scene_of(means: Vec<[f32; 3]>, scales: Vec<[f32; 3]>) -> Scene {
    let n = means.len();
    Scene {
        means,
        scales,
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![0.99; n],
        sh_degree: 0,
        sh: vec![0.0; n * 3],
        extras: Default::default(),
    }
}
