//! [`Problem`]: what every optimiser works on, and the one loss path.
//!
//! A problem is a scene on a device, the query windows (each object's per-Gaussian mask and
//! cost context), the weighted costs, and how to render (intrinsics, rasterizer). Its
//! [`Problem::evaluate`] renders exactly the channels the costs declare ([`Cost::channels`]:
//! a mask-only pass is pruned to the object, which is exact; nothing is rendered when no cost
//! reads an image) and evaluates the costs. The trajectory optimiser, the single-pose
//! optimiser, SGLD, `splatraj render --grad` and `splatraj bench` all compute their loss there.
//!
//! [`Cost::channels`]: crate::costs::Cost::channels

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::focus::Surroundings;
use splatraj_render::host::{OnDevice, as_stored};
use splatraj_render::joined_rows::cut_rows;
use splatraj_render::rasterize::{Approximations, RenderStats};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, ObjectMasks, ObjectView, Pruning, Rasterizer, RenderError,
    RenderRequest, Zoom, render_at,
};

use super::sampling::window_bounds;
use super::{OptimiseError, WindowTarget, backward, host_values};
use crate::clearance::Occupancy;
use crate::costs::{
    Cost, CostDomain, CostError, CostInputs, CostTerms, HostPoses, ImageChannel, PathSamples,
    PathStretch, QueryContext, SampleTimes, WeightedCosts, coverage,
};

/// A scene, its query windows, the costs and the camera: the arguments every optimiser shares.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a> {
    /// The scene, uploaded to the device the optimisation runs on (an autodiff device for
    /// gradients); poses take its device and dtype.
    pub scene: &'a DeviceScene,
    /// The query windows in time order (one for a single-pose problem).
    pub windows: &'a [WindowTarget],
    /// The weighted costs.
    pub costs: &'a WeightedCosts,
    /// The optimisation camera.
    pub intrinsics: Intrinsics,
    /// Which rasterizer composites the renders.
    pub rasterizer: Rasterizer,
    /// Prune a mask-only pass to the object (exact: same image and gradient; on by default,
    /// off only to measure what pruning saves).
    pub prune: bool,
    /// The scene's solid geometry, for costs that read it (clearance).
    pub occupancy: Option<&'a Occupancy>,
    /// Duration of the whole trajectory in seconds (motion limits), when known.
    pub seconds: Option<f64>,
    /// Rendering shortcuts of the optimisation passes (exact by default).
    pub approximations: Approximations,
    /// How the windows of a step share render calls.
    pub step_passes: StepPasses,
}

/// How the windows of an optimisation step share render calls ([`Problem::evaluate_windows`]).
///
/// One call for all windows makes a step's launches independent of the number of windows,
/// which is what a GPU is bound by. On the CPU the two take the same time since a pass's
/// rows are each pose's own (first-try guitar, flex on 2 cores: 148 ms a step in one call,
/// 144 ms in a call per window; before, one call carried the union of every window's
/// Gaussians for every pose and took 179 ms), and a call per window keeps the digits CPU runs
/// have always had: the batched costs sum in another order, which a run's f32 Adam steps
/// amplify (docs/gpu.md, "One pass a step").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepPasses {
    /// One render call for every window of the step, each object alone included, and the
    /// costs that batch run once on all its samples (the GPU).
    Shared,
    /// A render call and the costs per window, its object alone included (the CPU).
    #[default]
    PerWindow,
}

impl StepPasses {
    /// The faster choice on `backend` (measured; see the type's docs).
    pub fn for_backend(backend: BackendKind) -> Self {
        match backend {
            BackendKind::Wgpu => StepPasses::Shared,
            BackendKind::Flex | BackendKind::Ndarray => StepPasses::PerWindow,
        }
    }
}

/// How a problem's windows render ([`Problem::renders`]): the request, and each window's
/// object-alone mask when a cost reads the object alone.
#[derive(Debug, Clone)]
pub struct WindowRenders {
    /// The channels the costs read; the object masks' views are set per pass.
    request: RenderRequest,
    /// Per window, the index of its object-alone mask in the request's object masks.
    alone: Option<Vec<usize>>,
}

/// A window's densely sampled path (evenly spaced in time) for the path costs.
#[derive(Debug, Clone)]
pub enum WindowPath {
    /// Its poses `[P, 6]` (boxed: a tensor handle is large) and their time step.
    Poses(Box<Tensor<2>>, f64),
    /// Its P poses are the window's share of the rows after the samples in the poses given to
    /// [`Problem::evaluate_windows`] (every window's path, in window order), `time_step`
    /// apart: cut out only where a cost reads this window's path alone (on a GPU a slice is
    /// a launch, whether anything reads it or not).
    Rows(usize, f64),
}

impl WindowPath {
    /// Its number of poses P.
    pub fn rows(&self) -> usize {
        match self {
            WindowPath::Poses(poses, _) => poses.dims()[0],
            WindowPath::Rows(rows, _) => *rows,
        }
    }

    /// The normalised time between its consecutive poses.
    pub fn time_step(&self) -> f64 {
        match self {
            WindowPath::Poses(_, time_step) | WindowPath::Rows(_, time_step) => *time_step,
        }
    }

    /// Its poses `[P, 6]` and time step; `joined` holds every window's path, this one from
    /// row `first` on (needed for [`WindowPath::Rows`]).
    fn poses(
        &self,
        joined: Option<&Tensor<2>>,
        first: usize,
    ) -> Result<(Tensor<2>, f64), OptimiseError> {
        match (self, joined) {
            (WindowPath::Poses(poses, time_step), _) => Ok((*poses.clone(), *time_step)),
            (WindowPath::Rows(rows, time_step), Some(joined)) => {
                Ok((joined.clone().narrow(0, first, *rows), *time_step))
            }
            (WindowPath::Rows(..), None) => Err(OptimiseError::InvalidOptions {
                field: "windows",
                reason: "a window's path is given as rows of the poses, but the poses hold only \
                         the samples"
                    .into(),
            }),
        }
    }
}

