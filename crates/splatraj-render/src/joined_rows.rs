//! A tensor cut into consecutive row ranges (along its first axis), the parts' gradients
//! joined by one node.
//!
//! Why: burn differentiates each cut (`narrow`) into a zero fill of the whole tensor and a
//! slice assignment, and adds the cuts' gradients into the whole: on a GPU each of those is a
//! kernel launch. Here each part's backward only leaves its gradient with the others (a
//! shared slot), and one node between the whole and its parts concatenates them, a part that
//! got no gradient as zeros. burn-autodiff runs a backward by depth, deepest first, so every
//! part's step runs before the joining node's.

use std::any::Any;
use std::fmt;
use std::ops::Range;
use std::sync::{Arc, Mutex};

use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, TensorMetadata, backend_extension};
use burn::tensor::{Shape, Slice, Tensor};

/// The parts of one cut and what their backward steps leave for the joining node.
pub struct Joint {
    /// Each part's rows, consecutive from 0 to the whole's.
    parts: Vec<Range<usize>>,
    /// The joining node's tensor (an autodiff tensor of the backend) while the parts are made;
    /// then each part's gradient as its backward leaves it, and whether the joining node has
    /// been handed one to start from.
    state: Mutex<JointState>,
}

#[derive(Default)]
struct JointState {
    join: Option<Box<dyn Any + Send>>,
    gradients: Vec<Option<Box<dyn Any + Send>>>,
    handed: bool,
}

impl fmt::Debug for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Joint").field("parts", &self.parts).finish()
    }
}

impl Joint {
    fn lock(&self) -> std::sync::MutexGuard<'_, JointState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The slices of part `part` of a tensor of rank `rank`.
    fn slices(&self, part: usize, rank: usize) -> Vec<Slice> {
        let rows = &self.parts[part];
        let mut slices = vec![Slice::full(); rank];
        slices[0] = Slice::new(rows.start as isize, Some(rows.end as isize), 1);
        slices
    }
}

/// The parts of a joined cut, dispatched to the backend a tensor lives on.
#[backend_extension(
    Flex: cfg(feature = "flex"),
    NdArray: cfg(feature = "ndarray"),
    Cube: cfg(feature = "wgpu"),
    Autodiff
)]
pub trait JoinedRows: Backend {
    /// Rows `joint`'s part `part` of `whole`.
    fn joined_part(whole: FloatTensor<Self>, joint: Arc<Joint>, part: usize) -> FloatTensor<Self>;
}

/// [`JoinedRows::joined_part`] of a backend without autodiff: a slice.
fn slice_part<B: Backend>(whole: FloatTensor<B>, joint: &Joint, part: usize) -> FloatTensor<B> {
    let rank = whole.shape().num_dims();
    B::float_slice(whole, &joint.slices(part, rank))
}

/// Implements [`JoinedRows`] for backends without autodiff: [`slice_part`].
macro_rules! sliced_parts {
    ($($(#[$attr:meta])* $backend:ty;)*) => {$(
        $(#[$attr])*
        impl JoinedRows for $backend {
            fn joined_part(
                whole: FloatTensor<Self>,
                joint: Arc<Joint>,
                part: usize,
            ) -> FloatTensor<Self> {
                slice_part::<Self>(whole, &joint, part)
            }
        }
    )*};
}

sliced_parts! {
    #[cfg(feature = "flex")]
    burn::backend::Flex;
    #[cfg(feature = "ndarray")]
    #[allow(deprecated)]
    burn::backend::NdArray;
    #[cfg(feature = "wgpu")]
    burn::backend::Cube;
}

/// A part's backward step: leaves its gradient with the joint; the first hands the joining
/// node a gradient to start from (never read), so that its step runs.
#[derive(Debug)]
struct PartBackward;

impl<B: Backend> Backward<B, 1> for PartBackward {
    type State = (Arc<Joint>, usize);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let v_part = grads.consume::<B>(&ops.node);
        let (joint, part) = ops.state;
        let first = {
            let mut state = joint.lock();
            state.gradients[part] = Some(Box::new(v_part.clone()));
            !std::mem::replace(&mut state.handed, true)
        };
        if let ([Some(join)], true) = (ops.parents, first) {
            grads.register::<B>(join.id, v_part);
        }
    }
}

/// The joining node's backward step: the parts' gradients concatenated, zeros for a part
/// that got none.
#[derive(Debug)]
struct JoinBackward;

impl<B: Backend> Backward<B, 1> for JoinBackward {
    type State = (Arc<Joint>, Shape);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        // What the first part handed over stands for them all.
        let handed = grads.consume::<B>(&ops.node);
        let (joint, shape) = ops.state;
        let (device, dtype) = (handed.device(), handed.dtype());
        let gradients = std::mem::take(&mut joint.lock().gradients);
        let pieces: Vec<FloatTensor<B>> = gradients
            .into_iter()
            .zip(&joint.parts)
            .map(|(gradient, rows)| match gradient {
                Some(g) => *g
                    .downcast::<FloatTensor<B>>()
                    .expect("a part's gradient is of its backend"),
                None => {
                    let mut dims: Vec<usize> = shape.iter().copied().collect();
                    dims[0] = rows.len();
                    B::float_zeros(Shape::from(dims), &device, dtype.into())
                }
            })
            .collect();
        let v_whole = if pieces.len() == 1 {
            pieces.into_iter().next().expect("one piece")
        } else {
            B::float_cat(pieces, 0)
        };
        if let [Some(whole)] = ops.parents {
            grads.register::<B>(whole.id, v_whole);
        }
    }
}

