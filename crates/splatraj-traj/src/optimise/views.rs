//! Views before gradients: the viewpoint each window's camera starts from.
//!
//! Gradient descent only improves a view it can already see: it cannot walk the camera around
//! an occluder, out of an object it starts inside, or to the other side of a wall. So each
//! window's start is chosen by a search (docs/first-try.md "Views where the object shows"):
//!
//! 1. **Candidates** ([`candidate_views`]): cameras on spheres around the object's centre, at
//!    `distances` × its working distance (the prior radius), every 360°/`azimuths` around world
//!    up, at each of `elevations_degrees` above the horizontal, each looking at the centre
//!    (image up toward world up). Azimuth 0 is [`crate::optimise::object_side`]'s direction
//!    (from the objects toward the scene's middle), turning counter-clockwise seen from above.
//! 2. **Measures** ([`measure_views`]): at each candidate the object's mask is rendered twice
//!    at a small size, once composited with the whole scene (what the camera sees) and once
//!    with the object alone; the **visible share** is Σ seen / Σ alone (1: nothing in front of
//!    it), the **size** is the alone mask's share of the frame against the target ratio. The
//!    camera centre's clearance from the scene's solid geometry ([`crate::clearance`]) and
//!    whether it lies inside the object's box come from the host.
//! 3. **Choice** ([`choose_views`]): one candidate per window minimising the sum of each
//!    window's cost ([`ViewWeights`]: hidden share, size, clearance, being inside the object,
//!    elevation away from a natural eye line) and the cost of each move between consecutive
//!    windows (the camera's travel, in working distances, and its turn), by dynamic
//!    programming over the windows (Viterbi): the best sequence, not a greedy one, so one
//!    window's awkward side does not drag its neighbours after it.
//!
//! The weights make visibility dominant: half of the object hidden costs 2, one move at most
//! 1.1 (8 working distances of travel and a half turn), so a view that shows the whole object
//! beats one that hides half of it unless it costs about 14 working distances more of travel
//! over the window's two moves.

use burn::tensor::Tensor;
use glam::DVec3;
use serde::Serialize;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::OnDevice;
use splatraj_render::orbit::Orbit;
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render_poses,
};

use super::{OptimiseError, host_values};
use crate::clearance::Occupancy;

/// Where the candidates lie (module docs, step 1).
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSearch {
    /// Azimuths around world up, evenly spaced from azimuth 0.
    pub azimuths: usize,
    /// Elevations above the horizontal, degrees, each in (−90, 90).
    pub elevations_degrees: Vec<f64>,
    /// Distances from the object's centre, in working distances (prior radii), each > 0.
    pub distances: Vec<f64>,
    /// Width of the mask renders that measure the candidates (height from the camera's aspect).
    pub width: usize,
}

impl Default for ViewSearch {
    /// 16 azimuths × 6 elevations (−15° to 75°: a tabletop's objects are seen from above) ×
    /// 2 distances (the working distance and 0.7 of it, for rooms where the working distance
    /// lands behind a wall), measured at 64 pixels wide: 192 candidates per window, a second
    /// or two on a 150k-Gaussian capture.
    fn default() -> Self {
        Self {
            azimuths: 16,
            elevations_degrees: vec![-15.0, 5.0, 20.0, 35.0, 55.0, 75.0],
            distances: vec![1.0, 0.7],
            width: 64,
        }
    }
}

impl ViewSearch {
    /// Checks the ranges; errors name the field.
    pub fn validate(&self) -> Result<(), OptimiseError> {
        let bad = |field, reason: String| Err(OptimiseError::InvalidOptions { field, reason });
        if self.azimuths == 0 || self.width == 0 {
            return bad("views", "azimuths and width must be ≥ 1".into());
        }
        if self.elevations_degrees.is_empty()
            || self
                .elevations_degrees
                .iter()
                .any(|e| !(e.is_finite() && e.abs() < 90.0))
        {
            return bad(
                "views",
                format!(
                    "elevations {:?} must be non-empty, each in (−90°, 90°)",
                    self.elevations_degrees
                ),
            );
        }
        if self.distances.is_empty() || self.distances.iter().any(|d| !(d.is_finite() && *d > 0.0))
        {
            return bad(
                "views",
                format!("distances {:?} must be non-empty, each > 0", self.distances),
            );
        }
        Ok(())
    }
}

