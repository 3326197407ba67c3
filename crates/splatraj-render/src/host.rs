//! Moving values between the host and a device: one read-back helper, counted uploads, pose
//! tensors, and the device and dtype a scene lives on ([`OnDevice`]).
//!
//! Every part of splatraj that reads a tensor back (costs for a history row, metrics, images,
//! gradients) goes through [`to_host`], so there is one conversion rule: any float dtype is
//! read as f64.

use burn::tensor::{DType, Device, Int, Tensor, TensorData};

use crate::camera::Pose;

/// A tensor could not be read back to the host.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("reading a tensor back to the host: {0}")]
pub struct ReadBackError(pub String);

/// The values of a float tensor on the host as f64, in row-major order (a counted read).
pub fn to_host<const D: usize>(t: Tensor<D>) -> Result<Vec<f64>, ReadBackError> {
    read_data(t)?
        .convert::<f64>()
        .try_to_vec::<f64>()
        .map_err(|e| ReadBackError(format!("{e:?}")))
}

/// The data of a tensor on the host in its own dtype (a counted read). A failure of the device
/// since the last read (a buffer larger than it can allocate, a lost device) surfaces here:
/// it is returned as an error, where burn's `into_data` would panic.
pub fn read_data<const D: usize, K: burn::tensor::kind::Basic>(
    t: Tensor<D, K>,
) -> Result<TensorData, ReadBackError> {
    let data = t
        .try_into_data()
        .map_err(|e| ReadBackError(device_failure(&e.to_string())))?;
    crate::counters::read(data.as_bytes().len());
    Ok(data)
}

/// The lines of a device error's report that say what failed, joined on one line: CubeCL's
/// report repeats "Caused by:", placeholder backtraces and every operation it skipped.
fn device_failure(report: &str) -> String {
    let mut said: Vec<&str> = Vec::new();
    for line in report.lines().map(str::trim) {
        let noise = line.is_empty()
            || line == "Caused by:"
            || line == "Asked at:"
            || line == "No backtrace available"
            || line.starts_with("skipped `");
        if !noise && !said.contains(&line) {
            said.push(line);
        }
    }
    said.join(": ")
}

/// A tensor from host `data` on `device` in `dtype` (a counted upload).
pub fn upload<const D: usize>(data: TensorData, device: &Device, dtype: DType) -> Tensor<D> {
    crate::counters::upload(data.as_bytes().len());
    Tensor::from_data(data, (device, dtype))
}

/// An integer tensor (indices) from host `values` of `shape` on `device` (a counted upload).
pub fn upload_ints<const D: usize>(
    values: Vec<i64>,
    shape: [usize; D],
    device: &Device,
) -> Tensor<D, Int> {
    let data = TensorData::new(values, shape);
    crate::counters::upload(data.as_bytes().len());
    Tensor::from_data(data, device)
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

/// `poses` as a tensor of `dtype` holds them: each value rounded to the dtype and back (f32 and
/// f64; None for another dtype, whose rounding the caller must read back).
pub fn as_stored(poses: &[Pose], dtype: DType) -> Option<Vec<Pose>> {
    match dtype {
        DType::F64 => Some(poses.to_vec()),
        DType::F32 => Some(
            poses
                .iter()
                .map(|p| Pose(p.0.map(|v| f64::from(v as f32))))
                .collect(),
        ),
        _ => None,
    }
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

#[cfg(test)]
mod tests {
    use super::device_failure;

    #[test]
    fn a_device_failure_says_what_failed_on_one_line() {
        // The shape of CubeCL's report when lavapipe refused a 221 MB buffer.
        let report = "An error happened during execution\nCaused by:\n  Several failures at once\n\
            Caused by:\n  The bytes were never written (failure #1856, still claiming 5 buffer(s))\n  \
            skipped `ElemwiseFuse`: it needed memory ManagedMemoryId { value: 4513 }\n  \
            skipped `ReduceKernel`: it needed memory ManagedMemoryId { value: 4487 }\n\
            Caused by:\n  An IO error happened\nCaused by:\n  can't allocate buffer of size: \
            221184000\nNo backtrace available\nAsked at:\nNo backtrace available\n";
        assert_eq!(
            device_failure(report),
            "An error happened during execution: Several failures at once: The bytes were never \
             written (failure #1856, still claiming 5 buffer(s)): An IO error happened: can't \
             allocate buffer of size: 221184000"
        );
    }
}

#[cfg(test)]
mod stored_tests {
    use burn::tensor::{DType, Device};

    use super::{as_stored, poses_tensor, to_host};
    use crate::camera::Pose;

    /// The rounding `as_stored` assumes is the one burn applies when it uploads f64 values to
    /// an f32 tensor: read back, they are the same to the bit.
    #[test]
    fn stored_poses_are_what_the_device_holds() {
        let poses: Vec<Pose> = (0..50)
            .map(|k| {
                let x = 0.1 + k as f64 * 0.7313;
                Pose([
                    x.sin(),
                    1.0 / x,
                    -x.cos() * 3.3,
                    x * 1e3,
                    1e-7 / x,
                    -x.sqrt(),
                ])
            })
            .collect();
        let device = Device::flex();
        for dtype in [DType::F32, DType::F64] {
            let read = to_host(poses_tensor(&poses, &device, dtype)).unwrap();
            let stored: Vec<f64> = as_stored(&poses, dtype)
                .unwrap()
                .iter()
                .flat_map(|p| p.0)
                .collect();
            assert_eq!(stored, read, "{dtype:?}");
        }
        assert!(as_stored(&poses, DType::F16).is_none());
    }
}
