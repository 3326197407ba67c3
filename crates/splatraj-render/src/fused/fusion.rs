//! The fused ops (compositing, projection, colours, packed levels) on burn's fusion backend,
//! which is what wgpu runs on (`burn::backend::Cube` is `Fusion<CubeBackend>` with burn's
//! `fusion` feature).
//!
//! Why fusion: on a GPU an optimisation step was ~400 launches of tiny kernels besides ours
//! (the costs, Adam, the model's forward: docs/gpu.md), each a few microseconds whatever it
//! computes. Burn's fusion backend queues tensor ops and merges chains of elementwise ones into
//! single kernels. An op it does not know, like ours, joins that queue as one opaque operation:
//! it declares its outputs' shapes up front and runs the CubeCL kernels of [`super::cube`],
//! [`super::projection::cube`], [`super::colours::cube`] and [`super::levels::cube`] on the
//! inner backend's tensors when the queue reaches it. So the state a backward needs cannot be
//! returned by the forward call: the forward fills a [`Deferred`] slot when it runs, and the
//! backward, queued later on the same stream, takes it.

use std::sync::{Arc, Mutex};

use burn::backend::fusion::custom::{
    CustomOpIr, HandleContainer, OperationFn, OperationIr, StreamId, TensorIr,
};
use burn::backend::fusion::{FusionBackend, FusionRuntime, FusionTensor};
use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Cube, TensorMetadata};
use burn::tensor::{DType, Shape};
use burn_cubecl::CubeBackend;
use burn_cubecl::tensor::CubeTensor;

use super::colours::{ColourKernels, FusedColours};
use super::levels::PackedLevels;
use super::plan::CompositePlan;
use super::projection::{FusedProjection, ProjectionKernels, ProjectionPlan, SPLAT_COLUMNS};
use super::{CompositeKernels, ForwardUse, FusedComposite, SplatPrimitives};
use crate::stages::Stage;

type Runtime = <CubeBackend as FusionBackend>::FusionRuntime;
type Handles = HandleContainer<<Runtime as FusionRuntime>::FusionHandle>;

/// What an op's backward needs from its forward, filled when the fusion stream runs the
/// forward, with the shapes of the forward's inputs (the backward's outputs), known at once.
#[derive(Debug, Clone)]
pub struct Deferred<S> {
    state: Arc<Mutex<Option<S>>>,
    inputs: Vec<(Shape, DType)>,
}

impl<S> Deferred<S> {
    fn new(inputs: &[&FusionTensor<Runtime>]) -> Self {
        Self {
            state: Arc::new(Mutex::new(None)),
            inputs: inputs.iter().map(|t| (t.shape(), t.dtype())).collect(),
        }
    }

    fn put(&self, state: S) {
        *self.state.lock().unwrap_or_else(|e| e.into_inner()) = Some(state);
    }

    fn take(&self) -> S {
        self.state
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
            .expect("a fused op's backward runs after its forward on the same fusion stream")
    }
}

/// Queues `run` as one operation of the fusion stream, named `name` in its IR: when the stream
/// reaches it, `run` gets the inner backend's tensors of `inputs` (in order) and returns
/// tensors of `outputs`' shapes and dtypes (in order), which the returned lazy tensors stand
/// for. Its time is added to `stage` (where it has one) when it runs: the caller's own timer
/// sees only the queueing.
fn queue(
    name: &str,
    stage: Option<Stage>,
    inputs: Vec<FusionTensor<Runtime>>,
    outputs: Vec<(Shape, DType)>,
    run: impl Fn(Vec<CubeTensor>) -> Vec<CubeTensor> + Send + Sync + 'static,
) -> Vec<FusionTensor<Runtime>> {
    let client = inputs
        .first()
        .expect("a fused op has at least one input")
        .client
        .clone();
    let inputs: Vec<TensorIr> = inputs.into_iter().map(FusionTensor::into_ir).collect();
    let outputs: Vec<TensorIr> = outputs
        .into_iter()
        .map(|(shape, dtype)| TensorIr::uninit(client.create_empty_handle(), shape, dtype))
        .collect();
    let reads = inputs.clone();
    let writes: Vec<_> = outputs.iter().map(|t| t.id).collect();
    let operation = OperationFn(move |handles: &mut Handles| {
        let started = std::time::Instant::now();
        let tensors = reads
            .iter()
            .map(|t| handles.get_float_tensor::<CubeBackend>(t))
            .collect();
        for (id, tensor) in writes.iter().zip(run(tensors)) {
            handles.register_float_tensor::<CubeBackend>(id, tensor);
        }
        if let Some(stage) = stage {
            crate::stages::add(stage, started.elapsed());
        }
        Ok(())
    });
    let description = CustomOpIr {
        id: format!("splatraj_{name}"),
        inputs,
        outputs,
        scalars: Vec::new(),
    };
    client.register(
        StreamId::current(),
        OperationIr::Custom(description),
        operation,
    )
}

/// The two tensors of `tensors`, in order.
fn two<T>(tensors: Vec<T>) -> (T, T) {
    let mut each = tensors.into_iter();
    match (each.next(), each.next()) {
        (Some(a), Some(b)) => (a, b),
        _ => unreachable!("a fused op's closure receives the tensors it was queued with"),
    }
}

/// The one tensor of `tensors`.
fn one<T>(tensors: Vec<T>) -> T {
    tensors
        .into_iter()
        .next()
        .expect("a fused op returns the tensors it declared")
}

impl CompositeKernels for Cube {
    type Saved = Deferred<<CubeBackend as CompositeKernels>::Saved>;

