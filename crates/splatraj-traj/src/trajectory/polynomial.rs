//! Polynomial baseline: ψ(t) = [1, t, t², …, t^(N−1)], N = 6 as in the paper (degree 5).
//!
//! Plain monomials on [0, 1]: their Gram matrix is ill-conditioned (Hilbert-like, ~10⁷ for
//! N = 6), which is why [`super::Trajectory::fit`] uses QR rather than the normal equations. The
//! paper calls this "third-order" in one sentence and uses N = 6 in the next; we follow N = 6.

use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

use super::{Basis, TrajectoryError};

/// Number of terms N when the config gives none (the paper's).
pub const DEFAULT_TERMS: usize = 6;

/// The polynomial model's parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Polynomial {
    /// Number of terms N (degree N − 1).
    #[serde(default = "default_terms")]
    pub terms: usize,
}

fn default_terms() -> usize {
    DEFAULT_TERMS
}

impl Default for Polynomial {
    /// The paper's N = 6.
    fn default() -> Self {
        Self {
            terms: DEFAULT_TERMS,
        }
    }
}

impl Basis for Polynomial {
    fn count(&self) -> usize {
        self.terms
    }

    fn validate(&self) -> Result<(), TrajectoryError> {
        if self.terms == 0 {
            return Err(TrajectoryError::InvalidModel {
                key: "terms",
                reason: "must be at least 1".into(),
            });
        }
        Ok(())
    }

    fn eval_into(&self, t: f64, row: &mut [f64]) {
        let mut power = 1.0;
        for psi in row.iter_mut() {
            *psi = power;
            power *= t;
        }
    }

    /// Columns t⁰ … t^(N−1) by repeated products, stacked to `[B, N]`.
    fn tensor(&self, times: Tensor<1>) -> Tensor<2> {
        let mut columns = Vec::with_capacity(self.terms);
        let mut power = times.ones_like(); // [B]
        for _ in 0..self.terms {
            columns.push(power.clone());
            power = power * times.clone();
        }
        Tensor::stack(columns, 1)
    }
}