/// One window's samples in a pass of several windows ([`Problem::evaluate_windows`]).
#[derive(Debug, Clone)]
pub struct WindowSamples<'s> {
    /// Which window.
    pub window: usize,
    /// Its samples: the next `count` rows of the poses.
    pub count: usize,
    /// Their times t ∈ [0, 1] of the whole trajectory, for costs that depend on time.
    pub times: Option<&'s [f64]>,
    /// The window's densely sampled path, for the path costs.
    pub path: Option<WindowPath>,
    /// The host values of the samples and the path, when the caller has them.
    pub host: Option<&'s HostPoses>,
    /// The samples' zoom `[count]` when the lens zooms (None: the configured focal length).
    pub zoom: Option<Zoom>,
}

/// Each window's first row in the joined path (every window's path, in window order).
fn path_starts(windows: &[WindowSamples<'_>]) -> Vec<usize> {
    windows
        .iter()
        .scan(0, |next, w| {
            let first = *next;
            *next += w.path.as_ref().map_or(0, WindowPath::rows);
            Some(first)
        })
        .collect()
}

impl WindowSamples<'_> {
    /// These samples with their path as its own poses ([`WindowPath::Poses`]), cut out of
    /// `joined` from row `first` when given as rows.
    fn with_own_path(
        mut self,
        joined: Option<&Tensor<2>>,
        first: usize,
    ) -> Result<Self, OptimiseError> {
        if let Some(path) = &self.path {
            let (poses, time_step) = path.poses(joined, first)?;
            self.path = Some(WindowPath::Poses(Box::new(poses), time_step));
        }
        Ok(self)
    }
}

/// What [`Problem::evaluate_windows`] found: the step's loss, each window's term means, the
/// object masks of all samples `[ΣS, H, W]` when one was rendered, and the passes' work.
#[derive(Debug, Clone)]
pub struct StepEvaluation {
    /// The mean over the windows of each window's mean weighted total, `[1]`
    /// (differentiable).
    pub loss: Tensor<1>,
    /// Each window's unweighted term means, window after window, each in the costs' order,
    /// detached `[Σ terms]` (what a history row reads).
    pub means: Tensor<1>,
    /// Per window, each term's `(name, weight)` in the order of `means`.
    pub labels: Vec<Vec<(&'static str, f64)>>,
    /// Every sample's object mask, windows one after the other.
    pub masks: Option<Tensor<3>>,
    /// How much compositing work the passes had, summed over them (None when nothing was
    /// rendered).
    pub stats: Option<RenderStats>,
    /// How the windows were rendered: `PerWindow` also when a shared call was asked for and
    /// the device could not hold it (the later steps of a run need not try again).
    pub passes: StepPasses,
}

impl StepEvaluation {
    /// The evaluation of windows whose terms were made one window at a time.
    fn of_windows(
        terms: Vec<CostTerms>,
        masks: Option<Tensor<3>>,
        stats: Option<RenderStats>,
    ) -> Self {
        let n = terms.len().max(1) as f64;
        let loss = terms
            .iter()
            .map(|t| t.total.clone().mean())
            .reduce(|a, b| a + b)
            .expect("at least one window")
            .div_scalar(n);
        StepEvaluation {
            loss,
            means: Tensor::cat(terms.iter().map(CostTerms::means_on_device).collect(), 0),
            labels: terms.iter().map(CostTerms::labels).collect(),
            masks,
            stats,
            passes: StepPasses::PerWindow,
        }
    }

