//! The fused rasterizer: tile compositing as one burn operation with its own backward.
//!
//! This node takes the screen-space Gaussians of a batch as packed rows (mean, conic, opacity:
//! what [`projection`], the fused projection, returns) and their channel values, both
//! differentiable, and the host-side tile lists, and returns the channel images and alpha
//! packed in one tensor `[B, H, W, C + 1]`, which [`composite_packed`] splits with
//! differentiable slicing, or the channel images alone `[B, H, W, C]` where the plan drops
//! alpha ([`crate::rasterize::AlphaChannel`]). Its backward is registered in burn's autodiff
//! graph through the backend extension (`#[backend_extension]`), so the pose gradient is still
//! assembled by burn from end to end.
//!
//! Backends: on Flex and ndarray the compositing kernels ([`cpu`]) run in plain Rust on the
//! host, in parallel over (pose, tile), reading the inputs into host vectors (a copy in
//! memory). The GPU backend (`Cube`, i.e. wgpu) runs the same rules as CubeCL kernels
//! (`cube`, one workgroup per tile); only the tile lists travel from the host.

pub mod colours;
pub mod cpu;
#[cfg(feature = "wgpu")]
pub mod cube;
#[cfg(feature = "wgpu")]
pub mod fusion;
#[cfg(feature = "wgpu")]
mod host_pool;
#[cfg(feature = "wgpu")]
pub mod launch_grid;
pub mod levels;
pub mod plan;
pub mod projection;
pub mod real;
pub mod segments;

use std::sync::Arc;

use rayon::prelude::*;

use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, ExtensionType, TensorMetadata, backend_extension};
use burn::tensor::{DType, Tensor, TensorData, try_read_sync};

pub use plan::CompositePlan;

use crate::rasterize::{AlphaChannel, Composited, RenderStats, SplatInputs};
use cpu::{ForwardState, HostGradients, HostSplats, Real};

/// The two differentiable inputs of a compositing pass, as backend primitives.
#[derive(ExtensionType)]
pub struct SplatPrimitives<B: Backend> {
    /// Packed rows `[R, S]`, S ≥ 6: (u, v, conic a, b, c, opacity), further columns ignored
    /// (the fused projection's rows carry the depth there; [`projection::PackedColumn`]).
    pub splats: FloatTensor<B>,
    /// `[R, C]`
    pub values: FloatTensor<B>,
}

/// The fused compositing operation, dispatched to the backend a tensor lives on.
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Cube: cfg(feature = "wgpu"),
    Autodiff
)]
pub trait FusedComposite: Backend {
    /// Composites `plan` into the packed image `[B, H, W, C + 1]` (channels, then alpha), or
    /// `[B, H, W, C]` where the plan drops alpha.
    fn fused_composite(
        #[extension_type] inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
    ) -> FloatTensor<Self>;
}

/// What a compositing forward's result is for: the GPU kernels save more for a backward.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForwardUse {
    /// The image alone (frames, metrics, renders without a gradient).
    ImageOnly,
    /// The image and a backward after it.
    ForBackward,
}

/// Forward and backward kernels of a base (non-autodiff) backend.
pub trait CompositeKernels: Backend {
    /// What the forward pass keeps for the backward pass.
    type Saved: Clone + Send + Sync + std::fmt::Debug + 'static;