/// The object a window looks at, as the search sees it.
#[derive(Debug, Clone, Copy)]
pub struct ViewedObject<'a> {
    /// The whole scene (what the camera sees).
    pub scene: &'a DeviceScene,
    /// The object's Gaussians alone.
    pub alone: &'a DeviceScene,
    /// The object's per-Gaussian 0/1 mask over `scene`.
    pub mask: &'a [f32],
    /// Centre the cameras look at.
    pub centre: [f64; 3],
    /// Half the object's extent along each axis (its box is centre ± this).
    pub half_extent: [f64; 3],
    /// Working distance (prior radius) the candidates' distances multiply.
    pub radius: f64,
    /// Share of the frame the object should cover.
    pub target_ratio: f64,
}

/// One candidate view and what was measured there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Candidate {
    /// The camera Φ = [ω, c].
    pub pose: [f64; 6],
    /// Azimuth from azimuth 0 (module docs), degrees.
    pub azimuth_degrees: f64,
    /// Elevation above the horizontal, degrees.
    pub elevation_degrees: f64,
    /// Distance from the object's centre, scene units.
    pub distance: f64,
    /// Σ seen / Σ alone of the object's mask (1: nothing hides it; 0: hidden or out of frame).
    pub visible_share: f64,
    /// Share of the frame the object alone covers.
    pub coverage: f64,
    /// Clearance of the camera centre from the solid geometry (None: no geometry given);
    /// capped at a few margins.
    pub clearance: Option<f64>,
    /// Whether the camera centre lies inside the object's box.
    pub inside_object: bool,
}

/// The candidate cameras of `search` around an object at `centre` with working distance
/// `radius`, azimuth 0 along `reference` (horizontal part), world up `up`: (azimuth°,
/// elevation°, distance, pose), distances outermost first.
pub fn candidate_views(
    search: &ViewSearch,
    centre: [f64; 3],
    radius: f64,
    reference: [f64; 3],
    up: [f64; 3],
) -> Result<Vec<(f64, f64, f64, Pose)>, OptimiseError> {
    search.validate()?;
    if !(radius.is_finite() && radius > 0.0) {
        return Err(OptimiseError::InvalidOptions {
            field: "radius",
            reason: format!("= {radius} must be finite and > 0"),
        });
    }
    let up = DVec3::from(up);
    if !(up.is_finite() && up.length() > 0.0) {
        return Err(OptimiseError::InvalidOptions {
            field: "world_up",
            reason: format!("{up} must be finite and non-zero"),
        });
    }
    let orbit = Orbit::new(DVec3::from(centre), up, DVec3::from(reference), radius);
    let mut views = Vec::new();
    for &d in &search.distances {
        for &elevation in &search.elevations_degrees {
            for k in 0..search.azimuths {
                let azimuth = 360.0 * k as f64 / search.azimuths as f64;
                let azimuth = if azimuth > 180.0 {
                    azimuth - 360.0
                } else {
                    azimuth
                };
                let distance = d * radius;
                let pose = orbit
                    .pose_degrees(azimuth, elevation, distance)
                    .map_err(|e| OptimiseError::InvalidOptions {
                        field: "views",
                        reason: format!("no camera at azimuth {azimuth}°: {e}"),
                    })?;
                views.push((azimuth, elevation, distance, pose));
            }
        }
    }
    Ok(views)
}

/// Poses the view search renders at once (its peak memory is twice this many images: one batch
/// is read while the next renders).
pub const VIEW_SEARCH_BATCH: usize = 32;

/// Σ of the mask `mask` (one value per Gaussian of `scene`) at each pose, rendered pruned to
/// the mask at `intrinsics`, in batches of [`BATCH`].
fn mask_sums(
    scene: &DeviceScene,
    mask: &[f32],
    poses: &[Pose],
    intrinsics: &Intrinsics,
    rasterizer: Rasterizer,
) -> Result<Vec<f64>, OptimiseError> {
    let request = RenderRequest {
        pruning: Pruning::ObjectOnly,
        rasterizer,
        alpha: AlphaChannel::Dropped,
        ..RenderRequest::new(*intrinsics, vec![Channel::Mask(mask.to_vec())])
    };
    let per_view = intrinsics.width * intrinsics.height;
    let mut sums = Vec::with_capacity(poses.len());
    let mut add = |images: Tensor<4>| -> Result<(), OptimiseError> {
        let values = host_values(images)?;
        sums.extend(
            values
                .chunks_exact(per_view)
                .map(|image| image.iter().sum::<f64>()),
        );
        Ok(())
    };
    // One batch in flight while the one before is read: on a GPU the host decides and bins
    // the next views while the device composites these.
    let mut in_flight = None;
    for batch in poses.chunks(VIEW_SEARCH_BATCH) {
        let images = render_poses(scene, batch, &request)?.images; // [B, H, W, 1]
        scene.device().flush().map_err(|e| {
            OptimiseError::ReadBack(format!("starting the view search's renders: {e}"))
        })?;
        if let Some(done) = in_flight.replace(images) {
            add(done)?;
        }
    }
    if let Some(done) = in_flight {
        add(done)?;
    }
    if sums.len() != poses.len() {
        return Err(OptimiseError::ReadBack(format!(
            "the view search's renders gave {} masks for {} views",
            sums.len(),
            poses.len()
        )));
    }
    Ok(sums)
}

