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

use burn::tensor::{DType, Device, Tensor};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::focus::Surroundings;
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::rasterize::{Approximations, RenderStats};
use splatraj_render::render::{
    Channel, DeviceScene, ObjectMasks, ObjectView, Pruning, Rasterizer, RenderRequest, render_at,
};

use super::sampling::window_bounds;
use super::{OptimiseError, WindowTarget};
use crate::clearance::Occupancy;
use crate::costs::{
    CostInputs, CostTerms, HostPoses, ImageChannel, PathSamples, SampleTimes, WeightedCosts,
    coverage,
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
/// which is what a GPU is bound by. But one call lays the packed rows out per pose over the
/// union U of every window's Gaussians (`[B, U, 7]`, each pose reading only its own part),
/// and on the CPU moving those dense rows costs more than the calls it saves: demo 1 M,
/// 3 windows × 4 samples with each object alone, 128×72, flex on 2 cores: 1.27 s a step in
/// one call, 0.64 s in one call per window (docs/gpu.md, "One pass a step"). Rows laid out
/// only where a pose reads them would make one call the better choice everywhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepPasses {
    /// One render call for every window of the step, each object alone included (the GPU).
    Shared,
    /// One render call per window, its object alone included (the CPU).
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

/// One window's samples in a pass of several windows ([`Problem::evaluate_windows`]).
#[derive(Debug, Clone)]
pub struct WindowSamples<'s> {
    /// Which window.
    pub window: usize,
    /// Its samples: the next `count` rows of the poses.
    pub count: usize,
    /// Their times t ∈ [0, 1] of the whole trajectory, for costs that depend on time.
    pub times: Option<&'s [f64]>,
    /// The window's densely sampled path `[P, 6]` and its time step, for the path costs.
    pub path: Option<(Tensor<2>, f64)>,
    /// The host values of the samples and the path, when the caller has them.
    pub host: Option<&'s HostPoses>,
}

