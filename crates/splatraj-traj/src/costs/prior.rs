//! The decaying warm-start prior: pulls the camera near the object and turns it toward it.
//!
//! ```text
//! L_prior = max(‖c − o‖, r) + (1 − ⟨z_cam, (o − c)/‖o − c‖⟩),     weight α_k = α_0·γ^k
//! ```
//!
//! with c the camera centre, o the object centre, r the prior radius and z_cam = R_wc e_z the
//! optical axis in world coordinates. The first term pulls the camera to within r of o and is
//! flat inside; the second is 0 looking straight at o and 2 looking straight away. It is the
//! attracting form of docs/conventions.md: the paper prints
//! −max(r, ‖c − o‖) − ⟨…, (c − o)/‖c − o‖⟩, whose signs reward moving away from the object and
//! facing away from it (departure 2 there).
//!
//! The weight α_k = α_0·γ^k (k the optimisation step, γ ∈ (0, 1]) decays, so the image costs
//! take over once the object is in view.
//!
//! **Guard at c = o.** ‖o − c‖ is taken as √(‖o − c‖² + ε²), ε = [`PRIOR_EPSILON_FRACTION`]·r,
//! so both value and gradient are finite when the camera sits exactly on the object centre
//! (value r + 1 there: the alignment term is 0 when there is no direction to align with).
//! For ‖o − c‖ = d ≥ r it moves the distance term by at most ε²/(2d) ≤ 5e-7·r and the
//! alignment term by at most ε²/(2d²) ≤ 5e-7, below anything the optimiser resolves; inside r
//! only the alignment term is damped, and only within a few ε of o. Scaling ε with r keeps the
//! guard scale-free across scene units (its gradient there is O(1/ε), large but finite).

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use splatraj_render::rodrigues::Rotation;

use super::expansion::per_sample_on_host;
use super::{Cost, CostError, CostInputs, ImageChannel, check_weight, invalid};

/// ε of the guarded distance √(‖o − c‖² + ε²), as a fraction of the prior radius r.
pub const PRIOR_EPSILON_FRACTION: f64 = 1e-3;

/// Prior per sample `[B]`: rotations R_wc `[B, 3, 3]`, camera centres `[B, 3]`, object centre
/// `[1, 3]`, radius r > 0 and guard ε > 0 (see module docs).
pub fn prior(
    rotations: Tensor<3>,
    centres: Tensor<2>,
    object_centre: Tensor<2>,
    radius: f64,
    epsilon: f64,
) -> Tensor<1> {
    let [batch, _] = centres.dims();
    let forward = rotations.narrow(2, 2, 1).reshape([batch, 3]); // z_cam [B, 3]
    let to_object = object_centre - centres; // o − c [B, 3]
    let distance = to_object
        .clone()
        .square()
        .sum_dim(1)
        .add_scalar(epsilon * epsilon)
        .sqrt(); // [B, 1], ≥ ε > 0
    let alignment = (forward * to_object).sum_dim(1) / distance.clone(); // cos ∈ (−1, 1)
    (distance.clamp_min(radius) - alignment + 1.0).reshape([batch])
}

/// [`prior`] of one pose on the host in f64, with its gradient in the pose (ω then c): what
/// the cost evaluates; the tensor forms above are its specification (`tests/cost_terms.rs`).
pub fn prior_on_host(
    pose: &[f64; 6],
    object_centre: [f64; 3],
    radius: f64,
    epsilon: f64,
) -> (f64, [f64; 6]) {
    let rotation = Rotation::new([pose[0], pose[1], pose[2]]);
    let forward: [f64; 3] = std::array::from_fn(|i| rotation.matrix[i][2]); // z_cam
    let to_object: [f64; 3] = std::array::from_fn(|i| object_centre[i] - pose[3 + i]); // o − c
    let dot = |a: [f64; 3], b: [f64; 3]| (0..3).map(|i| a[i] * b[i]).sum::<f64>();
    let distance = (dot(to_object, to_object) + epsilon * epsilon).sqrt();
    let aim = dot(forward, to_object);
    let alignment = aim / distance;
    // The clamp passes the gradient on its bound too (burn's clamp_min).
    let pulls = distance >= radius;
    let value = distance.max(radius) - alignment + 1.0;
    // d/d(o − c): the distance term t/d where it pulls, minus the alignment's z/d − (z·t)t/d³.
    let v_to_object: [f64; 3] = std::array::from_fn(|i| {
        let pull = if pulls { to_object[i] / distance } else { 0.0 };
        pull - forward[i] / distance + aim * to_object[i] / distance.powi(3)
    });
    let mut v_matrix = [[0.0; 3]; 3];
    for (i, row) in v_matrix.iter_mut().enumerate() {
        row[2] = -to_object[i] / distance;
    }
    let v_omega = rotation.omega_gradient(&v_matrix);
    let gradient = [
        v_omega[0],
        v_omega[1],
        v_omega[2],
        -v_to_object[0],
        -v_to_object[1],
        -v_to_object[2],
    ];
    (value, gradient)
}

