//! The moments of a mask image: its mass Σm and first moments Σm·x, Σm·y per sample, which is
//! all that TCE, TRE, the coverage and the visibility cost read of the seen mask.
//!
//! **Why two matrix products.** On a GPU every tensor op is a kernel launch and an autodiff
//! node. Reducing the mask once per quantity (a sum over columns, then rows, for the mass and
//! for each weighted moment, plus the products, their constants and a concatenation) made TCE
//! and TRE about 80 of the 117 launches of a mask pass (docs/gpu.md). Written as
//!
//! ```text
//! A = M · X        X = [1 | x]  (W × 2): A[b, j] = (Σ_i m_bji, Σ_i m_bji·x_i)     [B, H, 2]
//! S = Y · A        Y = [1 ; y]  (2 × H): S[b] = [[Σm, Σm·x], [Σm·y, Σm·x·y]]      [B, 2, 2]
//! ```
//!
//! the four moments are two launches forward and two backward (a matrix product's backward is
//! a matrix product), whatever the image size, and [`super::CostInputs`] makes them once for
//! every cost that reads them. The weights X and Y are 2·(W + H) numbers, uploaded each time.
//!
//! x and y are pixel centres relative to the image centre in image fractions,
//! x_i = (i + ½)/W − ½ and y_j = (j + ½)/H − ½ (docs/conventions.md), so Σm·x/Σm is the
//! centroid's offset from the centre directly.

use burn::tensor::{Tensor, TensorData};

/// Mass and first moments of masks `[B, H, W]`, differentiable in the masks.
#[derive(Debug, Clone)]
pub struct MaskMoments {
    /// `[B, 4]`: Σm, Σm·x, Σm·y, Σm·x·y (the moment matrix of the module docs, row by row).
    sums: Tensor<2>,
    /// W·H, the pixels of one image.
    pixels: usize,
}

impl MaskMoments {
    /// The moments of `mask` `[B, H, W]` (two matrix products; see the module docs).
    pub fn of(mask: Tensor<3>) -> Self {
        let [batch, height, width] = mask.dims();
        let device = mask.device();
        let dtype = mask.dtype();
        let centres = |n: usize| (0..n).map(move |i| (i as f64 + 0.5) / n as f64 - 0.5);
        // X = [1 | x]: row i is (1, x_i).
        let x: Vec<f64> = centres(width).flat_map(|x| [1.0, x]).collect();
        // Y = [1 ; y]: row 0 all ones, row 1 the y_j.
        let y: Vec<f64> = std::iter::repeat_n(1.0, height)
            .chain(centres(height))
            .collect();
        let x = Tensor::<3>::from_data(TensorData::new(x, [1, width, 2]), (&device, dtype));
        let y = Tensor::<3>::from_data(TensorData::new(y, [1, 2, height]), (&device, dtype));
        let rows = mask.matmul(x); // [B, H, 2]
        Self {
            sums: y.matmul(rows).reshape([batch, 4]),
            pixels: width * height,
        }
    }

    /// Σm per sample `[B, 1]`, in pixels.
    pub fn mass(&self) -> Tensor<2> {
        self.sums.clone().narrow(1, 0, 1)
    }

    /// Share of the frame the mask covers, Σm / (W·H), per sample `[B]`.
    pub fn coverage(&self) -> Tensor<1> {
        let [batch, _] = self.sums.dims();
        self.mass().reshape([batch]).div_scalar(self.pixels as f64)
    }

    /// (Σm·x, Σm·y) per sample `[B, 2]`, x and y in image fractions from the centre (adjacent
    /// in the row-by-row moment matrix, so one slice).
    pub fn first(&self) -> Tensor<2> {
        self.sums.clone().narrow(1, 1, 2)
    }
}
