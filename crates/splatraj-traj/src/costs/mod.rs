//! Costs of the SplaTraj objective, one file per cost, behind the [`Cost`] trait.
//!
//! Per query window (docs/conventions.md "Optimisation problem") the optimiser minimises
//!
//! ```text
//! L = w_tce·TCE + w_tre·TRE + w_up·L_upright + α_k·L_prior,      α_k = α_0·γ^k
//! ```
//!
//! averaged over a batch of B sampled poses. Every cost maps the shared [`CostInputs`] (the
//! batch's poses Φ `[B, 6]`, the rendered object masks `[B, H, W]` when a render was made, the
//! step k and the query's [`QueryContext`]) to one unweighted value per sample `[B]`, and says
//! its own weight at step k. [`WeightedCosts`] sums w_i·cost_i and keeps each term for
//! `history.csv`.
//!
//! - [`mod@tce`]: target centring error (image cost); [`mod@tre`]: target ratio error (image cost);
//! - [`mod@upright`]: camera up against world up (`up-vector`, the paper's) or horizon tilt (`roll`);
//! - [`mod@prior`]: the decaying warm-start prior (attracting form; the paper's signs are a typo);
//! - [`mod@clearance`]: keeps the camera a margin away from the scene's geometry (path cost);
//! - [`mod@motion`]: speed, acceleration, turning- and orbit-rate limits, even speed (path cost;
//!   its terms and their gradients in [`mod@motion_rates`]);
//! - [`mod@shot`]: keeps a window's camera on its shot preset (orbit, dolly; [`crate::shots`]);
//! - [`iou`]: bounding-box IoU, a metric only (see that module for why it is not a [`Cost`]).
//!
//! **Samples and path.** Most costs judge each sampled pose on its own ([`CostDomain::Samples`]).
//! A path cost ([`CostDomain::Path`]) judges the camera's motion: in a trajectory optimisation
//! it reads [`CostInputs::path`], the window's stretch of the trajectory on a fine, evenly
//! spaced time grid, and returns its mean over that path `[1]`, which enters every sample's
//! total; without a path (single poses) it reads the sampled poses like any other cost. A
//! path cost that [`Cost::batches_windows`] also takes every window's stretch joined
//! ([`PathSamples::joined`]) and returns each stretch's mean `[W]`, the value it has on that
//! window's path alone ([`mod@path`]).
//!
//! **Extending.** A cost is a config struct (serde, its weights and parameters) implementing
//! [`CostConfig`] (`init()` builds the cost, burn's `XConfig` → `init()` style) and a [`Cost`]
//! (a tensor function of the [`CostInputs`]: poses, and the rendered channels it declares in
//! [`Cost::channels`]). A crate outside splatraj registers it under a name in a
//! [`CostRegistry`]; a config then turns it on with a `[costs.custom.<name>]` table, and
//! [`CostsConfig::build_with`] builds it after the built-in costs. The built-in costs are the
//! same kind of struct, with a typed field each in [`CostsConfig`] (so a typo in their keys is
//! caught when the file is parsed).
//!
//! The image costs are also plain tensor functions ([`tce()`], [`tre()`]; of the mask's
//! [`MaskMoments`], which the inputs make once for all costs): they run on the mask's
//! device and dtype and differentiate through burn's autodiff. The costs of the poses alone
//! (upright, prior, clearance, motion) are computed on the host in f64, value and gradient,
//! and join the graph by their first-order expansion about the poses ([`mod@expansion`]:
//! on a GPU a handful of launches instead of one per tensor op); their tensor forms
//! ([`upright()`], [`prior()`], [`clearance()`]) stay as the specification the tests hold
//! them to. None of the costs is ever NaN,
//! and for an empty mask (object out of view) TCE has a zero gradient and TRE a constant one,
//! so that nothing but the prior moves a camera that sees nothing (see each function's docs).

pub mod auto;
pub mod clearance;
pub mod expansion;
pub mod iou;
pub mod moments;
pub mod motion;
pub mod motion_rates;
pub mod path;
pub mod prior;
pub mod registry;
pub mod shot;
pub mod tce;
pub mod tre;
pub mod upright;
pub mod visibility;

use std::collections::BTreeMap;

