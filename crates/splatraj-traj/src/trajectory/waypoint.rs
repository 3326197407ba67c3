//! Waypoint baseline: the pose is constant on each of m equal segments of [0, 1].
//!
//! ψ_j(t) = 1 if t lies in segment j, else 0, with segment j = [(j−1)/m, j/m) for j < m and the
//! last one closed, [(m−1)/m, 1], so every t ∈ [0, 1] is in exactly one segment (the paper's
//! closed intervals overlap at their ends). Outside [0, 1] the end segments extend. Weight row j
//! is then the pose on segment j. m = 100 as in the paper. Host and tensor evaluations both take
//! the segment index as ⌊t·m⌋ clamped to [0, m−1]; an f32 time exactly on a boundary may round
//! to either side.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::{Basis, TrajectoryError};

/// Number of segments m when the config gives none (the paper's).
pub const DEFAULT_SEGMENTS: usize = 100;

/// The waypoint model's parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    /// Number of piecewise-constant segments m.
    #[serde(default = "default_segments")]
    pub segments: usize,
}

fn default_segments() -> usize {
    DEFAULT_SEGMENTS
}

impl Default for Waypoint {
    /// The paper's m = 100.
    fn default() -> Self {
        Self {
            segments: DEFAULT_SEGMENTS,
        }
    }
}

impl Waypoint {
    /// The segment index (0-based) that time `t` falls in.
    pub fn segment(&self, t: f64) -> usize {
        let last = (self.segments - 1) as f64;
        // NaN clamps to NaN and casts to 0: a NaN time takes the first pose rather than panicking.
        (t * self.segments as f64).floor().clamp(0.0, last) as usize
    }
}

impl Basis for Waypoint {
    fn count(&self) -> usize {
        self.segments
    }

    fn validate(&self) -> Result<(), TrajectoryError> {
        if self.segments == 0 {
            return Err(TrajectoryError::InvalidModel {
                key: "segments",
                reason: "must be at least 1".into(),
            });
        }
        Ok(())
    }

    fn eval_into(&self, t: f64, row: &mut [f64]) {
        row.fill(0.0);
        row[self.segment(t)] = 1.0;
    }

    /// One-hot of ⌊t·m⌋ clamped to [0, m−1], `[B, m]`, on the times' device.
    fn tensor(&self, times: Tensor<1>) -> Tensor<2> {
        let m = self.segments;
        times
            .mul_scalar(m as f64)
            .floor()
            .clamp(0.0, (m - 1) as f64)
            .one_hot::<2>(m)
    }
}