    /// The packed image `[B, H, W, C + 1]` (`[B, H, W, C]` where the plan drops alpha) and the
    /// state its backward needs; `used` lets the
    /// GPU kernels cut long lists only where a backward follows ([`segments`]).
    fn composite_forward(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
        used: ForwardUse,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// Gradients of the two inputs from the gradient of the packed image.
    fn composite_backward(saved: Self::Saved, v_image: FloatTensor<Self>) -> SplatPrimitives<Self>;
}

/// Host copies of the inputs in their precision.
#[derive(Debug, Clone)]
pub enum HostInputs {
    /// 32-bit floats.
    F32(HostSplats<f32>, ForwardState<f32>),
    /// 64-bit floats (gradient checks).
    F64(HostSplats<f64>, ForwardState<f64>),
}

/// The forward state of the host kernels: the inputs as read, the plan and per-pixel state.
#[derive(Debug, Clone)]
pub struct HostSaved {
    plan: Arc<CompositePlan>,
    inputs: Arc<HostInputs>,
    /// `[R, S]`, `[R, C]`: shapes to give the gradients.
    rows: usize,
    columns: usize,
    channels: usize,
}

/// A tensor's values on the host as `E` (a copy; a sync on a device).
pub(crate) fn read<B: Backend, E: burn::tensor::Element>(t: FloatTensor<B>) -> Vec<E> {
    let data = try_read_sync(B::float_into_data(t))
        .expect("the fused rasterizer runs on backends that can be read synchronously")
        .expect("reading a tensor back to the host");
    data.convert::<E>()
        .try_into_vec::<E>()
        .expect("converted data has the requested element type")
}

fn host_splats<B: Backend, E: Real + burn::tensor::Element>(
    inputs: SplatPrimitives<B>,
    columns: usize,
    channels: usize,
) -> HostSplats<E> {
    let rows = read::<B, E>(inputs.splats);
    // In parallel: a step's call holds millions of rows (`counters`' `rows`), and this copy on
    // one thread kept the other cores waiting.
    let column = |from: usize, width: usize| -> Vec<E> {
        let mut out = vec![E::ZERO; rows.len() / columns.max(1) * width];
        out.par_chunks_exact_mut(width)
            .zip(rows.par_chunks_exact(columns))
            .for_each(|(out, row)| out.copy_from_slice(&row[from..from + width]));
        out
    };
    HostSplats {
        means: column(0, 2),
        conics: column(2, 3),
        opacities: column(5, 1),
        values: read::<B, E>(inputs.values),
        channels,
    }
}

fn upload<B: Backend, E: burn::tensor::Element>(
    values: Vec<E>,
    shape: Vec<usize>,
    dtype: DType,
    device: &B::Device,
) -> FloatTensor<B> {
    B::float_from_data(TensorData::new(values, shape).convert_dtype(dtype), device)
}

/// [`CompositeKernels::composite_forward`] through the host kernels, for any backend.
pub fn host_forward<B: Backend>(
    inputs: SplatPrimitives<B>,
    plan: Arc<CompositePlan>,
) -> (FloatTensor<B>, HostSaved) {
    let device = inputs.splats.device();
    let dtype = inputs.splats.dtype();
    let [rows, channels] = inputs.values.shape().dims::<2>();
    let columns = inputs.splats.shape().dims::<2>()[1];
    let grid = plan.grid;
    let shape = vec![
        plan.batch(),
        grid.height,
        grid.width,
        plan.image_width(channels),
    ];
    let (image, host) = if dtype == DType::F64 {
        let splats = host_splats::<B, f64>(inputs, columns, channels);
        let (image, state) = cpu::forward(&splats, &plan);
        (
            upload::<B, f64>(image, shape, dtype, &device),
            HostInputs::F64(splats, state),
        )
    } else {
        let splats = host_splats::<B, f32>(inputs, columns, channels);
        let (image, state) = cpu::forward(&splats, &plan);
        (
            upload::<B, f32>(image, shape, dtype, &device),
            HostInputs::F32(splats, state),
        )
    };
    let saved = HostSaved {
        plan,
        inputs: Arc::new(host),
        rows,
        columns,
        channels,
    };
    (image, saved)
}

/// [`CompositeKernels::composite_backward`] through the host kernels, for any backend.
pub fn host_backward<B: Backend>(saved: HostSaved, v_image: FloatTensor<B>) -> SplatPrimitives<B> {
    let device = v_image.device();
    let dtype = v_image.dtype();
    let (rows, columns, channels) = (saved.rows, saved.columns, saved.channels);
    fn to_primitives<B: Backend, E: Real + burn::tensor::Element>(
        v: HostGradients<E>,
        [rows, columns, channels]: [usize; 3],
        dtype: DType,
        device: &B::Device,
    ) -> SplatPrimitives<B> {
        let mut splats = vec![E::ZERO; rows * columns];
        splats
            .par_chunks_exact_mut(columns)
            .enumerate()
            .for_each(|(r, row)| {
                row[..2].copy_from_slice(&v.means[2 * r..2 * r + 2]);
                row[2..5].copy_from_slice(&v.conics[3 * r..3 * r + 3]);
                row[5] = v.opacities[r];
            });
        SplatPrimitives {
            splats: upload::<B, E>(splats, vec![rows, columns], dtype, device),
            values: upload::<B, E>(v.values, vec![rows, channels], dtype, device),
        }
    }
    let sizes = [rows, columns, channels];
    match saved.inputs.as_ref() {
        HostInputs::F64(splats, state) => {
            let v_image = read::<B, f64>(v_image);
            let v = cpu::backward(splats, &saved.plan, state, &v_image);
            to_primitives::<B, f64>(v, sizes, dtype, &device)
        }
        HostInputs::F32(splats, state) => {
            let v_image = read::<B, f32>(v_image);
            let v = cpu::backward(splats, &saved.plan, state, &v_image);
            to_primitives::<B, f32>(v, sizes, dtype, &device)
        }
    }
}

/// Implements the kernels and the (non-autodiff) operation of a backend with the host kernels.
macro_rules! host_backend {
    ($backend:ty) => {
        impl CompositeKernels for $backend {
            type Saved = HostSaved;

            fn composite_forward(
                inputs: SplatPrimitives<Self>,
                plan: Arc<CompositePlan>,
                _: ForwardUse,
            ) -> (FloatTensor<Self>, HostSaved) {
                host_forward::<Self>(inputs, plan)
            }

            fn composite_backward(
                saved: HostSaved,
                v_image: FloatTensor<Self>,
            ) -> SplatPrimitives<Self> {
                host_backward::<Self>(saved, v_image)
            }
        }

        impl FusedComposite for $backend {
            fn fused_composite(
                inputs: SplatPrimitives<Self>,
                plan: Arc<CompositePlan>,
            ) -> FloatTensor<Self> {
                Self::composite_forward(inputs, plan, ForwardUse::ImageOnly).0
            }
        }
    };
}

#[cfg(feature = "flex")]
host_backend!(burn::backend::Flex);
#[cfg(feature = "ndarray")]
#[allow(deprecated)] // burn deprecates ndarray; it stays our second CPU backend for the tests
mod ndarray_kernels {
    use super::*;
    host_backend!(burn::backend::NdArray);
}

/// The backward step of the compositing node.
#[derive(Debug)]
struct CompositeBackward;

impl<B: CompositeKernels> Backward<B, 2> for CompositeBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let v_image = grads.consume::<B>(&ops.node);
        let started = std::time::Instant::now();
        let v = B::composite_backward(ops.state, v_image);
        crate::stages::add(crate::stages::Stage::CompositeBackward, started.elapsed());
        let [splats, values] = ops.parents;
        for (node, grad) in [(splats, v.splats), (values, v.values)] {
            if let Some(node) = node {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: CompositeKernels, C: CheckpointStrategy> FusedComposite for Autodiff<B, C> {
    fn fused_composite(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
    ) -> FloatTensor<Self> {
        let nodes = [inputs.splats.node(), inputs.values.node()];
        let primitives = SplatPrimitives {
            splats: inputs.splats.into_primitive(),
            values: inputs.values.into_primitive(),
        };
        match CompositeBackward
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (image, saved) =
                    B::composite_forward(primitives, plan, ForwardUse::ForBackward);
                prep.finish(saved, image)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::composite_forward(primitives, plan, ForwardUse::ImageOnly).0)
            }
        }
    }
}

