//! The GPU kernels' launch grids: a number of cubes laid out in two dimensions once it passes
//! the largest extent one axis of a grid may have, and that cap.
//!
//! Why in one place: the packing, the gather, the compositing tiles and the projection's
//! chunks each reach the cap on real captures (a step whose 40 poses keep 420 k Gaussians each
//! has more than 65 535 × 256 rows), and no test input is large enough to reach it on lavapipe.
//! A test lowers the cap here ([`set_axis_cap`]) so the same small pass runs on 2D grids and
//! must give the same results (`tests/gpu_same_pass.rs`).
//!
//! Kernels read a linear grid's cube as `CUBE_POS_Y · CUBE_COUNT_X + CUBE_POS_X` (or
//! `ABSOLUTE_POS`, which both CubeCL compilers linearise the same way) and skip the cubes past
//! their work, since `x · y` may exceed it.

use std::sync::atomic::{AtomicUsize, Ordering};

use burn_cubecl::cubecl::prelude::CubeCount;

/// The largest extent of a launch grid's axis on the APIs wgpu and Vulkan serve
/// (`maxComputeWorkgroupsPerDimension`, `maxComputeWorkGroupCount`: 65 535 at least, and the
/// common value).
pub const MAX_PER_AXIS: usize = 65_535;

/// The cap in force: [`MAX_PER_AXIS`] unless a test lowered it.
static AXIS_CAP: AtomicUsize = AtomicUsize::new(MAX_PER_AXIS);

/// Sets the largest extent the kernels' grids use per axis, clamped to 1..=[`MAX_PER_AXIS`],
/// for the whole process: for tests that run small passes on the 2D grids large ones need.
pub fn set_axis_cap(cap: usize) {
    AXIS_CAP.store(cap.clamp(1, MAX_PER_AXIS), Ordering::Relaxed);
}

/// The largest extent per axis the grids use now.
pub(crate) fn axis_cap() -> usize {
    AXIS_CAP.load(Ordering::Relaxed)
}

/// At least `cubes` cubes (one if none), `x` of them a row of the grid, as many rows as needed.
pub(crate) fn linear(cubes: usize) -> CubeCount {
    let x = cubes.clamp(1, axis_cap());
    CubeCount::Static(x as u32, cubes.div_ceil(x).max(1) as u32, 1)
}
