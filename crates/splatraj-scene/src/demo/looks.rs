//! How the parts look: materials (opacity, view-dependent colour, lighting), colours and
//! the textures of floor, walls and table.

use std::f64::consts::TAU;

use glam::DVec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::DEMO_TABLE_TOP_Z;

/// How a part's Gaussians look beyond their colour.
#[derive(Debug, Clone, Copy)]
pub(super) struct Look {
    /// Opacity range: most Gaussians in the upper one, some in the lower one.
    pub(super) opacity: Opacity,
    /// Standard deviation of the degree-1 SH coefficients (view-dependent colour).
    pub(super) sh: f64,
    /// How the baked key light shades the colour.
    pub(super) light: Light,
    /// Scale of the per-splat colour noise (1 for objects; less on large plain surfaces,
    /// whose coarser splats would otherwise look grainy).
    pub(super) noise: f64,
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Opacity {
    /// 80 % in [0.75, 0.99], 20 % in [0.25, 0.75], like a converged capture.
    Solid,
    /// Uniform in the range (semi-transparent materials).
    Range(f64, f64),
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Light {
    /// Lambert on the outer side.
    Diffuse,
    /// Lambert on either side (thin leaves).
    TwoSided,
    /// Unshaded (light sources).
    Emissive,
}

pub(super) const MATTE: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.04,
    light: Light::Diffuse,
    noise: 1.0,
};
pub(super) const ROOM: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.02,
    light: Light::Diffuse,
    noise: 0.4,
};
pub(super) const GLOSSY: Look = Look {
    opacity: Opacity::Solid,
    sh: 0.12,
    light: Light::Diffuse,
    noise: 1.0,
};

pub(super) type Paint = Box<dyn Fn(DVec3, f64, f64) -> DVec3>;

/// Colour of a plain material.
pub(super) fn plain(c: DVec3) -> Paint {
    Box::new(move |_, _, _| c)
}

/// Deterministic hash of integers to [0, 1) (splitmix64), for per-plank or per-leaf variation
/// that must not depend on the seed (the layout and textures stay fixed).
pub(super) fn hash01(a: i64, b: i64) -> f64 {
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
pub(super) fn floor_color(p: DVec3) -> DVec3 {
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
pub(super) fn wall_color(p: DVec3) -> DVec3 {
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
pub(super) fn table_color(p: DVec3) -> DVec3 {
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

/// Multiplies a colour by a slight random tint: different seeds look slightly different.
pub(super) fn tinted(rng: &mut ChaCha8Rng, c: DVec3) -> DVec3 {
    let mut f = || 1.0 + 0.03 * rng.sample::<f64, _>(StandardNormal);
    c * DVec3::new(f(), f(), f())
}
