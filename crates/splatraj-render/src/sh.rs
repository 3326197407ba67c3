//! View-dependent colour from spherical harmonics, as differentiable tensor ops.
//!
//! Real SH basis and signs of the INRIA 3DGS rasterizer, degree 0 to 3; colour =
//! max(0, 0.5 + Σ_k basis_k(d) · coeff_k) with d the unit vector from the camera centre to the
//! Gaussian's mean.

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_scene::Scene;

// The reference renderer keeps its own copy of these constants on purpose: it shares no code
// with the tensor path it checks. The fused colours (`crate::fused::colours`) share them: the
// tensor path is their yardstick, and a wrong constant would show in the reference's tests.
pub(crate) const C0: f64 = 0.282_094_791_773_878_14;
pub(crate) const C1: f64 = 0.488_602_511_902_919_9;
pub(crate) const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
pub(crate) const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// SH coefficients of a scene on a device. `[N, K, 3]`, K = (degree + 1)².
#[derive(Debug, Clone)]
pub struct ShTensors {
    /// SH degree, 0 to 3.
    pub degree: u8,
    /// Coefficients `[N, K, 3]`.
    pub coeffs: Tensor<3>,
}

impl ShTensors {
    /// Uploads the scene's SH coefficients (of the Gaussians `indices`, all when `None`).
    pub fn new(scene: &Scene, indices: Option<&[usize]>, device: &Device, dtype: DType) -> Self {
        let k = scene.sh_coeffs();
        let values: Vec<f32> = match indices {
            None => scene.sh.clone(),
            Some(indices) => indices
                .iter()
                .flat_map(|&i| scene.sh_of(i).iter().copied())
                .collect(),
        };
        let n = values.len() / (3 * k);
        ShTensors {
            degree: scene.sh_degree,
            coeffs: Tensor::from_data(TensorData::new(values, [n, k, 3]), (device, dtype)),
        }
    }
}

/// RGB of every Gaussian seen from every camera centre. `means` `[N, 3]`, `centres` `[B, 3]`
/// → `[B, N, 3]`.
pub fn sh_colours(sh: &ShTensors, means: Tensor<2>, centres: Tensor<2>) -> Tensor<3> {
    colours_along(
        sh,
        means.unsqueeze_dim::<3>(0) - centres.unsqueeze_dim::<3>(1),
    )
}

/// RGB of each row's Gaussian seen from its own camera centre: `sh` holds the rows'
/// coefficients `[R, K, 3]`, `means` and `centres` are `[R, 3]` → `[R, 3]` (a pass whose poses
/// each see their own Gaussians, [`crate::rows`]).
pub fn sh_colours_of_rows(sh: &ShTensors, means: Tensor<2>, centres: Tensor<2>) -> Tensor<2> {
    let [rows, _] = means.dims();
    colours_along(sh, (means - centres).unsqueeze_dim::<3>(0)).reshape([rows, 3])
}

/// RGB of Gaussian n seen along `dir[b, n]` (camera centre to mean, any length) `[B, N, 3]`
/// → `[B, N, 3]`.
fn colours_along(sh: &ShTensors, dir: Tensor<3>) -> Tensor<3> {
    let [n, k, _] = sh.coeffs.dims();
    let [batch, _, _] = dir.dims();
    // The norm is floored so that a camera exactly at a mean gives a finite (arbitrary) colour.
    let norm = dir.clone().square().sum_dim(2).clamp_min(1e-24).sqrt();
    let dir = dir / norm;
    let x = dir.clone().narrow(2, 0, 1); // [B, N, 1]
    let y = dir.clone().narrow(2, 1, 1);
    let z = dir.narrow(2, 2, 1);

    let mut basis = vec![x.ones_like().mul_scalar(C0)];
    if sh.degree >= 1 {
        basis.extend([
            y.clone().mul_scalar(-C1),
            z.clone().mul_scalar(C1),
            x.clone().mul_scalar(-C1),
        ]);
    }
    if sh.degree >= 2 {
        let (xx, yy, zz) = (x.clone().square(), y.clone().square(), z.clone().square());
        basis.extend([
            (x.clone() * y.clone()).mul_scalar(C2[0]),
            (y.clone() * z.clone()).mul_scalar(C2[1]),
            (zz.clone().mul_scalar(2.0) - xx.clone() - yy.clone()).mul_scalar(C2[2]),
            (x.clone() * z.clone()).mul_scalar(C2[3]),
            (xx.clone() - yy.clone()).mul_scalar(C2[4]),
        ]);
        if sh.degree >= 3 {
            basis.extend([
                (y.clone() * (xx.clone().mul_scalar(3.0) - yy.clone())).mul_scalar(C3[0]),
                (x.clone() * y.clone() * z.clone()).mul_scalar(C3[1]),
                (y.clone() * (zz.clone().mul_scalar(4.0) - xx.clone() - yy.clone()))
                    .mul_scalar(C3[2]),
                (z.clone()
                    * (zz.clone().mul_scalar(2.0)
                        - xx.clone().mul_scalar(3.0)
                        - yy.clone().mul_scalar(3.0)))
                .mul_scalar(C3[3]),
                (x.clone() * (zz.mul_scalar(4.0) - xx.clone() - yy.clone())).mul_scalar(C3[4]),
                (z * (xx.clone() - yy.clone())).mul_scalar(C3[5]),
                (x * (xx - yy.mul_scalar(3.0))).mul_scalar(C3[6]),
            ]);
        }
    }
    let basis = Tensor::cat(basis, 2).reshape([batch, n, k, 1]); // [B, N, K, 1]
    let colour = (basis * sh.coeffs.clone().unsqueeze_dim::<4>(0)).sum_dim(2); // [B, N, 1, 3]
    colour.reshape([batch, n, 3]).add_scalar(0.5).clamp_min(0.0)
}
