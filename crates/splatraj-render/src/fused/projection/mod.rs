//! The fused projection: Gaussians → screen space for a batch of poses as one burn operation
//! with its own backward, like the fused compositing.
//!
//! The tensor projection (`crate::project`) is about sixty burn ops forward and twice as many
//! in its autodiff backward, each a kernel launch and a graph node on a GPU, each a full pass
//! over `[B, U]` values on the CPU. This node takes the poses Φ `[B, 6]` and the zoom s `[B]`
//! (the differentiable inputs; pose b is seen with fx·s_b, fy·s_b), the scene's component
//! rows `[9, N]` and opacities `[N]` (constants, uploaded once per scene) and a plan saying
//! which Gaussian each row projects for which pose (pose after pose, [`crate::rows`]), and
//! returns what compositing needs, packed per row as `[R, 7]`: (u, v, conic a, b, c, opacity,
//! camera z); see [`PackedColumn`]. Its
//! backward returns d L/dΦ `[B, 6]` and d L/ds `[B]` directly: per row the gradient through
//! the camera's axes, centre and zoom, summed per pose, then through Rodrigues' derivative.
//! The rules, order of operations and clamp conventions are the tensor projection's (f64:
//! same values and gradients to rounding, `tests/fused_projection.rs`, `tests/zoom.rs`).
//!
//! Backends: on Flex the kernels ([`cpu`]) read the scene's rows in place (no copy) and run
//! in parallel over chunks of rows; ndarray copies them first. On `Cube` (wgpu) the same
//! rules run as CubeCL kernels (`cube`), one unit per row, the per-pose sums by a fixed tree
//! in shared memory.

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

use super::real::Real;
use crate::camera::Intrinsics;
use crate::project::{FOV_CLAMP, SceneTensors};
use crate::rows::PoseRows;

/// Values per packed row.
pub const SPLAT_COLUMNS: usize = 7;

/// The columns of a packed row, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackedColumn {
    /// Projected mean u, pixels (not clamped).
    MeanX = 0,
    /// Projected mean v, pixels.
    MeanY = 1,
    /// Conic a (inverse 2D covariance [[a, b], [b, c]]).
    ConicA = 2,
    /// Conic b.
    ConicB = 3,
    /// Conic c.
    ConicC = 4,
    /// Opacity (a scene constant, carried so compositing reads one row).
    Opacity = 5,
    /// Camera z, unclamped (what the depth channel composites).
    Depth = 6,
}

/// The camera constants a projection reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectionCamera {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// tan of half the horizontal field of view.
    pub tan_x: f64,
    /// tan of half the vertical field of view.
    pub tan_y: f64,
    /// Near plane: divisions use z clamped to at least this.
    pub near: f64,
}

impl ProjectionCamera {
    /// The constants of `intrinsics` with near plane `near`.
    pub fn new(intrinsics: &Intrinsics, near: f64) -> Self {
        let (tan_x, tan_y) = intrinsics.tan_half_fov();
        ProjectionCamera {
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            tan_x,
            tan_y,
            near,
        }
    }

    /// The Jacobian's clamp of x/z and y/z: ±[`FOV_CLAMP`]·tan(half fov).
    pub fn limits(&self) -> (f64, f64) {
        (FOV_CLAMP * self.tan_x, FOV_CLAMP * self.tan_y)
    }
}

/// The integer side of a projection: which Gaussian each row projects, for which pose, seen
/// through which camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectionPlan {
    /// Scene index of the Gaussian each row projects. `[R]`
    pub gaussians: Vec<u32>,
    /// Which rows each pose owns ([`crate::rows`]: in a render, only the Gaussians its tile
    /// lists read).
    pub rows: PoseRows,
    /// The camera.
    pub camera: ProjectionCamera,
    /// The row table once uploaded to a GPU.
    device_rows: DeviceRows,
}

impl ProjectionPlan {
    /// Pose b projects the Gaussians `gaussians[rows.range(b)]` (scene indices) through
    /// `camera`.
    pub fn new(gaussians: Vec<u32>, rows: PoseRows, camera: ProjectionCamera) -> Self {
        ProjectionPlan {
            gaussians,
            rows,
            camera,
            device_rows: DeviceRows::default(),
        }
    }

