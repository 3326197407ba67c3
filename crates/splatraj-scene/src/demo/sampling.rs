//! Gaussians on the parts' surfaces: rows of jittered samples, flat splats sized from the
//! local spacing, baked lighting, noise and opacity, then the scene's arrays.

use std::collections::BTreeMap;

use glam::{DMat3, DQuat, DVec3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::DEMO_LABEL_SOURCE;
use super::looks::{Light, Opacity};
use super::objects::{OBJECTS, Part};
use crate::scene::{Extras, Labels, SH_C0, Scene};

/// Direction towards the baked key light (above, in front of and right of the table).
const LIGHT_DIR: DVec3 = DVec3::new(0.35, -0.5, 0.8);
/// Share of the colour that does not depend on the light's angle.
const AMBIENT: f64 = 0.62;
/// Tangent standard deviation as a fraction of the local sample spacing: 3σ reaches well past
/// the neighbours, so the surface renders solid without holes.
const SPLAT_SPREAD: f64 = 0.8;

/// Per-Gaussian arrays under construction.
pub(super) struct Builder {
    means: Vec<[f32; 3]>,
    scales: Vec<[f32; 3]>,
    rotations: Vec<[f32; 4]>,
    opacities: Vec<f32>,
    sh: Vec<[f32; 12]>,
    pub(super) ids: Vec<i32>,
}

impl Builder {
    pub(super) fn with_capacity(n: usize) -> Self {
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
    pub(super) fn into_scene(self, order: &[usize]) -> Scene {
        let names: BTreeMap<i32, String> = (0..)
            .zip(&OBJECTS)
            .map(|(id, o)| (id, o.name.to_string()))
            .collect();
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
pub(super) fn sample_part(part: &Part, n: usize, rng: &mut ChaCha8Rng, out: &mut Builder) {
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