use burn::tensor::{DType, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::clearance::{Occupancy, OccupancySpec};

pub use auto::OrAuto;
pub use clearance::{
    ClearanceCost, DEFAULT_CLEARANCE_SIGMA, DEFAULT_MIN_OPACITY, auto_margin, clearance,
    clearance_on_host,
};
pub use expansion::{PoseGradients, expansion_at, per_sample_on_host, per_stretch_on_host};
pub use iou::{
    IOU_THRESHOLD, PixelBox, bbox_iou, bbox_iou_batch, box_from_hits, box_iou, mask_box, mask_hits,
};
pub use moments::{HostMoments, MaskMoments, MomentSums, mask_mass, moment_sums};
pub use motion::{MotionCost, auto_max_speed};
pub use path::{PathSamples, PathStretch, PerRow};
pub use prior::{PRIOR_EPSILON_FRACTION, PriorCost, default_prior_radius, prior, prior_on_host};
pub use registry::{CostConfig, CostRegistry};
pub use shot::ShotCost;
pub use tce::{
    MASS_FLOOR, NORM_EPSILON, TceCost, centroid_offset, centroid_offset_of, tce, tce_of,
    tce_on_host,
};
pub use tre::{DEFAULT_TARGET_RATIO, TreCost, coverage, tre, tre_of, tre_on_host};
pub use upright::{UprightCost, UprightMode, upright, upright_on_host};
pub use visibility::{VisibilityCost, hidden_share, hidden_share_of};

/// Prefix of every config key named in errors: the costs live in the config's `[costs]` table.
pub const CONFIG_TABLE: &str = "costs";

/// Why costs could not be configured or evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CostError {
    /// A config value is out of range; the error's key is the full config key (e.g.
    /// `costs.prior.gamma`).
    #[error(transparent)]
    InvalidConfig(#[from] splatraj_config::ConfigError),
    /// The per-query context is unusable (a caller bug or a degenerate object).
    #[error("cost context: `{field}` {reason}")]
    InvalidContext {
        /// Field of [`QueryContext`] or argument name.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A cost needs the rendered mask but the inputs hold none.
    #[error("cost `{cost}` needs the rendered object mask, but none was rendered")]
    MissingMask {
        /// Name of the cost.
        cost: &'static str,
    },
    /// A cost reads a rendered channel the inputs do not hold (it did not declare it in
    /// [`Cost::channels`]).
    #[error("cost `{cost}` needs the rendered {channel:?} channel, but none was rendered")]
    MissingChannel {
        /// Name of the cost.
        cost: &'static str,
        /// The channel.
        channel: ImageChannel,
    },
    /// A cost needs the scene's geometry but the problem holds none.
    #[error("cost `{cost}` needs the scene's geometry (an occupancy), but the problem has none")]
    MissingOccupancy {
        /// Name of the cost.
        cost: &'static str,
    },
    /// Tensor shapes or dtypes of the inputs disagree.
    #[error("cost inputs: {0}")]
    Shape(String),
    /// Two costs share a name (their history columns would collide), or none is configured.
    #[error("costs: {0}")]
    Set(String),
    /// A value a cost reads on the host could not be read back from the device.
    #[error("cost `{cost}`: {reason}")]
    ReadBack {
        /// The cost.
        cost: &'static str,
        /// The device's failure.
        reason: String,
    },
}

/// What one query (time window) contributes to the costs, on the host.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueryContext {
    /// Object centre o, world coordinates (the prior pulls the camera toward it).
    pub object_centre: [f64; 3],
    /// Prior radius r (> 0): the prior does not pull closer than this; see
    /// [`default_prior_radius`]. A `radius` in the prior's config overrides it.
    pub prior_radius: f64,
    /// World up (any length > 0; normalised where used).
    pub world_up: [f64; 3],
    /// Target ratio r_t ∈ (0, 1]: share of the frame the object should cover (TRE).
    pub target_ratio: f64,
}

impl QueryContext {
    /// Checks that every field is finite and in range (called by [`CostInputs::new`]).
    pub fn validate(&self) -> Result<(), CostError> {
        let bad = |field, reason: String| Err(CostError::InvalidContext { field, reason });
        if !self.object_centre.iter().all(|v| v.is_finite()) {
            return bad(
                "object_centre",
                format!("{:?} must be finite", self.object_centre),
            );
        }
        if !(self.prior_radius.is_finite() && self.prior_radius > 0.0) {
            return bad(
                "prior_radius",
                format!("{} must be finite and > 0", self.prior_radius),
            );
        }
        let up = self.world_up;
        let norm_sq = up.iter().map(|v| v * v).sum::<f64>();
        if !(up.iter().all(|v| v.is_finite()) && norm_sq > 0.0 && norm_sq.is_finite()) {
            return bad("world_up", format!("{up:?} must be finite and non-zero"));
        }
        if !(self.target_ratio > 0.0 && self.target_ratio <= 1.0) {
            return bad(
                "target_ratio",
                format!("{} must be in (0, 1]", self.target_ratio),
            );
        }
        Ok(())
    }

    /// World up scaled to unit length.
    pub fn unit_up(&self) -> [f64; 3] {
        let [x, y, z] = self.world_up;
        let n = (x * x + y * y + z * z).sqrt();
        [x / n, y / n, z / n]
    }
}

/// Everything a cost may read, for one batch of B samples of one query window.
///
/// Built by [`CostInputs::new`], which checks shapes; the rotations R_wc are computed once for
/// all costs. Tensors are cheap handles; costs clone what they consume.
#[derive(Debug, Clone)]
pub struct CostInputs {
    poses: Tensor<2>,
    /// R_wc, made on first use: image-only costs never need them, and on a GPU Rodrigues is
    /// two dozen launches forward.
    rotations: std::sync::OnceLock<Tensor<3>>,
    masks: Option<Tensor<3>>,
    /// The masks' moments, made on first use and shared by every cost that reads them (TCE,
    /// TRE and visibility would each reduce the mask again: launches on a GPU).
    moments: std::sync::OnceLock<MaskMoments>,
    mask_alone: Option<Tensor<3>>,
    depth: Option<Tensor<3>>,
    rgb: Option<Tensor<4>>,
    path: Option<PathSamples>,
    occupancy: Option<Occupancy>,
    times: Option<SampleTimes>,
    host_poses: Option<HostPoses>,
    /// The samples' and the path's values when no caller gave them and a cost read them:
    /// read once for all the costs computed on the host (each read waits for the device).
    read_samples: std::sync::OnceLock<Vec<[f64; 6]>>,
    read_path: std::sync::OnceLock<Vec<[f64; 6]>>,
    step: usize,
    query: QueryContext,
    /// One context per sample when the batch spans several windows (None: every sample has
    /// `query`).
    contexts: Option<std::sync::Arc<[QueryContext]>>,
}

/// The values of `poses` `[P, 6]`: those in `cache`, else read from the device (a failure
/// naming `cost`) and kept there.
fn read_once(
    cache: &std::sync::OnceLock<Vec<[f64; 6]>>,
    poses: &Tensor<2>,
    cost: &'static str,
) -> Result<Vec<[f64; 6]>, CostError> {
    if let Some(values) = cache.get() {
        return Ok(values.clone());
    }
    let values = splatraj_render::host::to_host(poses.clone().detach()).map_err(|e| {
        CostError::ReadBack {
            cost,
            reason: e.to_string(),
        }
    })?;
    let values: Vec<[f64; 6]> = values
        .chunks_exact(6)
        .map(|p| std::array::from_fn(|i| p[i]))
        .collect();
    Ok(cache.get_or_init(|| values).clone())
}

/// The values of the poses a cost reads, already on the host (read once per optimisation
/// step), so that the costs computed there (motion, clearance, prior, upright: docs/gpu.md,
/// "Costs on the host") do not read them back again. They must be the tensors' own values:
/// those costs expand about them.
#[derive(Debug, Clone, PartialEq)]
pub struct HostPoses {
    /// The sampled poses `[B][6]`.
    pub samples: Vec<[f64; 6]>,
    /// The path's poses `[P][6]`, when there is a path.
    pub path: Option<Vec<[f64; 6]>>,
}

/// When the sampled poses were taken (trajectory optimisation only): what costs that depend
/// on the time within the window (shots) read.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleTimes {
    /// Index of the query window the samples belong to.
    pub window: usize,
    /// Each sample's time within its window, s ∈ [0, 1] (0 at the window's start), `[B]`.
    pub within: Vec<f64>,
}

