//! How many poses one render pass may take, so that a pass's images fit the device.
//!
//! A pass of B poses at W×H with C channel values a pixel composites into an image tensor of
//! B·H·W·(C + 1) floats (the channels and the accumulated alpha), and keeps per-pixel state of
//! the same order. A GPU allocates each tensor as one buffer, and its largest buffer is a
//! property of the device: lavapipe (Mesa's software Vulkan) and WebGPU's default stop at
//! 128 MiB, which the 30 metric samples of a 1280×720 window in one pass (221 MB of mask and
//! alpha) exceed; a data-centre GPU holds tens of GB. Callers that render many poses (the window
//! metrics) split them into passes of [`poses_per_pass`]; a pass of one pose that still does not
//! fit is the device's error, reported by the read that follows ([`crate::host::read_data`]).
//!
//! The host backends have no buffer limit, but the same bound keeps a pass's images (and their
//! f64 copies on the host) to a few hundred MB, so it applies there too.
//!
//! Besides the images, a pass holds its packed rows (each pose's Gaussians, summed, × 7), its channel
//! values, its tile lists and, with a gradient, a slot per tile–Gaussian pair; the scene holds
//! its SH coefficients. [`first_oversized`] names the first of these a device cannot hold, so a
//! render refuses such a pass before any work, naming the buffer, instead of failing on the
//! device (a failure that burn reports only at the next read, as a chain of lost buffers).

use std::ops::Range;

use burn::tensor::{DType, Device};

/// The most bytes the images of one pass may take, whatever the device: 128 MiB, WebGPU's
/// default largest storage buffer (so a pass fits any conformant GPU) and, on the host, 18
/// poses of a 1280×720 mask.
pub const PASS_IMAGE_BYTES: u64 = 128 << 20;

/// The largest buffer one tensor may occupy on `device`, in bytes; None on the host backends.
pub fn max_buffer_bytes(device: &Device) -> Option<u64> {
    #[cfg(feature = "wgpu")]
    if let Some(cube) = crate::backend::cube_device(device) {
        return Some(cube.client().properties().memory.max_page_size);
    }
    #[cfg(not(feature = "wgpu"))]
    let _ = device;
    None
}

/// How many poses of `width`×`height` with `channels` channel values a pixel in `dtype` one pass
/// on `device` may take: their composited images (the channels and alpha) within
/// [`PASS_IMAGE_BYTES`] and the device's largest buffer, at least 1.
pub fn poses_per_pass(
    device: &Device,
    dtype: DType,
    width: usize,
    height: usize,
    channels: usize,
) -> usize {
    let limit = max_buffer_bytes(device).map_or(PASS_IMAGE_BYTES, |m| m.min(PASS_IMAGE_BYTES));
    let fit = poses_within(limit, dtype.size(), width, height, channels + 1);
    max_poses(device).map_or(fit, |most| fit.min(most))
}

/// The most poses one pass may hold on `device`: on a GPU, the projection's and colours'
/// kernels put a pass's poses on one axis of their launch grid, which holds 65 535 cubes
/// (`fused/launch_grid.rs`; 16×16 masks would otherwise fit 65 536 poses in the image bound);
/// None on the host backends.
pub fn max_poses(device: &Device) -> Option<usize> {
    #[cfg(feature = "wgpu")]
    if crate::backend::Execution::of(device) == crate::backend::Execution::Kernels {
        return Some(crate::fused::launch_grid::MAX_PER_AXIS);
    }
    #[cfg(not(feature = "wgpu"))]
    let _ = device;
    None
}

/// Poses whose images of `width`×`height`×`values` values of `value_bytes` each fit in
/// `limit` bytes, at least 1.
fn poses_within(
    limit: u64,
    value_bytes: usize,
    width: usize,
    height: usize,
    values: usize,
) -> usize {
    let per_pose = (width * height * values.max(1) * value_bytes) as u64;
    usize::try_from(limit / per_pose.max(1))
        .unwrap_or(usize::MAX)
        .max(1)
}

/// A buffer a render pass needs: what it holds, and its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PassBuffer {
    /// What it holds, e.g. "a pass's packed rows (3240000 pose–Gaussian rows × 7 values)".
    pub what: String,
    /// Its size.
    pub bytes: u64,
}

/// The first of `buffers` larger than `device`'s largest buffer, with that limit; None when
/// all fit or on the host backends (no limit), which never make the list: a render calls this
/// every pass, and the list's descriptions are formatted strings.
pub fn first_oversized(
    device: &Device,
    buffers: impl FnOnce() -> Vec<PassBuffer>,
) -> Option<(PassBuffer, u64)> {
    let limit = max_buffer_bytes(device)?;
    over_limit(limit, &buffers()).map(|b| (b.clone(), limit))
}

/// The first of `buffers` above `limit` bytes.
fn over_limit(limit: u64, buffers: &[PassBuffer]) -> Option<&PassBuffer> {
    buffers.iter().find(|b| b.bytes > limit)
}

/// `0..total` in consecutive ranges of at most `per_pass` (at least 1) indices.
pub fn passes(total: usize, per_pass: usize) -> impl Iterator<Item = Range<usize>> {
    let step = per_pass.max(1);
    (0..total)
        .step_by(step)
        .map(move |first| first..(first + step).min(total))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_fill_the_limit_and_never_drop_to_zero() {
        // 1280×720 mask and alpha in f32: 7.37 MB a pose, 18 in 128 MiB; 30 would be 221 MB.
        assert_eq!(poses_within(PASS_IMAGE_BYTES, 4, 1280, 720, 2), 18);
        const { assert!(30 * 1280 * 720 * 2 * 4 > PASS_IMAGE_BYTES) };
        // Four f64 channels at 8K: one pose is more than the limit, still one pose a pass.
        assert_eq!(poses_within(PASS_IMAGE_BYTES, 8, 7680, 4320, 4), 1);
        // A limit of exactly k poses gives k.
        assert_eq!(poses_within(3 * 100 * 50 * 4, 4, 100, 50, 1), 3);
        assert_eq!(poses_within(3 * 100 * 50 * 4 - 1, 4, 100, 50, 1), 2);
    }

    #[test]
    fn the_first_buffer_over_the_limit_is_named() {
        let buffer = |what: &str, bytes| PassBuffer {
            what: what.into(),
            bytes,
        };
        let buffers = [buffer("a", 100), buffer("b", 101), buffer("c", 500)];
        assert_eq!(over_limit(100, &buffers), Some(&buffers[1]));
        assert_eq!(over_limit(500, &buffers), None);
        assert_eq!(over_limit(99, &buffers), Some(&buffers[0]));
    }

    #[test]
    fn passes_cover_every_index_once_in_order() {
        let cut: Vec<Range<usize>> = passes(60, 36).collect();
        assert_eq!(cut, vec![0..36, 36..60]);
        assert_eq!(passes(5, 0).count(), 5);
        assert_eq!(passes(0, 7).count(), 0);
        let joined: Vec<usize> = passes(100, 7).flatten().collect();
        assert_eq!(joined, (0..100).collect::<Vec<_>>());
    }

    #[test]
    fn host_devices_take_the_fixed_limit() {
        let device = crate::backend::BackendKind::compiled()[0]
            .device()
            .expect("a compiled backend has a device");
        if max_buffer_bytes(&device).is_none() {
            assert_eq!(poses_per_pass(&device, DType::F32, 1280, 720, 1), 18);
        }
    }
}
