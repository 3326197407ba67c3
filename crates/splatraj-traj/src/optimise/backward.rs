//! The gradient of a loss, its forward graph handed to the device first.
//!
//! On the GPU backend burn-fusion queues ops and fuses the queue into kernels when it is
//! drained. Queued forward and backward together, a step's ops formed blocks that its search
//! composed into a cycle; burn-fusion 0.22 then runs the whole segment unfused (its
//! "[repair] falling back to unfused stream order", `BURN_FUSION_LOG=medium`), each elementwise
//! op a launch. Flushing after the forward (it waits for nothing: the queue is only handed to
//! the device) lets the backward be searched on its own. Counted on lavapipe with the moments as
//! three tensors (docs/gpu.md, "Three moments, three tensors"): a 128² mask pass 72 → 33
//! launches. On the CPU backends, which queue nothing, the flush does nothing.

use burn::tensor::{Gradients, Tensor};

use super::OptimiseError;

/// d `loss` / d everything it tracks (`loss` one value: `[1]`), after handing its forward
/// to the device.
pub fn backward(loss: &Tensor<1>) -> Result<Gradients, OptimiseError> {
    loss.device()
        .flush()
        .map_err(|e| OptimiseError::ReadBack(format!("starting the loss on the device: {e}")))?;
    Ok(loss.backward())
}