/// Which poses a cost judges (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CostDomain {
    /// Each sampled pose on its own; one value per sample.
    Samples,
    /// The densely sampled path when there is one (the cost returns its mean per stretch,
    /// `[1]` for a window's own path, and that enters the total), else the sampled poses.
    Path,
}

/// A rendered channel a cost can read (see [`Cost::channels`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ImageChannel {
    /// The query's object mask `[B, H, W]` (a pruned render when it is the only channel).
    Mask,
    /// Composited camera depth `[B, H, W]` of the whole scene (Σ z·α·T; divide by the
    /// coverage for the expected depth).
    Depth,
    /// Colour `[B, H, W, 3]` of the whole scene.
    Rgb,
    /// The query's object mask `[B, H, W]` rendered with the object's Gaussians alone
    /// (nothing in front of it): what [`mod@visibility`] compares the seen mask with.
    MaskAlone,
}

impl CostInputs {
    /// Inputs from poses Φ `[B, 6]`, masks `[B, H, W]` (None when nothing was rendered: the
    /// prior and upright need no render), the optimisation step k and the query's context.
    /// Masks and poses must share batch size, device and dtype.
    pub fn new(
        poses: Tensor<2>,
        masks: Option<Tensor<3>>,
        step: usize,
        query: QueryContext,
    ) -> Result<Self, CostError> {
        query.validate()?;
        let [batch, dim] = poses.dims();
        if dim != 6 {
            return Err(CostError::Shape(format!(
                "poses must be [B, 6], got [{batch}, {dim}]"
            )));
        }
        if let Some(m) = &masks {
            let [mb, _, _] = m.dims();
            if mb != batch {
                return Err(CostError::Shape(format!(
                    "masks hold {mb} samples, poses {batch}"
                )));
            }
            if m.dtype() != poses.dtype() {
                return Err(CostError::Shape(format!(
                    "masks are {:?}, poses {:?} (mixing dtypes in one op panics)",
                    m.dtype(),
                    poses.dtype()
                )));
            }
        }
        Ok(Self {
            poses,
            rotations: std::sync::OnceLock::new(),
            masks,
            moments: std::sync::OnceLock::new(),
            mask_alone: None,
            depth: None,
            rgb: None,
            path: None,
            occupancy: None,
            times: None,
            host_poses: None,
            read_samples: std::sync::OnceLock::new(),
            read_path: std::sync::OnceLock::new(),
            step,
            query,
            contexts: None,
        })
    }

