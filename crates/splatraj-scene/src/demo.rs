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
//! The scene is a pure function of [`DemoConfig`]: the same seed gives a bit-identical scene;
//! another seed changes sample positions, noise and slight colour tints, never the layout.
//! The total count is exactly `gaussians`: 62 % goes to floor, walls and table by area (the
//! table denser), 38 % to the objects, each getting a fixed minimum plus a share by area.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::ops::RangeInclusive;
use std::path::PathBuf;

use glam::{DMat3, DQuat, DVec3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::SceneError;
use crate::scene::{Extras, Labels, SH_C0, Scene};

/// World up of the demo scene (z-up).
pub const DEMO_UP: [f32; 3] = [0.0, 0.0, 1.0];

/// A typical overview camera position (standing in front of the table, eye height 1.2 m),
/// from which the blue box hides the glass of water.
pub const DEMO_VIEWPOINT: [f32; 3] = [-0.3, -1.8, 1.2];

/// Gaussian counts [`demo_scene`] accepts; 50 000 to 200 000 is the intended range (fewer
/// renders sparse, more only costs time).
pub const DEMO_GAUSSIANS_RANGE: RangeInclusive<usize> = 1_000..=2_000_000;

/// Height of the table's top surface above the floor (m).
pub const DEMO_TABLE_TOP_Z: f32 = 0.75;

/// Label source name the demo scene records in [`Labels::source`].
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

// The published layout. The geometry in `build_parts` is written to fit inside these boxes
// (a few millimetres of margin), and the tests check that it does.
const LAYOUT: [DemoObject; 11] = [
    obj(0, "floor", [0.0, 0.0, 0.0], [4.01, 4.01, 0.01]),
    obj(1, "walls", [0.0, 0.0, 1.25], [4.01, 4.01, 2.51]),
    obj(2, "table", [0.0, 0.0, 0.375], [1.61, 1.01, 0.76]),
    obj(3, "red mug", [0.32, -0.22, 0.80], [0.14, 0.10, 0.11]),
    obj(4, "green ball", [-0.40, -0.15, 0.82], [0.15, 0.15, 0.15]),
    obj(5, "blue box", [-0.05, 0.0, 0.86], [0.17, 0.08, 0.23]),
    obj(6, "yellow cone", [0.55, 0.25, 0.83], [0.13, 0.13, 0.17]),
    obj(7, "lamp", [-0.55, 0.28, 0.955], [0.25, 0.25, 0.42]),
    obj(8, "books", [0.22, 0.15, 0.8025], [0.275, 0.215, 0.115]),
    obj(9, "plant", [1.16, 0.72, 0.205], [0.38, 0.34, 0.42]),
    obj(
        10,
        "glass of water",
        [-0.05, 0.22, 0.805],
        [0.08, 0.08, 0.12],
    ),
];

const fn obj(id: i32, name: &'static str, center: [f32; 3], size: [f32; 3]) -> DemoObject {
    DemoObject {
        id,
        name,
        center,
        size,
    }
}

/// Every labelled part of the demo scene (floor, walls, table, then the objects), by id.
pub fn demo_layout() -> Vec<DemoObject> {
    LAYOUT.to_vec()
}

/// Names of the demo scene's objects (labels 3 and up, not floor, walls or table), by id.
pub fn demo_object_names() -> Vec<&'static str> {
    LAYOUT
        .iter()
        .filter(|o| o.id >= FIRST_OBJECT_ID)
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
    let parts = build_parts(&mut rng);
    let counts = allocate(&parts, config.gaussians);
    let mut out = Builder::with_capacity(config.gaussians);
    for (part, &n) in parts.iter().zip(&counts) {
        sample_part(part, n, &mut rng, &mut out);
    }
    debug_assert_eq!(out.ids.len(), config.gaussians);
    // Real captures store Gaussians in no meaningful order; shuffling keeps downstream code
    // from relying on labels being contiguous.
    let mut order: Vec<usize> = (0..config.gaussians).collect();
    order.shuffle(&mut rng);
    Ok(out.into_scene(&order))
}

// ---------------------------------------------------------------------------------------------
// Budget

/// Share of the budget for floor, walls and table; the rest goes to the objects.
const STRUCTURE_SHARE: f64 = 0.62;
/// Share every object gets whatever its area, so small objects still render solid.
const OBJECT_MIN_SHARE: f64 = 0.018;
/// Density multipliers of the structural labels (per unit area): the table is seen up close.
const STRUCTURE_DENSITY: [f64; 3] = [1.0, 0.6, 3.0];

/// Number of Gaussians per part, summing exactly to `total`.
fn allocate(parts: &[Part], total: usize) -> Vec<usize> {
    let labels = LAYOUT.len();
    let mut area = vec![0.0; labels];
    for p in parts {
        area[p.label as usize] += p.area * p.weight;
    }
    let objects = labels - FIRST_OBJECT_ID as usize;
    let object_area: f64 = area[FIRST_OBJECT_ID as usize..].iter().sum();
    let structure: f64 = (0..FIRST_OBJECT_ID as usize)
        .map(|l| area[l] * STRUCTURE_DENSITY[l])
        .sum();
    let area_share = 1.0 - STRUCTURE_SHARE - objects as f64 * OBJECT_MIN_SHARE;
    let label_weight: Vec<f64> = (0..labels)
        .map(|l| {
            if l < FIRST_OBJECT_ID as usize {
                STRUCTURE_SHARE * area[l] * STRUCTURE_DENSITY[l] / structure
            } else {
                OBJECT_MIN_SHARE + area_share * area[l] / object_area
            }
        })
        .collect();
    let label_counts = largest_remainder(&label_weight, total);
    let mut counts = vec![0; parts.len()];
    for (l, &label_count) in label_counts.iter().enumerate() {
        let idx: Vec<usize> = (0..parts.len())
            .filter(|&i| parts[i].label as usize == l)
            .collect();
        let w: Vec<f64> = idx
            .iter()
            .map(|&i| parts[i].area * parts[i].weight)
            .collect();
        for (&i, c) in idx.iter().zip(largest_remainder(&w, label_count)) {
            counts[i] = c;
        }
    }
    counts
}

