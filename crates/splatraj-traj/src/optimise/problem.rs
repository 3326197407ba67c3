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
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::rasterize::{Approximations, RenderStats};
use splatraj_render::render::{
    Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render_at,
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
    /// Each window's object alone (its Gaussians only, on the scene's device), for costs
    /// that read [`ImageChannel::MaskAlone`].
    pub alone: Option<&'a [DeviceScene]>,
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
            alone: None,
        }
    }

    /// The same problem with each window's object alone (needed by the visibility cost).
    pub fn with_alone(mut self, alone: Option<&'a [DeviceScene]>) -> Self {
        self.alone = alone;
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
        let alone = self.alone.and_then(|a| a.get(index..=index));
        Ok(Problem {
            windows,
            alone,
            ..*self
        })
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

    /// The render request for window `index`: the channels the costs read, pruned to the
    /// object when the mask is the only one; None when no cost reads an image.
    pub fn request(&self, index: usize) -> Option<RenderRequest> {
        // The object alone is another scene's render (see `evaluate_along`).
        let needed: Vec<ImageChannel> = self
            .costs
            .channels()
            .into_iter()
            .filter(|c| *c != ImageChannel::MaskAlone)
            .collect();
        if needed.is_empty() {
            return None;
        }
        let channels = needed
            .iter()
            .map(|c| match c {
                ImageChannel::Mask => Channel::Mask(self.windows[index].mask.clone()),
                ImageChannel::Depth => Channel::Depth,
                ImageChannel::Rgb => Channel::Rgb,
                ImageChannel::MaskAlone => unreachable!("filtered out above"),
            })
            .collect();
        let mut request = RenderRequest::new(self.intrinsics, channels);
        if self.prune && needed == [ImageChannel::Mask] {
            request.pruning = Pruning::ObjectOnly;
        }
        request.rasterizer = self.rasterizer;
        request.approximations = self.approximations;
        Some(request)
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
        request: Option<&RenderRequest>,
    ) -> Result<Evaluated, OptimiseError> {
        self.evaluate_along(index, poses, None, None, None, step, request)
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
        request: Option<&RenderRequest>,
    ) -> Result<Evaluated, OptimiseError> {
        let window = &self.windows[index];
        let seconds = self.seconds;
        let occupancy = self.occupancy;
        let (start, end) = window_bounds(index, self.windows.len());
        let times = times.map(|ts| SampleTimes {
            window: index,
            within: ts.iter().map(|t| (t - start) / (end - start)).collect(),
        });
        let attach = move |mut inputs: CostInputs| {
            if let Some(t) = times.clone() {
                inputs = inputs.with_times(t);
            }
            if let Some((poses, time_step)) = path.clone() {
                inputs = inputs.with_path(PathSamples {
                    poses,
                    time_step,
                    seconds,
                });
            }
            if let Some(o) = occupancy {
                inputs = inputs.with_occupancy(o.clone());
            }
            if let Some(h) = host {
                inputs = inputs.with_host_poses(h.clone());
            }
            inputs
        };
        let host_samples: Option<Vec<Pose>> =
            host.map(|h| h.samples.iter().map(|&p| Pose(p)).collect());
        let owned;
        let request = match request {
            Some(r) => Some(r),
            None => {
                owned = self.request(index);
                owned.as_ref()
            }
        };
        let Some(request) = request else {
            let inputs = attach(CostInputs::new(poses, None, step, window.context)?);
            let terms = self.costs.evaluate(&inputs)?;
            return Ok(Evaluated {
                terms,
                masks: None,
                stats: None,
            });
        };
        let rendered = render_at(self.scene, poses.clone(), host_samples.as_deref(), request)?;
        let images = rendered.images;
        let [batch, height, width, _] = images.dims();
        let mut masks = None;
        let (mut depth, mut rgb) = (None, None);
        let mut offset = 0;
        for channel in &request.channels {
            let w = channel.width();
            let part = images.clone().narrow(3, offset, w);
            offset += w;
            match channel {
                Channel::Mask(_) => masks = Some(part.reshape([batch, height, width])),
                Channel::Depth => depth = Some(part.reshape([batch, height, width])),
                Channel::Rgb => rgb = Some(part),
                Channel::Features { .. } => {}
            }
        }
        let mut inputs = attach(CostInputs::new(
            poses.clone(),
            masks.clone(),
            step,
            window.context,
        )?);
        if let Some(d) = depth {
            inputs = inputs.with_depth(d);
        }
        if let Some(c) = rgb {
            inputs = inputs.with_rgb(c);
        }
        if self.costs.channels().contains(&ImageChannel::MaskAlone)
            && let Some(alone) = self.alone.and_then(|a| a.get(index))
        {
            inputs = inputs.with_mask_alone(self.render_alone(
                alone,
                poses,
                host_samples.as_deref(),
                request,
            )?);
        }
        let terms = self.costs.evaluate(&inputs)?;
        Ok(Evaluated {
            terms,
            masks,
            stats: Some(rendered.stats),
        })
    }

    /// The object alone's mask `[B, H, W]` at `poses`, rendered as `request` renders the
    /// scene (camera, rasterizer, approximations), pruned to the object (all of it).
    fn render_alone(
        &self,
        alone: &DeviceScene,
        poses: Tensor<2>,
        host_poses: Option<&[Pose]>,
        request: &RenderRequest,
    ) -> Result<Tensor<3>, OptimiseError> {
        let mut request = request.clone();
        request.channels = vec![Channel::Mask(vec![1.0; alone.len()])];
        request.pruning = Pruning::ObjectOnly;
        let images = render_at(alone, poses, host_poses, &request)?.images;
        let [batch, height, width, _] = images.dims();
        Ok(images.reshape([batch, height, width]))
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
