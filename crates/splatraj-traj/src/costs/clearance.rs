//! Clearance: keeps the camera centre at least a margin away from the scene's geometry.
//!
//! ```text
//! L_clear = max(0, m − d(c))² / m²,     d(c) = signed distance from c to the nearest surface
//! ```
//!
//! with m the margin and the surfaces those of [`crate::clearance`] (the opaque Gaussians'
//! σ-ellipsoids). It is 0 at or beyond the margin, 1 on a surface, and grows quadratically
//! inside geometry, so a buried camera is pushed out along the deepest surface's normal.
//! Dividing by m² makes the weight independent of the scene's units.
//!
//! **Differentiable in the pose.** The nearest surface point x* and its outward normal n are
//! found on the host (exactly: [`crate::clearance::ellipsoid`]) and held fixed: d(c) =
//! n·(c − x*). That is the signed distance itself (c − x* is along n outside, against it
//! inside) and its exact gradient n (the envelope theorem: moving c moves x* only along the
//! surface, to first order), with no square root to blow up on the surface. The cost is
//! computed there too, value and gradient ([`clearance_on_host`]), and joins the graph by its
//! first-order expansion ([`super::expansion`]); [`clearance`] is the same as tensor ops.
//!
//! **Where it is evaluated.** It is a path cost ([`CostDomain::Path`]): in a trajectory
//! optimisation it sees the window's densely sampled path (a fine, randomly shifted time grid
//! every step, including the stretch into the next window), not only the few stratified
//! samples, so the path cannot slip through thin geometry between samples. Elsewhere (single
//! poses) it sees the sampled poses. It batches windows: on a joined path (every window's
//! stretch, [`super::PathSamples::joined`]) it returns each stretch's mean `[W]`.

use burn::tensor::Tensor;
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::expansion::{per_sample_on_host, per_stretch_on_host};
use super::{Cost, CostDomain, CostError, CostInputs, OrAuto, check_weight, invalid};
use crate::clearance::OccupancySpec;

/// Default ellipsoid size: 2σ holds most of a Gaussian's visible mass (3σ is where the
/// rasterizer cuts it off).
pub const DEFAULT_CLEARANCE_SIGMA: f64 = 2.0;

/// Default opacity below which a Gaussian does not block the camera.
pub const DEFAULT_MIN_OPACITY: f64 = 0.2;

/// Clearance per pose `[B]` from camera centres `[B, 3]` and, per pose, the nearest surface
/// point and outward normal `[B, 3]` (held fixed) and the margin m > 0.
pub fn clearance(
    centres: Tensor<2>,
    surface_points: Tensor<2>,
    normals: Tensor<2>,
    margin: f64,
) -> Tensor<1> {
    let [batch, _] = centres.dims();
    let distance = ((centres - surface_points) * normals)
        .sum_dim(1)
        .reshape([batch]);
    distance
        .neg()
        .add_scalar(margin)
        .clamp_min(0.0)
        .div_scalar(margin)
        .square()
}

/// [`clearance`] of one camera centre `c` on the host in f64, with its gradient in `c`: what
/// the cost evaluates; the tensor form is its specification.
pub fn clearance_on_host(
    c: DVec3,
    surface_point: DVec3,
    normal: DVec3,
    margin: f64,
) -> (f64, [f64; 3]) {
    let gap = margin - (c - surface_point).dot(normal);
    // The clamp passes the gradient on its bound too (burn's clamp_min).
    if gap < 0.0 {
        return (0.0, [0.0; 3]);
    }
    let value = (gap / margin).powi(2);
    let gradient = normal * (-2.0 * gap / (margin * margin));
    (value, gradient.to_array())
}

/// The clearance cost: table `[costs.clearance]`, keys `weight` (default 1), `margin` (scene
/// units, or `"auto"`, the default: derived from the scene, see [`auto_margin`]), `sigma`
/// (ellipsoid size in standard deviations, default 2) and `min_opacity` (default 0.2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClearanceCost {
    /// Weight (≥ 0).
    #[serde(default = "one")]
    pub weight: f64,
    /// Margin m (scene units, > 0): the clearance the camera keeps; `"auto"` until the
    /// experiment resolves it from the scene ([`auto_margin`]).
    #[serde(default)]
    pub margin: OrAuto,
    /// Ellipsoid size in standard deviations (> 0).
    #[serde(default = "default_sigma")]
    pub sigma: f64,
    /// Opacity below which a Gaussian is see-through, in [0, 1].
    #[serde(default = "default_min_opacity")]
    pub min_opacity: f64,
}

fn one() -> f64 {
    1.0
}

fn default_sigma() -> f64 {
    DEFAULT_CLEARANCE_SIGMA
}

fn default_min_opacity() -> f64 {
    DEFAULT_MIN_OPACITY
}

/// Share of the smallest working distance (prior radius) the automatic margin keeps.
///
/// The camera has to reach each object's working distance, so the margin must stay well below
/// it; a quarter still keeps the camera clear of a table edge or a wall it passes on the way
/// (the demo's hand-tuned 10 cm is a fifth of its smallest working distance, 0.5 m).
pub const AUTO_MARGIN_OF_RADIUS: f64 = 0.25;

