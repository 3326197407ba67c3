//! Vector maths of the features route: norms, cosine similarity and the LERF relevancy.

use crate::error::{Result, SemanticError};

/// Default temperature τ that scales cosine similarities before the softmax (LERF uses 10).
pub const DEFAULT_TEMPERATURE: f32 = 10.0;

/// The canonical negative phrases of LERF/LangSplat.
pub const DEFAULT_NEGATIVES: [&str; 4] = ["object", "things", "stuff", "texture"];

/// `v / ‖v‖`, or an error naming `what` when the norm is zero or a value is not finite.
///
/// A zero vector has no direction, so its cosine with anything is undefined: returning NaN
/// (or silently 0) would hide a broken feature file, so it is an error.
pub fn unit(v: &[f32], what: impl FnOnce() -> String) -> Result<Vec<f32>> {
    let mut sum = 0.0f64;
    for &x in v {
        if !x.is_finite() {
            return Err(SemanticError::NonFinite {
                what: what(),
                value: x,
            });
        }
        sum += f64::from(x) * f64::from(x);
    }
    let norm = sum.sqrt();
    // Below this the direction is dominated by rounding; treat it as zero.
    if norm <= 1e-12 {
        return Err(SemanticError::ZeroVector {
            what: what(),
            norm: norm as f32,
        });
    }
    Ok(v.iter().map(|&x| (f64::from(x) / norm) as f32).collect())
}

/// Cosine similarity of two vectors of the same length; an error when either has zero norm.
pub fn cosine(a: &[f32], b: &[f32]) -> Result<f32> {
    if a.len() != b.len() {
        return Err(SemanticError::Mismatch(format!(
            "cosine of vectors of lengths {} and {}",
            a.len(),
            b.len()
        )));
    }
    let a = unit(a, || "the first vector".to_string())?;
    let b = unit(b, || "the second vector".to_string())?;
    Ok(dot(&a, &b))
}

/// Dot product (f64 accumulation, so 512-d sums do not lose digits).
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| f64::from(x) * f64::from(y))
        .sum::<f64>() as f32
}

/// Softmax weight of the query in the pair (query, negative) of scaled cosines:
/// `exp(τ·cos_q) / (exp(τ·cos_q) + exp(τ·cos_neg))`, computed as the logistic of
/// `τ·(cos_q − cos_neg)` so that large τ cannot overflow.
pub fn pair_softmax(cos_query: f32, cos_negative: f32, temperature: f32) -> f32 {
    let z = f64::from(temperature) * (f64::from(cos_query) - f64::from(cos_negative));
    (1.0 / (1.0 + (-z).exp())) as f32
}

/// LERF relevancy of one unit feature vector: the minimum over the negatives of
/// [`pair_softmax`]. `query` and every negative must be unit vectors of the feature's length.
/// With no negatives the relevancy is 1 (nothing competes with the query).
pub fn relevancy(
    feature_unit: &[f32],
    query_unit: &[f32],
    negatives_unit: &[Vec<f32>],
    temperature: f32,
) -> f32 {
    let cq = dot(feature_unit, query_unit);
    negatives_unit
        .iter()
        .map(|n| pair_softmax(cq, dot(feature_unit, n), temperature))
        .fold(1.0f32, f32::min)
}