    /// The same inputs for a batch whose samples belong to several windows: `contexts[b]` is
    /// sample b's (each validated). Only costs that [`Cost::batches_windows`] read them.
    pub fn with_contexts(mut self, contexts: Vec<QueryContext>) -> Result<Self, CostError> {
        if contexts.len() != self.batch() {
            return Err(CostError::Shape(format!(
                "{} contexts for {} samples",
                contexts.len(),
                self.batch()
            )));
        }
        for c in &contexts {
            c.validate()?;
        }
        self.contexts = Some(contexts.into());
        Ok(self)
    }

    /// The one context of every sample, or None when the samples' windows differ.
    pub fn single_query(&self) -> Option<&QueryContext> {
        match &self.contexts {
            None => Some(&self.query),
            Some(_) => None,
        }
    }

    /// Sample b's context (the query's, unless the batch spans several windows).
    pub fn sample_context(&self, b: usize) -> &QueryContext {
        match &self.contexts {
            None => &self.query,
            Some(each) => &each[b],
        }
    }

    /// `f` of each sample's context as rows on the poses' device: `[1, K]` when every sample
    /// shares one context (it broadcasts), else `[B, K]` (one upload either way).
    pub fn context_rows<const K: usize>(&self, f: impl Fn(&QueryContext) -> [f64; K]) -> Tensor<2> {
        let rows: Vec<f64> = match &self.contexts {
            None => f(&self.query).to_vec(),
            Some(each) => each.iter().flat_map(f).collect(),
        };
        let count = rows.len() / K;
        splatraj_render::host::upload(
            TensorData::new(rows, [count, K]),
            &self.poses.device(),
            self.poses.dtype(),
        )
    }

    /// Adds the host values of the poses (they must be those of the tensors).
    pub fn with_host_poses(mut self, poses: HostPoses) -> Self {
        self.host_poses = Some(poses);
        self
    }

    /// The host values of [`CostInputs::path_or_sample_poses`], when the caller gave them.
    pub fn path_or_sample_host_poses(&self) -> Option<&[[f64; 6]]> {
        let host = self.host_poses.as_ref()?;
        match (&self.path, &host.path) {
            (Some(_), Some(path)) => Some(path),
            (Some(_), None) => None,
            (None, _) => Some(&host.samples),
        }
    }

    /// The host values of [`CostInputs::path_or_sample_poses`]: those the caller gave (read
    /// once per optimisation step with everything else), else read from the device here, a
    /// failure naming `cost`.
    pub fn host_path_or_sample_poses(
        &self,
        cost: &'static str,
    ) -> Result<Vec<[f64; 6]>, CostError> {
        match (self.path_or_sample_host_poses(), &self.path) {
            (Some(poses), _) => Ok(poses.to_vec()),
            (None, Some(path)) => read_once(&self.read_path, &path.poses, cost),
            (None, None) => read_once(&self.read_samples, &self.poses, cost),
        }
    }

    /// The host values of the sampled poses [`CostInputs::poses`], as
    /// [`CostInputs::host_path_or_sample_poses`] gets them.
    pub fn host_sample_poses(&self, cost: &'static str) -> Result<Vec<[f64; 6]>, CostError> {
        match &self.host_poses {
            Some(host) => Ok(host.samples.clone()),
            None => read_once(&self.read_samples, &self.poses, cost),
        }
    }