/// Share of the frame the object alone (`alone`: its Gaussians only) covers at each pose.
pub fn alone_coverage(
    alone: &DeviceScene,
    poses: &[Pose],
    intrinsics: &Intrinsics,
    rasterizer: Rasterizer,
) -> Result<Vec<f64>, OptimiseError> {
    let pixels = (intrinsics.width * intrinsics.height) as f64;
    let ones = vec![1.0; alone.len()];
    Ok(mask_sums(alone, &ones, poses, intrinsics, rasterizer)?
        .into_iter()
        .map(|s| s / pixels)
        .collect())
}

/// (visible share, coverage of the object alone) at each pose (module docs, step 2), rendered
/// at `intrinsics` (small: see [`ViewSearch::width`]).
pub fn measure_views(
    object: &ViewedObject<'_>,
    poses: &[Pose],
    intrinsics: &Intrinsics,
    rasterizer: Rasterizer,
) -> Result<Vec<(f64, f64)>, OptimiseError> {
    let pixels = (intrinsics.width * intrinsics.height) as f64;
    let seen = mask_sums(object.scene, object.mask, poses, intrinsics, rasterizer)?;
    let alone = alone_coverage(object.alone, poses, intrinsics, rasterizer)?;
    Ok(seen
        .iter()
        .zip(alone)
        .map(|(s, coverage)| {
            let a = coverage * pixels;
            // Less than a pixel of the object alone: out of frame (or behind the camera).
            let visible = if a >= 1.0 {
                (s / a).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (visible, coverage)
        })
        .collect())
}

/// Directions a working distance is measured from ([`calibrated_radius`]): a ring of 8
/// azimuths at 20° elevation, and one from above and one from below (45°).
const CALIBRATION_VIEWS: [(f64, f64); 10] = [
    (0.0, 20.0),
    (45.0, 20.0),
    (90.0, 20.0),
    (135.0, 20.0),
    (180.0, 20.0),
    (-135.0, 20.0),
    (-90.0, 20.0),
    (-45.0, 20.0),
    (0.0, 45.0),
    (0.0, -45.0),
];

/// The working distance at which the object alone covers `target_ratio` of the frame on
/// average over `CALIBRATION_VIEWS`, measured: from `radius` (an estimate from the object's
/// box), twice scaled by √(mean coverage / target) (coverage falls as 1/d² far from the
/// object). The box estimate is off by a factor 1.3–1.6 on real parts (a sphere cut from a
/// surface is thinner than its box; the first-try biker's jacket covered 0.45 of the frame at
/// 0.7 of its estimate, not 0.3), and every later choice (the views' distances, the prior's
/// pull, the clearance margin, the speed limit) scales with it. The estimate is kept when the
/// object is out of every view. Measured with `intrinsics`, the optimisation camera: its
/// rasterizer dilation (0.3 px²) widens a small silhouette, and TRE sees the same.
pub fn calibrated_radius(
    alone: &DeviceScene,
    centre: [f64; 3],
    radius: f64,
    target_ratio: f64,
    up: [f64; 3],
    intrinsics: &Intrinsics,
    rasterizer: Rasterizer,
) -> Result<f64, OptimiseError> {
    let up = DVec3::from(up);
    let orbit = Orbit::new(DVec3::from(centre), up, up.any_orthonormal_vector(), radius);
    let mut r = radius;
    for _ in 0..2 {
        let poses = CALIBRATION_VIEWS
            .iter()
            .map(|&(a, e)| orbit.pose_degrees(a, e, r))
            .collect::<Result<Vec<Pose>, _>>()
            .map_err(|e| OptimiseError::InvalidOptions {
                field: "radius",
                reason: format!("calibration view: {e}"),
            })?;
        let coverage = alone_coverage(alone, &poses, intrinsics, rasterizer)?;
        let mean = coverage.iter().sum::<f64>() / coverage.len() as f64;
        if !(mean > 0.0 && mean.is_finite()) {
            return Ok(radius);
        }
        // At most a factor 3 per round: a camera inside the object sees coverage near 1.
        r *= (mean / target_ratio).sqrt().clamp(1.0 / 3.0, 3.0);
    }
    Ok(r)
}

/// The candidates of `search` around `object` with everything measured: renders at
/// `intrinsics`' aspect, [`ViewSearch::width`] pixels wide; clearance from `geometry`
/// (occupancy and margin) when given.
pub fn search_views(
    object: &ViewedObject<'_>,
    search: &ViewSearch,
    reference: [f64; 3],
    up: [f64; 3],
    intrinsics: &Intrinsics,
    rasterizer: Rasterizer,
    geometry: Option<(&Occupancy, f64)>,
) -> Result<Vec<Candidate>, OptimiseError> {
    let views = candidate_views(search, object.centre, object.radius, reference, up)?;
    let small = intrinsics
        .rescaled(
            search.width,
            ((search.width * intrinsics.height) as f64 / intrinsics.width as f64)
                .round()
                .max(1.0) as usize,
        )
        .map_err(|e| OptimiseError::InvalidOptions {
            field: "views",
            reason: format!("search camera: {e}"),
        })?;
    let poses: Vec<Pose> = views.iter().map(|v| v.3).collect();
    let measured = measure_views(object, &poses, &small, rasterizer)?;
    let (centre, half) = (DVec3::from(object.centre), DVec3::from(object.half_extent));
    let clearances: Vec<Option<f64>> = {
        use rayon::prelude::*;
        poses
            .par_iter()
            .map(|p| {
                geometry.map(|(occupancy, margin)| {
                    let cap = 4.0 * margin;
                    occupancy
                        .nearest_up_to(p.centre(), margin, cap)
                        .map_or(cap, |c| c.surface.distance.min(cap))
                })
            })
            .collect()
    };
    Ok(views
        .iter()
        .zip(measured)
        .zip(clearances)
        .map(
            |(((azimuth, elevation, distance, pose), (visible, coverage)), clearance)| {
                let offset = (pose.centre() - centre).abs();
                Candidate {
                    pose: pose.0,
                    azimuth_degrees: *azimuth,
                    elevation_degrees: *elevation,
                    distance: *distance,
                    visible_share: visible,
                    coverage,
                    clearance,
                    inside_object: offset.cmple(half).all(),
                }
            },
        )
        .collect())
}

/// How [`choose_views`] weighs a candidate and a move (module docs, step 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewWeights {
    /// Per unit of hidden share (1 − visible share).
    pub hidden: f64,
    /// Per unit of |ln(coverage / target ratio)|, capped at 2 (a factor e² off).
    pub size: f64,
    /// Per unit of (1 − clearance / margin) when closer than the margin.
    pub clearance: f64,
    /// For a camera inside the object's box.
    pub inside: f64,
    /// Per 90° of elevation away from `eye_line_degrees`.
    pub elevation: f64,
    /// The elevation of a natural view, degrees (a person looking at a thing on a table).
    pub eye_line_degrees: f64,
    /// Per working distance the camera travels between consecutive windows (capped at 8).
    pub travel: f64,
    /// Per 180° the view turns between consecutive windows.
    pub turn: f64,
    /// For a candidate within half a working distance of one an earlier restart started from
    /// (so restarts try other views).
    pub repeat: f64,
}

