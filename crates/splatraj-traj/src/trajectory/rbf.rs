//! SplaTraj's model: squared-exponential radial basis functions spread over the query windows.
//!
//! ψ_k(t) = exp(−(t − t_k)² / (2σ²)). With n query windows T_i = [(i−1)/n, i/n] and c centres per
//! window, window i's centres split it into c equal cells and sit at the cells' middles:
//! t_{i,j} = (i−1)/n + (j − ½)/(c·n), j = 1 … c. For c = 1 that is (i − ½)/n, the middle of T_i
//! (the paper prints i/n − ½, a typo: docs/conventions.md). Over all windows the K = n·c centres
//! are evenly spaced by 1/(n·c), half a spacing in from 0 and 1. σ defaults to that spacing, so
//! neighbouring bases overlap (ψ = e^(−½) ≈ 0.61 at the next centre) and the sum of bases is
//! smooth.
//!
//! All centres lie inside [0, 1], so near t = 0 and t = 1 only one side's bases contribute: the
//! model is stiffest at the trajectory's ends, and the bases' sum falls there (to about 0.6 of
//! its value inside at t = 0 with σ = spacing): a pose held through the first window sags
//! toward the origin at t = 0 unless the weights make up for it, which is the lurch a first
//! frame shows. `normalisation = "partition-of-unity"` divides the bases by their sum at every
//! t (ψ̃_k = ψ_k / Σ_j ψ_j, a normalised RBF network): the bases then sum to 1 everywhere, a
//! constant pose is one weight vector, and the path's ends are a weighted average of the
//! nearest weights. The paper's model (`none`) stays the default of `kind = "rbf"`; a config
//! without `[trajectory]` gets the normalised one (docs/first-try.md). Measured: a least-squares fit (4 windows × 5
//! centres, σ = spacing) of a degree-5 polynomial with coefficients of size ~2 is off by ~0.24 at
//! t = 0 and 1 but ~0.01 at t = ½; σ = 0.1 brings both under 0.004 (at larger weights).

use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::{Basis, TrajectoryError};

/// Centres per window when the config gives none: one, as in the paper.
pub const DEFAULT_CENTRES_PER_WINDOW: usize = 1;

/// Whether the bases are divided by their sum (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RbfNormalisation {
    /// The paper's bases as they are.
    #[default]
    None,
    /// ψ_k / Σ_j ψ_j: the bases sum to 1 at every t.
    PartitionOfUnity,
}

impl RbfNormalisation {
    fn is_none(&self) -> bool {
        *self == RbfNormalisation::None
    }
}

/// The RBF model's parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rbf {
    /// Number of query windows n (the run sets it to the number of queries).
    #[serde(default = "one")]
    pub windows: usize,
    /// Centres per window c.
    #[serde(default = "default_centres")]
    pub centres_per_window: usize,
    /// Width σ in normalised time; `None` means the centre spacing 1/(n·c).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<f64>,
    /// Whether the bases are divided by their sum (module docs).
    #[serde(default, skip_serializing_if = "RbfNormalisation::is_none")]
    pub normalisation: RbfNormalisation,
}

fn one() -> usize {
    1
}

fn default_centres() -> usize {
    DEFAULT_CENTRES_PER_WINDOW
}

impl Default for Rbf {
    /// One window, the paper's one centre per window, σ = spacing.
    fn default() -> Self {
        Self {
            windows: 1,
            centres_per_window: DEFAULT_CENTRES_PER_WINDOW,
            sigma: None,
            normalisation: RbfNormalisation::None,
        }
    }
}

impl Rbf {
    /// An RBF model for `windows` windows with `centres_per_window` centres each and width
    /// `sigma` (`None`: the centre spacing).
    pub fn new(windows: usize, centres_per_window: usize, sigma: Option<f64>) -> Self {
        Self {
            windows,
            centres_per_window,
            sigma,
            normalisation: RbfNormalisation::None,
        }
    }