    /// Every one of `batch` poses projects each of `used` (scene indices): row b·U + u.
    pub fn dense(used: &[u32], batch: usize, camera: ProjectionCamera) -> Self {
        Self::new(
            (0..batch).flat_map(|_| used.iter().copied()).collect(),
            PoseRows::dense(batch, used.len()),
            camera,
        )
    }
}

/// A plan's row table uploaded to a GPU the first time one of its ops reads it, so that an
/// RGB pass's projection and colours upload it once (`cube::upload_rows`). A cache, not part
/// of what the plan says: plans compare equal whatever it holds.
#[derive(Debug, Clone, Default)]
struct DeviceRows {
    /// Each row's Gaussian `[R]` and each pose's first row, then R, `[B + 1]`.
    #[cfg(feature = "wgpu")]
    uploaded: std::sync::OnceLock<(
        burn_cubecl::tensor::CubeTensor,
        burn_cubecl::tensor::CubeTensor,
    )>,
}

impl PartialEq for DeviceRows {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// The fused projection, dispatched to the backend a tensor lives on.
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Cube: cfg(feature = "wgpu"),
    Autodiff
)]
pub trait FusedProjection: Backend {
    /// The packed rows `[R, 7]` of the plan's rows seen from `poses` `[B, 6]` through the plan's
    /// camera zoomed by `zoom` `[B]`, reading the scene's `components` `[9, N]` and
    /// `opacities` `[N]`.
    fn fused_project(
        poses: FloatTensor<Self>,
        zoom: FloatTensor<Self>,
        components: FloatTensor<Self>,
        opacities: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> FloatTensor<Self>;
}

/// Forward and backward kernels of a base (non-autodiff) backend.
pub trait ProjectionKernels: Backend {
    /// What the forward pass keeps for the backward pass.
    type Saved: Clone + Send + Sync + std::fmt::Debug + 'static;

    /// The packed rows `[R, 7]` and the state the backward needs.
    fn projection_forward(
        poses: FloatTensor<Self>,
        zoom: FloatTensor<Self>,
        components: FloatTensor<Self>,
        opacities: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved);