    /// The evaluation of windows whose batching costs ran once on all `counts` samples
    /// (`batched`), whose batching path costs ran once on every window's stretch of path
    /// (`path`: each value and the total per window `[W]`) and whose other costs ran per
    /// window (`per_window`). The windows' means come from one matrix product with the
    /// averaging weights, not a slice per window.
    fn of_batch(
        costs: &WeightedCosts,
        batched: Option<CostTerms>,
        path: Option<CostTerms>,
        per_window: Vec<Option<CostTerms>>,
        counts: &[usize],
        masks: Option<Tensor<3>>,
        stats: Option<RenderStats>,
    ) -> Self {
        let n = counts.len();
        let rows: usize = counts.iter().sum();
        let mut loss: Vec<Tensor<1>> = Vec::with_capacity(n + 1);
        let mut parts: Vec<Tensor<1>> = Vec::with_capacity(n + 1);
        // Where each window's term of each cost sits in `parts` concatenated.
        let mut place: Vec<std::collections::HashMap<&'static str, (usize, f64)>> =
            vec![Default::default(); n];
        if let Some(batched) = &batched {
            let (device, dtype) = (batched.total.device(), batched.total.dtype());
            // a[s] = 1 / (n·S_i) for sample s of window i: the loss's weights.
            let weights: Vec<f64> = counts
                .iter()
                .flat_map(|&c| std::iter::repeat_n(1.0 / (n * c) as f64, c))
                .collect();
            let weights: Tensor<1> =
                splatraj_render::host::upload(TensorData::new(weights, [rows]), &device, dtype);
            loss.push((batched.total.clone() * weights).sum());
            // Means per window: [n, ΣS] (1/S_i on window i's samples) · [ΣS, terms].
            let averages: Vec<f64> = (0..n)
                .flat_map(|i| {
                    counts.iter().enumerate().flat_map(move |(j, &c)| {
                        std::iter::repeat_n(if i == j { 1.0 / c as f64 } else { 0.0 }, c)
                    })
                })
                .collect();
            let averages: Tensor<2> =
                splatraj_render::host::upload(TensorData::new(averages, [n, rows]), &device, dtype);
            let terms = batched.terms.len();
            let values = Tensor::cat(
                batched
                    .terms
                    .iter()
                    .map(|t| t.value.clone().without_autodiff().reshape([rows, 1]))
                    .collect(),
                1,
            ); // [ΣS, terms]
            parts.push(averages.matmul(values).reshape([n * terms])); // window-major
            for (i, place) in place.iter_mut().enumerate() {
                for (k, t) in batched.terms.iter().enumerate() {
                    place.insert(t.name, (i * terms + k, t.weight));
                }
            }
        }
        let mut offset = parts.first().map_or(0, |p| p.dims()[0]);
        if let Some(path) = &path {
            // Already a value per window: the loss's share is their mean over the windows.
            loss.push(path.total.clone().sum().div_scalar(n as f64));
            let terms = path.terms.len();
            let values = Tensor::stack::<2>(
                path.terms
                    .iter()
                    .map(|t| t.value.clone().without_autodiff())
                    .collect(),
                1,
            ); // [W, terms]
            parts.push(values.reshape([n * terms])); // window-major
            for (i, place) in place.iter_mut().enumerate() {
                for (k, t) in path.terms.iter().enumerate() {
                    place.insert(t.name, (offset + i * terms + k, t.weight));
                }
            }
            offset += n * terms;
        }
        for (i, terms) in per_window.iter().enumerate() {
            let Some(terms) = terms else { continue };
            loss.push(terms.total.clone().mean().div_scalar(n as f64));
            parts.push(terms.means_on_device());
            for (k, t) in terms.terms.iter().enumerate() {
                place[i].insert(t.name, (offset + k, t.weight));
            }
            offset += terms.terms.len();
        }
        let mut labels = Vec::with_capacity(n);
        let mut order: Vec<i64> = Vec::with_capacity(offset);
        for place in &place {
            let mut window = Vec::with_capacity(place.len());
            for cost in costs.costs() {
                if let Some(&(at, weight)) = place.get(cost.name()) {
                    order.push(at as i64);
                    window.push((cost.name(), weight));
                }
            }
            labels.push(window);
        }
        let flat = Tensor::cat(parts, 0);
        let in_order = order.iter().enumerate().all(|(k, &at)| k as i64 == at);
        let means = if in_order {
            flat
        } else {
            let device = flat.device();
            let index = splatraj_render::host::upload_ints(order, [offset], &device);
            flat.select(0, index)
        };
        StepEvaluation {
            loss: loss
                .into_iter()
                .reduce(|a, b| a + b)
                .expect("at least one cost"),
            means,
            labels,
            masks,
            stats,
            passes: StepPasses::Shared,
        }
    }
}

/// A pass's images of all its samples (each `[ΣS, H, W]`, colour `[ΣS, H, W, 3]`; the
/// object alone of the same samples), and its work.
struct Pass {
    masks: Option<Tensor<3>>,
    mask_alone: Option<Tensor<3>>,
    depth: Option<Tensor<3>>,
    rgb: Option<Tensor<4>>,
    stats: RenderStats,
}

impl Pass {
    /// The images of samples `first .. first + count` (no slice when that is all of them).
    fn window(&self, first: usize, count: usize) -> Images {
        let all = self
            .masks
            .as_ref()
            .or(self.depth.as_ref())
            .map(|t| t.dims()[0]);
        let cut3 = |t: &Option<Tensor<3>>| {
            t.clone().map(|t| match all {
                Some(rows) if first == 0 && count == rows => t,
                _ => t.narrow(0, first, count),
            })
        };
        Images {
            mask: cut3(&self.masks),
            mask_alone: cut3(&self.mask_alone),
            depth: cut3(&self.depth),
            rgb: self.rgb.clone().map(|t| {
                if first == 0 && Some(count) == all {
                    t
                } else {
                    t.narrow(0, first, count)
                }
            }),
        }
    }
}

/// A value lent by the caller or made here.
enum Borrowed<'r, T> {
    Lent(Option<&'r T>),
    Owned(Option<T>),
}

impl<T> Borrowed<'_, T> {
    fn get(&self) -> Option<&T> {
        match self {
            Borrowed::Lent(r) => *r,
            Borrowed::Owned(t) => t.as_ref(),
        }
    }
}

/// One window's images from a pass (each `[S, H, W]`, colour `[S, H, W, 3]`).
#[derive(Default)]
struct Images {
    mask: Option<Tensor<3>>,
    mask_alone: Option<Tensor<3>>,
    depth: Option<Tensor<3>>,
    rgb: Option<Tensor<4>>,
}

/// One evaluation: the cost terms and the object mask when one was rendered.
#[derive(Debug, Clone)]
pub struct Evaluated {
    /// Each term and the weighted total per sample.
    pub terms: CostTerms,
    /// Rendered object masks `[B, H, W]`, when a cost asked for them.
    pub masks: Option<Tensor<3>>,
    /// How much compositing work the render had (None when nothing was rendered).
    pub stats: Option<RenderStats>,
}

/// The loss of one pose on the host (`render --grad`, `bench`).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseLoss {
    /// Weighted total.
    pub total: f64,
    /// Each term as `(name, weight, unweighted value)`.
    pub terms: Vec<(&'static str, f64, f64)>,
    /// d total / dΦ when asked for (None on a plain device).
    pub grad_pose: Option<Vec<f64>>,
    /// Share of the frame the object's mask covers, when a mask was rendered.
    pub coverage: Option<f64>,
    /// How much compositing work the render had (None when nothing was rendered).
    pub stats: Option<RenderStats>,
}

