//! The built-in demo scene: a small room with a table and eight labelled objects.
//!
//! A user without data runs splatraj on this scene, and the camera optimiser must find every
//! object in it, so it is built to render like a real capture rather than a cloud of dots:
//!
//! - Gaussians sample the *surfaces* of simple shapes (planes, discs, cylinders, cones,
//!   spheres, tori, leaves). Each is flat: two scales tangent to the surface, sized from the
//!   local sample spacing so neighbours overlap, and a small one along the normal; its rotation
//!   maps the local axes (x, y, z) to (tangent, bitangent, normal).
//! - Colours carry baked lighting (a fixed key light from above and in front), per-splat noise
//!   and textures on the floor (wood planks, a checked rug) and walls (a picture, a window), so
//!   camera motion is visible. SH degree 1 with small random view-dependent terms, larger on
//!   glossy objects.
//! - Opacities are mostly high, some low, as in real captures; the glass of water is
//!   semi-transparent.
//!
//! Layout (z-up, metres, see [`demo_layout`]): a 4 × 4 m floor centred on the origin, two
//! 2.5 m walls (the back wall at y = 2, the left wall at x = −2), a 1.6 × 1.0 m table with its
//! top at z = 0.75, seven objects on the table and a potted plant on the floor beside it. From
//! [`DEMO_VIEWPOINT`] the tall blue box hides the glass of water behind it, so occlusion
//! matters. Label ids: 0 floor, 1 walls, 2 table, 3.. the objects in [`demo_object_names`]
//! order.
//!
//! Split by concern: `objects` describes each part once (its surfaces, material and colour),
//! `shapes` the parametric surfaces, `looks` materials and textures, `budget` how many
//! Gaussians each part gets, `sampling` the Gaussians on a surface. The published boxes
//! ([`demo_layout`]) are derived from the surfaces.
//!
//! The scene is a pure function of [`DemoConfig`]: the same seed gives a bit-identical scene;
//! another seed changes sample positions, noise and slight colour tints, never the layout.
//! The total count is exactly `gaussians`: 62 % goes to floor, walls and table by area (the
//! table denser), 38 % to the objects, each getting a fixed minimum plus a share by area.

mod budget;
mod looks;
mod objects;
mod sampling;
mod shapes;

use std::ops::RangeInclusive;
use std::path::PathBuf;
use std::sync::OnceLock;

use glam::DVec3;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use crate::error::SceneError;
use crate::scene::Scene;
use objects::OBJECTS;

/// World up of the demo scene (z-up).
pub const DEMO_UP: [f32; 3] = [0.0, 0.0, 1.0];

/// A typical overview camera position (standing in front of the table, eye height 1.2 m),
/// from which the blue box hides the glass of water.
pub const DEMO_VIEWPOINT: [f32; 3] = [-0.3, -1.8, 1.2];

/// Gaussian counts [`demo_scene`] accepts; 50 000 to 200 000 is the intended range (fewer
/// renders sparse, more only costs time). The top is above the size of large real captures
/// (3–6 M), so the demo can stand in for them in scale tests (`splatraj bench scale`).
pub const DEMO_GAUSSIANS_RANGE: RangeInclusive<usize> = 1_000..=10_000_000;

/// Height of the table's top surface above the floor (m).
pub const DEMO_TABLE_TOP_Z: f32 = 0.75;

/// Label source name the demo scene records in [`crate::scene::Labels::source`].
pub const DEMO_LABEL_SOURCE: &str = "demo";

/// Settings of the demo scene.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// Seed of the ChaCha8 generator: sample positions, noise and tints (not the layout).
    pub seed: u64,
    /// Exact number of Gaussians, within [`DEMO_GAUSSIANS_RANGE`].
    pub gaussians: usize,
}

impl Default for DemoConfig {
    fn default() -> Self {
        DemoConfig {
            seed: 7,
            gaussians: 100_000,
        }
    }
}

/// One labelled part of the demo scene with the axis-aligned box that holds all its
/// Gaussian centres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemoObject {
    /// Label id of its Gaussians.
    pub id: i32,
    /// Label name.
    pub name: &'static str,
    /// Centre of its bounding box (m).
    pub center: [f32; 3],
    /// Edge lengths of its bounding box (m).
    pub size: [f32; 3],
}

