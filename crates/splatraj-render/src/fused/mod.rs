//! The fused rasterizer: tile compositing as one burn operation with its own backward.
//!
//! Everything before compositing (projection, SH) and after it (costs) stays burn tensor ops;
//! this node takes the screen-space Gaussians of a batch (means, conics, opacities, channel
//! values, all differentiable) and the host-side tile lists, and returns the channel images and
//! alpha packed in one tensor `[B, H, W, C + 1]`, which [`composite_fused`] splits with
//! differentiable slicing. Its backward is registered in burn's autodiff graph through the
//! backend extension (`#[backend_extension]`), so the pose gradient is still assembled by
//! burn from end to end.
//!
//! Backends: on Flex and ndarray the compositing kernels ([`cpu`]) run in plain Rust on the
//! host, in parallel over (pose, tile), reading the inputs into host vectors (a copy in
//! memory). The GPU backend (`Cube`, i.e. wgpu) runs the same rules as CubeCL kernels
//! ([`cube`], one workgroup per tile); only the tile lists travel from the host.

pub mod cpu;
#[cfg(feature = "wgpu")]
pub mod cube;
pub mod plan;
pub mod real;

use std::sync::Arc;

use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, ExtensionType, TensorMetadata, backend_extension};
use burn::tensor::{DType, Tensor, TensorData, try_read_sync};

pub use plan::CompositePlan;

use crate::rasterize::{Composited, RenderStats, SplatInputs};
use cpu::{ForwardState, HostGradients, HostSplats, Real};

/// The four differentiable inputs of a compositing pass, as backend primitives.
#[derive(ExtensionType)]
pub struct SplatPrimitives<B: Backend> {
    /// `[R, 2]`
    pub means: FloatTensor<B>,
    /// `[R, 3]`
    pub conics: FloatTensor<B>,
    /// `[R]`
    pub opacities: FloatTensor<B>,
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
    /// Composites `plan` into the packed image `[B, H, W, C + 1]` (channels, then alpha).
    fn fused_composite(
        #[extension_type] inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
    ) -> FloatTensor<Self>;
}

/// Forward and backward kernels of a base (non-autodiff) backend.
pub trait CompositeKernels: Backend {
    /// What the forward pass keeps for the backward pass.
    type Saved: Clone + Send + Sync + std::fmt::Debug + 'static;

