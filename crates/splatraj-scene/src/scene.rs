//! The Gaussian scene as plain Rust data: a struct of arrays, activated values.

use std::collections::BTreeMap;

use serde::Serialize;

/// Zeroth-order spherical harmonic constant: colour = 0.5 + C0 · f_dc.
pub const SH_C0: f32 = 0.282_094_8;

/// Number of SH coefficients per colour channel for a degree (1, 4, 9, 16).
pub fn sh_coeffs_for_degree(degree: u8) -> usize {
    let d = degree as usize + 1;
    d * d
}

/// SH degree whose per-channel coefficient count is `coeffs`, if it is a valid count.
pub fn sh_degree_for_coeffs(coeffs: usize) -> Option<u8> {
    (0..=3u8).find(|&d| sh_coeffs_for_degree(d) == coeffs)
}

/// A 3D Gaussian Splatting scene.
///
/// Every per-Gaussian array has `len()` entries. Values are *activated*: scales are linear
/// (exp of the file's log-scales), opacities are in [0, 1] (sigmoid of the file's logits) and
/// rotations are unit quaternions `(w, x, y, z)` that map the Gaussian's local axes to world.
///
/// Spherical harmonics are stored per Gaussian as `[coefficient][channel]`, i.e. the flat
/// layout `[n, sh_coeffs_for_degree(sh_degree), 3]`, coefficient 0 being the DC term. INRIA
/// files group `f_rest_*` by channel (all red, then green, then blue); readers and the writer
/// convert between the two layouts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    /// Gaussian centres in world coordinates.
    pub means: Vec<[f32; 3]>,
    /// Standard deviations along the Gaussian's local axes (activated, > 0).
    pub scales: Vec<[f32; 3]>,
    /// Unit quaternions (w, x, y, z): local axes to world.
    pub rotations: Vec<[f32; 4]>,
    /// Opacities in [0, 1] (activated).
    pub opacities: Vec<f32>,
    /// Degree of the spherical harmonics, 0 to 3.
    pub sh_degree: u8,
    /// SH coefficients, flat `[n, (sh_degree + 1)², 3]`.
    pub sh: Vec<f32>,
    /// Optional per-Gaussian data beyond the rendering parameters.
    pub extras: Extras,
}

/// Per-Gaussian data that is not needed to render colour: labels, features, other properties.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Extras {
    /// Integer object/instance labels, if the file or a sidecar gave them.
    pub labels: Option<Labels>,
    /// Feature vectors (e.g. language embeddings), if the file or a sidecar gave them.
    pub features: Option<Features>,
    /// Any other named per-Gaussian float property (kept so that a round trip loses nothing).
    pub properties: Vec<NamedProperty>,
}

/// Integer labels, one per Gaussian, with optional names.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Labels {
    /// Where the labels came from (a PLY property name or a sidecar file).
    pub source: String,
    /// One label id per Gaussian.
    pub ids: Vec<i32>,
    /// Human-readable name of each id that has one.
    pub names: BTreeMap<i32, String>,
}

impl Labels {
    /// Distinct label ids with how many Gaussians carry each, ascending by id.
    pub fn counts(&self) -> BTreeMap<i32, usize> {
        let mut counts = BTreeMap::new();
        for &id in &self.ids {
            *counts.entry(id).or_insert(0) += 1;
        }
        counts
    }
}

/// Feature vectors, `dim` floats per Gaussian, flat `[n, dim]`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Features {
    /// Names of the properties the columns came from (`semantic_0`, …) or a sidecar name.
    pub names: Vec<String>,
    /// Length of each vector.
    pub dim: usize,
    /// Flat `[n, dim]` values.
    pub values: Vec<f32>,
}

impl Features {
    /// Feature vector of Gaussian `i`.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.values[i * self.dim..(i + 1) * self.dim]
    }
}

/// A named per-Gaussian float property that has no special meaning to splatraj.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NamedProperty {
    /// Property name as in the file.
    pub name: String,
    /// One value per Gaussian.
    pub values: Vec<f32>,
}

/// Axis-aligned bounds of a set of points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bounds {
    /// Smallest coordinate on each axis.
    pub min: [f32; 3],
    /// Largest coordinate on each axis.
    pub max: [f32; 3],
}

impl Bounds {
    /// Centre of the box.
    pub fn center(&self) -> [f32; 3] {
        std::array::from_fn(|k| 0.5 * (self.min[k] + self.max[k]))
    }
    /// Edge lengths of the box.
    pub fn size(&self) -> [f32; 3] {
        std::array::from_fn(|k| self.max[k] - self.min[k])
    }
}