/// Composites a batch with the fused operation; same contract as [`crate::rasterize::composite`].
pub fn composite_fused(inputs: &SplatInputs, plan: CompositePlan) -> Composited {
    let splats = Tensor::cat(
        vec![
            inputs.means_2d.clone(),
            inputs.conics.clone(),
            inputs.opacities.clone().unsqueeze_dim::<2>(1),
        ],
        1,
    ); // [R, 6]
    composite_packed(splats, inputs.values.clone(), plan)
}

/// Composites packed rows `splats` `[R, S ≥ 6]` (u, v, conic a, b, c, opacity, then columns
/// it ignores) with channel values `values` `[R, C]`: the fused projection's output as it is.
///
/// A GPU kernel stages every channel of 256 entries in workgroup memory, so a device holds
/// only so many channels a composite (lavapipe 16, a 48 KiB GPU 28; feature renders of mask
/// files have a channel per label): more are composited in groups that fit, on the same lists,
/// and joined; the alpha is the first group's (every group's is the same, so the others drop
/// theirs), and autodiff sums each group's gradient of the rows.
pub fn composite_packed(splats: Tensor<2>, values: Tensor<2>, plan: CompositePlan) -> Composited {
    #[cfg(feature = "wgpu")]
    if let Some(group) = cube::channels_per_composite(&splats.device())
        && let channels = values.dims()[1]
        && channels > group
    {
        let rest = Arc::new(plan.clone().with_alpha(AlphaChannel::Dropped));
        let first = Arc::new(plan);
        let parts: Vec<Composited> = (0..channels)
            .step_by(group)
            .map(|start| {
                let count = group.min(channels - start);
                composite_shared_plan(
                    splats.clone(),
                    values.clone().narrow(1, start, count),
                    if start == 0 {
                        first.clone()
                    } else {
                        rest.clone()
                    },
                )
            })
            .collect();
        let head = parts[0].clone();
        return head.with_images(Tensor::cat(
            parts.into_iter().map(|p| p.images).collect(),
            3,
        ));
    }
    composite_shared_plan(splats, values, Arc::new(plan))
}

/// [`composite_packed`] of one group of channels.
fn composite_shared_plan(
    splats: Tensor<2>,
    values: Tensor<2>,
    plan: Arc<CompositePlan>,
) -> Composited {
    let stats = RenderStats {
        tiles: plan.tiles.len(),
        pairs: plan.rows.len(),
        gaussians_used: plan.pose_rows.largest(),
    };
    let alpha = plan.alpha;
    let image = Tensor::<4>::from_dispatch(<Dispatch as FusedComposite>::fused_composite(
        SplatPrimitives {
            splats: splats.into_dispatch(),
            values: values.into_dispatch(),
        },
        plan,
    )); // [B, H, W, C + 1], or [B, H, W, C] where alpha is dropped
    match alpha {
        AlphaChannel::Returned => Composited::from_packed(image, stats),
        AlphaChannel::Dropped => Composited::without_alpha(image, stats),
    }
}