/// What [`Problem::evaluate_windows`] found: each window's terms, the object masks of all
/// samples `[ΣS, H, W]` when one was rendered, and the pass's compositing work.
#[derive(Debug, Clone)]
pub struct StepEvaluation {
    /// Per window (as listed), each term and the weighted total per sample.
    pub windows: Vec<CostTerms>,
    /// Every sample's object mask, windows one after the other.
    pub masks: Option<Tensor<3>>,
    /// How much compositing work the passes had, summed over them (None when nothing was
    /// rendered).
    pub stats: Option<RenderStats>,
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
                masks,
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
            path,
            host,
        };
        let mut evaluated = self.evaluate_windows(poses, vec![window], step, renders)?;
        Ok(Evaluated {
            terms: evaluated.windows.remove(0),
            masks: evaluated.masks,
            stats: evaluated.stats,
        })
    }

    /// Renders what the costs read for the samples of several windows and evaluates each
    /// window's costs at step `step`: `poses` `[ΣS, 6]` holds the windows' samples one window
    /// after the other, as `windows` lists them. With [`StepPasses::Shared`] one render call
    /// serves the whole step (each window's object alone included), so the launches of a step
    /// do not grow with the number of windows; with [`StepPasses::PerWindow`] each window has
    /// a call of its own (docs/gpu.md, "One pass a step").
    /// `renders`: [`Problem::renders`] when the caller keeps it (made here otherwise).
    pub fn evaluate_windows(
        &self,
        poses: Tensor<2>,
        windows: Vec<WindowSamples<'_>>,
        step: usize,
        renders: Option<&WindowRenders>,
    ) -> Result<StepEvaluation, OptimiseError> {
        let [rows, _] = poses.dims();
        let total: usize = windows.iter().map(|w| w.count).sum();
        if total != rows {
            return Err(OptimiseError::InvalidOptions {
                field: "windows",
                reason: format!("the windows' samples add up to {total}, the poses to {rows}"),
            });
        }
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
        let owned;
        let renders = match renders {
            Some(r) => Some(r),
            None => {
                owned = self.renders();
                owned.as_ref()
            }
        };
        if self.step_passes == StepPasses::PerWindow && windows.len() > 1 {
            let mut each = StepEvaluation {
                windows: Vec::with_capacity(windows.len()),
                masks: None,
                stats: None,
            };
            let mut masks = Vec::with_capacity(windows.len());
            let mut offset = 0;
            for w in windows {
                let count = w.count;
                let window_poses = poses.clone().narrow(0, offset, count);
                offset += count;
                let one = self.evaluate_windows(window_poses, vec![w], step, renders)?;
                each.windows.extend(one.windows);
                masks.extend(one.masks);
                each.stats = match (each.stats, one.stats) {
                    (Some(a), Some(b)) => Some(RenderStats {
                        tiles: a.tiles + b.tiles,
                        pairs: a.pairs + b.pairs,
                        gaussians_used: a.gaussians_used + b.gaussians_used,
                    }),
                    (a, b) => a.or(b),
                };
            }
            if masks.len() == each.windows.len() {
                each.masks = Some(Tensor::cat(masks, 0));
            }
            return Ok(each);
        }
        let host_samples: Option<Vec<Pose>> = windows
            .iter()
            .map(|w| w.host.map(|h| h.samples.iter().map(|&p| Pose(p))))
            .collect::<Option<Vec<_>>>()
            .map(|each| each.into_iter().flatten().collect());
        let Some(renders) = renders else {
            let mut offset = 0;
            let mut terms = Vec::with_capacity(windows.len());
            for w in windows {
                let window_poses = poses.clone().narrow(0, offset, w.count);
                offset += w.count;
                terms.push(self.window_terms(w, window_poses, Images::default(), step)?);
            }
            return Ok(StepEvaluation {
                windows: terms,
                masks: None,
                stats: None,
            });
        };
        let mut request = renders.request.clone();
        let alone = renders.alone.as_ref();
        let mut render_poses = poses.clone();
        let mut render_host = host_samples.clone();
        if let Some(Channel::ObjectMasks(objects)) = request.channels.first_mut() {
            let scene_views = windows.iter().flat_map(|w| {
                std::iter::repeat_n(
                    ObjectView {
                        object: w.window,
                        surroundings: Surroundings::Scene,
                    },
                    w.count,
                )
            });
            objects.views = scene_views.collect();
            if let Some(alone) = alone {
                // The same poses again, each drawing its window's object alone.
                objects.views.extend(windows.iter().flat_map(|w| {
                    std::iter::repeat_n(
                        ObjectView {
                            object: alone[w.window],
                            surroundings: Surroundings::Nothing,
                        },
                        w.count,
                    )
                }));
                render_poses = Tensor::cat(vec![poses.clone(), poses.clone()], 0);
                render_host = host_samples.map(|h| [h.clone(), h].concat());
            }
        }
        let rendered = render_at(self.scene, render_poses, render_host.as_deref(), &request)?;
        let images = rendered.images; // [B', H, W, C]
        let [_, height, width, _] = images.dims();
        let channel = |name: fn(&Channel) -> bool| -> Option<(usize, usize)> {
            let mut offset = 0;
            for c in &request.channels {
                if name(c) {
                    return Some((offset, c.width()));
                }
                offset += c.width();
            }
            None
        };
        let mask_at = channel(|c| matches!(c, Channel::ObjectMasks(_)));
        let depth_at = channel(|c| matches!(c, Channel::Depth));
        let rgb_at = channel(|c| matches!(c, Channel::Rgb));
        let part = |(offset, width): (usize, usize), rows: (usize, usize)| {
            images
                .clone()
                .narrow(0, rows.0, rows.1)
                .narrow(3, offset, width)
        };
        let flat = |t: Tensor<4>, count: usize| t.reshape([count, height, width]);
        let masks = mask_at.map(|at| flat(part(at, (0, rows)), rows));
        let mut offset = 0;
        let mut terms = Vec::with_capacity(windows.len());
        for w in windows {
            let count = w.count;
            let own = (offset, count);
            let window_images = Images {
                mask: masks.as_ref().map(|m| m.clone().narrow(0, offset, count)),
                mask_alone: alone
                    .and(mask_at)
                    .map(|at| flat(part(at, (rows + offset, count)), count)),
                depth: depth_at.map(|at| flat(part(at, own), count)),
                rgb: rgb_at.map(|at| part(at, own)),
            };
            let window_poses = poses.clone().narrow(0, offset, count);
            offset += count;
            terms.push(self.window_terms(w, window_poses, window_images, step)?);
        }
        Ok(StepEvaluation {
            windows: terms,
            masks,
            stats: Some(rendered.stats),
        })
    }

    /// One window's cost terms from its samples' poses and images.
    fn window_terms(
        &self,
        samples: WindowSamples<'_>,
        poses: Tensor<2>,
        images: Images,
        step: usize,
    ) -> Result<CostTerms, OptimiseError> {
        let index = samples.window;
        let (start, end) = window_bounds(index, self.windows.len());
        let mut inputs = CostInputs::new(poses, images.mask, step, self.windows[index].context)?;
        if let Some(ts) = samples.times {
            inputs = inputs.with_times(SampleTimes {
                window: index,
                within: ts.iter().map(|t| (t - start) / (end - start)).collect(),
            });
        }
        if let Some((poses, time_step)) = samples.path {
            inputs = inputs.with_path(PathSamples {
                poses,
                time_step,
                seconds: self.seconds,
            });
        }
        if let Some(o) = self.occupancy {
            inputs = inputs.with_occupancy(o.clone());
        }
        if let Some(h) = samples.host {
            inputs = inputs.with_host_poses(h.clone());
        }
        if let Some(m) = images.mask_alone {
            inputs = inputs.with_mask_alone(m);
        }
        if let Some(d) = images.depth {
            inputs = inputs.with_depth(d);
        }
        if let Some(c) = images.rgb {
            inputs = inputs.with_rgb(c);
        }
        Ok(self.costs.evaluate(&inputs)?)
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
        let host = HostPoses {
            samples: vec![pose.0],
            path: None,
        };
        let evaluated =
            self.evaluate_along(index, poses.clone(), None, None, Some(&host), 0, None)?;
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
            let grads = terms.total.clone().sum().backward();
            // No gradient at all means nothing in the graph depended on the pose.
            parts.push(match poses.grad(&grads) {
                Some(g) => g.reshape([6]),
                None => Tensor::<1>::zeros([6], (&poses.device().inner(), poses.dtype())),
            });
        }
        let values = read(Tensor::cat(parts, 0))?;
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

fn read<const D: usize>(t: Tensor<D>) -> Result<Vec<f64>, OptimiseError> {
    to_host(t).map_err(|e| OptimiseError::ReadBack(e.to_string()))
}