impl Scene {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when the scene holds no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per channel, `(sh_degree + 1)²`.
    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }

    /// SH coefficients of Gaussian `i`, `[coefficient][channel]`.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let stride = 3 * self.sh_coeffs();
        &self.sh[i * stride..(i + 1) * stride]
    }

    /// The same scene with SH of `degree`: a lower degree drops the coefficients above it (the
    /// finer view dependence), a higher one adds zero coefficients (the same colours, at the
    /// cost of the higher degree: what `bench frames --sh-degree` times). Panics above 3, which
    /// callers check ([`sh_degree_for_coeffs`] names the valid degrees).
    pub fn with_sh_degree(mut self, degree: u8) -> Scene {
        assert!(degree <= 3, "SH degree {degree}: 0 to 3 only");
        let (from, to) = (self.sh_coeffs(), sh_coeffs_for_degree(degree));
        if from != to {
            let kept = 3 * from.min(to);
            let mut sh = vec![0.0f32; self.len() * 3 * to];
            for (new, old) in sh
                .chunks_exact_mut(3 * to)
                .zip(self.sh.chunks_exact(3 * from))
            {
                // `[coefficient][channel]`: the first coefficients of each Gaussian are kept.
                new[..kept].copy_from_slice(&old[..kept]);
            }
            self.sh = sh;
        }
        self.sh_degree = degree;
        self
    }

    /// Base (view-independent) colour of Gaussian `i`: max(0, 0.5 + C0 · f_dc).
    pub fn base_color(&self, i: usize) -> [f32; 3] {
        let dc = &self.sh_of(i)[..3];
        std::array::from_fn(|c| (0.5 + SH_C0 * dc[c]).max(0.0))
    }

    /// Bounds of all Gaussian centres; `None` for an empty scene.
    pub fn bounds(&self) -> Option<Bounds> {
        bounds_of(self.means.iter().copied())
    }

    /// Bounds of the centres between the `q` and `1 − q` quantiles on each axis, which ignores
    /// the stray far-away Gaussians real captures have. `None` for an empty scene.
    pub fn robust_bounds(&self, q: f32) -> Option<Bounds> {
        if self.is_empty() {
            return None;
        }
        let mut min = [0.0; 3];
        let mut max = [0.0; 3];
        for k in 0..3 {
            let mut axis: Vec<f32> = self.means.iter().map(|m| m[k]).collect();
            axis.sort_by(f32::total_cmp);
            let at = |p: f32| axis[((axis.len() - 1) as f32 * p).round() as usize];
            min[k] = at(q);
            max[k] = at(1.0 - q);
        }
        Some(Bounds { min, max })
    }

    /// Keeps only the Gaussians for which `keep[i]` is true, in every array and extra.
    pub fn retain(&mut self, keep: &[bool]) {
        *self = self.subset(keep);
    }

    /// A new scene of the Gaussians for which `keep[i]` is true, every array and extra
    /// included; copies only what it keeps (an object of a 3M-Gaussian scene without a copy of
    /// the whole scene first).
    pub fn subset(&self, keep: &[bool]) -> Scene {
        assert_eq!(
            keep.len(),
            self.len(),
            "subset mask length must match the scene"
        );
        fn filter<T: Copy>(values: &[T], keep: &[bool], stride: usize) -> Vec<T> {
            values
                .chunks_exact(stride)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(v, _)| v.iter().copied())
                .collect()
        }
        let extras = &self.extras;
        Scene {
            means: filter(&self.means, keep, 1),
            scales: filter(&self.scales, keep, 1),
            rotations: filter(&self.rotations, keep, 1),
            opacities: filter(&self.opacities, keep, 1),
            sh_degree: self.sh_degree,
            sh: filter(&self.sh, keep, 3 * self.sh_coeffs()),
            extras: Extras {
                labels: extras.labels.as_ref().map(|labels| Labels {
                    source: labels.source.clone(),
                    ids: filter(&labels.ids, keep, 1),
                    names: labels.names.clone(),
                }),
                features: extras.features.as_ref().map(|features| Features {
                    names: features.names.clone(),
                    dim: features.dim,
                    values: filter(&features.values, keep, features.dim.max(1)),
                }),
                properties: extras
                    .properties
                    .iter()
                    .map(|p| NamedProperty {
                        name: p.name.clone(),
                        values: filter(&p.values, keep, 1),
                    })
                    .collect(),
            },
        }
    }
}

/// Bounds of a set of points; `None` when there are none.
pub fn bounds_of(points: impl IntoIterator<Item = [f32; 3]>) -> Option<Bounds> {
    let mut it = points.into_iter();
    let first = it.next()?;
    let (mut min, mut max) = (first, first);
    for p in it {
        for k in 0..3 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    Some(Bounds { min, max })
}

/// Logistic sigmoid, the activation of PLY opacities.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Inverse of [`sigmoid`], for writing opacities back as logits. Clamped so 0 and 1 stay finite.
pub fn logit(p: f32) -> f32 {
    let p = p.clamp(1e-7, 1.0 - 1e-7);
    (p / (1.0 - p)).ln()
}
