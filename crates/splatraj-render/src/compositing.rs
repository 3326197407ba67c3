//! Front-to-back alpha compositing along a depth-sorted axis, as differentiable tensor ops.

use burn::tensor::Tensor;

/// Exclusive transmittance T_i = Π_{j<i} (1 − α_j) along the last axis.
///
/// Computed as exp(cumsum(log1p(−α)) − log1p(−α)): a running product would underflow its
/// gradient and divide by (1 − α) in backward; the log form stays finite for α ≤ 0.99, the
/// largest alpha the rasterizer produces.
pub fn exclusive_transmittance<const D: usize>(alpha: Tensor<D>) -> Tensor<D> {
    let log_keep = alpha.neg().log1p(); // [.., K]
    let inclusive = log_keep.clone().cumsum(D - 1);
    (inclusive - log_keep).exp()
}