    /// The packed image `[B, H, W, C + 1]` and the state its backward needs.
    fn composite_forward(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// Gradients of the four inputs from the gradient of the packed image.
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
    /// `[R]`, `[R, C]`: shapes to give the gradients.
    rows: usize,
    channels: usize,
}

fn read<B: Backend, E: burn::tensor::Element>(t: FloatTensor<B>) -> Vec<E> {
    let data = try_read_sync(B::float_into_data(t))
        .expect("the fused rasterizer runs on backends that can be read synchronously")
        .expect("reading a tensor back to the host");
    data.convert::<E>()
        .try_into_vec::<E>()
        .expect("converted data has the requested element type")
}

fn host_splats<B: Backend, E: Real + burn::tensor::Element>(
    inputs: SplatPrimitives<B>,
    channels: usize,
) -> HostSplats<E> {
    HostSplats {
        means: read::<B, E>(inputs.means),
        conics: read::<B, E>(inputs.conics),
        opacities: read::<B, E>(inputs.opacities),
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
    let device = inputs.means.device();
    let dtype = inputs.means.dtype();
    let [rows, channels] = inputs.values.shape().dims::<2>();
    let grid = plan.grid;
    let shape = vec![plan.batch, grid.height, grid.width, channels + 1];
    let (image, host) = if dtype == DType::F64 {
        let splats = host_splats::<B, f64>(inputs, channels);
        let (image, state) = cpu::forward(&splats, &plan);
        (
            upload::<B, f64>(image, shape, dtype, &device),
            HostInputs::F64(splats, state),
        )
    } else {
        let splats = host_splats::<B, f32>(inputs, channels);
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
        channels,
    };
    (image, saved)
}

/// [`CompositeKernels::composite_backward`] through the host kernels, for any backend.
pub fn host_backward<B: Backend>(saved: HostSaved, v_image: FloatTensor<B>) -> SplatPrimitives<B> {
    let device = v_image.device();
    let dtype = v_image.dtype();
    let (rows, channels) = (saved.rows, saved.channels);
    fn to_primitives<B: Backend, E: burn::tensor::Element>(
        v: HostGradients<E>,
        rows: usize,
        channels: usize,
        dtype: DType,
        device: &B::Device,
    ) -> SplatPrimitives<B> {
        SplatPrimitives {
            means: upload::<B, E>(v.means, vec![rows, 2], dtype, device),
            conics: upload::<B, E>(v.conics, vec![rows, 3], dtype, device),
            opacities: upload::<B, E>(v.opacities, vec![rows], dtype, device),
            values: upload::<B, E>(v.values, vec![rows, channels], dtype, device),
        }
    }
    match saved.inputs.as_ref() {
        HostInputs::F64(splats, state) => {
            let v_image = read::<B, f64>(v_image);
            let v = cpu::backward(splats, &saved.plan, state, &v_image);
            to_primitives::<B, f64>(v, rows, channels, dtype, &device)
        }
        HostInputs::F32(splats, state) => {
            let v_image = read::<B, f32>(v_image);
            let v = cpu::backward(splats, &saved.plan, state, &v_image);
            to_primitives::<B, f32>(v, rows, channels, dtype, &device)
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
                Self::composite_forward(inputs, plan).0
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

impl<B: CompositeKernels> Backward<B, 4> for CompositeBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 4>, grads: &mut Gradients, _: &mut Checkpointer) {
        let v_image = grads.consume::<B>(&ops.node);
        let started = std::time::Instant::now();
        let v = B::composite_backward(ops.state, v_image);
        crate::stages::add(crate::stages::Stage::CompositeBackward, started.elapsed());
        let [means, conics, opacities, values] = ops.parents;
        for (node, grad) in [
            (means, v.means),
            (conics, v.conics),
            (opacities, v.opacities),
            (values, v.values),
        ] {
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
        let nodes = [
            inputs.means.node(),
            inputs.conics.node(),
            inputs.opacities.node(),
            inputs.values.node(),
        ];
        let primitives = SplatPrimitives {
            means: inputs.means.into_primitive(),
            conics: inputs.conics.into_primitive(),
            opacities: inputs.opacities.into_primitive(),
            values: inputs.values.into_primitive(),
        };
        match CompositeBackward
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (image, saved) = B::composite_forward(primitives, plan);
                prep.finish(saved, image)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::composite_forward(primitives, plan).0),
        }
    }
}

/// Composites a batch with the fused operation; same contract as [`crate::rasterize::composite`].
pub fn composite_fused(inputs: &SplatInputs, plan: CompositePlan) -> Composited {
    let channels = inputs.values.dims()[1];
    let (batch, grid) = (plan.batch, plan.grid);
    let stats = RenderStats {
        tiles: plan.tiles.len(),
        pairs: plan.rows.len(),
        gaussians_used: inputs.opacities.dims()[0] / batch.max(1),
    };
    let packed = Tensor::<4>::from_dispatch(<Dispatch as FusedComposite>::fused_composite(
        SplatPrimitives {
            means: inputs.means_2d.clone().into_dispatch(),
            conics: inputs.conics.clone().into_dispatch(),
            opacities: inputs.opacities.clone().into_dispatch(),
            values: inputs.values.clone().into_dispatch(),
        },
        Arc::new(plan),
    )); // [B, H, W, C + 1]
    let alpha = packed
        .clone()
        .narrow(3, channels, 1)
        .reshape([batch, grid.height, grid.width]);
    Composited {
        images: packed.narrow(3, 0, channels),
        alpha,
        stats,
    }
}
