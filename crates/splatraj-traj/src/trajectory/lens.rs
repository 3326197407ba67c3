//! The lens over time: a zoom s(t) (focal lengths fx·s, fy·s about the fixed principal point)
//! carried by the trajectory and optimised with the pose (docs/conventions.md, "The lens").
//!
//! The zoom is a smooth, bounded function of the same basis as the pose:
//!
//! ```text
//! u(t) = Ψ(t)·w_s                                   (w_s: [K] free weights, the parameters)
//! s(t) = s_min · (s_max / s_min)^σ(u(t) + u₀)       (σ: the logistic function)
//! u₀ = logit(ln(1 / s_min) / ln(s_max / s_min))      (so that u = 0 is s = 1)
//! ```
//!
//! Why this map: s stays inside (s_min, s_max) for any weights, so no step of the optimiser
//! can leave the range or reach a zero focal length; it is smooth (as smooth as Ψ), and it is
//! even in log s, so a zoom in and a zoom out by the same factor are the same distance in u.
//! With the default range [0.5, 2] (a 4× range, wide enough for a dolly zoom that halves or
//! doubles the field of view, narrow enough that the optimisation camera's few pixels still
//! resolve the part when zoomed out). The range must hold s = 1 strictly inside: zero weights
//! are then the configured camera, where every run starts (u₀ = 0 for a range whose geometric
//! mean is 1, as the default's).

use burn::tensor::Tensor;
use burn::tensor::activation::sigmoid;
use serde::{Deserialize, Serialize};

use super::{Basis, TrajectoryError, TrajectoryModel};

/// Smallest zoom of the default range: the focal length halved (field of view about doubled).
pub const DEFAULT_ZOOM_MIN: f64 = 0.5;
/// Largest zoom of the default range: the focal length doubled.
pub const DEFAULT_ZOOM_MAX: f64 = 2.0;

/// Bounds of the zoom s, both finite with 0 < min < max.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZoomRange {
    /// Smallest zoom s_min (> 0).
    pub min: f64,
    /// Largest zoom s_max (> s_min).
    pub max: f64,
}

impl Default for ZoomRange {
    /// [`DEFAULT_ZOOM_MIN`], [`DEFAULT_ZOOM_MAX`].
    fn default() -> Self {
        Self {
            min: DEFAULT_ZOOM_MIN,
            max: DEFAULT_ZOOM_MAX,
        }
    }
}

impl ZoomRange {
    /// Checks 0 < min < 1 < max, both finite; the error's key is `zoom_range`.
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        let (min, max) = (self.min, self.max);
        if !(min.is_finite() && max.is_finite() && min > 0.0 && min < 1.0 && max > 1.0) {
            return Err(TrajectoryError::InvalidModel {
                key: "zoom_range",
                reason: format!(
                    "= [{min}, {max}] must be finite with 0 < min < 1 < max (a zoom multiplies \
                     the focal length, and a run starts from the configured one, s = 1)"
                ),
            });
        }
        Ok(())
    }

    /// u₀: the offset that makes u = 0 the zoom 1.
    fn offset(&self) -> f64 {
        let sigma = -self.min.ln() / self.log_span();
        (sigma / (1.0 - sigma)).ln()
    }

    /// ln(s_max / s_min): how far σ moves log s.
    fn log_span(&self) -> f64 {
        (self.max / self.min).ln()
    }

    /// The zoom s of a free value u, on the host.
    pub fn zoom(&self, u: f64) -> f64 {
        let sigma = 1.0 / (1.0 + (-(u + self.offset())).exp());
        self.min * (self.log_span() * sigma).exp()
    }

    /// The free value u whose zoom is `s` (the inverse of [`ZoomRange::zoom`]); `s` must lie
    /// strictly inside the range.
    pub fn free(&self, s: f64) -> f64 {
        let sigma = (s / self.min).ln() / self.log_span();
        (sigma / (1.0 - sigma)).ln() - self.offset()
    }

    /// The zoom of free values `[B]`, differentiable in them.
    pub fn zoom_tensor(&self, u: Tensor<1>) -> Tensor<1> {
        sigmoid(u.add_scalar(self.offset()))
            .mul_scalar(self.log_span())
            .add_scalar(self.min.ln())
            .exp()
    }
}

/// What the camera's lens does over the trajectory (`[camera] lens`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Lens {
    /// The configured focal length throughout (s ≡ 1): every result before the zoom.
    #[default]
    Fixed,
    /// A zoom s(t) in the range, optimised with the pose.
    Zoom(ZoomRange),
}