impl<B: Backend, C: CheckpointStrategy> JoinedRows for Autodiff<B, C> {
    fn joined_part(whole: FloatTensor<Self>, joint: Arc<Joint>, part: usize) -> FloatTensor<Self> {
        let join: FloatTensor<Self> = {
            let mut state = joint.lock();
            match &state.join {
                Some(join) => join
                    .downcast_ref::<FloatTensor<Self>>()
                    .expect("a joint's node is of its backend")
                    .clone(),
                None => {
                    let shape = whole.shape();
                    let nodes = [whole.node()];
                    let primitive = whole.into_primitive();
                    let join = match JoinBackward.prepare::<C>(nodes).compute_bound().stateful() {
                        OpsKind::Tracked(prep) => prep.finish((joint.clone(), shape), primitive),
                        OpsKind::UnTracked(prep) => prep.finish(primitive),
                    };
                    state.join = Some(Box::new(join.clone()));
                    join
                }
            }
        };
        let rank = join.shape().num_dims();
        let slices = joint.slices(part, rank);
        let nodes = [join.node()];
        let primitive = join.into_primitive();
        match PartBackward.prepare::<C>(nodes).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                prep.finish((joint.clone(), part), B::float_slice(primitive, &slices))
            }
            OpsKind::UnTracked(prep) => prep.finish(B::float_slice(primitive, &slices)),
        }
    }
}

/// `whole` `[N, …]` cut into consecutive parts of `rows` rows each (summing to N), whose
/// gradients reach `whole` through one concatenation (module docs). Panics when the rows do
/// not sum to N (a caller's bug).
pub fn cut_rows<const D: usize>(whole: Tensor<D>, rows: &[usize]) -> Vec<Tensor<D>> {
    let total = whole.dims()[0];
    assert_eq!(rows.iter().sum::<usize>(), total, "parts of {total} rows");
    let mut start = 0;
    let parts = rows
        .iter()
        .map(|&count| {
            start += count;
            start - count..start
        })
        .collect::<Vec<_>>();
    let joint = Arc::new(Joint {
        state: Mutex::new(JointState {
            gradients: parts.iter().map(|_| None).collect(),
            ..JointState::default()
        }),
        parts,
    });
    let cut = (0..rows.len())
        .map(|part| {
            Tensor::from_dispatch(<Dispatch as JoinedRows>::joined_part(
                whole.clone().into_dispatch(),
                joint.clone(),
                part,
            ))
        })
        .collect();
    // The joining node's tensor was needed only to make the parts: kept, it would hold the
    // whole's buffer until the backward.
    joint.lock().join = None;
    cut
}

#[cfg(test)]
mod tests {
    use burn::tensor::{DType, Tensor, TensorData};

    use super::cut_rows;
    use crate::backend::BackendKind;

    /// The parts are the rows they name, and the whole's gradient is what cuts by `narrow`
    /// give: each part's gradient in its rows, zeros in the rows of a part no loss read.
    #[test]
    fn parts_and_their_joined_gradient_are_narrows() {
        let device = BackendKind::Flex.device().unwrap().autodiff();
        let values: Vec<f64> = (0..6 * 2 * 3).map(|i| (i as f64 * 0.37).sin()).collect();
        let leaf = || {
            Tensor::<3>::from_data(
                TensorData::new(values.clone(), [6, 2, 3]),
                (&device, DType::F64),
            )
            .require_grad()
        };
        // Rows 0–1, 2–4 (read by no loss) and 5.
        let counts = [2, 3, 1];
        let weights = |rows: usize, seed: f64| {
            let w: Vec<f64> = (0..rows * 6).map(|i| seed + i as f64).collect();
            Tensor::<3>::from_data(TensorData::new(w, [rows, 2, 3]), (&device, DType::F64))
        };
        let loss_of = |parts: &[Tensor<3>]| {
            (parts[0].clone() * weights(2, 0.5)).sum()
                + (parts[2].clone().powf_scalar(2.0) * weights(1, -3.0)).sum()
        };

        let whole = leaf();
        let joined = cut_rows(whole.clone(), &counts);
        let narrowed_whole = leaf();
        let mut first = 0;
        let narrowed: Vec<Tensor<3>> = counts
            .iter()
            .map(|&n| {
                first += n;
                narrowed_whole.clone().narrow(0, first - n, n)
            })
            .collect();
        for (j, n) in joined.iter().zip(&narrowed) {
            assert_eq!(j.dims(), n.dims());
            let (j, n): (Vec<f64>, Vec<f64>) = (
                j.clone().into_data().try_to_vec::<f64>().unwrap(),
                n.clone().into_data().try_to_vec::<f64>().unwrap(),
            );
            assert_eq!(j, n);
        }
        let got: Vec<f64> = whole
            .grad(&loss_of(&joined).backward())
            .expect("a gradient")
            .into_data()
            .try_to_vec::<f64>()
            .unwrap();
        let want: Vec<f64> = narrowed_whole
            .grad(&loss_of(&narrowed).backward())
            .expect("a gradient")
            .into_data()
            .try_to_vec::<f64>()
            .unwrap();
        assert_eq!(got, want);
        assert!(
            got[2 * 6..5 * 6].iter().all(|&g| g == 0.0),
            "the unread part's rows"
        );
        assert!(got[..2 * 6].iter().all(|&g| g != 0.0), "{got:?}");
    }
}