/// Default prior radius: the distance at which an object of axis-aligned extent `extent`
/// (side lengths in world units) covers `target_ratio` of a frame with full fields of view
/// `fov_x`, `fov_y` (radians).
///
/// Derivation. A camera at distance d sees the object's silhouette, of area A in world units,
/// as A/d² in the normalised image plane (x/z, y/z), whose frame is 2·tan(fov_x/2) by
/// 2·tan(fov_y/2). Setting A/d² = r_t·4·tan(fov_x/2)·tan(fov_y/2) gives
///
/// ```text
/// r = √( A / (4 · r_t · tan(fov_x/2) · tan(fov_y/2)) )
/// ```
///
/// For A we take the silhouette area averaged over all viewing directions, which for a convex
/// body is a quarter of its surface area (Cauchy's formula): for a box with sides a, b, c,
/// A = (ab + bc + ca)/2. It grows with every side (unlike the largest side alone), does not
/// assume a viewing direction, and is exact on average for box-like objects; a flat object
/// (c = 0) still gets A = ab/2. It is a far-field estimate (d ≫ extent), which is where a
/// 15 % coverage puts the camera. Example: a unit cube, 60° × 60°, r_t = 0.15 gives r ≈ 2.74.
///
/// Errors when the sides are negative or not finite, all are 0 (a point has no size to
/// frame), a field of view is outside (0, π), or r_t is outside (0, 1].
pub fn default_prior_radius(
    extent: [f64; 3],
    fov_x: f64,
    fov_y: f64,
    target_ratio: f64,
) -> Result<f64, CostError> {
    let bad = |field, reason: String| Err(CostError::InvalidContext { field, reason });
    if !extent.iter().all(|s| s.is_finite() && *s >= 0.0) {
        return bad("extent", format!("{extent:?} must be finite and ≥ 0"));
    }
    for (field, fov) in [("fov_x", fov_x), ("fov_y", fov_y)] {
        if !(fov > 0.0 && fov < std::f64::consts::PI) {
            return bad(field, format!("{fov} rad must be in (0, π)"));
        }
    }
    if !(target_ratio > 0.0 && target_ratio <= 1.0) {
        return bad("target_ratio", format!("{target_ratio} must be in (0, 1]"));
    }
    let [a, b, c] = extent;
    let area = 0.5 * (a * b + b * c + c * a);
    // A segment (two sides 0) has no area: frame its length as a disc's diameter instead.
    let area = if area > 0.0 {
        area
    } else {
        let length = a.max(b).max(c);
        0.25 * std::f64::consts::PI * length * length
    };
    if area <= 0.0 {
        return bad(
            "extent",
            format!("{extent:?} is a point: it has no size to frame"),
        );
    }
    let frame = 4.0 * (0.5 * fov_x).tan() * (0.5 * fov_y).tan();
    Ok((area / (target_ratio * frame)).sqrt())
}

/// The prior as a [`Cost`]: table `[costs.prior]`, keys `alpha0` (α_0, default 1), `gamma`
/// (γ ∈ (0, 1], default 0.99) and optional `radius` (> 0; overrides the query's default
/// radius from [`default_prior_radius`]).
///
/// γ = 0.99 leaves 13 % of α_0 after 200 steps (the paper's trajectory runs) and 2 % after
/// 400 (its single-pose runs); γ = 1 keeps the prior constant (the paper's "3D prior" ablation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PriorCost {
    /// Initial weight α_0 (≥ 0).
    pub alpha0: f64,
    /// Decay per step γ ∈ (0, 1].
    pub gamma: f64,
    /// Prior radius r (> 0); None uses the query's [`super::QueryContext::prior_radius`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
}

impl Default for PriorCost {
    /// α_0 = 1, γ = 0.99, radius from the query.
    fn default() -> Self {
        Self {
            alpha0: 1.0,
            gamma: 0.99,
            radius: None,
        }
    }
}

impl PriorCost {
    /// α_k = α_0·γ^k.
    pub fn alpha(&self, step: usize) -> f64 {
        // powf: powi takes an i32 and k may exceed it in long runs.
        self.alpha0 * self.gamma.powf(step as f64)
    }
}

impl Cost for PriorCost {
    fn name(&self) -> &'static str {
        "prior"
    }
    fn weight(&self, step: usize) -> f64 {
        self.alpha(step)
    }
    fn channels(&self) -> &'static [ImageChannel] {
        &[]
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "alpha0", self.alpha0)?;
        if !(self.gamma > 0.0 && self.gamma <= 1.0) {
            return Err(invalid(
                self.name(),
                "gamma",
                format!("= {} must be in (0, 1]", self.gamma),
            ));
        }
        if let Some(r) = self.radius
            && !(r.is_finite() && r > 0.0)
        {
            return Err(invalid(
                self.name(),
                "radius",
                format!("= {r} must be finite and > 0"),
            ));
        }
        Ok(())
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        // On the host (docs/gpu.md, "Costs on the host").
        per_sample_on_host(inputs, self.name(), |pose, query| {
            let radius = self.radius.unwrap_or(query.prior_radius);
            prior_on_host(
                pose,
                query.object_centre,
                radius,
                PRIOR_EPSILON_FRACTION * radius,
            )
        })
    }
}