    /// Adds the object's mask rendered alone `[B, H, W]`.
    pub fn with_mask_alone(mut self, mask: Tensor<3>) -> Self {
        self.mask_alone = Some(mask);
        self
    }

    /// The object's mask rendered alone, or [`CostError::MissingChannel`] naming `cost`.
    pub fn require_mask_alone(&self, cost: &'static str) -> Result<Tensor<3>, CostError> {
        self.mask_alone.clone().ok_or(CostError::MissingChannel {
            cost,
            channel: ImageChannel::MaskAlone,
        })
    }

    /// Adds the rendered depth `[B, H, W]`.
    pub fn with_depth(mut self, depth: Tensor<3>) -> Self {
        self.depth = Some(depth);
        self
    }

    /// Adds the rendered colour `[B, H, W, 3]`.
    pub fn with_rgb(mut self, rgb: Tensor<4>) -> Self {
        self.rgb = Some(rgb);
        self
    }

    /// Adds the densely sampled path (for path costs).
    pub fn with_path(mut self, path: PathSamples) -> Self {
        self.path = Some(path);
        self
    }

    /// Adds the scene's geometry (for clearance).
    pub fn with_occupancy(mut self, occupancy: Occupancy) -> Self {
        self.occupancy = Some(occupancy);
        self
    }

    /// Adds when the samples were taken (for costs that depend on time, e.g. shots).
    pub fn with_times(mut self, times: SampleTimes) -> Self {
        self.times = Some(times);
        self
    }

    /// When the samples were taken, in a trajectory optimisation.
    pub fn times(&self) -> Option<&SampleTimes> {
        self.times.as_ref()
    }

    /// The densely sampled path, in a trajectory optimisation.
    pub fn path(&self) -> Option<&PathSamples> {
        self.path.as_ref()
    }

    /// The path's poses `[P, 6]` when there is a path, else the sampled poses `[B, 6]`.
    pub fn path_or_sample_poses(&self) -> Tensor<2> {
        match &self.path {
            Some(p) => p.poses.clone(),
            None => self.poses.clone(),
        }
    }

    /// The scene's geometry, or [`CostError::MissingOccupancy`] naming `cost`.
    pub fn require_occupancy(&self, cost: &'static str) -> Result<Occupancy, CostError> {
        self.occupancy
            .clone()
            .ok_or(CostError::MissingOccupancy { cost })
    }

    /// Rendered depth `[B, H, W]`, or [`CostError::MissingChannel`] naming `cost`.
    pub fn require_depth(&self, cost: &'static str) -> Result<Tensor<3>, CostError> {
        self.depth.clone().ok_or(CostError::MissingChannel {
            cost,
            channel: ImageChannel::Depth,
        })
    }

    /// Rendered colour `[B, H, W, 3]`, or [`CostError::MissingChannel`] naming `cost`.
    pub fn require_rgb(&self, cost: &'static str) -> Result<Tensor<4>, CostError> {
        self.rgb.clone().ok_or(CostError::MissingChannel {
            cost,
            channel: ImageChannel::Rgb,
        })
    }

    /// Batch size B.
    pub fn batch(&self) -> usize {
        self.poses.dims()[0]
    }

    /// Poses Φ `[B, 6]`.
    pub fn poses(&self) -> &Tensor<2> {
        &self.poses
    }

    /// Camera centres c `[B, 3]` (Φ's last three components).
    pub fn centres(&self) -> Tensor<2> {
        self.poses.clone().narrow(1, 3, 3)
    }

    /// Camera-to-world rotations R_wc `[B, 3, 3]` (differentiable Rodrigues of Φ's ω).
    pub fn rotations(&self) -> &Tensor<3> {
        self.rotations.get_or_init(|| {
            splatraj_render::camera::rotation_matrices(self.poses.clone().narrow(1, 0, 3))
        })
    }

    /// Column `axis` of R_wc, `[B, 3]`: the camera's x (right, 0), y (down, 1) or z (forward,
    /// 2) axis in world coordinates.
    pub fn camera_axis(&self, axis: usize) -> Tensor<2> {
        let batch = self.batch();
        self.rotations()
            .clone()
            .narrow(2, axis, 1)
            .reshape([batch, 3])
    }

    /// Rendered object masks `[B, H, W]`, if a render was made.
    pub fn masks(&self) -> Option<&Tensor<3>> {
        self.masks.as_ref()
    }

    /// The masks, or [`CostError::MissingMask`] naming `cost`.
    pub fn require_masks(&self, cost: &'static str) -> Result<Tensor<3>, CostError> {
        self.masks.clone().ok_or(CostError::MissingMask { cost })
    }