/// Splits `total` in proportion to `weights` into integers that sum to `total` exactly
/// (Hamilton's method: floors, then the largest fractional parts get one more).
fn largest_remainder(weights: &[f64], total: usize) -> Vec<usize> {
    let sum: f64 = weights.iter().sum();
    let exact: Vec<f64> = weights.iter().map(|w| w / sum * total as f64).collect();
    let mut counts: Vec<usize> = exact.iter().map(|e| e.floor() as usize).collect();
    let given: usize = counts.iter().sum();
    let mut order: Vec<usize> = (0..weights.len()).collect();
    // Stable sort with an index tie-break keeps the split deterministic.
    order.sort_by(|&a, &b| {
        let (fa, fb) = (exact[a] - exact[a].floor(), exact[b] - exact[b].floor());
        fb.total_cmp(&fa).then(a.cmp(&b))
    });
    for &i in order.iter().take(total - given) {
        counts[i] += 1;
    }
    counts
}

// ---------------------------------------------------------------------------------------------
// Surfaces

/// A parametric surface over (u, v) ∈ [0, 1]².
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// `origin + u·a + v·b`; outward normal a × b.
    Rect { origin: DVec3, a: DVec3, b: DVec3 },
    /// Ring between radii r0 and r1 around `center` in the (e1, e2) plane; normal e1 × e2.
    Annulus {
        center: DVec3,
        e1: DVec3,
        e2: DVec3,
        r0: f64,
        r1: f64,
    },
    /// Lateral surface of a truncated cone along e1 × e2 from radius r0 (at `base`) to r1
    /// (at `base + height·axis`); a cylinder when r0 = r1, a cone when r1 = 0.
    Frustum {
        base: DVec3,
        e1: DVec3,
        e2: DVec3,
        r0: f64,
        r1: f64,
        height: f64,
        inward: bool,
    },
    /// Sphere.
    Sphere { center: DVec3, radius: f64 },
    /// Tube of radius `minor` around the arc of radius `major` in the (e1, e2) plane, from
    /// angle a0 to a1.
    Torus {
        center: DVec3,
        e1: DVec3,
        e2: DVec3,
        major: f64,
        minor: f64,
        a0: f64,
        a1: f64,
    },
    /// A drooping, slightly folded leaf from `base` along `dir`, widest halfway.
    Leaf {
        base: DVec3,
        dir: DVec3,
        side: DVec3,
        length: f64,
        half_width: f64,
        droop: f64,
    },
}

impl Shape {
    /// Whether u wraps around (an angle), so rows may start at a random phase.
    fn periodic_u(&self) -> bool {
        !matches!(self, Shape::Rect { .. } | Shape::Leaf { .. })
    }

    /// Which parameter bounds are open edges of the surface (u = 0 and 1 together, v = 0,
    /// v = 1), as opposed to seams, poles or apexes where the surface closes or continues.
    fn open_edges(&self) -> (bool, bool, bool) {
        match *self {
            Shape::Rect { .. } | Shape::Leaf { .. } => (true, true, true),
            Shape::Annulus { r0, .. } => (false, r0 > 0.0, true),
            Shape::Frustum { .. } => (false, true, true),
            Shape::Sphere { .. } | Shape::Torus { .. } => (false, false, false),
        }
    }

    /// Point at (u, v) and a direction on the outer side of the surface there.
    fn eval(&self, u: f64, v: f64) -> (DVec3, DVec3) {
        match *self {
            Shape::Rect { origin, a, b } => (origin + u * a + v * b, a.cross(b)),
            Shape::Annulus {
                center,
                e1,
                e2,
                r0,
                r1,
            } => {
                // r² linear in v makes equal v-steps cover equal areas.
                let r = (r0 * r0 + v * (r1 * r1 - r0 * r0)).max(0.0).sqrt();
                let t = TAU * u;
                (center + r * (t.cos() * e1 + t.sin() * e2), e1.cross(e2))
            }
            Shape::Frustum {
                base,
                e1,
                e2,
                r0,
                r1,
                height,
                inward,
            } => {
                // Area up to slant fraction s grows as r0·s + (r1 − r0)·s²/2; invert it so
                // equal v-steps cover equal areas (no crowding at a cone's apex).
                let s = if (r1 - r0).abs() < 1e-9 {
                    v
                } else {
                    let disc = (r0 * r0 + v * (r1 * r1 - r0 * r0)).max(0.0);
                    ((disc.sqrt() - r0) / (r1 - r0)).clamp(0.0, 1.0)
                };
                let r = r0 + (r1 - r0) * s;
                let t = TAU * u;
                let radial = t.cos() * e1 + t.sin() * e2;
                let p = base + s * height * e1.cross(e2) + r * radial;
                (p, if inward { -radial } else { radial })
            }
            Shape::Sphere { center, radius } => {
                // z uniform in [−1, 1] is area-uniform on the sphere (Archimedes).
                let z = 2.0 * v - 1.0;
                let rho = (1.0 - z * z).max(0.0).sqrt();
                let t = TAU * u;
                let d = DVec3::new(rho * t.cos(), rho * t.sin(), z);
                (center + radius * d, d)
            }
            Shape::Torus {
                center,
                e1,
                e2,
                major,
                minor,
                a0,
                a1,
            } => {
                let phi = a0 + (a1 - a0) * v;
                let ring = phi.cos() * e1 + phi.sin() * e2;
                let psi = TAU * u;
                let off = psi.cos() * ring + psi.sin() * e1.cross(e2);
                (center + major * ring + minor * off, off)
            }
            Shape::Leaf {
                base,
                dir,
                side,
                length,
                half_width,
                droop,
            } => {
                let up = dir.cross(side).normalize();
                let up = if up.z < 0.0 { -up } else { up };
                let across = 2.0 * u - 1.0;
                let w = half_width * (PI * v).sin().powf(0.7);
                let p = base + length * v * dir + w * across * side
                    - droop * length * v * v * DVec3::Z
                    + 0.3 * w * across * across * up;
                (p, up)
            }
        }
    }

