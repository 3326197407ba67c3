//! The moments of a mask image: its mass Σm and first moments Σm·x, Σm·y per sample, which is
//! all that TCE, TRE, the coverage and the visibility cost read of the seen mask. Each is its
//! own `[B]` tensor, so that every cost after them is an elementwise chain on `[B]`.
//!
//! **Two ways to the same sums, chosen by where the ops run** ([`MomentSums`]):
//!
//! - On the host (flex, ndarray), two matrix products give all four moments at once,
//!
//!   ```text
//!   A = M · X        X = [1 | x]  (W × 2): A[b, j] = (Σ_i m_bji, Σ_i m_bji·x_i)     [B, H, 2]
//!   S = Y · A        Y = [1 ; y]  (2 × H): S[b] = [[Σm, Σm·x], [Σm·y, Σm·x·y]]      [B, 2, 2]
//!   ```
//!
//!   and the three are cut out of S: on a CPU a cut costs a copy of B numbers. This is faster
//!   on the host than three reductions of the whole mask (a first-try guitar step 126–129 against
//!   132–134 ms on 2 cores) and gives the digits every earlier run gave.
//! - On a GPU every op is a kernel launch unless burn-fusion merges it, and a cut is a launch
//!   forward and two backward (a zero fill and a slice assignment). Chains that started from
//!   those cuts were mostly left unfused, so there the three are three reductions (Σm, Σm·x,
//!   Σm·y) and nothing is cut (docs/gpu.md, "Three moments, three tensors"): counted on
//!   lavapipe, a 128² mask pass 50 → 33 launches and a first-try guitar step 120 → 94 (with the
//!   loss's forward handed to the device before its backward, [`crate::optimise::backward`]).
//!
//! A figure that is read back rather than differentiated (a frame's or a metric sample's TCE,
//! TRE and coverage) takes the four sums as one tensor ([`moment_sums`]: two launches on a
//! GPU, nothing cut) and applies the costs' formulas to them on the host ([`HostMoments`]).
//!
//! [`super::CostInputs`] makes the moments once for every cost that reads them; a quantity
//! that needs only the mass ([`mask_mass`]: the coverage, the object alone's pixels) takes
//! only that on a GPU, where every queued op is a launch whether it is read or not.
//!
//! x and y are pixel centres relative to the image centre in image fractions,
//! x_i = (i + ½)/W − ½ and y_j = (j + ½)/H − ½ (docs/conventions.md), so Σm·x/Σm is the
//! centroid's offset from the centre directly.

use burn::tensor::{Tensor, TensorData};
use splatraj_render::backend::Execution;

/// How [`MaskMoments`] sums the mask (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MomentSums {
    /// Two matrix products and three cuts of their result: the host's way.
    Products,
    /// Three reductions of the mask, nothing cut: the GPU's way.
    Reductions,
}

impl MomentSums {
    /// The faster way where `mask` lives.
    pub fn for_mask(mask: &Tensor<3>) -> Self {
        match Execution::of(&mask.device()) {
            Execution::Host => MomentSums::Products,
            Execution::Kernels => MomentSums::Reductions,
        }
    }
}

/// Mass and first moments of masks `[B, H, W]`, differentiable in the masks.
#[derive(Debug, Clone)]
pub struct MaskMoments {
    /// Σm per sample, in pixels. `[B]`
    mass: Tensor<1>,
    /// Σm·x per sample. `[B]`
    first_x: Tensor<1>,
    /// Σm·y per sample. `[B]`
    first_y: Tensor<1>,
    /// W·H, the pixels of one image.
    pixels: usize,
}

impl MaskMoments {
    /// The moments of `mask` `[B, H, W]`, summed the faster way where it lives.
    pub fn of(mask: Tensor<3>) -> Self {
        let sums = MomentSums::for_mask(&mask);
        Self::summed(mask, sums)
    }

    /// The moments of `mask` `[B, H, W]`, summed by `sums`.
    pub fn summed(mask: Tensor<3>, sums: MomentSums) -> Self {
        let [batch, height, width] = mask.dims();
        let pixels = width * height;
        match sums {
            MomentSums::Products => {
                let sums = moment_sums(mask.unsqueeze_dim(3), 0); // [B, 4]
                let column = |k: usize| sums.clone().narrow(1, k, 1).reshape([batch]);
                Self {
                    mass: column(0),
                    first_x: column(1),
                    first_y: column(2),
                    pixels,
                }
            }
            MomentSums::Reductions => {
                // Broadcast over the batch and the other image axis: W + H numbers uploaded.
                let x = constant_like(&mask, pixel_centres(width).collect(), [1, 1, width]);
                let y = constant_like(&mask, pixel_centres(height).collect(), [1, height, 1]);
                Self {
                    mass: reduced_mass(mask.clone()),
                    first_x: reduced_mass(mask.clone() * x),
                    first_y: reduced_mass(mask * y),
                    pixels,
                }
            }
        }
    }

    /// Σm per sample `[B]`, in pixels.
    pub fn mass(&self) -> Tensor<1> {
        self.mass.clone()
    }

    /// Share of the frame the mask covers, Σm / (W·H), per sample `[B]`.
    pub fn coverage(&self) -> Tensor<1> {
        self.mass().div_scalar(self.pixels as f64)
    }

    /// Σm·x per sample `[B]`, x in image fractions from the centre.
    pub fn first_x(&self) -> Tensor<1> {
        self.first_x.clone()
    }

