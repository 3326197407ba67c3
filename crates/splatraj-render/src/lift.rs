//! Lifting per-pixel 2D values onto the Gaussians through the rasterizer's backward.
//!
//! For Gaussian i and a pixel p of a rendered view, `w_i(p) = α_i(p)·T_i(p)` is the weight with
//! which i's channel value enters p (docs/conventions.md, rule 9); hidden Gaussians have T ≈ 0
//! and so get no vote. A per-pixel value f(p) (a CLIP similarity, a mask label) is lifted as the
//! weighted average `Σ_views Σ_p w_i(p)·f(p) / Σ_views Σ_p w_i(p)`.
//!
//! That weight is the gradient of the composited image with respect to the Gaussian's channel
//! value: with a per-Gaussian value tensor V `[N, C]` composited into image I `[B, H, W, C]`,
//! `∂(Σ_p f(p)·I(p))/∂V_i = Σ_p w_i(p)·f(p)`. So a lift is one [`crate::render`] with V as
//! [`RenderRequest::gaussian_values`] (zeros: the image does not matter, only its derivative)
//! and one backward of `Σ I·F`, where F holds the `dim` pixel values and one extra channel of
//! ones whose gradient is the denominator `Σ_p w_i(p)`. The same code renders and lifts, on
//! either rasterizer and any backend, exactly (no pruning, no approximation).

use burn::tensor::{Tensor, TensorData};

use crate::camera::{Intrinsics, Pose};
use crate::host::{OnDevice, to_host};
use crate::render::{
    AlphaChannel, DeviceScene, Rasterizer, RenderError, RenderRequest, render_poses,
};

/// Views rendered together in one lifting pass (bounds the memory of a pass).
const VIEWS_PER_PASS: usize = 4;

/// `Σ_p w_i(p)·f_c(p)` and `Σ_p w_i(p)` for every Gaussian of a scene, summed over views.
#[derive(Debug, Clone, PartialEq)]
pub struct LiftSums {
    /// Values per pixel (and per Gaussian).
    pub dim: usize,
    /// `Σ w·f` per Gaussian and channel. `[N, dim]`
    pub weighted: Vec<f64>,
    /// `Σ w` per Gaussian. `[N]`
    pub weights: Vec<f64>,
}

impl LiftSums {
    /// Empty sums for `n` Gaussians and `dim` values.
    pub fn zeros(n: usize, dim: usize) -> Self {
        LiftSums {
            dim,
            weighted: vec![0.0; n * dim],
            weights: vec![0.0; n],
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// True for sums over no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// Adds `other`'s sums (more views of the same scene). Panics if the shapes differ.
    pub fn add(&mut self, other: &LiftSums) {
        assert!(
            self.dim == other.dim && self.len() == other.len(),
            "adding lift sums of {}×{} to {}×{}",
            other.len(),
            other.dim,
            self.len(),
            self.dim
        );
        for (a, b) in self.weighted.iter_mut().zip(&other.weighted) {
            *a += b;
        }
        for (a, b) in self.weights.iter_mut().zip(&other.weights) {
            *a += b;
        }
    }

    /// The lifted values `Σ w·f / Σ w`, `[N, dim]` flat; `None` for every channel of a Gaussian
    /// whose `Σ w` is not above `min_weight` (it had no vote).
    pub fn mean(&self, min_weight: f64) -> Vec<Option<f32>> {
        let dim = self.dim;
        self.weights
            .iter()
            .enumerate()
            .flat_map(|(g, &w)| {
                let row = &self.weighted[g * dim..(g + 1) * dim];
                row.iter()
                    .map(move |&s| (w > min_weight).then(|| (s / w) as f32))
            })
            .collect()
    }
}

/// Lifts `pixels` `[B, H, W, dim]` of the views `poses` onto the Gaussians of `scene`.
///
/// The scene must live on an autodiff device (`Device::flex().autodiff()`, or wgpu's); poses
/// are constants. Errors on a pixel buffer of the wrong length, `dim` 0 or non-finite values.
pub fn lift_views(
    scene: &DeviceScene,
    poses: &[Pose],
    intrinsics: &Intrinsics,
    pixels: &[f32],
    dim: usize,
    rasterizer: Rasterizer,
) -> Result<LiftSums, RenderError> {
    if dim == 0 {
        return Err(RenderError::ZeroWidth { index: 0 });
    }
    let per_view = intrinsics.width * intrinsics.height * dim;
    let expected = poses.len() * per_view;
    if pixels.len() != expected {
        return Err(RenderError::PixelCount {
            got: pixels.len(),
            expected,
        });
    }
    if let Some(index) = pixels.iter().position(|v| !v.is_finite()) {
        return Err(RenderError::NonFinitePixel { index });
    }
    let device = scene.device();
    if !device.is_autodiff() {
        return Err(RenderError::NeedsAutodiff);
    }
    let (n, dtype) = (scene.len(), scene.dtype());
    let mut sums = LiftSums::zeros(n, dim);
    for (views, pixels) in poses
        .chunks(VIEWS_PER_PASS)
        .zip(pixels.chunks(VIEWS_PER_PASS * per_view))
    {
        // Zeros: the composited image is irrelevant, only its derivative in V is read.
        let values = Tensor::<2>::zeros([n, dim + 1], (&device, dtype)).require_grad(); // [N, dim + 1]
        let request = RenderRequest {
            rasterizer,
            gaussian_values: Some(values.clone()),
            alpha: AlphaChannel::Dropped,
            ..RenderRequest::new(*intrinsics, Vec::new())
        };
        let rendered = render_poses(scene, views, &request)?;
        if rendered.stats.gaussians_used == 0 {
            continue; // nothing drawn: every weight is 0 and there is no graph to walk
        }
        // F: the pixel values and a channel of ones for Σ w. [B, H, W, dim + 1]
        let with_ones: Vec<f32> = pixels
            .chunks_exact(dim)
            .flat_map(|f| f.iter().copied().chain([1.0]))
            .collect();
        let shape = [views.len(), intrinsics.height, intrinsics.width, dim + 1];
        let f: Tensor<4> = crate::host::upload(TensorData::new(with_ones, shape), &device, dtype);
        let grads = (rendered.images * f).sum().backward();
        let Some(gradient) = values.grad(&grads) else {
            continue; // no used Gaussian reached the image
        };
        let gradient = to_host(gradient).map_err(|e| RenderError::ReadBack(e.0))?; // [N, dim + 1]
        for (g, row) in gradient.chunks_exact(dim + 1).enumerate() {
            for (sum, value) in sums.weighted[g * dim..(g + 1) * dim].iter_mut().zip(row) {
                *sum += value;
            }
            sums.weights[g] += row[dim];
        }
    }
    Ok(sums)
}
