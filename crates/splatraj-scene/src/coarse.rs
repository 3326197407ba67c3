//! A coarser copy of a scene for renders that cannot tell the difference: neighbouring small
//! Gaussians of the same class merged into one, so that a 6 M-Gaussian capture optimised at
//! 96 × 54 pixels costs what a 1 M one does.
//!
//! **Grouping.** Space is cut into cubic cells; the Gaussians of one cell and one class (the
//! caller's label: which objects a Gaussian belongs to, so a merged Gaussian never mixes an
//! object with its surroundings) become one. A Gaussian whose 3σ reach is larger than a cell
//! is kept as it is (it is already coarse, and merging it with its small neighbours would
//! smear them over it). The cell size is the smallest (found by bisection on its logarithm)
//! whose group count fits the budget.
//!
//! **Merging** (moment matching, as in the level-of-detail hierarchies of hierarchical 3DGS):
//! each member weighs wᵢ = αᵢ·aᵢ, its opacity times the area of its largest cross-section
//! (aᵢ = the product of its two largest scales), what it contributes to the image. The merged
//! mean and SH coefficients are the weighted means; the covariance is the weighted mean of
//! Σᵢ + (μᵢ − μ)(μᵢ − μ)ᵀ, whose eigen-decomposition gives the scales and rotation; the opacity
//! spreads the members' total Σ wᵢ over the merged cross-section a, α = Σ wᵢ / a, at most what
//! the members give stacked on one another, 1 − Π(1 − αᵢ). Where that bound saturates it (an
//! opaque surface of small splats), the cross-section grows instead, up to twice its area: a
//! single Gaussian at the bound covers only half the disc its members fill.
//!
//! It is an approximation: renders of the copy match the scene's where a merged Gaussian
//! covers at most a pixel or so. What renders it is for the caller to decide.

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;

use crate::scene::{Extras, Scene};

/// Cells per axis at most: a cell index fits 18 bits, three of them and a class 64.
const CELL_BITS: u32 = 18;
/// Classes at most (the 10 bits of the key a cell leaves).
pub const MAX_CLASSES: usize = 1 << (64 - 3 * CELL_BITS);
/// Bisection steps on log2(cell size).
const BISECTIONS: usize = 14;
/// The most a saturated merge's cross-section grows (see [`merge_group`]).
const MAX_AREA_GROWTH: f64 = 2.0;
/// Reach of a Gaussian, in standard deviations, compared with the cell size.
const REACH_SIGMAS: f32 = 3.0;

/// A coarser copy of a scene and which of its Gaussians each original one went into.
#[derive(Debug, Clone)]
pub struct Coarse {
    /// The merged scene (SH degree of the original; no extras).
    pub scene: Scene,
    /// For each Gaussian of the original scene, the index of its merged Gaussian.
    pub coarse_from_fine: Vec<u32>,
    /// Edge of the cells, in scene units.
    pub cell: f32,
}

impl Coarse {
    /// Per-Gaussian values of the original scene (e.g. an object mask) carried to the copy:
    /// each merged Gaussian gets its members' mean, weighted as the merge weighs them.
    pub fn carry(&self, fine: &Scene, values: &[f32]) -> Vec<f32> {
        let mut sums = vec![(0.0f64, 0.0f64); self.scene.len()];
        for (i, &g) in self.coarse_from_fine.iter().enumerate() {
            let w = weight(fine, i);
            let s = &mut sums[g as usize];
            s.0 += w * f64::from(values[i]);
            s.1 += w;
        }
        sums.iter()
            .map(|&(v, w)| if w > 0.0 { (v / w) as f32 } else { 0.0 })
            .collect()
    }
}

/// Why a scene was not coarsened.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CoarseError {
    /// More classes than the key holds.
    #[error("{0} classes of Gaussians to keep apart; at most {MAX_CLASSES} can be")]
    TooManyClasses(usize),
    /// `classes` is not one per Gaussian.
    #[error("{classes} classes for {gaussians} Gaussians")]
    ClassCount {
        /// Classes given.
        classes: usize,
        /// Gaussians in the scene.
        gaussians: usize,
    },
    /// The scene's centres are not finite.
    #[error("the scene's centres have no finite bounds")]
    NoBounds,
}