impl Default for ViewWeights {
    /// Hidden 4, size 0.5, clearance 2, inside 4, elevation 0.3 from 20°, travel 0.1, turn
    /// 0.3, repeat 2 (as much as half the object hidden).
    fn default() -> Self {
        Self {
            hidden: 4.0,
            size: 0.5,
            clearance: 2.0,
            inside: 4.0,
            elevation: 0.3,
            eye_line_degrees: 20.0,
            travel: 0.1,
            turn: 0.3,
            repeat: 2.0,
        }
    }
}

impl ViewWeights {
    /// The cost of one candidate for a window whose object should cover `target_ratio` of
    /// the frame, with clearance margin `margin` (ignored without a measured clearance).
    pub fn unary(&self, c: &Candidate, target_ratio: f64, margin: Option<f64>) -> f64 {
        let size = if c.coverage > 0.0 {
            (c.coverage / target_ratio).ln().abs().min(2.0)
        } else {
            2.0
        };
        let crowded = match (c.clearance, margin) {
            (Some(d), Some(m)) if m > 0.0 => (1.0 - d / m).clamp(0.0, 2.0),
            _ => 0.0,
        };
        self.hidden * (1.0 - c.visible_share)
            + self.size * size
            + self.clearance * crowded
            + if c.inside_object { self.inside } else { 0.0 }
            + self.elevation * (c.elevation_degrees - self.eye_line_degrees).abs() / 90.0
    }

