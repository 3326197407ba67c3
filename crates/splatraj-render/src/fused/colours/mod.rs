//! The fused colours: each row's view-dependent RGB from spherical harmonics as one burn
//! operation with its own backward, beside the fused projection.
//!
//! The tensor path (`crate::sh`) is about twenty burn ops forward and more in its backward,
//! each a kernel launch on a GPU, and on the host each a pass over `[R, K, 3]` values: a 720p
//! frame of a million degree-3 Gaussians spent more time there than in compositing. This node
//! takes the poses Φ `[B, 6]` (differentiable; only the camera centres move a colour), the
//! scene's component rows `[9, N]` (the centres are rows 0–2) and SH coefficients `[N, K, 3]`
//! (constants, uploaded once per scene) and the projection's plan (which Gaussian each row
//! shows to which pose), and returns each row's RGB `[R, 3]`. Its backward returns d L/dΦ
//! `[B, 6]` directly. The rules are the tensor path's (f64: the same values and gradients to
//! rounding, `tests/fused_colours.rs`).
//!
//! Backends: on Flex the kernels ([`cpu`]) read the scene in place and run in parallel over
//! chunks of rows; ndarray copies it first. On `Cube` (wgpu) the same rules run as CubeCL
//! kernels (`cube`), one unit per row, the per-pose sums by a fixed tree.

pub mod cpu;
#[cfg(feature = "wgpu")]
pub mod cube;

use std::sync::Arc;

use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, TensorMetadata, backend_extension};
use burn::tensor::{DType, Tensor, TensorData};

use super::projection::{HostFloat, HostView, ProjectionPlan};
use crate::project::SceneTensors;
use crate::sh::ShTensors;

/// The fused colours, dispatched to the backend a tensor lives on.
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Cube: cfg(feature = "wgpu"),
    Autodiff
)]
pub trait FusedColours: Backend {
    /// The RGB `[R, 3]` of the plan's rows seen from `poses` `[B, 6]`, reading the scene's
    /// `components` `[9, N]` and SH `coeffs` `[N, K, 3]`.
    fn fused_colours(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> FloatTensor<Self>;
}

/// Forward and backward kernels of a base (non-autodiff) backend.
pub trait ColourKernels: Backend {
    /// What the forward pass keeps for the backward pass.
    type Saved: Clone + Send + Sync + std::fmt::Debug + 'static;

