//! A cost of the poses alone, computed on the host, joined to the optimisation graph by its
//! first-order expansion about the poses it was computed at.
//!
//! Some costs read nothing but the poses: their arithmetic is a few small loops over a few
//! hundred poses (the motion limits' rates along the path). As burn ops each loop becomes
//! slices, differences, reductions and their backward, each a kernel launch on a GPU: the
//! motion cost alone was 139 of a first-try step's 349 launches on wgpu (docs/gpu.md, "Costs
//! on the host"). An optimisation step reads its poses to the host anyway (the renderer
//! decides and bins there), so such a cost is computed there in f64, value and gradient by
//! hand, and enters the graph as
//!
//! ```text
//! L_w(Φ) = L_w(Φ₀) + G_w · (Φ − Φ₀),   G_w = ∂L_w/∂Φ at Φ₀
//! ```
//!
//! a difference, a product and a sum (a handful of launches forward and backward, three small
//! uploads), whatever the cost computes. At Φ = Φ₀, which is where a step evaluates it (Φ₀ are
//! Φ's own values read back), this has the cost's value and the cost's gradient exactly, and
//! that is all gradient descent reads; the expansion is never evaluated anywhere else.

use burn::tensor::{Tensor, TensorData};
use splatraj_render::host::upload;

use super::{CostError, CostInputs, PathStretch, QueryContext};

/// The gradients of host values in the poses, by which poses each value reads.
#[derive(Debug, Clone, PartialEq)]
pub enum PoseGradients {
    /// Value b reads pose b alone (a cost per sample): its gradient `[B, 6]`.
    OwnPose(Vec<f64>),
    /// Each value may read every pose (a cost per window's stretch of path): value w's
    /// gradient in all of them `[W, P·6]`, pose after pose.
    AllPoses(Vec<f64>),
}

/// `values` `[W]` (each computed on the host at the poses `at` `[P]`) as a graph value of
/// `poses` `[P, 6]`: `values + G·(poses − at)` `[W]`, G the `gradients` (ω then c in each
/// pose's six). `at` must be the values of `poses` (read from them): then the result is
/// `values` and its gradient in `poses` is G. Mismatched lengths are a [`CostError::Shape`].
pub fn expansion_at(
    poses: &Tensor<2>,
    at: &[[f64; 6]],
    values: Vec<f64>,
    gradients: PoseGradients,
) -> Result<Tensor<1>, CostError> {
    let [count, _] = poses.dims();
    let windows = values.len();
    let expected = match &gradients {
        PoseGradients::OwnPose(g) => (windows == count).then_some(g.len() == count * 6),
        PoseGradients::AllPoses(g) => Some(g.len() == windows * count * 6),
    };
    if at.len() != count || expected != Some(true) {
        return Err(CostError::Shape(format!(
            "an expansion of {windows} values about {} host poses for {count} poses",
            at.len()
        )));
    }
    // Counted uploads, like every other the step makes.
    let (device, dtype) = (poses.device(), poses.dtype());
    let flat: Vec<f64> = at.iter().flatten().copied().collect();
    let at = upload::<2>(TensorData::new(flat, [count, 6]), &device, dtype);
    let values = upload::<1>(TensorData::new(values, [windows]), &device, dtype);
    // Zero in the forward (the poses are `at`); G's weights in the backward.
    let shift = poses.clone() - at; // [P, 6]
    Ok(match gradients {
        PoseGradients::OwnPose(gradients) => {
            let gradients = upload::<2>(TensorData::new(gradients, [count, 6]), &device, dtype);
            values + (shift * gradients).sum_dim(1).reshape([count])
        }
        PoseGradients::AllPoses(gradients) => {
            let data = TensorData::new(gradients, [windows, count * 6]);
            let gradients = upload::<2>(data, &device, dtype);
            values
                + gradients
                    .matmul(shift.reshape([count * 6, 1]))
                    .reshape([windows])
        }
    })
}

/// A cost per sample computed on the host: `form(pose, context)` gives one sample's value and
/// its gradient in its own pose (ω then c); the samples' host values come with `inputs` (read
/// here when the caller has not, a failure naming `cost`). `[B]`, as [`expansion_at`] joins it.
pub fn per_sample_on_host(
    inputs: &CostInputs,
    cost: &'static str,
    form: impl Fn(&[f64; 6], &QueryContext) -> (f64, [f64; 6]),
) -> Result<Tensor<1>, CostError> {
    let host = inputs.host_sample_poses(cost)?;
    let mut values = Vec::with_capacity(host.len());
    let mut gradients = Vec::with_capacity(6 * host.len());
    for (b, pose) in host.iter().enumerate() {
        let (value, gradient) = form(pose, inputs.sample_context(b));
        values.push(value);
        gradients.extend(gradient);
    }
    expansion_at(
        inputs.poses(),
        &host,
        values,
        PoseGradients::OwnPose(gradients),
    )
}

/// A cost per window's stretch of the path of `inputs` computed on the host: `form(stretch,
/// poses)` gives a stretch's value and its gradient in each of its poses; the path's host
/// values come with `inputs` (read here when the caller has not, a failure naming `cost`).
/// `[W]`, one value per stretch, as [`expansion_at`] joins it; a [`CostError::Shape`] without
/// a path.
pub fn per_stretch_on_host(
    inputs: &CostInputs,
    cost: &'static str,
    form: impl Fn(&PathStretch, &[[f64; 6]]) -> (f64, Vec<[f64; 6]>),
) -> Result<Tensor<1>, CostError> {
    let path = inputs.path().ok_or_else(|| {
        CostError::Shape(format!("{cost}: a cost per stretch of path without a path"))
    })?;
    let host = inputs.host_path_or_sample_poses(cost)?; // [ΣP]
    let count = host.len();
    let stretches = path.stretches();
    let mut values = Vec::with_capacity(stretches.len()); // [W]
    let mut gradients = vec![0.0; stretches.len() * count * 6]; // [W, ΣP·6]
    let mut start = 0;
    for (w, stretch) in stretches.iter().enumerate() {
        let own = host.get(start..start + stretch.rows).ok_or_else(|| {
            CostError::Shape(format!("path stretches beyond its {count} host poses"))
        })?;
        let (value, gradient) = form(stretch, own);
        if gradient.len() != stretch.rows {
            return Err(CostError::Shape(format!(
                "{} pose gradients for a stretch of {} poses",
                gradient.len(),
                stretch.rows
            )));
        }
        values.push(value);
        let at = (w * count + start) * 6;
        gradients[at..at + 6 * stretch.rows].copy_from_slice(gradient.as_flattened());
        start += stretch.rows;
    }
    expansion_at(
        &path.poses,
        &host,
        values,
        PoseGradients::AllPoses(gradients),
    )
}