impl Lens {
    /// The lens of a trajectory of `count` basis functions at its start: none when fixed, else
    /// zero weights (s ≡ 1).
    pub fn start(&self, count: usize) -> Option<LensPath> {
        match self {
            Lens::Fixed => None,
            Lens::Zoom(range) => Some(LensPath {
                range: *range,
                weights: vec![0.0; count],
            }),
        }
    }
}

/// A trajectory's zoom: its range and free weights w_s, one per basis function (what
/// `trajectory.json` holds under `lens`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LensPath {
    /// Bounds of s.
    pub range: ZoomRange,
    /// Free weights w_s `[K]`: u(t) = Ψ(t)·w_s.
    pub weights: Vec<f64>,
}

impl LensPath {
    /// Checks the range and one finite weight per basis function of a model of `count`; errors
    /// name the key (`lens.weights`).
    pub fn validate(&self, count: usize) -> Result<(), TrajectoryError> {
        self.range.validate()?;
        if self.weights.len() != count {
            return Err(TrajectoryError::InvalidModel {
                key: "lens.weights",
                reason: format!(
                    "has {} values, the model {count} basis functions",
                    self.weights.len()
                ),
            });
        }
        if let Some((row, w)) = self
            .weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && w.abs() <= super::MAX_WEIGHT))
        {
            return Err(TrajectoryError::InvalidModel {
                key: "lens.weights",
                reason: format!("row {row} = {w:e} is not finite or too large"),
            });
        }
        Ok(())
    }

    /// The lens of `range` on `model`'s basis whose zoom best matches `zooms` at `times`: the
    /// free values u = [`ZoomRange::free`] of the zooms fitted by least squares (the ridge of
    /// [`super::Trajectory::fit`]). Every zoom must lie strictly inside the range.
    pub fn fit(
        model: &TrajectoryModel,
        range: ZoomRange,
        times: &[f64],
        zooms: &[f64],
    ) -> Result<Self, TrajectoryError> {
        // The range first: `free` needs a valid one (the rest is `fit_free`'s to check).
        range.validate()?;
        if let Some(s) = zooms.iter().find(|&&s| !(s > range.min && s < range.max)) {
            return Err(TrajectoryError::FitData(format!(
                "zoom {s} is not inside the zoom range [{}, {}]",
                range.min, range.max
            )));
        }
        let free: Vec<f64> = zooms.iter().map(|&s| range.free(s)).collect();
        Self::fit_free(model, range, times, &free)
    }

    /// The lens of `range` on `model`'s basis whose free value u(t) best matches `free` at
    /// `times`, by least squares (the ridge of [`super::Trajectory::fit`]): [`LensPath::fit`]
    /// without the zooms' round trip through [`ZoomRange::free`], for a zoom already given as
    /// free values (another basis' u(t), which may lie where s rounds to the range's ends).
    pub fn fit_free(
        model: &TrajectoryModel,
        range: ZoomRange,
        times: &[f64],
        free: &[f64],
    ) -> Result<Self, TrajectoryError> {
        range.validate()?;
        model.validate()?;
        if times.len() != free.len() || times.is_empty() {
            return Err(TrajectoryError::FitData(format!(
                "{} times for {} zooms",
                times.len(),
                free.len()
            )));
        }
        if let Some(u) = free.iter().find(|u| !u.is_finite()) {
            return Err(TrajectoryError::FitData(format!(
                "the zoom's free value {u} is not finite"
            )));
        }
        // The pose fit's solver, with u in the first of its six columns.
        let targets: Vec<f64> = free
            .iter()
            .flat_map(|&u| [u, 0.0, 0.0, 0.0, 0.0, 0.0])
            .collect();
        let basis = model.matrix(times);
        let rows = super::lstsq::ridge_lstsq(
            &basis,
            times.len(),
            model.count(),
            &targets,
            super::DEFAULT_RIDGE,
        );
        Ok(Self {
            range,
            weights: rows.iter().map(|row| row[0]).collect(),
        })
    }

    /// The zoom at each of `times`, on the host, through the model's basis `basis` `[B, K]`
    /// (row-major, as [`super::Basis::matrix`] gives it).
    pub fn zooms(&self, basis: &[f64]) -> Vec<f64> {
        self.free_values(basis)
            .into_iter()
            .map(|u| self.range.zoom(u))
            .collect()
    }

    /// The free value u = Ψ·w_s at each row of `basis` `[B, K]` (row-major), on the host.
    pub fn free_values(&self, basis: &[f64]) -> Vec<f64> {
        basis
            .chunks_exact(self.weights.len().max(1))
            .map(|row| row.iter().zip(&self.weights).map(|(p, w)| p * w).sum())
            .collect()
    }
}