    /// d L/dΦ `[B, 6]` and d L/ds `[B]` from the gradient of the packed rows.
    fn projection_backward(
        saved: Self::Saved,
        v_rows: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>);
}

/// The float types the host kernels run in, as burn elements and plain bytes.
pub trait HostFloat: Real + burn::tensor::Element + bytemuck::Pod {}
impl HostFloat for f32 {}
impl HostFloat for f64 {}

/// Host access to a backend's float tensors.
pub trait HostView: Backend {
    /// Calls `f` with the values of `t` as `E` on the host: in place where the backend keeps
    /// them there contiguously in that type, else from a copy.
    fn with_host<E: HostFloat, R>(t: &FloatTensor<Self>, f: impl FnOnce(&[E]) -> R) -> R {
        f(&super::read::<Self, E>(t.clone()))
    }
}

#[cfg(feature = "flex")]
impl HostView for burn::backend::Flex {
    fn with_host<E: HostFloat, R>(t: &FloatTensor<Self>, f: impl FnOnce(&[E]) -> R) -> R {
        // The scene's rows are hundreds of megabytes on a large capture: read them where they
        // are. `as_slice` declines (None) a non-contiguous tensor or another dtype.
        match t.as_slice::<E>() {
            Some(values) => f(values),
            None => f(&super::read::<Self, E>(t.clone())),
        }
    }
}

#[cfg(feature = "ndarray")]
#[allow(deprecated)] // burn deprecates ndarray; it stays our second CPU backend for the tests
impl HostView for burn::backend::NdArray {}

/// What the host kernels keep for the backward: the poses and zooms as read, the scene's
/// handles (no copy) and the plan.
#[derive(Debug, Clone)]
pub struct HostSaved<B: Backend> {
    poses: Arc<Vec<f64>>,
    zoom: Arc<Vec<f64>>,
    components: FloatTensor<B>,
    opacities: FloatTensor<B>,
    plan: Arc<ProjectionPlan>,
}

/// [`ProjectionKernels::projection_forward`] through the host kernels.
pub fn host_forward<B: HostView>(
    poses: FloatTensor<B>,
    zoom: FloatTensor<B>,
    components: FloatTensor<B>,
    opacities: FloatTensor<B>,
    plan: Arc<ProjectionPlan>,
) -> (FloatTensor<B>, HostSaved<B>) {
    let device = poses.device();
    let dtype = components.dtype();
    let host_poses = super::read::<B, f64>(poses);
    let host_zoom = super::read::<B, f64>(zoom);
    let shape = vec![plan.rows.total(), SPLAT_COLUMNS];
    fn run<B: HostView, E: HostFloat>(
        poses: &[f64],
        zoom: &[f64],
        components: &FloatTensor<B>,
        opacities: &FloatTensor<B>,
        plan: &ProjectionPlan,
    ) -> Vec<E> {
        B::with_host::<E, _>(components, |components| {
            B::with_host::<E, _>(opacities, |opacities| {
                let scene = cpu::SceneRows {
                    components,
                    opacities,
                };
                cpu::forward(poses, zoom, scene, plan)
            })
        })
    }
    let rows = if dtype == DType::F64 {
        let rows = run::<B, f64>(&host_poses, &host_zoom, &components, &opacities, &plan);
        B::float_from_data(TensorData::new(rows, shape), &device)
    } else {
        let rows = run::<B, f32>(&host_poses, &host_zoom, &components, &opacities, &plan);
        B::float_from_data(TensorData::new(rows, shape).convert_dtype(dtype), &device)
    };
    let saved = HostSaved {
        poses: Arc::new(host_poses),
        zoom: Arc::new(host_zoom),
        components,
        opacities,
        plan,
    };
    (rows, saved)
}

/// [`ProjectionKernels::projection_backward`] through the host kernels.
pub fn host_backward<B: HostView>(
    saved: HostSaved<B>,
    v_rows: FloatTensor<B>,
) -> (FloatTensor<B>, FloatTensor<B>) {
    let device = v_rows.device();
    let dtype = v_rows.dtype();
    fn run<B: HostView, E: HostFloat>(
        saved: &HostSaved<B>,
        v_rows: FloatTensor<B>,
    ) -> (Vec<f64>, Vec<f64>) {
        let v_rows = super::read::<B, E>(v_rows);
        B::with_host::<E, _>(&saved.components, |components| {
            B::with_host::<E, _>(&saved.opacities, |opacities| {
                let scene = cpu::SceneRows {
                    components,
                    opacities,
                };
                cpu::backward(&saved.poses, &saved.zoom, scene, &saved.plan, &v_rows)
            })
        })
    }
    let (v_poses, v_zoom) = if dtype == DType::F64 {
        run::<B, f64>(&saved, v_rows)
    } else {
        run::<B, f32>(&saved, v_rows)
    };
    let batch = saved.poses.len() / 6;
    (
        B::float_from_data(
            TensorData::new(v_poses, [batch, 6]).convert_dtype(dtype),
            &device,
        ),
        B::float_from_data(
            TensorData::new(v_zoom, [batch]).convert_dtype(dtype),
            &device,
        ),
    )
}

/// Implements the kernels and the (non-autodiff) operation of a backend with the host kernels.
macro_rules! host_projection {
    ($backend:ty) => {
        impl ProjectionKernels for $backend {
            type Saved = HostSaved<$backend>;

            fn projection_forward(
                poses: FloatTensor<Self>,
                zoom: FloatTensor<Self>,
                components: FloatTensor<Self>,
                opacities: FloatTensor<Self>,
                plan: Arc<ProjectionPlan>,
            ) -> (FloatTensor<Self>, Self::Saved) {
                host_forward::<Self>(poses, zoom, components, opacities, plan)
            }

            fn projection_backward(
                saved: Self::Saved,
                v_rows: FloatTensor<Self>,
            ) -> (FloatTensor<Self>, FloatTensor<Self>) {
                host_backward::<Self>(saved, v_rows)
            }
        }

        impl FusedProjection for $backend {
            fn fused_project(
                poses: FloatTensor<Self>,
                zoom: FloatTensor<Self>,
                components: FloatTensor<Self>,
                opacities: FloatTensor<Self>,
                plan: Arc<ProjectionPlan>,
            ) -> FloatTensor<Self> {
                Self::projection_forward(poses, zoom, components, opacities, plan).0
            }
        }
    };
}

#[cfg(feature = "flex")]
host_projection!(burn::backend::Flex);
#[cfg(feature = "ndarray")]
#[allow(deprecated)]
mod ndarray_kernels {
    use super::*;
    host_projection!(burn::backend::NdArray);
}

/// The backward step of the projection node.
#[derive(Debug)]
struct ProjectionBackward;

impl<B: ProjectionKernels> Backward<B, 2> for ProjectionBackward {
    type State = B::Saved;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let v_rows = grads.consume::<B>(&ops.node);
        let started = std::time::Instant::now();
        let (v_poses, v_zoom) = B::projection_backward(ops.state, v_rows);
        crate::stages::add(crate::stages::Stage::ProjectBackward, started.elapsed());
        let [poses, zoom] = ops.parents;
        if let Some(node) = poses {
            grads.register::<B>(node.id, v_poses);
        }
        // An untracked zoom (a render without one gets ones) has no parent: nothing to register.
        if let Some(node) = zoom {
            grads.register::<B>(node.id, v_zoom);
        }
    }
}

