//! Stochastic gradient Langevin dynamics (SGLD): samples of one pose's posterior.
//!
//! Each chain follows (docs/conventions.md "Optimisation problem")
//!
//! ```text
//! θ ← θ − ½·η·∇L(θ) + N(0, η·τ)
//! ```
//!
//! which, for small η, samples θ from the density ∝ exp(−L(θ)/τ): the poses that frame the
//! object well, with their spread. θ is Φ in normalised units ([`PoseUnits`]: radians and
//! `position` scene units), so one η suits both halves. All chains step together as one batch
//! `[C, 6]` (one batched render per step); the loss is the sum of the chains' totals, so each
//! chain gets exactly its own gradient. After `burn_in` steps every `thin`-th state is kept.
//!
//! A chain whose total or gradient is not finite at a step stays where it is for that step
//! (counted in [`SgldResult::skipped_updates`]); the others move on.

use std::time::{Duration, Instant};

use burn::tensor::TensorData;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use splatraj_render::camera::Pose;

use super::units::PoseUnits;
use super::{OptimiseError, Problem, backward, check_starts, per_sample};
use crate::costs::HostPoses;

/// Settings of [`sample_poses_sgld`] (the config's `[sgld]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SgldOptions {
    /// Steps per chain. Default 300.
    pub iterations: usize,
    /// Steps discarded before samples are kept (< iterations). Default 100.
    pub burn_in: usize,
    /// Keep every `thin`-th state after burn-in (≥ 1). Default 10.
    pub thin: usize,
    /// Step size η > 0, in normalised units. Default 0.01.
    pub step_size: f64,
    /// Temperature τ > 0 of the target density exp(−L/τ). Default 0.01.
    pub temperature: f64,
}

impl Default for SgldOptions {
    /// 300 steps, burn-in 100, thin 10, η = 0.01, τ = 0.01.
    fn default() -> Self {
        Self {
            iterations: 300,
            burn_in: 100,
            thin: 10,
            step_size: 0.01,
            temperature: 0.01,
        }
    }
}

impl SgldOptions {
    /// Checks every field; errors name the field.
    pub fn validate(&self) -> Result<(), OptimiseError> {
        let bad = |field, reason: String| Err(OptimiseError::InvalidOptions { field, reason });
        if self.burn_in >= self.iterations {
            return bad(
                "burn_in",
                format!(
                    "= {} must be below iterations = {}",
                    self.burn_in, self.iterations
                ),
            );
        }
        if self.thin == 0 {
            return bad("thin", "must be at least 1".into());
        }
        for (field, v) in [
            ("step_size", self.step_size),
            ("temperature", self.temperature),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, format!("= {v} must be finite and > 0"));
            }
        }
        Ok(())
    }
}

/// One kept state of one chain.
#[derive(Debug, Clone, PartialEq)]
pub struct SgldSample {
    /// Chain index (0-based, the order of the starts).
    pub chain: usize,
    /// Step at which the state was evaluated.
    pub step: usize,
    /// The pose.
    pub pose: Pose,
    /// Its weighted total.
    pub total: f64,
}

/// What [`sample_poses_sgld`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SgldResult {
    /// Kept states of all chains, by step then chain.
    pub samples: Vec<SgldSample>,
    /// Chain updates skipped because a total or gradient was not finite.
    pub skipped_updates: usize,
    /// Wall time.
    pub elapsed: Duration,
}

/// Runs one SGLD chain from each of `starts` on the costs of `problem`'s one window.
///
/// Same problem as [`super::optimise_poses`]; `units` sets the normalised units and `seed` the
/// noise. `problem.scene` must live on an autodiff device.
pub fn sample_poses_sgld(
    problem: &Problem<'_>,
    starts: &[Pose],
    units: PoseUnits,
    options: &SgldOptions,
    seed: u64,
) -> Result<SgldResult, OptimiseError> {
    options.validate()?;
    units.validate()?;
    problem.single()?;
    check_starts(starts, "chains")?;
    let (device, dtype) = problem.gradient_setup()?;
    let renders = problem.renders();
    let chains = starts.len();
    let mut theta: Vec<[f64; 6]> = starts.iter().map(|p| units.normalise(&p.0)).collect();
    let noise = Normal::new(0.0, (options.step_size * options.temperature).sqrt())
        .expect("η·τ is finite and > 0 (validated)");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let started = Instant::now();
    let mut samples = Vec::new();
    let mut skipped_updates = 0;
    for step in 0..options.iterations {
        let flat: Vec<f64> = theta.iter().flatten().copied().collect();
        let normalised =
            splatraj_render::host::upload::<2>(TensorData::new(flat, [chains, 6]), &device, dtype)
                .require_grad();
        let poses = units.to_scene(normalised.clone());
        // The chains live on the host, so the render takes their poses from there and the
        // step reads once: totals and gradient together.
        let host = HostPoses {
            samples: theta.iter().map(|t| units.to_scene_as(t, dtype)).collect(),
            path: None,
        };
        let terms = problem
            .evaluate_along(0, poses, None, None, Some(&host), step, renders.as_ref())?
            .terms;
        let grads = backward(&terms.total.clone().sum())?;
        let grad = normalised.grad(&grads).map(|g| g.reshape([chains * 6]));
        let (rows, grad) = per_sample(&terms, grad)?;
        let totals: Vec<f64> = rows.into_iter().map(|(t, _)| t).collect();
        let grad = grad.unwrap_or_else(|| vec![0.0; chains * 6]);
        if step >= options.burn_in && (step - options.burn_in).is_multiple_of(options.thin) {
            for (chain, (t, &total)) in theta.iter().zip(&totals).enumerate() {
                samples.push(SgldSample {
                    chain,
                    step,
                    pose: Pose(units.denormalise(t)),
                    total,
                });
            }
        }
        for (c, t) in theta.iter_mut().enumerate() {
            let g = &grad[c * 6..(c + 1) * 6];
            if !(totals[c].is_finite() && g.iter().all(|v| v.is_finite())) {
                skipped_updates += 1;
                continue;
            }
            for (value, gi) in t.iter_mut().zip(g) {
                *value += -0.5 * options.step_size * gi + noise.sample(&mut rng);
            }
        }
    }
    Ok(SgldResult {
        samples,
        skipped_updates,
        elapsed: started.elapsed(),
    })
}
