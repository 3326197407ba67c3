//! The exact Euclidean distance from a point to an ellipsoid's surface, and the nearest surface
//! point, inside or outside.
//!
//! Algorithm: D. Eberly, "Distance from a Point to an Ellipse, an Ellipsoid, or a
//! Hyperellipsoid" (Geometric Tools, 2013). In the ellipsoid's own frame, with semi-axes sorted
//! e₀ ≥ e₁ ≥ e₂ and the point reflected into the first octant, the nearest surface point is
//! x_i = e_i² y_i / (t + e_i²), where t is the one root of Σ (e_i y_i / (t + e_i²))² = 1 in the
//! bracket that contains it; the root is found by bisection, which cannot fail or diverge
//! (and ends when the bracket stops shrinking in f64). Points on a symmetry plane take the
//! lower-dimensional branches of the paper, so the centre and points on an axis are exact too.
//! It is written out here: no maintained Rust crate offers point–ellipsoid distance (parry
//! and its kin have balls, boxes and convex hulls, not ellipsoids).

use glam::{DMat3, DQuat, DVec3};

/// Bisection steps at most (f64's bracket stops shrinking after ~1100 halvings at worst; the
/// loop ends earlier when it does).
const MAX_BISECTIONS: usize = 1100;

/// An ellipsoid: a centre, three orthonormal axes and a semi-axis length along each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    /// Centre, world coordinates.
    pub centre: DVec3,
    /// Columns: the local axes in world coordinates (orthonormal).
    pub axes: DMat3,
    /// Semi-axis lengths along the columns of `axes` (> 0).
    pub radii: DVec3,
}

/// The surface point of an ellipsoid nearest to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// The nearest surface point, world coordinates.
    pub point: DVec3,
    /// Outward unit normal of the surface there.
    pub normal: DVec3,
    /// Signed distance from the query point to the surface: > 0 outside, < 0 inside.
    pub distance: f64,
}

impl Ellipsoid {
    /// The `sigma`-σ ellipsoid of a Gaussian with mean `mean`, standard deviations `scale`
    /// along its local axes and rotation `quaternion` (w, x, y, z; normalised here).
    pub fn of_gaussian(mean: [f32; 3], scale: [f32; 3], quaternion: [f32; 4], sigma: f64) -> Self {
        let [w, x, y, z] = quaternion.map(f64::from);
        let q = DQuat::from_xyzw(x, y, z, w).normalize();
        Ellipsoid {
            centre: DVec3::from(mean.map(f64::from)),
            axes: DMat3::from_quat(q),
            radii: DVec3::from(scale.map(f64::from)) * sigma,
        }
    }

    /// The largest semi-axis.
    pub fn reach(&self) -> f64 {
        self.radii.max_element()
    }

    /// Whether `p` is inside (the quadratic form Σ (y_i/e_i)² is below 1).
    pub fn contains(&self, p: DVec3) -> bool {
        let y = self.axes.transpose() * (p - self.centre);
        (y / self.radii).length_squared() < 1.0
    }

    /// The nearest surface point to `p`, its outward normal and the signed distance.
    pub fn nearest(&self, p: DVec3) -> SurfacePoint {
        let local = self.axes.transpose() * (p - self.centre);
        // Sort the axes by decreasing radius; keep the order to put the answer back.
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| self.radii[b].total_cmp(&self.radii[a]));
        let e = order.map(|i| self.radii[i]);
        let y = order.map(|i| local[i].abs());
        let x_sorted = nearest_in_octant(e, y);
        let mut x = DVec3::ZERO;
        for (k, &i) in order.iter().enumerate() {
            x[i] = x_sorted[k].copysign(local[i]);
        }
        let inside = (local / self.radii).length_squared() < 1.0;
        let gap = (local - x).length();
        // ∇ of Σ (x_i/e_i)² at x: the outward normal, in local coordinates.
        let normal_local = (x / (self.radii * self.radii)).normalize_or_zero();
        SurfacePoint {
            point: self.centre + self.axes * x,
            normal: self.axes * normal_local,
            distance: if inside { -gap } else { gap },
        }
    }
}

