//! Wobble: how much of the framing error along t changes faster than a viewer follows.
//!
//! A camera that keeps its object framed on average can still swing it back and forth (with
//! too many RBF centres per window the framing error of a first-try capture cycled 0.02 ↔ 0.37
//! every half second). The wobble of a series x_k sampled at `fps` is the largest
//! |x_k − m_k|, with m the series smoothed by a Gaussian of σ = [`WOBBLE_SIGMA_S`] seconds
//! (truncated at 3σ, renormalised where it meets the series' ends). Smoothing keeps a
//! component of frequency f with gain exp(−2π²f²σ²), so the residual keeps
//! 1 − exp(−2π²f²σ²) of it: 12 % at 0.5 Hz, 40 % at 1 Hz, 87 % at 2 Hz — a cut at about 1 Hz.
//! A pan or a drift (slow, or linear) leaves nearly nothing; the corner of a V (the framing
//! error crossing its minimum at slope s per second) leaves about 0.8·s·σ.

/// Width σ of the Gaussian that separates slow from fast, seconds (module docs).
pub const WOBBLE_SIGMA_S: f64 = 0.16;

/// The wobble of `series` sampled at `fps` per second (module docs); None for fewer than
/// three samples.
pub fn wobble(series: &[f64], fps: f64) -> Option<f64> {
    if series.len() < 3 || !(fps.is_finite() && fps > 0.0) {
        return None;
    }
    let sigma = WOBBLE_SIGMA_S * fps; // in samples
    let reach = (3.0 * sigma).ceil() as usize;
    let weights: Vec<f64> = (0..=reach)
        .map(|d| (-0.5 * (d as f64 / sigma.max(1e-9)).powi(2)).exp())
        .collect();
    let n = series.len();
    (0..n)
        .map(|k| {
            let (lo, hi) = (k.saturating_sub(reach), (k + reach).min(n - 1));
            let (mut sum, mut total) = (0.0, 0.0);
            for (j, x) in series.iter().enumerate().take(hi + 1).skip(lo) {
                let w = weights[k.abs_diff(j)];
                sum += w * x;
                total += w;
            }
            (series[k] - sum / total).abs()
        })
        .reduce(f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fast_swing_is_most_of_its_amplitude_and_a_slow_drift_is_nothing() {
        let fps = 30.0;
        let t: Vec<f64> = (0..90).map(|k| k as f64 / fps).collect();
        let tau = std::f64::consts::TAU;
        let gain =
            |f: f64| 1.0 - (-2.0 * (std::f64::consts::PI * f * WOBBLE_SIGMA_S).powi(2)).exp();
        // 2 Hz around a slow drift: the residual keeps gain(2) of the swing.
        let fast: Vec<f64> = t
            .iter()
            .map(|t| 0.2 + 0.05 * t + 0.15 * (tau * 2.0 * t).sin())
            .collect();
        let w = wobble(&fast, fps).unwrap();
        assert!(
            (w - 0.15 * gain(2.0)).abs() < 0.02,
            "{w} against {}",
            0.15 * gain(2.0)
        );
        // A drift alone: nothing but the ends, where the renormalised kernel lags the line
        // by at most 0.8σ.
        let drift: Vec<f64> = t.iter().map(|t| 0.1 + 0.05 * t).collect();
        assert!(wobble(&drift, fps).unwrap() < 0.05 * 0.8 * WOBBLE_SIGMA_S + 1e-9);
        // A quarter-hertz swing barely leaks through: its gain, and at the ends the lag of its
        // steepest slope (0.15·2π·0.25 per second).
        let slow: Vec<f64> = t.iter().map(|t| 0.15 * (tau * 0.25 * t).sin()).collect();
        let bound = 0.15 * gain(0.25) + 0.15 * tau * 0.25 * 0.8 * WOBBLE_SIGMA_S;
        assert!(wobble(&slow, fps).unwrap() < bound);
        assert_eq!(wobble(&[0.1, 0.2], fps), None);
    }
}