impl PoseLoss {
    /// The unweighted value of the term `name` (NaN when the problem has no such cost).
    pub fn term(&self, name: &str) -> f64 {
        self.terms
            .iter()
            .find(|t| t.0 == name)
            .map_or(f64::NAN, |t| t.2)
    }
}

impl<'a> Problem<'a> {
    /// A problem rendered with the default rasterizer.
    pub fn new(
        scene: &'a DeviceScene,
        windows: &'a [WindowTarget],
        costs: &'a WeightedCosts,
        intrinsics: Intrinsics,
    ) -> Self {
        Self {
            scene,
            windows,
            costs,
            intrinsics,
            rasterizer: Rasterizer::default(),
            prune: true,
            occupancy: None,
            seconds: None,
            approximations: Approximations::default(),
            step_passes: StepPasses::default(),
        }
    }

    /// The same problem with its windows sharing render calls as `passes` says.
    pub fn with_step_passes(mut self, passes: StepPasses) -> Self {
        self.step_passes = passes;
        self
    }

    /// The same problem with rendering shortcuts (`[approximations]`; not for metrics).
    pub fn with_approximations(mut self, approximations: Approximations) -> Self {
        self.approximations = approximations;
        self
    }

    /// The same problem with the scene's geometry (needed by the clearance cost).
    pub fn with_occupancy(mut self, occupancy: Option<&'a Occupancy>) -> Self {
        self.occupancy = occupancy;
        self
    }

    /// The same problem with the trajectory's duration in seconds (needed by motion limits).
    pub fn with_seconds(mut self, seconds: Option<f64>) -> Self {
        self.seconds = seconds;
        self
    }

    /// The same problem with another rasterizer.
    pub fn with_rasterizer(mut self, rasterizer: Rasterizer) -> Self {
        self.rasterizer = rasterizer;
        self
    }