impl<B: ProjectionKernels, C: CheckpointStrategy> FusedProjection for Autodiff<B, C> {
    fn fused_project(
        poses: FloatTensor<Self>,
        zoom: FloatTensor<Self>,
        components: FloatTensor<Self>,
        opacities: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> FloatTensor<Self> {
        let nodes = [poses.node(), zoom.node()];
        let poses = poses.into_primitive();
        let zoom = zoom.into_primitive();
        // The scene is a constant of the pass: no gradient flows to it.
        let components = components.into_primitive();
        let opacities = opacities.into_primitive();
        match ProjectionBackward
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (rows, saved) = B::projection_forward(poses, zoom, components, opacities, plan);
                prep.finish(saved, rows)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::projection_forward(poses, zoom, components, opacities, plan).0)
            }
        }
    }
}

/// The packed rows `[R, 7]` of the plan's rows (Gaussians by their index into `scene`, pose
/// after pose) seen from `poses` `[B, 6]`; differentiable in the poses. Columns:
/// [`PackedColumn`]. Panics when the plan's poses are not B or it does not name a Gaussian for
/// each of its rows (a caller's bug).
pub fn project_packed(scene: &SceneTensors, poses: Tensor<2>, plan: ProjectionPlan) -> Tensor<2> {
    project_packed_zoomed(scene, poses, None, plan)
}

/// [`project_packed`] through the plan's camera zoomed per pose by `zoom` `[B]` (s > 0: fx·s,
/// fy·s about the fixed principal point; `None`: s = 1); differentiable in the poses and the
/// zoom. The plan may come shared (`Arc`), so a caller keeps reading its row table without a
/// copy.
pub fn project_packed_zoomed(
    scene: &SceneTensors,
    poses: Tensor<2>,
    zoom: Option<Tensor<1>>,
    plan: impl Into<Arc<ProjectionPlan>>,
) -> Tensor<2> {
    let plan = plan.into();
    let [batch, _] = poses.dims();
    assert_eq!(
        plan.rows.batch(),
        batch,
        "a projection plan for another batch"
    );
    // The GPU kernels index the table by row without a bounds check.
    assert_eq!(
        plan.gaussians.len(),
        plan.rows.total(),
        "a projection plan names a Gaussian for each row"
    );
    // Without a zoom the kernels read ones: B values up, no launch, and no autodiff parent.
    let zoom = match zoom {
        Some(zoom) if zoom.dtype() == scene.components.dtype() => zoom,
        Some(zoom) => zoom.cast(scene.components.dtype()),
        None => {
            crate::counters::upload(batch * scene.components.dtype().size());
            Tensor::<1>::from_data(
                TensorData::new(vec![1.0f64; batch], [batch]),
                (&poses.device(), scene.components.dtype()),
            )
        }
    };
    Tensor::<2>::from_dispatch(<Dispatch as FusedProjection>::fused_project(
        poses.into_dispatch(),
        zoom.into_dispatch(),
        scene.components.clone().into_dispatch(),
        scene.opacities.clone().into_dispatch(),
        plan,
    ))
}