    /// Point, derivatives along u and v, and the outer-side hint at (u, v).
    fn frame(&self, u: f64, v: f64) -> (DVec3, DVec3, DVec3, DVec3) {
        const H: f64 = 1e-4;
        let (p, hint) = self.eval(u, v);
        let (ua, ub) = if self.periodic_u() {
            (u - H, u + H)
        } else {
            ((u - H).max(0.0), (u + H).min(1.0))
        };
        let (va, vb) = ((v - H).max(0.0), (v + H).min(1.0));
        let pu = (self.eval(ub, v).0 - self.eval(ua, v).0) / (ub - ua);
        let pv = (self.eval(u, vb).0 - self.eval(u, va).0) / (vb - va);
        (p, pu, pv, hint)
    }

    /// Surface area, by the midpoint rule on a 24 × 24 grid (exact enough to split a budget).
    fn area(&self) -> f64 {
        const N: usize = 24;
        let mut sum = 0.0;
        for i in 0..N {
            for j in 0..N {
                let (u, v) = ((i as f64 + 0.5) / N as f64, (j as f64 + 0.5) / N as f64);
                let (_, pu, pv, _) = self.frame(u, v);
                sum += pu.cross(pv).length();
            }
        }
        sum / (N * N) as f64
    }
}

/// How a part's Gaussians look beyond their colour.
#[derive(Debug, Clone, Copy)]
struct Look {
    /// Opacity range: most Gaussians in the upper one, some in the lower one.
    opacity: Opacity,
    /// Standard deviation of the degree-1 SH coefficients (view-dependent colour).
    sh: f64,
    /// How the baked key light shades the colour.
    light: Light,
    /// Scale of the per-splat colour noise (1 for objects; less on large plain surfaces,
    /// whose coarser splats would otherwise look grainy).
    noise: f64,
}

#[derive(Debug, Clone, Copy)]
enum Opacity {
    /// 80 % in [0.75, 0.99], 20 % in [0.25, 0.75], like a converged capture.
    Solid,
    /// Uniform in the range (semi-transparent materials).
    Range(f64, f64),
}

#[derive(Debug, Clone, Copy)]
enum Light {
    /// Lambert on the outer side.
    Diffuse,
    /// Lambert on either side (thin leaves).
    TwoSided,
    /// Unshaded (light sources).
    Emissive,
}

const MATTE: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.04,
    light: Light::Diffuse,
    noise: 1.0,
};
const ROOM: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.02,
    light: Light::Diffuse,
    noise: 0.4,
};
const GLOSSY: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.12,
    light: Light::Diffuse,
    noise: 1.0,
};

type Paint = Box<dyn Fn(DVec3, f64, f64) -> DVec3>;

/// A surface with its label, colour and material.
struct Part {
    label: i32,
    shape: Shape,
    /// Density multiplier within the label (hidden undersides get fewer).
    weight: f64,
    area: f64,
    look: Look,
    paint: Paint,
}

/// Colour of a plain material.
fn plain(c: DVec3) -> Paint {
    Box::new(move |_, _, _| c)
}

/// Collects parts, computing their areas.
struct Parts(Vec<Part>);

impl Parts {
    fn add(&mut self, label: i32, shape: Shape, weight: f64, look: Look, paint: Paint) {
        let area = shape.area();
        self.0.push(Part {
            label,
            shape,
            weight,
            area,
            look,
            paint,
        });
    }
}

/// The six faces of a box standing on `bottom_center`, yawed by `yaw` about z, in the order
/// +z, −z, +a, −a, +b, −b (a, b the yawed x and y axes), each with an outward normal.
fn box_faces(bottom_center: DVec3, half_a: f64, half_b: f64, height: f64, yaw: f64) -> [Shape; 6] {
    let a = DVec3::new(yaw.cos(), yaw.sin(), 0.0);
    let b = DVec3::new(-yaw.sin(), yaw.cos(), 0.0);
    let z = DVec3::Z;
    let c = bottom_center;
    let rect = |origin, a, b| Shape::Rect { origin, a, b };
    [
        rect(
            c + height * z - half_a * a - half_b * b,
            2.0 * half_a * a,
            2.0 * half_b * b,
        ),
        rect(
            c - half_a * a - half_b * b,
            2.0 * half_b * b,
            2.0 * half_a * a,
        ),
        rect(c + half_a * a - half_b * b, 2.0 * half_b * b, height * z),
        rect(c - half_a * a - half_b * b, height * z, 2.0 * half_b * b),
        rect(c + half_b * b - half_a * a, height * z, 2.0 * half_a * a),
        rect(c - half_b * b - half_a * a, 2.0 * half_a * a, height * z),
    ]
}

