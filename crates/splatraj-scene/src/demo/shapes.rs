//! The parametric surfaces Gaussians are sampled on, and the composite shapes (box faces,
//! upright shells, flat rings) the objects are built from.

use std::f64::consts::{PI, TAU};

use glam::DVec3;

/// A parametric surface over (u, v) ∈ [0, 1]².
#[derive(Debug, Clone, Copy)]
pub(super) enum Shape {
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
    pub(super) fn periodic_u(&self) -> bool {
        !matches!(self, Shape::Rect { .. } | Shape::Leaf { .. })
    }

    /// Which parameter bounds are open edges of the surface (u = 0 and 1 together, v = 0,
    /// v = 1), as opposed to seams, poles or apexes where the surface closes or continues.
    pub(super) fn open_edges(&self) -> (bool, bool, bool) {
        match *self {
            Shape::Rect { .. } | Shape::Leaf { .. } => (true, true, true),
            Shape::Annulus { r0, .. } => (false, r0 > 0.0, true),
            Shape::Frustum { .. } => (false, true, true),
            Shape::Sphere { .. } | Shape::Torus { .. } => (false, false, false),
        }
    }

    /// Point at (u, v) and a direction on the outer side of the surface there.
    pub(super) fn eval(&self, u: f64, v: f64) -> (DVec3, DVec3) {
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
    pub(super) fn frame(&self, u: f64, v: f64) -> (DVec3, DVec3, DVec3, DVec3) {
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
    pub(super) fn area(&self) -> f64 {
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

/// The six faces of a box standing on `bottom_center`, yawed by `yaw` about z, in the order
/// +z, −z, +a, −a, +b, −b (a, b the yawed x and y axes), each with an outward normal.
pub(super) fn box_faces(
    bottom_center: DVec3,
    half_a: f64,
    half_b: f64,
    height: f64,
    yaw: f64,
) -> [Shape; 6] {
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
pub(super) fn upright(base: DVec3, r0: f64, r1: f64, height: f64, inward: bool) -> Shape {
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
pub(super) fn flat_ring(center: DVec3, r0: f64, r1: f64, down: bool) -> Shape {
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