    /// Σm·y per sample `[B]`, y in image fractions from the centre.
    pub fn first_y(&self) -> Tensor<1> {
        self.first_y.clone()
    }
}

/// The moment sums of channel `channel` of images `[B, H, W, C]` as one tensor `[B, 4]`: Σm,
/// Σm·x, Σm·y, Σm·x·y per sample, by the two matrix products of the module docs. Nothing is cut
/// out of the images or of the sums, so on a GPU it is two launches: what a caller reads back
/// whole ([`HostMoments`]) takes this. A mask `[B, H, W]` is `[B, H, W, 1]`, channel 0;
/// `channel` must be one of the C.
pub fn moment_sums(images: Tensor<4>, channel: usize) -> Tensor<2> {
    let [batch, height, width, channels] = images.dims();
    assert!(channel < channels, "channel {channel} of {channels}");
    let images = images.reshape([batch, height, width * channels]);
    // X = [1 | x] with a zero row for each other channel: row i·C + c is (1, x_i) for the
    // channel, (0, 0) for the others (cheaper on a GPU than a launch to cut the channel out).
    // Y = [1 ; y]: row 0 all ones, row 1 the y_j.
    let x = pixel_centres(width)
        .flat_map(|x| {
            (0..channels).flat_map(move |c| if c == channel { [1.0, x] } else { [0.0; 2] })
        })
        .collect();
    let y = std::iter::repeat_n(1.0, height).chain(pixel_centres(height));
    let x = constant_like(&images, x, [1, width * channels, 2]);
    let y = constant_like(&images, y.collect(), [1, 2, height]);
    let rows = images.matmul(x); // [B, H, 2]
    y.matmul(rows).reshape([batch, 4])
}

/// `values` as a tensor of `shape` on `like`'s device, in its dtype: uploaded the first time,
/// then the same device tensor again (the pixel centres of an image size are the same every
/// pass, and on a GPU each upload is a transfer the pass waits behind).
fn constant_like(like: &Tensor<3>, values: Vec<f64>, shape: [usize; 3]) -> Tensor<3> {
    /// A handful: one entry per image size, mask layout and device a process renders at.
    const KEPT: usize = 16;
    // The device and whether it records gradients: burn's device equality ignores autodiff, and
    // a constant is made on the device of the tensors it meets.
    type Entry = (
        (
            burn::tensor::Device,
            bool,
            burn::tensor::DType,
            [usize; 3],
            Vec<f64>,
        ),
        Tensor<3>,
    );
    static KEPT_CONSTANTS: std::sync::Mutex<Vec<Entry>> = std::sync::Mutex::new(Vec::new());
    let device = like.device();
    let key = (
        device.clone(),
        device.is_autodiff(),
        like.dtype(),
        shape,
        values,
    );
    let mut kept = KEPT_CONSTANTS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((_, tensor)) = kept.iter().find(|(k, _)| *k == key) {
        return tensor.clone();
    }
    let tensor: Tensor<3> =
        splatraj_render::host::upload(TensorData::new(key.4.clone(), shape), &device, key.2);
    if kept.len() == KEPT {
        kept.remove(0);
    }
    kept.push((key, tensor.clone()));
    tensor
}

/// x_i = (i + ½)/n − ½ for the n pixels of an image axis: centres in image fractions from the
/// image centre.
fn pixel_centres(n: usize) -> impl Iterator<Item = f64> {
    (0..n).map(move |i| (i as f64 + 0.5) / n as f64 - 0.5)
}

/// One mask's moments read back to the host, in f64: what a figure reported for a picture
/// (a frame's or a sample's TCE, TRE and coverage) is made of, without a launch an op on a GPU.
/// [`super::tce_on_host`] and [`super::tre_on_host`] are the costs' formulas on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HostMoments {
    /// Σm, in pixels.
    pub mass: f64,
    /// Σm·x, x in image fractions from the centre.
    pub first_x: f64,
    /// Σm·y.
    pub first_y: f64,
    /// W·H, the pixels of one image.
    pub pixels: usize,
}

impl HostMoments {
    /// Each sample's moments from [`moment_sums`] read back (`[B, 4]` row after row), for
    /// images of `pixels` pixels.
    pub fn from_sums(sums: &[f64], pixels: usize) -> Vec<Self> {
        sums.chunks_exact(4)
            .map(|row| Self {
                mass: row[0],
                first_x: row[1],
                first_y: row[2],
                pixels,
            })
            .collect()
    }

    /// Share of the frame the mask covers, Σm / (W·H): [`MaskMoments::coverage`].
    pub fn coverage(&self) -> f64 {
        self.mass / self.pixels as f64
    }
}

/// Σm per sample of masks `[B, H, W]`, in pixels, `[B]`: [`MaskMoments::mass`], and on a GPU
/// only that reduction.
pub fn mask_mass(mask: Tensor<3>) -> Tensor<1> {
    match MomentSums::for_mask(&mask) {
        MomentSums::Products => MaskMoments::summed(mask, MomentSums::Products).mass(),
        MomentSums::Reductions => reduced_mass(mask),
    }
}

/// Σm per sample of `mask` `[B, H, W]` by one reduction: `[B]`.
fn reduced_mass(mask: Tensor<3>) -> Tensor<1> {
    let [batch, height, width] = mask.dims();
    mask.reshape([batch, height * width])
        .sum_dim(1) // [B, 1]
        .reshape([batch])
}