/// Vertical cylinder or truncated cone standing at `base`.
fn upright(base: DVec3, r0: f64, r1: f64, height: f64, inward: bool) -> Shape {
    Shape::Frustum {
        base,
        e1: DVec3::X,
        e2: DVec3::Y,
        r0,
        r1,
        height,
        inward,
    }
}

/// Horizontal ring (or disc when r0 = 0) facing up, or down when `down`.
fn flat_ring(center: DVec3, r0: f64, r1: f64, down: bool) -> Shape {
    let (e1, e2) = if down {
        (DVec3::Y, DVec3::X)
    } else {
        (DVec3::X, DVec3::Y)
    };
    Shape::Annulus {
        center,
        e1,
        e2,
        r0,
        r1,
    }
}

// ---------------------------------------------------------------------------------------------
// Textures

/// Deterministic hash of integers to [0, 1) (splitmix64), for per-plank or per-leaf variation
/// that must not depend on the seed (the layout and textures stay fixed).
fn hash01(a: i64, b: i64) -> f64 {
    let mut x = (a as u64)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add((b as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
        .wrapping_add(0x1656_67B1_9E37_79F9);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// 1 inside the axis-aligned rectangle |x − cx| < hx, |y − cy| < hy, fading to 0 over `blur`.
fn soft_rect(x: f64, y: f64, cx: f64, cy: f64, hx: f64, hy: f64, blur: f64) -> f64 {
    let fx = 1.0 - smoothstep(hx - blur, hx + blur, (x - cx).abs());
    let fy = 1.0 - smoothstep(hy - blur, hy + blur, (y - cy).abs());
    fx * fy
}

/// Oak planks 16 cm wide along x with staggered ends and grain, and a checked rug under the
/// table; the table and plant cast soft contact shadows.
fn floor_color(p: DVec3) -> DVec3 {
    let (x, y) = (p.x, p.y);
    let shadow = 1.0
        - 0.4 * soft_rect(x, y, 0.0, 0.0, 0.8, 0.5, 0.25)
        - 0.35 * soft_rect(x, y, 1.15, 0.75, 0.09, 0.09, 0.08);
    let (rx, ry) = (1.15, 0.85);
    if x.abs() < rx && y.abs() < ry {
        let border = x.abs() > rx - 0.09 || y.abs() > ry - 0.09;
        let c = if border {
            DVec3::new(0.86, 0.80, 0.66)
        } else {
            let (i, j) = ((x / 0.23).floor() as i64, (y / 0.23).floor() as i64);
            if (i + j).rem_euclid(2) == 0 {
                DVec3::new(0.20, 0.40, 0.46)
            } else {
                DVec3::new(0.64, 0.56, 0.42)
            }
        };
        return c * shadow;
    }
    let width = 0.16;
    let row = (y / width).floor() as i64;
    let len = 1.3;
    let shift = hash01(row, 11) * len;
    let col = ((x + shift) / len).floor() as i64;
    let tone = 0.86 + 0.26 * hash01(row, col);
    let grain = 1.0 + 0.07 * (TAU * (y * 28.0 + 0.7 * (x * 2.3 + col as f64).sin())).sin();
    let in_row = y / width - row as f64;
    let in_col = (x + shift) / len - col as f64;
    let seam = if !(0.03..=0.97).contains(&in_row) || !(0.005..=0.995).contains(&in_col) {
        0.55
    } else {
        1.0
    };
    DVec3::new(0.74, 0.56, 0.36) * tone * grain * seam * shadow
}

/// Painted walls with a skirting board, a framed picture on the back wall and a window on
/// the left wall.
fn wall_color(p: DVec3) -> DVec3 {
    let back = p.y > 1.99;
    let (s, z) = (if back { p.x } else { p.y }, p.z);
    if z < 0.1 {
        return DVec3::splat(0.93);
    }
    let base = if back {
        DVec3::new(0.86, 0.82, 0.74)
    } else {
        DVec3::new(0.78, 0.83, 0.84)
    };
    let mottle = 1.0 + 0.04 * (s * 1.7 + 0.5 * (z * 2.1).sin()).sin() * (z * 1.3 + s).cos();
    let wall = base * mottle;
    if back {
        // Picture: x ∈ [−0.2, 0.8], z ∈ [1.2, 1.85], a 5 cm dark frame around a landscape.
        let (x0, x1, z0, z1) = (-0.2, 0.8, 1.2, 1.85);
        if (x0..=x1).contains(&s) && (z0..=z1).contains(&z) {
            let f = 0.05;
            if s < x0 + f || s > x1 - f || z < z0 + f || z > z1 - f {
                return DVec3::new(0.28, 0.18, 0.10);
            }
            let sun = DVec3::new(s - 0.5, 0.0, z - 1.62).length() < 0.09;
            return if sun {
                DVec3::new(0.98, 0.66, 0.18)
            } else if z < 1.42 + 0.05 * (s * 9.0).sin() {
                DVec3::new(0.25, 0.55, 0.25)
            } else {
                DVec3::new(0.45, 0.68, 0.90)
            };
        }
        wall
    } else {
        // Window: y ∈ [−1.2, 0.2], z ∈ [0.9, 2.0], white frame and a cross mullion.
        let (y0, y1, z0, z1) = (-1.2, 0.2, 0.9, 2.0);
        if (y0..=y1).contains(&s) && (z0..=z1).contains(&z) {
            let f = 0.06;
            let mullion = (s - 0.5 * (y0 + y1)).abs() < 0.025 || (z - 1.5).abs() < 0.025;
            if s < y0 + f || s > y1 - f || z < z0 + f || z > z1 - f || mullion {
                return DVec3::splat(0.96);
            }
            let t = (z - z0) / (z1 - z0);
            return DVec3::new(0.62, 0.78, 0.95) * (0.85 + 0.2 * t);
        }
        wall
    }
}

/// Walnut with grain along x and contact shadows of the objects standing on it.
fn table_color(p: DVec3) -> DVec3 {
    let grain = 1.0
        + 0.09 * (TAU * (p.y * 30.0 + 0.6 * (p.x * 3.1).sin() + 0.2 * (p.x * 17.0).sin())).sin();
    let mut c = DVec3::new(0.50, 0.33, 0.20) * grain;
    if p.z > f64::from(DEMO_TABLE_TOP_Z) - 1e-6 {
        // (x, y, radius) of each object's footprint.
        const FEET: [(f64, f64, f64); 7] = [
            (0.30, -0.22, 0.05),
            (-0.40, -0.15, 0.045),
            (-0.05, 0.0, 0.085),
            (-0.05, 0.22, 0.04),
            (0.55, 0.25, 0.065),
            (-0.55, 0.28, 0.085),
            (0.22, 0.15, 0.13),
        ];
        for (x, y, r) in FEET {
            let d = DVec3::new(p.x - x, p.y - y, 0.0).length();
            c *= 1.0 - 0.35 * (1.0 - smoothstep(r, 1.6 * r, d));
        }
    }
    c
}

// ---------------------------------------------------------------------------------------------
// The scene's parts

/// Multiplies a colour by a slight random tint: different seeds look slightly different.
fn tinted(rng: &mut ChaCha8Rng, c: DVec3) -> DVec3 {
    let mut f = || 1.0 + 0.03 * rng.sample::<f64, _>(StandardNormal);
    c * DVec3::new(f(), f(), f())
}

fn build_parts(rng: &mut ChaCha8Rng) -> Vec<Part> {
    let mut parts = Parts(Vec::new());
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let top = f64::from(DEMO_TABLE_TOP_Z);

    // Floor and walls (the room is open towards +x and −y so cameras can stand back).
    parts.add(
        0,
        Shape::Rect {
            origin: DVec3::new(-2.0, -2.0, 0.0),
            a: 4.0 * x,
            b: 4.0 * y,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| floor_color(p)),
    );
    parts.add(
        1,
        Shape::Rect {
            origin: DVec3::new(-2.0, 2.0, 0.0),
            a: 4.0 * x,
            b: 2.5 * z,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| wall_color(p)),
    );
    parts.add(
        1,
        Shape::Rect {
            origin: DVec3::new(-2.0, -2.0, 0.0),
            a: 4.0 * y,
            b: 2.5 * z,
        },
        1.0,
        ROOM,
        Box::new(|p, _, _| wall_color(p)),
    );

    // Table: a 4 cm top slab and four 5 cm square legs.
    let slab = box_faces(DVec3::new(0.0, 0.0, top - 0.04), 0.8, 0.5, 0.04, 0.0);
    for (k, face) in slab.into_iter().enumerate() {
        let weight = if k == 1 { 0.25 } else { 1.0 };
        parts.add(2, face, weight, MATTE, Box::new(|p, _, _| table_color(p)));
    }
    for (lx, ly) in [(0.7, 0.4), (-0.7, 0.4), (0.7, -0.4), (-0.7, -0.4)] {
        let leg = box_faces(DVec3::new(lx, ly, 0.0), 0.025, 0.025, top - 0.04, 0.0);
        for face in leg.into_iter().skip(2) {
            parts.add(
                2,
                face,
                1.0,
                MATTE,
                Box::new(|_, _, v| DVec3::new(0.40, 0.26, 0.16) * (0.9 + 0.1 * v)),
            );
        }
    }

    // 3: red mug, 9 cm wide and 10 cm tall, white inside, handle towards +x.
    let c = DVec3::new(0.30, -0.22, top);
    let red = tinted(rng, DVec3::new(0.80, 0.10, 0.09));
    let cream = tinted(rng, DVec3::new(0.93, 0.90, 0.84));
    parts.add(
        3,
        upright(c, 0.045, 0.045, 0.10, false),
        1.0,
        GLOSSY,
        plain(red),
    );
    parts.add(
        3,
        upright(c + 0.006 * z, 0.041, 0.041, 0.094, true),
        1.0,
        MATTE,
        plain(cream),
    );
    parts.add(
        3,
        flat_ring(c + 0.10 * z, 0.041, 0.045, false),
        1.0,
        GLOSSY,
        plain(red),
    );
    parts.add(
        3,
        flat_ring(c + 0.006 * z, 0.0, 0.041, false),
        1.0,
        MATTE,
        plain(cream),
    );
    parts.add(3, flat_ring(c, 0.0, 0.045, true), 0.3, MATTE, plain(red));
    parts.add(
        3,
        Shape::Torus {
            center: c + 0.045 * x + 0.05 * z,
            e1: x,
            e2: z,
            major: 0.03,
            minor: 0.008,
            a0: -0.45 * PI,
            a1: 0.45 * PI,
        },
        1.5,
        GLOSSY,
        plain(red),
    );

    // 4: green ball, 14 cm across.
    let green = tinted(rng, DVec3::new(0.16, 0.66, 0.22));
    parts.add(
        4,
        Shape::Sphere {
            center: DVec3::new(-0.40, -0.15, top + 0.07),
            radius: 0.07,
        },
        1.0,
        GLOSSY,
        Box::new(move |p, _, _| {
            // A pale seam around the ball makes its spin readable.
            let seam = (p.z - (top + 0.07) + 0.02 * (p.x * 60.0).sin()).abs() < 0.004;
            if seam { DVec3::splat(0.9) } else { green }
        }),
    );

    // 5: blue box, 16 × 7 × 22 cm, a white label band on its front (−y) face.
    let blue = tinted(rng, DVec3::new(0.10, 0.24, 0.78));
    let faces = box_faces(DVec3::new(-0.05, 0.0, top), 0.08, 0.035, 0.22, 0.0);
    for (k, face) in faces.into_iter().enumerate() {
        let weight = if k == 1 { 0.2 } else { 1.0 };
        let paint: Paint = if k == 5 {
            Box::new(move |p, _, _| {
                let band = (top + 0.09..top + 0.15).contains(&p.z);
                let stripe = (top + 0.11..top + 0.125).contains(&p.z) && p.x < -0.01;
                match (band, stripe) {
                    (true, true) => DVec3::new(0.85, 0.15, 0.12),
                    (true, false) => DVec3::splat(0.94),
                    _ => blue,
                }
            })
        } else {
            plain(blue)
        };
        parts.add(5, face, weight, MATTE, paint);
    }

    // 6: yellow cone, 12 cm base, 16 cm tall.
    let yellow = tinted(rng, DVec3::new(0.96, 0.80, 0.10));
    let c = DVec3::new(0.55, 0.25, top);
    parts.add(
        6,
        upright(c, 0.06, 0.0, 0.16, false),
        1.0,
        MATTE,
        plain(yellow),
    );
    parts.add(6, flat_ring(c, 0.0, 0.06, true), 0.3, MATTE, plain(yellow));

    // 7: lamp, 40 cm tall: round base, thin pole, bulb inside an open conical shade.
    let c = DVec3::new(-0.55, 0.28, top);
    let bronze = tinted(rng, DVec3::new(0.30, 0.25, 0.20));
    let shade = tinted(rng, DVec3::new(0.93, 0.86, 0.70));
    let glow = DVec3::new(1.0, 0.96, 0.82);
    parts.add(
        7,
        upright(c, 0.08, 0.08, 0.02, false),
        1.0,
        GLOSSY,
        plain(bronze),
    );
    parts.add(
        7,
        flat_ring(c + 0.02 * z, 0.0, 0.08, false),
        1.0,
        GLOSSY,
        plain(bronze),
    );
    parts.add(
        7,
        upright(c + 0.02 * z, 0.008, 0.008, 0.28, false),
        2.0,
        GLOSSY,
        plain(DVec3::new(0.72, 0.72, 0.74)),
    );
    parts.add(
        7,
        upright(c + 0.26 * z, 0.12, 0.065, 0.14, false),
        1.0,
        MATTE,
        plain(shade),
    );
    let emissive = Look {
        light: Light::Emissive,
        ..MATTE
    };
    parts.add(
        7,
        upright(c + 0.26 * z, 0.117, 0.062, 0.14, true),
        0.7,
        emissive,
        plain(glow),
    );
    parts.add(
        7,
        Shape::Sphere {
            center: c + 0.30 * z,
            radius: 0.025,
        },
        1.0,
        emissive,
        plain(DVec3::new(1.0, 0.99, 0.93)),
    );

    // 8: a stack of three books, each a little askew, spines to the front (−y).
    let pages = DVec3::new(0.92, 0.89, 0.80);
    let books = [
        (
            0.0,
            0.0,
            0.12,
            0.085,
            0.035,
            8f64,
            DVec3::new(0.55, 0.10, 0.12),
        ),
        (
            0.005,
            -0.005,
            0.11,
            0.075,
            0.03,
            -5.0,
            DVec3::new(0.10, 0.15, 0.42),
        ),
        (
            -0.008,
            0.006,
            0.10,
            0.07,
            0.04,
            15.0,
            DVec3::new(0.14, 0.36, 0.20),
        ),
    ];
    let mut z0 = top;
    for (dx, dy, ha, hb, h, yaw, cover) in books {
        let cover = tinted(rng, cover);
        let faces = box_faces(
            DVec3::new(0.22 + dx, 0.15 + dy, z0),
            ha,
            hb,
            h,
            yaw.to_radians(),
        );
        for (k, face) in faces.into_iter().enumerate() {
            let (weight, paint): (f64, Paint) = match k {
                0 => (1.0, plain(cover)),
                1 => (0.2, plain(cover)),
                // The spine, with a gold band near each end.
                5 => (
                    1.0,
                    Box::new(move |_, u, _| {
                        if (0.1..0.16).contains(&u) || (0.84..0.9).contains(&u) {
                            DVec3::new(0.85, 0.70, 0.30)
                        } else {
                            cover
                        }
                    }),
                ),
                _ => (
                    1.0,
                    Box::new(move |_, _, v| pages * (0.93 + 0.07 * (v * PI).sin())),
                ),
            };
            parts.add(8, face, weight, MATTE, paint);
        }
        z0 += h;
    }

    // 9: potted plant on the floor beside the table, 40 cm tall.
    let c = DVec3::new(1.15, 0.75, 0.0);
    let terracotta = tinted(rng, DVec3::new(0.76, 0.40, 0.24));
    parts.add(
        9,
        upright(c, 0.08, 0.11, 0.18, false),
        1.0,
        MATTE,
        plain(terracotta),
    );
    parts.add(
        9,
        upright(c + 0.15 * z, 0.1033, 0.1067, 0.03, true),
        1.0,
        MATTE,
        plain(terracotta * 0.8),
    );
    parts.add(
        9,
        flat_ring(c + 0.15 * z, 0.0, 0.1033, false),
        1.0,
        MATTE,
        plain(DVec3::new(0.24, 0.16, 0.10)),
    );
    let leaf_green = tinted(rng, DVec3::new(0.20, 0.52, 0.15));
    let leaf_look = Look {
        light: Light::TwoSided,
        ..MATTE
    };
    for k in 0..16 {
        // Golden-angle yaws and spread pitches give an even, natural crown; steeper leaves
        // are longer, as inner leaves of a real plant are.
        let kf = k as f64;
        let yaw = kf * 2.399_963 + 0.3;
        let steep = (kf * 0.618_034).fract();
        let pitch = (30.0 + 50.0 * steep).to_radians();
        let length = 0.18 + 0.16 * steep;
        let radial = DVec3::new(yaw.cos(), yaw.sin(), 0.0);
        let dir = pitch.cos() * radial + pitch.sin() * z;
        let side = DVec3::new(-yaw.sin(), yaw.cos(), 0.0);
        let tone = 0.8 + 0.35 * hash01(k, 5);
        parts.add(
            9,
            Shape::Leaf {
                base: c + 0.15 * z + 0.02 * radial,
                dir,
                side,
                length,
                half_width: 0.045,
                droop: 0.2,
            },
            1.0,
            leaf_look,
            Box::new(move |_, u, _| {
                // A paler midrib down the leaf's centre.
                let rib = if (u - 0.5).abs() < 0.05 { 1.3 } else { 1.0 };
                leaf_green * tone * rib
            }),
        );
    }

    // 10: glass of water, 7 cm wide, 11 cm tall, two-thirds full; semi-transparent.
    let c = DVec3::new(-0.05, 0.22, top);
    let glass = Look {
        opacity: Opacity::Range(0.08, 0.3),
        sh: 0.15,
        light: Light::Diffuse,
        noise: 1.0,
    };
    let water = Look {
        opacity: Opacity::Range(0.15, 0.4),
        sh: 0.08,
        light: Light::Diffuse,
        noise: 1.0,
    };
    let glass_tint = tinted(rng, DVec3::new(0.84, 0.91, 0.95));
    let water_tint = tinted(rng, DVec3::new(0.45, 0.66, 0.86));
    parts.add(
        10,
        upright(c, 0.035, 0.037, 0.11, false),
        1.0,
        glass,
        plain(glass_tint),
    );
    parts.add(
        10,
        flat_ring(c + 0.004 * z, 0.0, 0.035, false),
        1.0,
        Look {
            opacity: Opacity::Range(0.3, 0.6),
            ..glass
        },
        plain(glass_tint),
    );
    parts.add(
        10,
        upright(c + 0.006 * z, 0.0335, 0.0347, 0.069, false),
        1.0,
        water,
        plain(water_tint),
    );
    parts.add(
        10,
        flat_ring(c + 0.075 * z, 0.0, 0.0347, false),
        1.0,
        Look {
            opacity: Opacity::Range(0.35, 0.65),
            ..water
        },
        plain(water_tint * 1.1),
    );
    parts.add(
        10,
        Shape::Torus {
            center: c + 0.11 * z,
            e1: x,
            e2: y,
            major: 0.037,
            minor: 0.0015,
            a0: 0.0,
            a1: TAU,
        },
        4.0,
        Look {
            opacity: Opacity::Range(0.4, 0.7),
            ..glass
        },
        plain(DVec3::splat(0.95)),
    );

    parts.0
}

// ---------------------------------------------------------------------------------------------
// Sampling

/// Direction towards the baked key light (above, in front of and right of the table).
const LIGHT_DIR: DVec3 = DVec3::new(0.35, -0.5, 0.8);
/// Share of the colour that does not depend on the light's angle.
const AMBIENT: f64 = 0.62;
/// Tangent standard deviation as a fraction of the local sample spacing: 3σ reaches well past
/// the neighbours, so the surface renders solid without holes.
const SPLAT_SPREAD: f64 = 0.8;

/// Per-Gaussian arrays under construction.
struct Builder {
    means: Vec<[f32; 3]>,
    scales: Vec<[f32; 3]>,
    rotations: Vec<[f32; 4]>,
    opacities: Vec<f32>,
    sh: Vec<[f32; 12]>,
    ids: Vec<i32>,
}

impl Builder {
    fn with_capacity(n: usize) -> Self {
        Builder {
            means: Vec::with_capacity(n),
            scales: Vec::with_capacity(n),
            rotations: Vec::with_capacity(n),
            opacities: Vec::with_capacity(n),
            sh: Vec::with_capacity(n),
            ids: Vec::with_capacity(n),
        }
    }

    /// The scene with Gaussians in `order`.
    fn into_scene(self, order: &[usize]) -> Scene {
        let names: BTreeMap<i32, String> =
            LAYOUT.iter().map(|o| (o.id, o.name.to_string())).collect();
        Scene {
            means: order.iter().map(|&i| self.means[i]).collect(),
            scales: order.iter().map(|&i| self.scales[i]).collect(),
            rotations: order.iter().map(|&i| self.rotations[i]).collect(),
            opacities: order.iter().map(|&i| self.opacities[i]).collect(),
            sh_degree: 1,
            sh: order.iter().flat_map(|&i| self.sh[i]).collect(),
            extras: Extras {
                labels: Some(Labels {
                    source: DEMO_LABEL_SOURCE.to_string(),
                    ids: order.iter().map(|&i| self.ids[i]).collect(),
                    names,
                }),
                ..Extras::default()
            },
        }
    }
}

/// Places `n` Gaussians on a part: rows along v, each row spread evenly along u with jitter,
/// the row count chosen so the spacing is about equal along u and v.
fn sample_part(part: &Part, n: usize, rng: &mut ChaCha8Rng, out: &mut Builder) {
    if n == 0 {
        return;
    }
    let shape = &part.shape;
    let (mut len_u, mut len_v) = (0.0, 0.0);
    for i in 0..4 {
        for j in 0..4 {
            let (_, pu, pv, _) = shape.frame((i as f64 + 0.5) / 4.0, (j as f64 + 0.5) / 4.0);
            len_u += pu.length();
            len_v += pv.length();
        }
    }
    let rows = ((n as f64 * len_v / len_u).sqrt().round() as usize).clamp(1, n);
    let light = LIGHT_DIR.normalize();
    for j in 0..rows {
        let in_row = (j + 1) * n / rows - j * n / rows;
        if in_row == 0 {
            continue;
        }
        let phase = if shape.periodic_u() {
            rng.random()
        } else {
            0.0
        };
        for i in 0..in_row {
            // Jitter stays inside the cell, so points never leave the surface's domain.
            let u = (i as f64 + 0.5 + rng.random_range(-0.3..0.3)) / in_row as f64 + phase;
            let u = u - u.floor();
            let v = (j as f64 + 0.5 + rng.random_range(-0.3..0.3)) / rows as f64;
            let (p, pu, pv, hint) = shape.frame(u, v);
            let mut normal = pu.cross(pv).try_normalize().unwrap_or(hint.normalize());
            if normal.dot(hint) < 0.0 {
                normal = -normal;
            }
            let t = (pu - normal * normal.dot(pu))
                .try_normalize()
                .unwrap_or_else(|| normal.any_orthonormal_vector());
            // A slight random spin about the normal, as optimised splats have.
            let spin: f64 = rng.random_range(-0.25..0.25);
            let t1 = t * spin.cos() + normal.cross(t) * spin.sin();
            let t2 = normal.cross(t1);
            let (space_u, space_v) = (pu.length() / in_row as f64, pv.length() / rows as f64);
            let mut s1 = SPLAT_SPREAD * space_u * rng.random_range(0.85..1.2);
            let mut s2 = SPLAT_SPREAD * space_v * rng.random_range(0.85..1.2);
            // Keep splats from spilling past open edges (a cone's tip, a table's rim), which
            // would blur silhouettes into halos.
            let (edge_u, edge_v0, edge_v1) = shape.open_edges();
            if edge_u {
                let d = u.min(1.0 - u) * pu.length();
                s1 = s1.min((0.5 * d).max(0.3 * space_u));
            }
            let d = match (edge_v0, edge_v1) {
                (true, true) => v.min(1.0 - v),
                (true, false) => v,
                (false, true) => 1.0 - v,
                (false, false) => f64::INFINITY,
            } * pv.length();
            s2 = s2.min((0.5 * d).max(0.3 * space_v));
            // Near poles and apexes one spacing shrinks; widen that axis rather than leave
            // needle-like splats.
            let big = s1.max(s2);
            s1 = s1.max(0.25 * big);
            s2 = s2.max(0.25 * big);
            let s3 = (0.07 * s1.min(s2)).max(2e-5);
            let q = DQuat::from_mat3(&DMat3::from_cols(t1, t2, normal)).normalize();
            let q = [q.w as f32, q.x as f32, q.y as f32, q.z as f32];
            let qn = q.iter().map(|c| c * c).sum::<f32>().sqrt();

            let lambert = normal.dot(light);
            let shading = match part.look.light {
                Light::Diffuse => AMBIENT + (1.0 - AMBIENT) * lambert.max(0.0),
                Light::TwoSided => AMBIENT + (1.0 - AMBIENT) * lambert.abs(),
                Light::Emissive => 1.0,
            };
            let mut gauss = || rng.sample::<f64, _>(StandardNormal);
            let noise = part.look.noise;
            let luminance = 1.0 + 0.04 * noise * gauss();
            let base = (part.paint)(p, u, v) * shading * luminance;
            let colour = DVec3::new(
                base.x + 0.02 * noise * gauss(),
                base.y + 0.02 * noise * gauss(),
                base.z + 0.02 * noise * gauss(),
            )
            .clamp(DVec3::ZERO, DVec3::ONE);
            let mut sh = [0.0f32; 12];
            for (c, value) in colour.to_array().into_iter().enumerate() {
                sh[c] = ((value - 0.5) / f64::from(SH_C0)) as f32;
            }
            for coefficient in &mut sh[3..] {
                *coefficient = (part.look.sh * gauss()) as f32;
            }
            let opacity = match part.look.opacity {
                Opacity::Solid => {
                    if rng.random_bool(0.8) {
                        rng.random_range(0.75..0.99)
                    } else {
                        rng.random_range(0.25..0.75)
                    }
                }
                Opacity::Range(lo, hi) => rng.random_range(lo..hi),
            };

            out.means.push([p.x as f32, p.y as f32, p.z as f32]);
            out.scales.push([s1 as f32, s2 as f32, s3 as f32]);
            out.rotations.push(q.map(|c| c / qn));
            out.opacities.push(opacity as f32);
            out.sh.push(sh);
            out.ids.push(part.label);
        }
    }
}
