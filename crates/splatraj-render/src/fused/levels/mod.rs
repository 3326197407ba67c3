//! A frame's 8-bit RGB levels made where its images are, packed one integer a pixel
//! (r + 256·g + 65 536·b), as one operation: what [`crate::images::packed_rgb8`] calls.
//!
//! Why an operation of its own: as burn tensor ops the levels were four kernel launches on a
//! GPU (the clamp chain, the cast to integers, the product by each channel's place and the sum
//! over the channels), a third of an output frame's launches. On `Cube` (wgpu) it is one
//! CubeCL kernel ([`cube`]), one unit a pixel; on the host backends a loop over the values,
//! which are in memory already. No gradient: frames are pictures, not costs.
//!
//! The rule is [`crate::images::to_u8`]'s (the nearest level, halves up; NaN is 0) computed
//! in f32 as `⌊min(max(v, 0), 1) · 255 + 0.5⌋`: within about 1e-5 of half a level f32 may land
//! one level above `to_u8`, which computes in f64 (`tests/backend.rs`,
//! `packed_levels_are_rgb8_s_on_every_backend`, holds every backend to that).

#[cfg(feature = "wgpu")]
pub mod cube;

use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Backend, TensorMetadata, backend_extension};
use burn::tensor::TensorData;

/// The packed levels, dispatched to the backend a tensor lives on.
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Cube: cfg(feature = "wgpu"),
    Autodiff
)]
pub trait PackedLevels: Backend {
    /// The packed levels `[B, H, W]` (i32) of the first three channels of `images`
    /// `[B, H, W, C ≥ 3]`; the other channels are not read.
    fn packed_rgb8(images: FloatTensor<Self>) -> IntTensor<Self>;
}

/// One channel value's 8-bit level in f32, as every backend computes it (module docs).
#[inline]
fn level_f32(v: f32) -> u32 {
    // NaN stays NaN through the clamp and the cast makes it 0 (Rust's float casts saturate).
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u32
}

/// [`PackedLevels::packed_rgb8`] on the host: the values read (a copy on ndarray, a view's
/// copy on Flex) and packed pixel after pixel.
fn host_packed<B: Backend>(images: FloatTensor<B>) -> IntTensor<B> {
    let device = images.device();
    let [batch, height, width, channels] = images.shape().dims::<4>();
    let values = super::read::<B, f32>(images);
    let packed: Vec<i32> = values
        .chunks_exact(channels)
        .map(|px| (level_f32(px[0]) | level_f32(px[1]) << 8 | level_f32(px[2]) << 16) as i32)
        .collect();
    B::int_from_data(TensorData::new(packed, [batch, height, width]), &device)
}

#[cfg(feature = "flex")]
impl PackedLevels for burn::backend::Flex {
    fn packed_rgb8(images: FloatTensor<Self>) -> IntTensor<Self> {
        host_packed::<Self>(images)
    }
}

#[cfg(feature = "ndarray")]
#[allow(deprecated)]
impl PackedLevels for burn::backend::NdArray {
    fn packed_rgb8(images: FloatTensor<Self>) -> IntTensor<Self> {
        host_packed::<Self>(images)
    }
}

impl<B: PackedLevels, C: CheckpointStrategy> PackedLevels for Autodiff<B, C> {
    fn packed_rgb8(images: FloatTensor<Self>) -> IntTensor<Self> {
        // Off the graph: integer levels have no gradient.
        B::packed_rgb8(images.into_primitive())
    }
}
