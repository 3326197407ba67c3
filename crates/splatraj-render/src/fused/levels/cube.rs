//! The packed levels on the GPU backend (`CubeBackend`, under burn's fusion:
//! [`crate::fused::fusion`]): one unit a pixel reads its first three channels and writes
//! their levels as one integer. One launch, nothing uploaded.

use burn::backend::TensorMetadata;
use burn::tensor::IntDType;
use burn_backend::cubecl::dtype_to_storage_type;
use burn_backend::ops::IntTensorOps;
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;

/// Units a cube.
const UNITS: u32 = 256;

/// One channel value's level: [`super::level_f32`]'s rule.
#[cube]
fn level<F: Float>(v: F) -> u32 {
    // Written as a choice, not `clamp`: NaN fails `v > 0` and gives 0, as on the host.
    let mut clamped = F::new(0.0);
    if v > F::new(0.0) {
        clamped = F::min(v, F::new(1.0));
    }
    u32::cast_from(clamped * F::new(255.0) + F::new(0.5))
}

#[cube(launch)]
fn pack_kernel<F: Float, I: Int>(
    images: &Tensor<F>,     // [P, C]
    packed: &mut Tensor<I>, // [P]
    pixels: u32,
    channels: u32,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let p = (CUBE_POS_Y * CUBE_COUNT_X + CUBE_POS_X) * UNITS + UNIT_POS;
    if p < pixels {
        let at = p as usize * channels as usize;
        let r = level::<F>(images[at]);
        let g = level::<F>(images[at + 1]);
        let b = level::<F>(images[at + 2]);
        packed[p as usize] = I::cast_from(r + g * 256u32 + b * 65_536u32);
    }
}

/// The packed levels `[B, H, W]` (i32) of `images` `[B, H, W, C ≥ 3]`.
pub fn packed_rgb8(images: CubeTensor) -> CubeTensor {
    let images = into_contiguous(images);
    let [batch, height, width, channels] = images.shape().dims::<4>();
    let pixels = batch * height * width;
    let packed = CubeBackend::int_empty(
        vec![batch, height, width].into(),
        &images.device,
        IntDType::I32,
    );
    if pixels > 0 {
        pack_kernel::launch(
            &images.client,
            crate::fused::launch_grid::linear(pixels.div_ceil(UNITS as usize)),
            CubeDim::new_1d(UNITS),
            images.clone().into_tensor_arg(),
            packed.clone().into_tensor_arg(),
            pixels as u32,
            channels as u32,
            [
                dtype_to_storage_type(images.dtype),
                dtype_to_storage_type(packed.dtype),
            ],
        );
    }
    packed
}
