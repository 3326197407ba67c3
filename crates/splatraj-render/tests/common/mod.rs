//! Helpers shared by the render crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use burn::tensor::{DType, Device, Tensor, TensorData};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::RefCamera;

/// The reference renderer's camera for a pose and intrinsics (near plane 0.01).
pub fn ref_camera(pose: &Pose, k: &Intrinsics) -> RefCamera {
    RefCamera::from_pose(pose, k, 0.01)
}

/// Poses as a `[B, 6]` tensor.
pub fn pose_tensor(poses: &[Pose], device: &Device, dtype: DType) -> Tensor<2> {
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    Tensor::from_data(TensorData::new(flat, [poses.len(), 6]), (device, dtype))
}

/// A tensor's values as f64 on the host, row-major.
pub fn host<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    t.into_data().convert::<f64>().try_to_vec::<f64>().unwrap()
}

/// Small deterministic generator (xorshift), so the tests need no rand dependency.
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}
