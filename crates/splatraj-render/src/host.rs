//! Moving values between the host and a device: one read-back helper, counted uploads, pose
//! tensors, and the device and dtype a scene lives on ([`OnDevice`]).
//!
//! Every part of splatraj that reads a tensor back (costs for a history row, metrics, images,
//! gradients) goes through [`to_host`], so there is one conversion rule: any float dtype is
//! read as f64.

use burn::tensor::{DType, Device, Tensor, TensorData};

use crate::camera::Pose;

/// A tensor could not be read back to the host.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("reading a tensor back to the host: {0}")]
pub struct ReadBackError(pub String);

/// The values of a float tensor on the host as f64, in row-major order (a counted read).
pub fn to_host<const D: usize>(t: Tensor<D>) -> Result<Vec<f64>, ReadBackError> {
    let data = t.into_data();
    crate::counters::read(data.as_bytes().len());
    data.convert::<f64>()
        .try_to_vec::<f64>()
        .map_err(|e| ReadBackError(format!("{e:?}")))
}

/// A tensor from host `data` on `device` in `dtype` (a counted upload).
pub fn upload<const D: usize>(data: TensorData, device: &Device, dtype: DType) -> Tensor<D> {
    crate::counters::upload(data.as_bytes().len());
    Tensor::from_data(data, (device, dtype))
}

/// The single value of a one-element tensor (or NaN if it cannot be read).
pub fn scalar<const D: usize>(t: Tensor<D>) -> f64 {
    to_host(t)
        .ok()
        .and_then(|v| v.first().copied())
        .unwrap_or(f64::NAN)
}

/// Poses Φ as a `[B, 6]` tensor on `device` in `dtype`.
pub fn poses_tensor(poses: &[Pose], device: &Device, dtype: DType) -> Tensor<2> {
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    upload(TensorData::new(flat, [poses.len(), 6]), device, dtype)
}

/// One pose Φ as a `[1, 6]` tensor.
pub fn pose_tensor(pose: &Pose, device: &Device, dtype: DType) -> Tensor<2> {
    poses_tensor(std::slice::from_ref(pose), device, dtype)
}

/// Where a scene lives: the device (plain or autodiff) and float dtype of its tensors.
pub trait OnDevice {
    /// The device of the scene's tensors.
    fn device(&self) -> Device;
    /// The float dtype of the scene's tensors.
    fn dtype(&self) -> DType;
    /// Poses Φ `[B, 6]` on the scene's device, in its dtype.
    fn poses(&self, poses: &[Pose]) -> Tensor<2> {
        poses_tensor(poses, &self.device(), self.dtype())
    }
}