    /// The moments of the rendered masks (made once, on first use), or
    /// [`CostError::MissingMask`] naming `cost`.
    pub fn require_mask_moments(&self, cost: &'static str) -> Result<&MaskMoments, CostError> {
        let masks = self.masks.as_ref().ok_or(CostError::MissingMask { cost })?;
        Ok(self.moments.get_or_init(|| MaskMoments::of(masks.clone())))
    }

    /// Optimisation step k (0 first).
    pub fn step(&self) -> usize {
        self.step
    }

    /// The query's context (of the first sample, when the batch spans several windows: a
    /// cost that [`Cost::batches_windows`] reads [`CostInputs::context_rows`] or
    /// [`CostInputs::sample_context`] instead).
    pub fn query(&self) -> &QueryContext {
        &self.query
    }

    /// A host vector as a `[1, 3]` row on the poses' device and dtype (for broadcasting).
    pub fn row(&self, v: [f64; 3]) -> Tensor<2> {
        splatraj_render::host::upload(
            TensorData::new(v.to_vec(), [1, 3]),
            &self.poses.device(),
            self.poses.dtype(),
        )
    }

    /// Dtype of poses (and masks).
    pub fn dtype(&self) -> DType {
        self.poses.dtype()
    }
}

/// One cost term: a name, a weight from the config, and a per-sample value.
pub trait Cost: std::fmt::Debug + Send + Sync {
    /// Name used in logs and as the `history.csv` column (the config table's name).
    fn name(&self) -> &'static str;

    /// Weight of the term at optimisation step `step` (constant for all but the prior).
    fn weight(&self, step: usize) -> f64;

    /// The rendered channels [`Cost::evaluate`] reads (none: the cost reads only the poses,
    /// and a run whose costs all say so renders nothing).
    fn channels(&self) -> &'static [ImageChannel] {
        &[]
    }

    /// Which poses it judges (default: each sample on its own).
    fn domain(&self) -> CostDomain {
        CostDomain::Samples
    }

    /// The scene geometry it reads ([`CostInputs::require_occupancy`]), if any.
    fn occupancy(&self) -> Option<OccupancySpec> {
        None
    }

    /// Whether one evaluation may serve several windows (an optimisation step's whole batch,
    /// so its launches do not grow with the windows). A sample cost ([`CostDomain::Samples`])
    /// then reads the query context only through [`CostInputs::context_rows`],
    /// [`CostInputs::sample_context`] (or [`CostInputs::single_query`]) and reads no times,
    /// path or geometry (the samples' host values it may read: they come for the whole
    /// batch). A path
    /// cost ([`CostDomain::Path`]) then takes a path of several stretches ([`PathSamples`],
    /// each with its window's context and time step) and returns each stretch's mean `[W]`,
    /// no term pairing one stretch's poses with the next's. Default false: evaluated per
    /// window.
    fn batches_windows(&self) -> bool {
        false
    }

    /// Checks the config values; errors name the full key (`costs.<name>.<field>`).
    fn validate(&self) -> Result<(), CostError>;

    /// Unweighted cost per sample `[B]`, differentiable w.r.t. the poses and masks.
    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError>;
}

/// Checks a config weight (finite, ≥ 0), naming `costs.<cost>.<field>` on error.
pub fn check_weight(cost: &str, field: &str, value: f64) -> Result<(), CostError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            cost,
            field,
            format!("= {value} must be finite and ≥ 0"),
        ))
    }
}

/// An [`CostError::InvalidConfig`] for key `costs.<cost>.<field>`.
pub fn invalid(cost: &str, field: &str, reason: String) -> CostError {
    CostError::InvalidConfig(splatraj_config::ConfigError::new(
        format!("{CONFIG_TABLE}.{cost}.{field}"),
        reason,
    ))
}