/// `scene` merged down to at most `budget` Gaussians (see the module docs), never mixing two
/// `classes` (one per Gaussian, each below [`MAX_CLASSES`]). A scene of at most `budget`
/// Gaussians comes back as it is, one merged Gaussian per original. When even the coarsest
/// cells leave more groups than `budget` (more large Gaussians than that), the coarsest is
/// returned.
pub fn coarsen(scene: &Scene, classes: &[u32], budget: usize) -> Result<Coarse, CoarseError> {
    if classes.len() != scene.len() {
        return Err(CoarseError::ClassCount {
            classes: classes.len(),
            gaussians: scene.len(),
        });
    }
    if let Some(&c) = classes.iter().find(|&&c| c as usize >= MAX_CLASSES) {
        return Err(CoarseError::TooManyClasses(c as usize + 1));
    }
    let bounds = scene.bounds().ok_or(CoarseError::NoBounds)?;
    let extent = (0..3)
        .map(|k| bounds.max[k] - bounds.min[k])
        .fold(0.0f32, f32::max)
        .max(f32::MIN_POSITIVE);
    let grid = Grid {
        origin: bounds.min,
        scene,
        classes,
    };
    if scene.len() <= budget {
        // A zero cell keeps every Gaussian alone, in its order.
        return Ok(grid.merge(0.0));
    }
    // The finest cell at which a cell index still fits its bits, and the whole scene.
    let (mut fine, mut coarse) = (
        (extent / ((1u32 << CELL_BITS) - 2) as f32).log2(),
        extent.log2() + 1.0,
    );
    if grid.groups(fine.exp2()) <= budget {
        return Ok(grid.merge(fine.exp2()));
    }
    for _ in 0..BISECTIONS {
        let middle = 0.5 * (fine + coarse);
        if grid.groups(middle.exp2()) <= budget {
            coarse = middle;
        } else {
            fine = middle;
        }
    }
    Ok(grid.merge(coarse.exp2()))
}

/// The merge weight of Gaussian `i`: opacity times its largest cross-section.
fn weight(scene: &Scene, i: usize) -> f64 {
    let mut s = scene.scales[i].map(f64::from);
    s.sort_by(f64::total_cmp);
    f64::from(scene.opacities[i]) * s[1] * s[2]
}

/// The cells of one cell size over a scene.
struct Grid<'a> {
    origin: [f32; 3],
    scene: &'a Scene,
    classes: &'a [u32],
}

/// The key of a Gaussian kept alone (its own group): above every cell key.
const ALONE: u64 = u64::MAX;

impl Grid<'_> {
    /// Gaussian `i`'s group key at cell size `cell`: its class and cell, or [`ALONE`].
    fn key(&self, i: usize, cell: f32) -> u64 {
        let scale = self.scene.scales[i].into_iter().fold(0.0f32, f32::max);
        if REACH_SIGMAS * scale > cell {
            return ALONE;
        }
        let max = (1u64 << CELL_BITS) - 1;
        let mut key = u64::from(self.classes[i]);
        for k in 0..3 {
            let index = ((self.scene.means[i][k] - self.origin[k]) / cell).floor();
            key = (key << CELL_BITS) | (index.max(0.0) as u64).min(max);
        }
        key
    }

    /// Keys of every Gaussian, sorted, with the Gaussians' indices.
    fn sorted(&self, cell: f32) -> Vec<(u64, u32)> {
        let mut keys: Vec<(u64, u32)> = (0..self.scene.len())
            .into_par_iter()
            .map(|i| (self.key(i, cell), i as u32))
            .collect();
        keys.par_sort_unstable();
        keys
    }

    /// Number of groups at cell size `cell`.
    fn groups(&self, cell: f32) -> usize {
        let keys = self.sorted(cell);
        ranges(&keys).len()
    }

    /// The merged scene at cell size `cell`.
    fn merge(&self, cell: f32) -> Coarse {
        let keys = self.sorted(cell);
        let groups = ranges(&keys);
        let members = |g: &std::ops::Range<usize>| keys[g.clone()].iter().map(|k| k.1 as usize);
        let merged: Vec<Merged> = groups
            .par_iter()
            .map(|g| merge_group(self.scene, members(g)))
            .collect();
        let mut coarse_from_fine = vec![0u32; self.scene.len()];
        for (j, g) in groups.iter().enumerate() {
            for i in members(g) {
                coarse_from_fine[i] = j as u32;
            }
        }
        let coeffs = 3 * self.scene.sh_coeffs();
        let scene = Scene {
            means: merged.iter().map(|m| m.mean).collect(),
            scales: merged.iter().map(|m| m.scale).collect(),
            rotations: merged.iter().map(|m| m.rotation).collect(),
            opacities: merged.iter().map(|m| m.opacity).collect(),
            sh_degree: self.scene.sh_degree,
            sh: merged.iter().flat_map(|m| m.sh.iter().copied()).collect(),
            extras: Extras::default(),
        };
        debug_assert_eq!(scene.sh.len(), coeffs * scene.len());
        Coarse {
            scene,
            coarse_from_fine,
            cell,
        }
    }
}

/// The index ranges of equal keys in sorted `keys`; each [`ALONE`] key is a range of its own.
fn ranges(keys: &[(u64, u32)]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=keys.len() {
        if i == keys.len() || keys[i].0 != keys[start].0 || keys[start].0 == ALONE {
            out.push(start..i);
            start = i;
        }
    }
    out
}