impl DemoObject {
    /// Smallest corner of the bounding box.
    pub fn min(&self) -> [f32; 3] {
        std::array::from_fn(|k| self.center[k] - 0.5 * self.size[k])
    }
    /// Largest corner of the bounding box.
    pub fn max(&self) -> [f32; 3] {
        std::array::from_fn(|k| self.center[k] + 0.5 * self.size[k])
    }
}

/// First label id of the objects (ids below are floor, walls and table).
const FIRST_OBJECT_ID: i32 = 3;

/// Room left between an object's surfaces and its published box on every side (m).
pub const DEMO_BOX_MARGIN: f32 = 0.005;

/// Samples per side of the (u, v) grid on which each surface's bounds are measured: the
/// curved surfaces' bounds between grid points lie well within [`DEMO_BOX_MARGIN`].
const BOUNDS_GRID: usize = 129;

/// Every labelled part of the demo scene (floor, walls, table, then the objects), by id.
///
/// Each box is derived from the part's surfaces (the only description of its geometry): the
/// bounds of every surface the Gaussians are sampled on, measured on a dense (u, v) grid,
/// widened by [`DEMO_BOX_MARGIN`]. Every Gaussian centre of any seed and size lies inside.
pub fn demo_layout() -> Vec<DemoObject> {
    static LAYOUT: OnceLock<Vec<DemoObject>> = OnceLock::new();
    LAYOUT.get_or_init(derive_layout).clone()
}

fn derive_layout() -> Vec<DemoObject> {
    // The geometry does not depend on the generator (only the colour tints do).
    let parts = objects::build_parts(&mut ChaCha8Rng::seed_from_u64(0));
    let mut lo = vec![DVec3::splat(f64::INFINITY); OBJECTS.len()];
    let mut hi = vec![DVec3::splat(f64::NEG_INFINITY); OBJECTS.len()];
    let last = (BOUNDS_GRID - 1) as f64;
    for part in &parts {
        let l = part.label as usize;
        for i in 0..BOUNDS_GRID {
            for j in 0..BOUNDS_GRID {
                let (p, ..) = part.shape.frame(i as f64 / last, j as f64 / last);
                lo[l] = lo[l].min(p);
                hi[l] = hi[l].max(p);
            }
        }
    }
    let margin = f64::from(DEMO_BOX_MARGIN);
    (0..)
        .zip(&OBJECTS)
        .map(|(id, object)| {
            let (min, max) = (lo[id as usize] - margin, hi[id as usize] + margin);
            DemoObject {
                id,
                name: object.name,
                center: (0.5 * (min + max)).as_vec3().to_array(),
                size: (max - min).as_vec3().to_array(),
            }
        })
        .collect()
}

/// Names of the demo scene's objects (labels 3 and up, not floor, walls or table), by id.
pub fn demo_object_names() -> Vec<&'static str> {
    OBJECTS[FIRST_OBJECT_ID as usize..]
        .iter()
        .map(|o| o.name)
        .collect()
}

/// Builds the demo scene; fails if `config.gaussians` is outside [`DEMO_GAUSSIANS_RANGE`].
pub fn demo_scene(config: &DemoConfig) -> Result<Scene, SceneError> {
    if !DEMO_GAUSSIANS_RANGE.contains(&config.gaussians) {
        return Err(SceneError::malformed(
            PathBuf::from("demo scene"),
            format!(
                "gaussians = {} is outside the supported range {}..={} (50000 to 200000 is the \
                 intended range)",
                config.gaussians,
                DEMO_GAUSSIANS_RANGE.start(),
                DEMO_GAUSSIANS_RANGE.end()
            ),
        ));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let parts = objects::build_parts(&mut rng);
    let counts = budget::allocate(&parts, config.gaussians);
    let mut out = sampling::Builder::with_capacity(config.gaussians);
    for (part, &n) in parts.iter().zip(&counts) {
        sampling::sample_part(part, n, &mut rng, &mut out);
    }
    debug_assert_eq!(out.ids.len(), config.gaussians);
    // Real captures store Gaussians in no meaningful order; shuffling keeps downstream code
    // from relying on labels being contiguous.
    let mut order: Vec<usize> = (0..config.gaussians).collect();
    order.shuffle(&mut rng);
    Ok(out.into_scene(&order))
}