/// The `[costs]` table: one optional sub-table per cost; a cost is on when its table is there.
///
/// ```toml
/// [costs.tce]
/// weight = 1.0
/// [costs.upright]
/// mode = "roll"      # or "up-vector" (default)
/// [costs.prior]
/// alpha0 = 1.0
/// gamma = 0.99
/// ```
///
/// [`Default`] is the paper's objective: the four optimised costs with their default weights
/// (L = TCE + TRE + L_upright + α·L_prior). An experiment config without a `[costs]` table
/// gets [`CostsConfig::first_try`] instead (those four, the horizon-only upright, clearance and
/// motion limits derived from the scene, visibility); a `[costs]` table lists exactly the costs that are
/// on (the ablations: prior only, prior + TCE, …). Unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CostsConfig {
    /// Target centring error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tce: Option<TceCost>,
    /// Target ratio error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tre: Option<TreCost>,
    /// Uprightness.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub upright: Option<UprightCost>,
    /// Decaying warm-start prior.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<PriorCost>,
    /// Clearance from the scene's geometry (path cost; off unless its table is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<ClearanceCost>,
    /// Motion limits (path cost; off unless its table is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionCost>,
    /// Visibility: the share of the object other geometry hides (off unless its table is
    /// given; renders the object alone too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility: Option<VisibilityCost>,
    /// Costs registered by other crates ([`CostRegistry`]), by name: `[costs.custom.<name>]`
    /// holds that cost's config table.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub custom: BTreeMap<String, toml::Value>,
}

impl Default for CostsConfig {
    /// All four costs with their defaults (the paper's objective).
    fn default() -> Self {
        Self {
            tce: Some(TceCost::default()),
            tre: Some(TreCost::default()),
            upright: Some(UprightCost::default()),
            prior: Some(PriorCost::default()),
            clearance: None,
            motion: None,
            visibility: None,
            custom: BTreeMap::new(),
        }
    }
}

impl CostsConfig {
    /// The costs of a config that names none: the paper's four, with the horizon-only
    /// upright (`roll`: a camera may pitch down to an object on the floor), clearance with an
    /// automatic margin, motion limits (an automatic speed, [`motion`]'s default turning
    /// rate) and visibility. What a new user's capture needs on the first run
    /// (docs/first-try.md).
    pub fn first_try() -> Self {
        Self {
            upright: Some(UprightCost {
                mode: UprightMode::Roll,
                ..UprightCost::default()
            }),
            clearance: Some(ClearanceCost::default()),
            motion: Some(MotionCost::first_try()),
            visibility: Some(VisibilityCost::default()),
            ..Self::default()
        }
    }

    /// Validates every configured cost and collects them, in the order tce, tre, upright, prior,
    /// clearance, motion, visibility.
    /// A `custom` cost is an error here: build those with [`CostsConfig::build_with`].
    pub fn build(&self) -> Result<WeightedCosts, CostError> {
        self.build_with(&CostRegistry::default())
    }