    fn composite_forward(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
        used: ForwardUse,
    ) -> (FloatTensor<Self>, Self::Saved) {
        let saved = Deferred::new(&[&inputs.splats, &inputs.values]);
        let channels = inputs.values.shape().dims::<2>()[1];
        let image = Shape::from(vec![
            plan.batch(),
            plan.grid.height,
            plan.grid.width,
            plan.image_width(channels),
        ]); // [B, H, W, C + 1], or [B, H, W, C] where alpha is dropped
        let dtype = inputs.splats.dtype();
        let keep = saved.clone();
        let outputs = queue(
            "composite",
            Some(Stage::Composite),
            vec![inputs.splats, inputs.values],
            vec![(image, dtype)],
            move |tensors| {
                let (splats, values) = two(tensors);
                let (image, state) = CubeBackend::composite_forward(
                    SplatPrimitives { splats, values },
                    plan.clone(),
                    used,
                );
                keep.put(state);
                vec![image]
            },
        );
        (one(outputs), saved)
    }

    fn composite_backward(saved: Self::Saved, v_image: FloatTensor<Self>) -> SplatPrimitives<Self> {
        let outputs = saved.inputs.clone();
        let (splats, values) = two(queue(
            "composite_backward",
            Some(Stage::CompositeBackward),
            vec![v_image],
            outputs,
            move |tensors| {
                let v = CubeBackend::composite_backward(saved.take(), one(tensors));
                vec![v.splats, v.values]
            },
        ));
        SplatPrimitives { splats, values }
    }
}

impl FusedComposite for Cube {
    fn fused_composite(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
    ) -> FloatTensor<Self> {
        Self::composite_forward(inputs, plan, ForwardUse::ImageOnly).0
    }
}

impl ProjectionKernels for Cube {
    type Saved = Deferred<<CubeBackend as ProjectionKernels>::Saved>;

    fn projection_forward(
        poses: FloatTensor<Self>,
        zoom: FloatTensor<Self>,
        components: FloatTensor<Self>,
        opacities: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved) {
        // The backward's outputs are the gradients of the poses and the zooms only.
        let saved = Deferred::new(&[&poses, &zoom]);
        let rows = Shape::from(vec![plan.rows.total(), SPLAT_COLUMNS]); // [R, 7]
        let dtype = components.dtype();
        let keep = saved.clone();
        let outputs = queue(
            "projection",
            Some(Stage::Project),
            vec![poses, zoom, components, opacities],
            vec![(rows, dtype)],
            move |tensors| {
                let mut each = tensors.into_iter();
                let mut next = || each.next().expect("the four inputs it was queued with");
                let (poses, zoom, components, opacities) = (next(), next(), next(), next());
                let (rows, state) = CubeBackend::projection_forward(
                    poses,
                    zoom,
                    components,
                    opacities,
                    plan.clone(),
                );
                keep.put(state);
                vec![rows]
            },
        );
        (one(outputs), saved)
    }

    fn projection_backward(
        saved: Self::Saved,
        v_rows: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, FloatTensor<Self>) {
        let outputs = saved.inputs.clone();
        two(queue(
            "projection_backward",
            Some(Stage::ProjectBackward),
            vec![v_rows],
            outputs,
            move |tensors| {
                let (v_poses, v_zoom) =
                    CubeBackend::projection_backward(saved.take(), one(tensors));
                vec![v_poses, v_zoom]
            },
        ))
    }
}

impl FusedProjection for Cube {
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

impl ColourKernels for Cube {
    type Saved = Deferred<<CubeBackend as ColourKernels>::Saved>;

    fn colours_forward(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> (FloatTensor<Self>, Self::Saved) {
        // The backward's output is the gradient of the poses only.
        let saved = Deferred::new(&[&poses]);
        let colours = Shape::from(vec![plan.rows.total(), 3]); // [R, 3]
        let dtype = components.dtype();
        let keep = saved.clone();
        let outputs = queue(
            "colours",
            Some(Stage::Project),
            vec![poses, components, coeffs],
            vec![(colours, dtype)],
            move |tensors| {
                let mut each = tensors.into_iter();
                let mut next = || each.next().expect("the three inputs it was queued with");
                let (poses, components, coeffs) = (next(), next(), next());
                let (colours, state) =
                    CubeBackend::colours_forward(poses, components, coeffs, plan.clone());
                keep.put(state);
                vec![colours]
            },
        );
        (one(outputs), saved)
    }

    fn colours_backward(saved: Self::Saved, v_colours: FloatTensor<Self>) -> FloatTensor<Self> {
        let outputs = saved.inputs.clone();
        one(queue(
            "colours_backward",
            Some(Stage::ProjectBackward),
            vec![v_colours],
            outputs,
            move |tensors| vec![CubeBackend::colours_backward(saved.take(), one(tensors))],
        ))
    }
}

impl FusedColours for Cube {
    fn fused_colours(
        poses: FloatTensor<Self>,
        components: FloatTensor<Self>,
        coeffs: FloatTensor<Self>,
        plan: Arc<ProjectionPlan>,
    ) -> FloatTensor<Self> {
        Self::colours_forward(poses, components, coeffs, plan).0
    }
}

impl PackedLevels for Cube {
    fn packed_rgb8(images: FloatTensor<Self>) -> IntTensor<Self> {
        let [batch, height, width, _] = images.shape().dims::<4>();
        // `queue` registers its outputs as float handles: on `CubeBackend` an integer tensor
        // is the same `CubeTensor`, its dtype (I32 here) saying what it holds.
        one(queue(
            "packed_levels",
            None,
            vec![images],
            vec![(Shape::from(vec![batch, height, width]), DType::I32)],
            |tensors| vec![super::levels::cube::packed_rgb8(one(tensors))],
        ))
    }
}