    /// The single-window problem of window `index`.
    pub fn window(&self, index: usize) -> Result<Problem<'a>, OptimiseError> {
        let windows =
            self.windows
                .get(index..=index)
                .ok_or_else(|| OptimiseError::InvalidOptions {
                    field: "window",
                    reason: format!("= {index}, but there are {} windows", self.windows.len()),
                })?;
        Ok(Problem { windows, ..*self })
    }

    /// The one window of a single-pose problem.
    pub fn single(&self) -> Result<&'a WindowTarget, OptimiseError> {
        match self.windows {
            [w] => Ok(w),
            _ => Err(OptimiseError::InvalidOptions {
                field: "windows",
                reason: format!(
                    "a single-pose problem has exactly one window, got {} (use Problem::window)",
                    self.windows.len()
                ),
            }),
        }
    }

    /// How the windows render: one request for the channels the costs read, every window's
    /// object mask among them (pruned to each pose's object when the mask is the only channel),
    /// and each window's object alone when a cost reads it; None when no cost reads an image.
    /// Made once per run (it copies the masks); each pass says which poses are whose.
    pub fn renders(&self) -> Option<WindowRenders> {
        let needed = self.costs.channels();
        if needed.is_empty() {
            return None;
        }
        let wants_mask = needed
            .iter()
            .any(|c| matches!(c, ImageChannel::Mask | ImageChannel::MaskAlone));
        let mut masks: Vec<Vec<f32>> = Vec::new();
        let mut alone = None;
        if wants_mask {
            masks = self.windows.iter().map(|w| w.mask.clone()).collect();
            if needed.contains(&ImageChannel::MaskAlone) {
                // The object alone is its Gaussians (non-zero mask) with value 1 each: the
                // window's own mask where that is already so, else one more mask.
                let mut objects = Vec::with_capacity(self.windows.len());
                for (i, w) in self.windows.iter().enumerate() {
                    if w.mask.iter().all(|&m| m == 0.0 || m == 1.0) {
                        objects.push(i);
                    } else {
                        objects.push(masks.len());
                        masks.push(w.mask.iter().map(|&m| f32::from(m != 0.0)).collect());
                    }
                }
                alone = Some(objects);
            }
        }
        let channels: Vec<Channel> = needed
            .iter()
            .filter_map(|c| match c {
                ImageChannel::Mask | ImageChannel::MaskAlone => None,
                ImageChannel::Depth => Some(Channel::Depth),
                ImageChannel::Rgb => Some(Channel::Rgb),
            })
            .collect();
        let channels = if wants_mask {
            let objects = Channel::ObjectMasks(ObjectMasks {
                masks: masks.into(),
                views: Vec::new(),
            });
            std::iter::once(objects).chain(channels).collect()
        } else {
            channels
        };
        let mut request = RenderRequest::new(self.intrinsics, channels);
        let mask_only = needed
            .iter()
            .all(|c| matches!(c, ImageChannel::Mask | ImageChannel::MaskAlone));
        if self.prune && mask_only {
            request.pruning = Pruning::ObjectOnly;
        }
        request.rasterizer = self.rasterizer;
        request.approximations = self.approximations;
        request.alpha = AlphaChannel::Dropped;
        Some(WindowRenders { request, alone })
    }

    /// The scene's device (checked to be autodiff) and dtype, and that every window's
    /// context is valid: what a gradient loop needs before it starts.
    pub(crate) fn gradient_setup(&self) -> Result<(Device, DType), OptimiseError> {
        let device = self.scene.device();
        if !device.is_autodiff() {
            return Err(OptimiseError::NotAutodiff);
        }
        if self.windows.is_empty() {
            return Err(OptimiseError::InvalidOptions {
                field: "windows",
                reason: "at least one query is needed".into(),
            });
        }
        for w in self.windows {
            w.context.validate()?;
        }
        Ok((device, self.scene.dtype()))
    }

    /// Renders what the costs read at poses Φ `[B, 6]` for window `index` and evaluates the
    /// costs at optimisation step `step`.
    pub fn evaluate(
        &self,
        index: usize,
        poses: Tensor<2>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<Evaluated, OptimiseError> {
        self.evaluate_along(index, poses, None, None, None, step, renders)
    }

    /// [`Problem::evaluate`] with the samples' times `[B]` (t ∈ [0, 1] of the whole
    /// trajectory, for costs that depend on time), the window's densely sampled path (poses
    /// `[P, 6]` at times `time_step` apart) for the path costs, and the host values of the
    /// samples and the path when the caller has them (then nothing is read back here: the
    /// renders' decisions and the clearance cost take them).
    #[allow(clippy::too_many_arguments)]
    pub fn evaluate_along(
        &self,
        index: usize,
        poses: Tensor<2>,
        times: Option<&[f64]>,
        path: Option<(Tensor<2>, f64)>,
        host: Option<&HostPoses>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<Evaluated, OptimiseError> {
        let [count, _] = poses.dims();
        let window = WindowSamples {
            window: index,
            count,
            times,
            path: path.map(|(poses, time_step)| WindowPath::Poses(Box::new(poses), time_step)),
            host,
            zoom: None,
        };
        let renders = self.renders_or(renders);
        let (terms, pass) = self.evaluate_one(window, poses, step, renders.get())?;
        Ok(Evaluated {
            terms,
            masks: pass.as_ref().and_then(|p| p.masks.clone()),
            stats: pass.map(|p| p.stats),
        })
    }

    /// Renders what the costs read for the samples of several windows and evaluates their
    /// costs at step `step`: `poses` `[ΣS, 6]` holds the windows' samples one window after
    /// the other, as `windows` lists them, optionally followed by every window's path in the
    /// same order `[ΣS + ΣP, 6]` (then the joined path is one slice of them, and a
    /// [`WindowPath::Rows`] path is cut out of them; a [`WindowPath::Poses`] path must be those
    /// very rows: only the counts are checked). The result is the step's loss (the mean over
    /// the windows of each window's mean weighted total) and each window's term means.
    ///
    /// With [`StepPasses::Shared`] one render call serves the whole step (each window's
    /// object alone included), and the costs that [`Cost::batches_windows`] run once on the
    /// whole batch with each sample's own context, and the path costs that batch run once on
    /// every window's stretch of path joined (each window's mean over its own stretch), so
    /// neither the render's launches nor those costs' grow with the number of windows; the
    /// other costs (time-dependent ones, custom ones) run per window. With
    /// [`StepPasses::PerWindow`] each window has its own render call and costs (docs/gpu.md,
    /// "One pass a step").
    ///
    /// [`Cost::batches_windows`]: crate::costs::Cost::batches_windows
    pub fn evaluate_windows(
        &self,
        poses: Tensor<2>,
        windows: Vec<WindowSamples<'_>>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<StepEvaluation, OptimiseError> {
        let [rows, _] = poses.dims();
        let total: usize = windows.iter().map(|w| w.count).sum();
        let path_rows: Option<usize> = windows
            .iter()
            .map(|w| w.path.as_ref().map(WindowPath::rows))
            .sum();
        // The samples alone, or the samples then every window's path: the joined path is
        // then one slice of the caller's rows, not the windows' paths cut out and joined
        // again (on a GPU ~12 launches a step less, most of them in the backward).
        let (poses, joined) = match path_rows {
            _ if rows == total => (poses, None),
            Some(path_rows) if rows == total + path_rows => (
                poses.clone().narrow(0, 0, total),
                Some(poses.narrow(0, total, path_rows)),
            ),
            _ => {
                let paths = match path_rows {
                    Some(p) => format!(" and their paths to {p}"),
                    None => String::new(),
                };
                return Err(OptimiseError::InvalidOptions {
                    field: "windows",
                    reason: format!(
                        "the windows' samples add up to {total}{paths}, the poses to {rows}"
                    ),
                });
            }
        };
        let rows = total;
        if let Some(w) = windows.iter().find(|w| w.window >= self.windows.len()) {
            return Err(OptimiseError::InvalidOptions {
                field: "window",
                reason: format!(
                    "= {}, but there are {} windows",
                    w.window,
                    self.windows.len()
                ),
            });
        }
        let renders = self.renders_or(renders);
        let counts: Vec<usize> = windows.iter().map(|w| w.count).collect();
        if self.step_passes == StepPasses::PerWindow || windows.len() == 1 {
            return self.evaluate_per_window(poses, joined, windows, step, renders.get());
        }
        let pass = match self.render_pass(poses.clone(), &windows, renders.get()) {
            // Every window's packed rows in one buffer are the largest buffer of a run; a
            // device too small for them (lavapipe, a laptop's GPU) may hold each window's
            // own, a window's share of them.
            Err(OptimiseError::Render(RenderError::BufferTooLarge { what, .. })) => {
                tracing::info!(
                    "step {step}: {what} do not fit the device in one render call; the windows \
                     render one call each"
                );
                return self.evaluate_per_window(poses, joined, windows, step, renders.get());
            }
            pass => pass?,
        };
        let batched_cost = |c: &dyn Cost| c.batches_windows() && c.domain() == CostDomain::Samples;
        // The costs that batch: once, on every sample with its own window's context.
        let contexts: Vec<QueryContext> = windows
            .iter()
            .flat_map(|w| std::iter::repeat_n(self.windows[w.window].context, w.count))
            .collect();
        let whole = pass.as_ref().map(|p| p.window(0, rows)).unwrap_or_default();
        let mut inputs = self.attach_images(
            CostInputs::new(poses.clone(), whole.mask, step, contexts[0])?
                .with_contexts(contexts)?,
            Images {
                mask: None,
                ..whole
            },
        );
        if let Some(o) = self.occupancy {
            inputs = inputs.with_occupancy(o.clone());
        }
        // The costs computed on the host read the samples' values from here, not the device.
        if let Some(hosts) = windows.iter().map(|w| w.host).collect::<Option<Vec<_>>>() {
            inputs = inputs.with_host_poses(HostPoses {
                samples: hosts.iter().flat_map(|h| h.samples.clone()).collect(),
                path: None,
            });
        }
        let batched = self.costs.evaluate_where(&inputs, batched_cost)?;
        // The path costs that batch: once, on every window's stretch of path joined.
        let path = self.joined_path(poses.clone(), joined.clone(), &windows, step)?;
        let joined_rows = joined;
        let batched_path =
            |c: &dyn Cost| path.is_some() && c.batches_windows() && c.domain() == CostDomain::Path;
        let path_terms = match &path {
            Some(inputs) => self.costs.evaluate_where(inputs, batched_path)?,
            None => None,
        };
        let per_window_cost = |c: &dyn Cost| !batched_cost(c) && !batched_path(c);
        // The others, window by window (images cut out only when such a cost reads one).
        let others_read_images = self
            .costs
            .costs()
            .iter()
            .any(|c| per_window_cost(c.as_ref()) && !c.channels().is_empty());
        // Nothing is cut out for a window no cost reads alone (a slice is a launch).
        let others = self
            .costs
            .costs()
            .iter()
            .any(|c| per_window_cost(c.as_ref()));
        let mut per_window = Vec::with_capacity(windows.len());
        let starts = path_starts(&windows);
        let mut offset = 0;
        for (w, first_path_row) in windows.into_iter().zip(starts) {
            let count = w.count;
            if others {
                let own = poses.clone().narrow(0, offset, count);
                let images = match (&pass, others_read_images) {
                    (Some(pass), true) => pass.window(offset, count),
                    _ => Images::default(),
                };
                let w = w.with_own_path(joined_rows.as_ref(), first_path_row)?;
                per_window.push(self.window_terms_where(w, own, images, step, per_window_cost)?);
            } else {
                per_window.push(None);
            }
            offset += count;
        }
        Ok(StepEvaluation::of_batch(
            self.costs,
            batched,
            path_terms,
            per_window,
            &counts,
            pass.as_ref().and_then(|p| p.masks.clone()),
            pass.map(|p| p.stats),
        ))
    }

    /// The inputs of the path costs that batch in a shared step: the samples `poses` and every
    /// window's stretch of path joined `[ΣP, 6]` (each with its context and time step; given
    /// as `joined` when the caller's rows hold it), their host values when every window has
    /// them; None when a window has no path (the path costs then judge each window's samples,
    /// per window).
    fn joined_path(
        &self,
        poses: Tensor<2>,
        joined: Option<Tensor<2>>,
        windows: &[WindowSamples<'_>],
        step: usize,
    ) -> Result<Option<CostInputs>, OptimiseError> {
        let batches = |c: &dyn Cost| c.batches_windows() && c.domain() == CostDomain::Path;
        if !self.costs.costs().iter().any(|c| batches(c.as_ref())) {
            return Ok(None);
        }
        let Some(paths) = windows
            .iter()
            .map(|w| w.path.clone())
            .collect::<Option<Vec<_>>>()
        else {
            return Ok(None);
        };
        let stretches: Vec<PathStretch> = windows
            .iter()
            .zip(&paths)
            .map(|(w, path)| PathStretch {
                rows: path.rows(),
                time_step: path.time_step(),
                context: self.windows[w.window].context,
            })
            .collect();
        // [ΣP, 6]
        let joined = match joined {
            Some(joined) => joined,
            None => {
                let each = paths
                    .iter()
                    .map(|path| path.poses(None, 0).map(|(poses, _)| poses))
                    .collect::<Result<Vec<_>, _>>()?;
                Tensor::cat(each, 0)
            }
        };
        let first = self.windows[windows[0].window].context;
        let mut inputs = CostInputs::new(poses, None, step, first)?.with_path(PathSamples::joined(
            joined,
            stretches,
            self.seconds,
        )?);
        if let Some(o) = self.occupancy {
            inputs = inputs.with_occupancy(o.clone());
        }
        let hosts: Option<Vec<&HostPoses>> = windows.iter().map(|w| w.host).collect();
        let host_path: Option<Vec<[f64; 6]>> = hosts.as_ref().and_then(|hosts| {
            hosts
                .iter()
                .map(|h| h.path.clone())
                .collect::<Option<Vec<_>>>()
                .map(|each| each.concat())
        });
        if let (Some(hosts), Some(path)) = (hosts, host_path) {
            inputs = inputs.with_host_poses(HostPoses {
                samples: hosts.iter().flat_map(|h| h.samples.clone()).collect(),
                path: Some(path),
            });
        }
        Ok(Some(inputs))
    }

    /// One window's render and cost terms.
    fn evaluate_one(
        &self,
        window: WindowSamples<'_>,
        poses: Tensor<2>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<(CostTerms, Option<Pass>), OptimiseError> {
        let [count, _] = poses.dims();
        let pass = self.render_pass(poses.clone(), std::slice::from_ref(&window), renders)?;
        let images = pass
            .as_ref()
            .map(|p| p.window(0, count))
            .unwrap_or_default();
        Ok((self.window_terms(window, poses, images, step)?, pass))
    }

    /// `renders`, or the problem's own when the caller keeps none.
    fn renders_or<'r>(&self, renders: Option<&'r WindowRenders>) -> Borrowed<'r, WindowRenders> {
        match renders {
            Some(r) => Borrowed::Lent(Some(r)),
            None => Borrowed::Owned(self.renders()),
        }
    }

    /// [`Self::evaluate_windows`] with a render call and the costs per window.
    fn evaluate_per_window(
        &self,
        poses: Tensor<2>,
        joined: Option<Tensor<2>>,
        windows: Vec<WindowSamples<'_>>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<StepEvaluation, OptimiseError> {
        // Each window alone, as a CPU run has always done: the same digits as before the
        // shared pass (a run's f32 optimisation amplifies rounding; the demo's second
        // window is framed in 90 % of its middle this way, 72 % with the costs batched).
        let mut terms = Vec::with_capacity(windows.len());
        let mut masks = Vec::with_capacity(windows.len());
        let mut stats: Option<RenderStats> = None;
        let starts = path_starts(&windows);
        let mut offset = 0;
        for (w, first_path_row) in windows.into_iter().zip(starts) {
            let own = poses.clone().narrow(0, offset, w.count);
            offset += w.count;
            let w = w.with_own_path(joined.as_ref(), first_path_row)?;
            let (window_terms, pass) = self.evaluate_one(w, own, step, renders)?;
            terms.push(window_terms);
            if let Some(pass) = pass {
                masks.extend(pass.masks);
                let a = stats.unwrap_or_default();
                stats = Some(RenderStats {
                    tiles: a.tiles + pass.stats.tiles,
                    pairs: a.pairs + pass.stats.pairs,
                    gaussians_used: a.gaussians_used + pass.stats.gaussians_used,
                });
            }
        }
        let masks = (masks.len() == terms.len()).then(|| Tensor::cat(masks, 0));
        Ok(StepEvaluation::of_windows(terms, masks, stats))
    }

    /// One render call for `windows`' samples at `poses` (their rows in order), each
    /// window's object alone after them when a cost reads it; None when no cost reads an
    /// image.
    fn render_pass(
        &self,
        poses: Tensor<2>,
        windows: &[WindowSamples<'_>],
        renders: Option<&WindowRenders>,
    ) -> Result<Option<Pass>, OptimiseError> {
        let Some(renders) = renders else {
            return Ok(None);
        };
        let [rows, _] = poses.dims();
        let host_samples: Option<Vec<Pose>> = windows
            .iter()
            .map(|w| w.host.map(|h| h.samples.iter().map(|&p| Pose(p))))
            .collect::<Option<Vec<_>>>()
            .map(|each| each.into_iter().flatten().collect());
        let mut request = renders.request.clone();
        let alone = renders.alone.as_ref();
        request.zoom = pass_zoom(windows, alone.is_some());
        let mut render_poses = poses.clone();
        let mut render_host = host_samples.clone();
        if let Some(Channel::ObjectMasks(objects)) = request.channels.first_mut() {
            let views = |object: &dyn Fn(usize) -> usize, surroundings| -> Vec<ObjectView> {
                windows
                    .iter()
                    .flat_map(|w| {
                        let view = ObjectView {
                            object: object(w.window),
                            surroundings,
                        };
                        std::iter::repeat_n(view, w.count)
                    })
                    .collect()
            };
            objects.views = views(&|i| i, Surroundings::Scene);
            if let Some(alone) = alone {
                // The same poses again, each drawing its window's object alone.
                objects
                    .views
                    .extend(views(&|i| alone[i], Surroundings::Nothing));
                render_poses = Tensor::cat(vec![poses.clone(), poses], 0);
                render_host = host_samples.map(|h| [h.clone(), h].concat());
            }
        }
        let rendered = render_at(self.scene, render_poses, render_host.as_deref(), &request)?;
        let images = rendered.images; // [B', H, W, C]
        let [_, height, width, _] = images.dims();
        let channel = |wanted: fn(&Channel) -> bool| -> Option<(usize, usize)> {
            let mut offset = 0;
            for c in &request.channels {
                if wanted(c) {
                    return Some((offset, c.width()));
                }
                offset += c.width();
            }
            None
        };
        let mask_at = channel(|c| matches!(c, Channel::ObjectMasks(_)));
        // The samples seen with the scene, then (where drawn) each alone: cut apart by one
        // joined cut, whose backward is a concatenation (`joined_rows`).
        let total = images.dims()[0];
        let counts: Vec<usize> = [rows, total - rows]
            .into_iter()
            .filter(|&c| c > 0)
            .collect();
        let halves = cut_rows(images, &counts);
        let part = |(offset, width): (usize, usize), first: usize| {
            halves[usize::from(first > 0)]
                .clone()
                .narrow(3, offset, width)
        };
        let flat = |t: Tensor<4>| t.reshape([rows, height, width]);
        Ok(Some(Pass {
            masks: mask_at.map(|at| flat(part(at, 0))),
            mask_alone: alone.and(mask_at).map(|at| flat(part(at, rows))),
            depth: channel(|c| matches!(c, Channel::Depth)).map(|at| flat(part(at, 0))),
            rgb: channel(|c| matches!(c, Channel::Rgb)).map(|at| part(at, 0)),
            stats: rendered.stats,
        }))
    }

    /// `inputs` with the images of `images` that are there (the mask is given to
    /// [`CostInputs::new`]).
    fn attach_images(&self, mut inputs: CostInputs, images: Images) -> CostInputs {
        if let Some(m) = images.mask_alone {
            inputs = inputs.with_mask_alone(m);
        }
        if let Some(d) = images.depth {
            inputs = inputs.with_depth(d);
        }
        if let Some(c) = images.rgb {
            inputs = inputs.with_rgb(c);
        }
        inputs
    }

    /// One window's cost terms from its samples' poses and images.
    fn window_terms(
        &self,
        samples: WindowSamples<'_>,
        poses: Tensor<2>,
        images: Images,
        step: usize,
    ) -> Result<CostTerms, OptimiseError> {
        self.window_terms_where(samples, poses, images, step, |_| true)?
            .ok_or_else(|| OptimiseError::Cost(CostError::Set("no cost is configured".into())))
    }

    /// [`Problem::window_terms`] of the costs `keep` selects; None when it keeps none.
    fn window_terms_where(
        &self,
        samples: WindowSamples<'_>,
        poses: Tensor<2>,
        images: Images,
        step: usize,
        keep: impl Fn(&dyn Cost) -> bool,
    ) -> Result<Option<CostTerms>, OptimiseError> {
        let index = samples.window;
        let (start, end) = window_bounds(index, self.windows.len());
        let mask = images.mask.clone();
        let mut inputs = self.attach_images(
            CostInputs::new(poses, mask, step, self.windows[index].context)?,
            images,
        );
        if let Some(ts) = samples.times {
            inputs = inputs.with_times(SampleTimes {
                window: index,
                within: ts.iter().map(|t| (t - start) / (end - start)).collect(),
            });
        }
        if let Some(path) = samples.path {
            let (poses, time_step) = path.poses(None, 0)?;
            inputs = inputs.with_path(PathSamples::new(
                poses,
                time_step,
                self.seconds,
                self.windows[index].context,
            ));
        }
        if let Some(o) = self.occupancy {
            inputs = inputs.with_occupancy(o.clone());
        }
        if let Some(h) = samples.host {
            inputs = inputs.with_host_poses(h.clone());
        }
        Ok(self.costs.evaluate_where(&inputs, keep)?)
    }

    /// The loss of `pose` for window `index` (step 0), read back to the host, and its
    /// gradient d total / dΦ when `gradient` is set (the scene must then be on an autodiff
    /// device). Everything is read back, so a timing of this call is complete.
    pub fn loss_at(
        &self,
        index: usize,
        pose: &Pose,
        gradient: bool,
    ) -> Result<PoseLoss, OptimiseError> {
        if gradient && !self.scene.device().is_autodiff() {
            return Err(OptimiseError::NotAutodiff);
        }
        let mut poses = self.scene.poses(std::slice::from_ref(pose));
        if gradient {
            poses = poses.require_grad();
        }
        // The tensor's own values (the costs computed on the host expand about them); for a
        // dtype whose rounding the host does not know, they read them back.
        let host =
            as_stored(std::slice::from_ref(pose), self.scene.dtype()).map(|stored| HostPoses {
                samples: vec![stored[0].0],
                path: None,
            });
        let evaluated =
            self.evaluate_along(index, poses.clone(), None, None, host.as_ref(), 0, None)?;
        let terms = &evaluated.terms;
        // Everything the host wants in one read (one wait for the device on a GPU): the total,
        // each term, the coverage and the gradient.
        let mut parts: Vec<Tensor<1>> = vec![terms.total.clone().without_autodiff()];
        parts.extend(
            terms
                .terms
                .iter()
                .map(|t| t.value.clone().without_autodiff()),
        );
        if let Some(m) = &evaluated.masks {
            parts.push(coverage(m.clone()).without_autodiff());
        }
        if gradient {
            let grads = backward(&terms.total.clone().sum())?;
            // No gradient at all means nothing in the graph depended on the pose.
            parts.push(match poses.grad(&grads) {
                Some(g) => g.reshape([6]),
                None => Tensor::<1>::zeros([6], (&poses.device().inner(), poses.dtype())),
            });
        }
        let values = host_values(Tensor::cat(parts, 0))?;
        let mut next = values.into_iter();
        let total = next.next().unwrap_or(f64::NAN);
        let terms: Vec<(&'static str, f64, f64)> = terms
            .terms
            .iter()
            .map(|t| (t.name, t.weight, next.next().unwrap_or(f64::NAN)))
            .collect();
        let coverage = evaluated.masks.as_ref().and_then(|_| next.next());
        let grad_pose = gradient.then(|| next.collect());
        Ok(PoseLoss {
            total,
            terms,
            grad_pose,
            coverage,
            stats: evaluated.stats,
        })
    }
}

/// The zoom of a pass over `windows`' samples (twice over when each object alone follows
/// them); None when no window zooms (a window without a zoom then has s = 1).
fn pass_zoom(windows: &[WindowSamples<'_>], twice: bool) -> Option<Zoom> {
    let first = windows.iter().find_map(|w| w.zoom.as_ref())?;
    let ones =
        |count: usize| Tensor::<1>::ones([count], (&first.values.device(), first.values.dtype()));
    let (mut values, mut host) = (Vec::new(), Some(Vec::new()));
    for w in windows {
        match &w.zoom {
            Some(z) => {
                values.push(z.values.clone());
                host = host.zip(z.host.as_ref()).map(|(mut h, more)| {
                    h.extend_from_slice(more);
                    h
                });
            }
            None => {
                values.push(ones(w.count));
                host = host.map(|mut h| {
                    h.extend(std::iter::repeat_n(1.0, w.count));
                    h
                });
            }
        }
    }
    let mut values = Tensor::cat(values, 0);
    if twice {
        values = Tensor::cat(vec![values.clone(), values], 0);
        host = host.map(|h| [h.clone(), h].concat());
    }
    Some(Zoom { values, host })
}