    /// The cost of moving from candidate `a` (working distance `radius_a`) to `b`
    /// (`radius_b`).
    pub fn pairwise(&self, a: &Candidate, radius_a: f64, b: &Candidate, radius_b: f64) -> f64 {
        let (pa, pb) = (Pose(a.pose), Pose(b.pose));
        let scale = 0.5 * (radius_a + radius_b);
        let travel = (pa.centre().distance(pb.centre()) / scale.max(1e-12)).min(8.0);
        let forward = |p: &Pose| p.rotation_wc().z_axis;
        let turn = forward(&pa).angle_between(forward(&pb));
        let turn = if turn.is_finite() { turn } else { 0.0 };
        self.travel * travel + self.turn * turn / std::f64::consts::PI
    }
}

/// What one window contributes to the choice.
#[derive(Debug, Clone)]
pub struct WindowViews {
    /// Its candidates, measured.
    pub candidates: Vec<Candidate>,
    /// Its working distance.
    pub radius: f64,
    /// Its target ratio.
    pub target_ratio: f64,
    /// Candidates earlier restarts chose (those and their neighbours are charged
    /// [`ViewWeights::repeat`]).
    pub used: Vec<usize>,
}

impl WindowViews {
    /// Candidate `k`'s window cost: [`ViewWeights::unary`], plus [`ViewWeights::repeat`] when
    /// its camera is within half a working distance of a view an earlier restart used.
    pub fn cost(&self, k: usize, weights: &ViewWeights, margin: Option<f64>) -> f64 {
        let c = &self.candidates[k];
        let near_used = self.used.iter().any(|&u| {
            let used = Pose(self.candidates[u].pose).centre();
            used.distance(Pose(c.pose).centre()) < 0.5 * self.radius
        });
        weights.unary(c, self.target_ratio, margin) + if near_used { weights.repeat } else { 0.0 }
    }
}

/// One candidate index per window minimising the summed window and move costs (module docs,
/// step 3); `margin` is the clearance margin the candidates' clearances are judged by. None
/// when a window has no candidate.
pub fn choose_views(
    windows: &[WindowViews],
    weights: &ViewWeights,
    margin: Option<f64>,
) -> Option<Vec<usize>> {
    if windows.iter().any(|w| w.candidates.is_empty()) {
        return None;
    }
    let first = windows.first()?;
    // best[k]: the cheapest sequence ending at candidate k of the current window.
    let mut best: Vec<f64> = (0..first.candidates.len())
        .map(|k| first.cost(k, weights, margin))
        .collect();
    let mut back: Vec<Vec<usize>> = Vec::with_capacity(windows.len());
    for pair in windows.windows(2) {
        let (previous, current) = (&pair[0], &pair[1]);
        let mut next = Vec::with_capacity(current.candidates.len());
        let mut from = Vec::with_capacity(current.candidates.len());
        for (k, b) in current.candidates.iter().enumerate() {
            let (j, cost) = previous
                .candidates
                .iter()
                .enumerate()
                .map(|(j, a)| {
                    (
                        j,
                        best[j] + weights.pairwise(a, previous.radius, b, current.radius),
                    )
                })
                .min_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)))
                .unwrap_or((0, f64::INFINITY)); // no candidate: excluded above
            next.push(cost + current.cost(k, weights, margin));
            from.push(j);
        }
        best = next;
        back.push(from);
    }
    let mut k = (0..best.len()).min_by(|&a, &b| best[a].total_cmp(&best[b]).then(a.cmp(&b)))?;
    let mut chosen = vec![k];
    for from in back.iter().rev() {
        k = from[k];
        chosen.push(k);
    }
    chosen.reverse();
    Some(chosen)
}