/// Cap of the automatic margin as a share of the scene's robust diagonal: in a large scene
/// with one large object the margin stays a small part of the room.
pub const AUTO_MARGIN_OF_SCENE: f64 = 0.03;

/// The margin `"auto"` stands for: [`AUTO_MARGIN_OF_RADIUS`] × the smallest working distance
/// of the queries, at most [`AUTO_MARGIN_OF_SCENE`] × the scene's robust diagonal.
pub fn auto_margin(smallest_radius: f64, scene_diagonal: f64) -> f64 {
    let by_radius = AUTO_MARGIN_OF_RADIUS * smallest_radius;
    let by_scene = AUTO_MARGIN_OF_SCENE * scene_diagonal;
    match (by_radius > 0.0, by_scene > 0.0) {
        (true, true) => by_radius.min(by_scene),
        (true, false) => by_radius,
        _ => by_scene,
    }
}

impl Default for ClearanceCost {
    /// Weight 30, margin `"auto"`, the default geometry: what a config without `[costs]`
    /// gets. Weight 30 because the image costs are of order 1 per sample and a camera inside
    /// the margin must lose against them (the demo config measured 1, 10 and 30: only 30 kept
    /// the margin everywhere).
    fn default() -> Self {
        Self {
            weight: 30.0,
            margin: OrAuto::Auto,
            sigma: DEFAULT_CLEARANCE_SIGMA,
            min_opacity: DEFAULT_MIN_OPACITY,
        }
    }
}

impl ClearanceCost {
    /// A clearance cost of weight 1 with margin `margin` and the default geometry.
    pub fn with_margin(margin: f64) -> Self {
        Self {
            weight: 1.0,
            margin: OrAuto::Value(margin),
            sigma: DEFAULT_CLEARANCE_SIGMA,
            min_opacity: DEFAULT_MIN_OPACITY,
        }
    }

    /// The margin in scene units, or an error naming the key when it is still `"auto"`.
    pub fn margin(&self) -> Result<f64, CostError> {
        self.margin.value().ok_or_else(|| {
            invalid(
                "clearance",
                "margin",
                "is \"auto\" but was never derived from a scene (prepare the experiment \
                 first, or give a number)"
                    .into(),
            )
        })
    }
}

impl Cost for ClearanceCost {
    fn name(&self) -> &'static str {
        "clearance"
    }
    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }
    fn domain(&self) -> CostDomain {
        CostDomain::Path
    }
    fn batches_windows(&self) -> bool {
        true
    }
    fn occupancy(&self) -> Option<OccupancySpec> {
        Some(OccupancySpec {
            sigma: self.sigma,
            min_opacity: self.min_opacity,
        })
    }
    fn validate(&self) -> Result<(), CostError> {
        check_weight(self.name(), "weight", self.weight)?;
        let margin = self.margin.value().unwrap_or(1.0);
        for (field, value) in [("margin", margin), ("sigma", self.sigma)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(invalid(
                    self.name(),
                    field,
                    format!("= {value} must be finite and > 0"),
                ));
            }
        }
        if !(0.0..=1.0).contains(&self.min_opacity) {
            return Err(invalid(
                self.name(),
                "min_opacity",
                format!("= {} must be in [0, 1]", self.min_opacity),
            ));
        }
        Ok(())
    }
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let occupancy = inputs.require_occupancy(self.name())?;
        let margin = self.margin()?;
        // On the host (docs/gpu.md, "Costs on the host"): a pose's value and its gradient.
        let at = |pose: &[f64; 6]| -> (f64, [f64; 6]) {
            let c = DVec3::new(pose[3], pose[4], pose[5]);
            match occupancy.nearest_within(c, margin) {
                Some(contact) if contact.surface.distance < margin => {
                    let surface = contact.surface;
                    let (value, g) = clearance_on_host(c, surface.point, surface.normal, margin);
                    (value, [0.0, 0.0, 0.0, g[0], g[1], g[2]])
                }
                // Clear of everything: 0 and no gradient.
                _ => (0.0, [0.0; 6]),
            }
        };
        match inputs.path() {
            // Its mean per window's stretch [W] (the mean of a window's own path [1]).
            Some(_) => per_stretch_on_host(inputs, self.name(), |_, poses| {
                let share = 1.0 / poses.len().max(1) as f64;
                // In parallel: each pose's nearest surface is k-d searches and bisections, about
                // 0.3 ms a window of 16 poses (first-try guitar; 0.2 on 2 cores), host work a
                // GPU step waits for (docs/gpu.md). The sums below stay in order: the same bits.
                let rows: Vec<(f64, [f64; 6])> = poses.par_iter().map(at).collect();
                let value = rows.iter().map(|r| r.0).sum::<f64>() * share;
                (value, rows.iter().map(|r| r.1.map(|g| g * share)).collect())
            }),
            None => per_sample_on_host(inputs, self.name(), |pose, _| at(pose)),
        }
    }
}