    /// Distance between neighbouring centres, 1/(n·c).
    pub fn spacing(&self) -> f64 {
        1.0 / (self.windows * self.centres_per_window) as f64
    }

    /// The width σ in use (the configured one, else the spacing).
    pub fn effective_sigma(&self) -> f64 {
        self.sigma.unwrap_or_else(|| self.spacing())
    }

    /// The K = n·c centres t_k in increasing order, window by window.
    pub fn centres(&self) -> Vec<f64> {
        let (n, c) = (self.windows as f64, self.centres_per_window as f64);
        (0..self.windows)
            .flat_map(|i| {
                (0..self.centres_per_window).map(move |j| i as f64 / n + (j as f64 + 0.5) / (c * n))
            })
            .collect()
    }
}

impl Basis for Rbf {
    fn count(&self) -> usize {
        // Saturating: a file or key may claim any size; the resource check refuses it.
        self.windows.saturating_mul(self.centres_per_window)
    }

    fn validate(&self) -> Result<(), TrajectoryError> {
        if self.windows == 0 {
            return Err(TrajectoryError::InvalidModel {
                key: "windows",
                reason: "must be at least 1".into(),
            });
        }
        if self.centres_per_window == 0 {
            return Err(TrajectoryError::InvalidModel {
                key: "centres_per_window",
                reason: "must be at least 1".into(),
            });
        }
        if let Some(sigma) = self.sigma
            && !(sigma.is_finite() && sigma > 0.0)
        {
            return Err(TrajectoryError::InvalidModel {
                key: "sigma",
                reason: format!("must be a finite number > 0, got {sigma}"),
            });
        }
        Ok(())
    }

    fn eval_into(&self, t: f64, row: &mut [f64]) {
        let inv_two_var = 1.0 / (2.0 * self.effective_sigma().powi(2));
        let centres = self.centres();
        // Normalised, the bases are exp(−(d² − min d²)/(2σ²)) over their sum: the same
        // ratios, and the nearest basis is exactly 1, so nothing underflows to 0/0.
        let shift = match self.normalisation {
            RbfNormalisation::None => 0.0,
            RbfNormalisation::PartitionOfUnity => centres
                .iter()
                .map(|c| (t - c).powi(2))
                .fold(f64::INFINITY, f64::min),
        };
        for (psi, centre) in row.iter_mut().zip(centres) {
            *psi = (-((t - centre).powi(2) - shift) * inv_two_var).exp();
        }
        if self.normalisation == RbfNormalisation::PartitionOfUnity {
            let sum = row.iter().sum::<f64>();
            row.iter_mut().for_each(|psi| *psi /= sum);
        }
    }

    /// exp(−(t − t_k)²/(2σ²)) by broadcasting `[B, 1] − [1, K]`, on the times' device and dtype.
    fn tensor(&self, times: Tensor<1>) -> Tensor<2> {
        let k = self.count();
        let centres: Tensor<2> = splatraj_render::host::upload(
            TensorData::new(self.centres(), [1, k]),
            &times.device(),
            times.dtype(),
        );
        let diff = times.unsqueeze_dim::<2>(1) - centres; // [B, 1] − [1, K] → [B, K]
        let inv_two_var = 1.0 / (2.0 * self.effective_sigma().powi(2));
        let squared = diff.clone() * diff; // [B, K]
        match self.normalisation {
            RbfNormalisation::None => squared.mul_scalar(-inv_two_var).exp(),
            RbfNormalisation::PartitionOfUnity => {
                // Shifted by each row's smallest squared distance (a constant: the ratios do
                // not depend on it), so the nearest basis is 1 and the sum is ≥ 1 in any
                // dtype, whatever σ and t (see `eval_into`).
                let nearest = squared.clone().min_dim(1).detach(); // [B, 1]
                let psi = (squared - nearest).mul_scalar(-inv_two_var).exp();
                let sum = psi.clone().sum_dim(1); // [B, 1]
                psi / sum
            }
        }
    }
}