/// One merged Gaussian.
struct Merged {
    mean: [f32; 3],
    scale: [f32; 3],
    rotation: [f32; 4],
    opacity: f32,
    sh: Vec<f32>,
}

/// Gaussian `i`'s covariance R diag(s²) Rᵀ.
fn covariance(scene: &Scene, i: usize) -> DMat3 {
    let [w, x, y, z] = scene.rotations[i].map(f64::from);
    let r = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w).normalize());
    let s = DVec3::from(scene.scales[i].map(f64::from));
    r * DMat3::from_diagonal(s * s) * r.transpose()
}

/// The moment-matched merge of `members` (see the module docs).
fn merge_group(scene: &Scene, members: impl Iterator<Item = usize> + Clone) -> Merged {
    let coeffs = 3 * scene.sh_coeffs();
    let mut first = members.clone();
    let only = first.next().expect("a group has a member");
    if first.next().is_none() {
        return Merged {
            mean: scene.means[only],
            scale: scene.scales[only],
            rotation: scene.rotations[only],
            opacity: scene.opacities[only],
            sh: scene.sh[only * coeffs..(only + 1) * coeffs].to_vec(),
        };
    }
    let members: Vec<usize> = members.collect();
    let weights: Vec<f64> = members.iter().map(|&i| weight(scene, i)).collect();
    let total: f64 = weights.iter().sum();
    // A group of fully transparent members still needs weights: fall back to equal ones.
    let shares: Vec<f64> = if total > 0.0 {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / members.len() as f64; members.len()]
    };
    let mean: DVec3 = members
        .iter()
        .zip(&shares)
        .map(|(&i, &w)| w * DVec3::from(scene.means[i].map(f64::from)))
        .sum();
    let mut spread = DMat3::ZERO;
    let mut sh = vec![0.0f64; coeffs];
    let mut clear = 1.0f64;
    for (&i, &w) in members.iter().zip(&shares) {
        let d = DVec3::from(scene.means[i].map(f64::from)) - mean;
        let outer = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        spread += (covariance(scene, i) + outer) * w;
        for (s, &c) in sh.iter_mut().zip(&scene.sh[i * coeffs..(i + 1) * coeffs]) {
            *s += w * f64::from(c);
        }
        clear *= 1.0 - f64::from(scene.opacities[i]);
    }
    let (mut scale, rotation) = scales_and_rotation(spread);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| scale[a].total_cmp(&scale[b]));
    let area = scale[order[1]] * scale[order[2]];
    let spread_opacity = if area > 0.0 {
        total / area
    } else {
        f64::INFINITY
    };
    let most = (1.0 - clear).clamp(0.0, 1.0);
    let opacity = if spread_opacity <= most {
        spread_opacity
    } else {
        // Saturated: the members cover their footprint more evenly than one Gaussian at that
        // opacity can, so the cross-section grows to carry the rest of Σ wᵢ, up to twice
        // (the area of the disc that a uniform spread of σ fills is 2 · 2πσ², the integral
        // of a Gaussian of opacity 1).
        let grow = (spread_opacity / most).min(MAX_AREA_GROWTH).sqrt();
        scale[order[1]] *= grow;
        scale[order[2]] *= grow;
        most
    };
    Merged {
        mean: mean.as_vec3().to_array(),
        scale: scale.as_vec3().to_array(),
        rotation,
        opacity: opacity as f32,
        sh: sh.into_iter().map(|c| c as f32).collect(),
    }
}

/// Standard deviations and rotation (w, x, y, z) of a covariance: its eigen-decomposition.
/// nalgebra's symmetric eigen-solver (the linear-algebra crate of the Rust ecosystem) rather
/// than a hand-written Jacobi sweep.
fn scales_and_rotation(covariance: DMat3) -> (DVec3, [f32; 4]) {
    let m = nalgebra::Matrix3::from_fn(|r, c| covariance.col(c)[r]);
    let eigen = nalgebra::SymmetricEigen::new(m);
    let column = |k: usize| {
        let v = eigen.eigenvectors.column(k);
        DVec3::new(v[0], v[1], v[2])
    };
    let (x, y) = (column(0), column(1));
    // A rotation needs a right-handed frame; the third axis follows from the first two.
    let axes = DMat3::from_cols(x, y, x.cross(y));
    let scale = DVec3::new(
        eigen.eigenvalues[0].max(0.0).sqrt(),
        eigen.eigenvalues[1].max(0.0).sqrt(),
        eigen.eigenvalues[2].max(0.0).sqrt(),
    );
    // Degenerate merges (collinear or coincident members) keep a sliver of thickness.
    let floor = 1e-7 * scale.max_element().max(1e-12);
    let q = DQuat::from_mat3(&axes).normalize();
    (
        scale.max(DVec3::splat(floor)),
        [q.w as f32, q.x as f32, q.y as f32, q.z as f32],
    )
}