    /// [`CostsConfig::build`], then the `custom` costs (in name order) from `registry`.
    pub fn build_with(&self, registry: &CostRegistry) -> Result<WeightedCosts, CostError> {
        let mut costs: Vec<Box<dyn Cost>> = Vec::new();
        if let Some(c) = &self.tce {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.tre {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.upright {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.prior {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.clearance {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.motion {
            costs.push(Box::new(c.clone()));
        }
        if let Some(c) = &self.visibility {
            costs.push(Box::new(c.clone()));
        }
        for (name, table) in &self.custom {
            costs.push(registry.build(name, table)?);
        }
        WeightedCosts::new(costs)
    }
}

/// One evaluated term: its weight at this step and its unweighted value per sample.
#[derive(Debug, Clone)]
pub struct CostTerm {
    /// The cost's name.
    pub name: &'static str,
    /// Weight w_i at this step (α_k for the prior).
    pub weight: f64,
    /// Unweighted value per sample `[B]` (a path cost's per stretch: `[1]` on a window's own
    /// path, `[W]` on a joined one).
    pub value: Tensor<1>,
}

/// The weighted sum and its terms, for one batch.
#[derive(Debug, Clone)]
pub struct CostTerms {
    /// Σ_i w_i·cost_i per sample `[B]`, per stretch `[W]` on a joined path (differentiable).
    pub total: Tensor<1>,
    /// Each term, in the order of the [`WeightedCosts`].
    pub terms: Vec<CostTerm>,
}

impl CostTerms {
    /// Batch means of each unweighted term, `(name, weight, mean)`, on the host (a history row).
    pub fn means(&self) -> Vec<(&'static str, f64, f64)> {
        self.terms
            .iter()
            .map(|t| (t.name, t.weight, host_mean(t.value.clone())))
            .collect()
    }

    /// Batch mean of the weighted total, on the host.
    pub fn total_mean(&self) -> f64 {
        host_mean(self.total.clone())
    }

    /// Each term's `(name, weight)`, in the order of [`CostTerms::means_on_device`].
    pub fn labels(&self) -> Vec<(&'static str, f64)> {
        self.terms.iter().map(|t| (t.name, t.weight)).collect()
    }

    /// Batch means of each unweighted term `[terms]`, left on the device (detached), so that
    /// an optimisation step reads them together with everything else it reads.
    pub fn means_on_device(&self) -> Tensor<1> {
        Tensor::cat(
            self.terms
                .iter()
                .map(|t| t.value.clone().without_autodiff().mean())
                .collect(),
            0,
        )
    }
}

fn host_mean(t: Tensor<1>) -> f64 {
    splatraj_render::host::scalar(t.mean())
}

/// A set of costs with distinct names, summed with their weights.
#[derive(Debug)]
pub struct WeightedCosts {
    costs: Vec<Box<dyn Cost>>,
}

impl WeightedCosts {
    /// Validates each cost; errors when none is given or two share a name.
    pub fn new(costs: Vec<Box<dyn Cost>>) -> Result<Self, CostError> {
        if costs.is_empty() {
            return Err(CostError::Set(format!(
                "no cost is configured: add at least one `[{CONFIG_TABLE}.<name>]` table"
            )));
        }
        for (i, c) in costs.iter().enumerate() {
            c.validate()?;
            if costs[..i].iter().any(|d| d.name() == c.name()) {
                return Err(CostError::Set(format!("cost `{}` given twice", c.name())));
            }
        }
        Ok(Self { costs })
    }

    /// The same set with `cost` added last (a cost built outside the config, e.g. the shots').
    pub fn with_cost(self, cost: Box<dyn Cost>) -> Result<Self, CostError> {
        let mut costs = self.costs;
        costs.push(cost);
        Self::new(costs)
    }

    /// The costs, in evaluation order.
    pub fn costs(&self) -> &[Box<dyn Cost>] {
        &self.costs
    }

    /// Names of the terms, in order (the `history.csv` columns).
    pub fn names(&self) -> Vec<&'static str> {
        self.costs.iter().map(|c| c.name()).collect()
    }

    /// Whether any cost reads the rendered mask.
    pub fn needs_mask(&self) -> bool {
        self.channels().contains(&ImageChannel::Mask)
    }

    /// Every channel some cost reads, sorted, each once.
    pub fn channels(&self) -> Vec<ImageChannel> {
        let mut all: Vec<ImageChannel> = self
            .costs
            .iter()
            .flat_map(|c| c.channels().iter().copied())
            .collect();
        all.sort();
        all.dedup();
        all
    }

    /// Whether any cost judges the path (the optimiser then samples it densely).
    pub fn needs_path(&self) -> bool {
        self.costs.iter().any(|c| c.domain() == CostDomain::Path)
    }

    /// The scene geometry some cost reads (the first one's spec; None when no cost does).
    pub fn occupancy(&self) -> Option<OccupancySpec> {
        self.costs.iter().find_map(|c| c.occupancy())
    }

    /// Every term and Σ_i w_i(k)·cost_i per sample `[B]` (a path cost adds its mean over the
    /// path to every sample).
    pub fn evaluate(&self, inputs: &CostInputs) -> Result<CostTerms, CostError> {
        self.evaluate_where(inputs, |_| true)?
            .ok_or_else(|| CostError::Set("no cost is configured".into()))
    }

    /// [`WeightedCosts::evaluate`] of the costs `keep` selects (in order); None when it keeps
    /// none. On a path of several stretches ([`PathSamples::joined`]) it keeps only path
    /// costs, and their values and the total are per stretch `[W]`.
    pub fn evaluate_where(
        &self,
        inputs: &CostInputs,
        keep: impl Fn(&dyn Cost) -> bool,
    ) -> Result<Option<CostTerms>, CostError> {
        let mut total: Option<Tensor<1>> = None;
        let mut terms = Vec::with_capacity(self.costs.len());
        let batch = inputs.batch();
        let stretches = inputs.path().map_or(1, |p| p.stretches().len());
        for cost in self.costs.iter().filter(|c| keep(c.as_ref())) {
            let on_path = cost.domain() == CostDomain::Path && inputs.path().is_some();
            if stretches > 1 && !on_path {
                return Err(CostError::Shape(format!(
                    "cost `{}` judges samples, but the inputs hold {stretches} windows' paths \
                     (evaluate it on the samples' inputs)",
                    cost.name()
                )));
            }
            let weight = cost.weight(inputs.step());
            let value = cost.evaluate(inputs)?;
            let weighted = if stretches > 1 {
                value.clone().mul_scalar(weight) // [W]
            } else if on_path {
                value.clone().mean().mul_scalar(weight).expand([batch])
            } else {
                value.clone().mul_scalar(weight)
            };
            total = Some(match total {
                Some(t) => t + weighted,
                None => weighted,
            });
            terms.push(CostTerm {
                name: cost.name(),
                weight,
                value,
            });
        }
        Ok(total.map(|total| CostTerms { total, terms }))
    }
}