    /// The colours `[R, 3]` and the state the backward needs.
    fn colours_forward(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// d L/dΦ `[B, 6]` from the colours' gradient `[R, 3]`.
    fn colours_backward(saved: Self::Saved, v_colours: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// What the host kernels keep for the backward: the poses as read, the scene's handles (no
/// copy) and the plan.
#[derive(Debug, Clone)]
pub struct HostSaved<B: Backend> {
    poses: Arc<Vec<f64>>,
    components: FloatTensor<B>,
    coeffs: FloatTensor<B>,
    plan: Arc<ProjectionPlan>,
}

/// Runs `f` on the host views of `components` and `coeffs` in the float type `E`.
fn with_rows<B: HostView, E: HostFloat, R>(
    components: &FloatTensor<B>,
    coeffs: &FloatTensor<B>,
    f: impl FnOnce(cpu::ShRows<'_, E>) -> R,
) -> R {
    let basis = coeffs.shape().dims::<3>()[1];
    B::with_host::<E, _>(components, |components| {
        B::with_host::<E, _>(coeffs, |coeffs| {
            f(cpu::ShRows {
                components,
                coeffs,
                basis,
            })
        })
    })
}

/// [`ColourKernels::colours_forward`] through the host kernels.
pub fn host_forward<B: HostView>(
    poses: FloatTensor<B>,
    components: FloatTensor<B>,
    coeffs: FloatTensor<B>,
    plan: Arc<ProjectionPlan>,
) -> (FloatTensor<B>, HostSaved<B>) {
    let device = poses.device();
    let dtype = components.dtype();
    let host_poses = super::read::<B, f64>(poses);
    let shape = vec![plan.rows.total(), 3];
    let colours = if dtype == DType::F64 {
        let colours = with_rows::<B, f64, _>(&components, &coeffs, |scene| {
            cpu::forward(&host_poses, scene, &plan)
        });
        B::float_from_data(TensorData::new(colours, shape), &device)
    } else {
        let colours = with_rows::<B, f32, _>(&components, &coeffs, |scene| {
            cpu::forward(&host_poses, scene, &plan)
        });
        B::float_from_data(
            TensorData::new(colours, shape).convert_dtype(dtype),
            &device,
        )
    };
    let saved = HostSaved {
        poses: Arc::new(host_poses),
        components,
        coeffs,
        plan,
    };
    (colours, saved)
}

/// [`ColourKernels::colours_backward`] through the host kernels.
pub fn host_backward<B: HostView>(
    saved: HostSaved<B>,
    v_colours: FloatTensor<B>,
) -> FloatTensor<B> {
    let device = v_colours.device();
    let dtype = v_colours.dtype();
    fn run<B: HostView, E: HostFloat>(saved: &HostSaved<B>, v_colours: FloatTensor<B>) -> Vec<f64> {
        let v_colours = super::read::<B, E>(v_colours);
        with_rows::<B, E, _>(&saved.components, &saved.coeffs, |scene| {
            cpu::backward(&saved.poses, scene, &saved.plan, &v_colours)
        })
    }
    let v_poses = if dtype == DType::F64 {
        run::<B, f64>(&saved, v_colours)
    } else {
        run::<B, f32>(&saved, v_colours)
    };
    let batch = saved.poses.len() / 6;
    B::float_from_data(
        TensorData::new(v_poses, [batch, 6]).convert_dtype(dtype),
        &device,
    )
}

/// Implements the kernels and the (non-autodiff) operation of a backend with the host kernels.
macro_rules! host_colours {
    ($backend:ty) => {
        impl ColourKernels for $backend {
            type Saved = HostSaved<$backend>;

            fn colours_forward(
                poses: FloatTensor<Self>,
                components: FloatTensor<Self>,
                coeffs: FloatTensor<Self>,
                plan: Arc<ProjectionPlan>,
            ) -> (FloatTensor<Self>, Self::Saved) {
                host_forward::<Self>(poses, components, coeffs, plan)
            }

            fn colours_backward(
                saved: Self::Saved,
                v_colours: FloatTensor<Self>,
            ) -> FloatTensor<Self> {
                host_backward::<Self>(saved, v_colours)
            }
        }

        impl FusedColours for $backend {
            fn fused_colours(
                poses: FloatTensor<Self>,
                components: FloatTensor<Self>,
                coeffs: FloatTensor<Self>,
                plan: Arc<ProjectionPlan>,
            ) -> FloatTensor<Self> {
                Self::colours_forward(poses, components, coeffs, plan).0
            }
        }
    };
}

#[cfg(feature = "flex")]
host_colours!(burn::backend::Flex);
#[cfg(feature = "ndarray")]
#[allow(deprecated)]
mod ndarray_kernels {
    use super::*;
    host_colours!(burn::backend::NdArray);
}

/// The backward step of the colours node.
#[derive(Debug)]
struct ColoursBackward;

impl<B: ColourKernels> Backward<B, 1> for ColoursBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let v_colours = grads.consume::<B>(&ops.node);
        let started = std::time::Instant::now();
        let v_poses = B::colours_backward(ops.state, v_colours);
        crate::stages::add(crate::stages::Stage::ProjectBackward, started.elapsed());
        let [poses] = ops.parents;
        if let Some(node) = poses {
            grads.register::<B>(node.id, v_poses);
        }
    }
}

impl<B: ColourKernels, C: CheckpointStrategy> FusedColours for Autodiff<B, C> {
    fn fused_colours(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> FloatTensor<Self> {
        let nodes = [poses.node()];
        let poses = poses.into_primitive();
        // The scene is a constant of the pass: no gradient flows to it.
        let components = components.into_primitive();
        let coeffs = coeffs.into_primitive();
        match ColoursBackward
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (colours, saved) = B::colours_forward(poses, components, coeffs, plan);
                prep.finish(saved, colours)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::colours_forward(poses, components, coeffs, plan).0)
            }
        }
    }
}

/// The RGB `[R, 3]` of the plan's rows (Gaussians by their index into `scene`, pose after
/// pose) seen from `poses` `[B, 6]`: max(0, 0.5 + Σ_k basis_k(d) · coeff_k), d the unit vector
/// from the camera centre to the mean, as [`crate::sh::sh_colours_of_rows`] computes it;
/// differentiable in the poses' centres. Panics when the plan's poses are not B or the
/// degree is above 3 (a caller's bug).
pub fn colours_of_rows(
    scene: &SceneTensors,
    sh: &ShTensors,
    poses: Tensor<2>,
    plan: impl Into<Arc<ProjectionPlan>>,
) -> Tensor<2> {
    let plan = plan.into();
    let [batch, _] = poses.dims();
    assert_eq!(plan.rows.batch(), batch, "a colour plan for another batch");
    assert_eq!(
        plan.gaussians.len(),
        plan.rows.total(),
        "a colour plan names a Gaussian for each row"
    );
    // Scenes are validated to degree ≤ 3; the kernels hold at most 16 basis functions.
    let basis = sh.coeffs.dims()[1];
    assert!(
        [1, 4, 9, 16].contains(&basis),
        "SH coefficients of degree 0 to 3, not {basis} a channel"
    );
    Tensor::<2>::from_dispatch(<Dispatch as FusedColours>::fused_colours(
        poses.into_dispatch(),
        scene.components.clone().into_dispatch(),
        sh.coeffs.clone().into_dispatch(),
        plan,
    ))
}