/// Nearest point of the ellipsoid with semi-axes e₀ ≥ e₁ ≥ e₂ > 0 to y ≥ 0 (componentwise).
fn nearest_in_octant(e: [f64; 3], y: [f64; 3]) -> [f64; 3] {
    let [e0, e1, e2] = e;
    let [y0, y1, y2] = y;
    if y2 > 0.0 {
        if y1 > 0.0 {
            if y0 > 0.0 {
                let z = [y0 / e0, y1 / e1, y2 / e2];
                let g = z[0] * z[0] + z[1] * z[1] + z[2] * z[2] - 1.0;
                if g == 0.0 {
                    return y;
                }
                let r = [(e0 / e2).powi(2), (e1 / e2).powi(2), 1.0];
                let s = root(r, z, g);
                return [0, 1, 2].map(|i| r[i] * y[i] / (s + r[i]));
            }
            let [x1, x2] = nearest_on_ellipse([e1, e2], [y1, y2]);
            return [0.0, x1, x2];
        }
        if y0 > 0.0 {
            let [x0, x2] = nearest_on_ellipse([e0, e2], [y0, y2]);
            return [x0, 0.0, x2];
        }
        return [0.0, 0.0, e2];
    }
    // y₂ = 0: the nearest point may leave the plane (an inside point near the flat side).
    let (denom0, denom1) = (e0 * e0 - e2 * e2, e1 * e1 - e2 * e2);
    let (numer0, numer1) = (e0 * y0, e1 * y1);
    if numer0 < denom0 && numer1 < denom1 {
        let (xde0, xde1) = (numer0 / denom0, numer1 / denom1);
        let discr = 1.0 - xde0 * xde0 - xde1 * xde1;
        if discr > 0.0 {
            return [e0 * xde0, e1 * xde1, e2 * discr.sqrt()];
        }
    }
    let [x0, x1] = nearest_on_ellipse([e0, e1], [y0, y1]);
    [x0, x1, 0.0]
}

/// Nearest point of the ellipse with semi-axes e₀ ≥ e₁ > 0 to y ≥ 0.
fn nearest_on_ellipse(e: [f64; 2], y: [f64; 2]) -> [f64; 2] {
    let [e0, e1] = e;
    let [y0, y1] = y;
    if y1 > 0.0 {
        if y0 > 0.0 {
            let z = [y0 / e0, y1 / e1, 0.0];
            let g = z[0] * z[0] + z[1] * z[1] - 1.0;
            if g == 0.0 {
                return y;
            }
            let r = [(e0 / e1).powi(2), 1.0, 1.0];
            let s = root(r, z, g);
            return [r[0] * y0 / (s + r[0]), y1 / (s + 1.0)];
        }
        return [0.0, e1];
    }
    let (numer0, denom0) = (e0 * y0, e0 * e0 - e1 * e1);
    if numer0 < denom0 {
        let xde0 = numer0 / denom0;
        return [e0 * xde0, e1 * (1.0 - xde0 * xde0).max(0.0).sqrt()];
    }
    [e0, 0.0]
}

/// The root s of Σ_i (r_i z_i / (s + r_i))² = 1 (r sorted decreasing, the last r = 1; unused
/// components have z = 0), bracketed by [z_last − 1, 0] inside (g < 0) and
/// [z_last − 1, ‖r ⊙ z‖ − 1] outside. Bisection until the bracket stops shrinking.
fn root(r: [f64; 3], z: [f64; 3], g: f64) -> f64 {
    let n = [r[0] * z[0], r[1] * z[1], z[2]];
    // The last non-zero component's z bounds the root from below.
    let last = if z[2] > 0.0 { z[2] } else { z[1] };
    let mut s0 = last - 1.0;
    let mut s1 = if g < 0.0 {
        0.0
    } else {
        DVec3::from(n).length() - 1.0
    };
    let mut s = 0.0;
    for _ in 0..MAX_BISECTIONS {
        s = 0.5 * (s0 + s1);
        if s == s0 || s == s1 {
            break;
        }
        let f: f64 = (0..3)
            .map(|i| {
                let ratio = n[i] / (s + r[i]);
                ratio * ratio
            })
            .sum::<f64>()
            - 1.0;
        if f > 0.0 {
            s0 = s;
        } else if f < 0.0 {
            s1 = s;
        } else {
            break;
        }
    }
    s
}
