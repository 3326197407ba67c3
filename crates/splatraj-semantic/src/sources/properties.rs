//! Numbered per-Gaussian properties (`obj_dc_0..`, `clip_f_indices_0..`) as one matrix: how
//! language fields that the scene reader does not know as features store their vectors.

use std::collections::BTreeMap;

use splatraj_scene::Scene;

use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};

/// The scene's properties `<prefix>0..<prefix>{D-1}` as an `[N, D]` matrix in index order; an
/// error naming `source_kind` when there are none, an index is missing or a value is not
/// finite. `what` says what the properties are, for the error ("Gaussian Grouping's identity
/// encodings").
pub fn numbered_properties(
    scene: &Scene,
    prefix: &str,
    source_kind: &'static str,
    what: &str,
) -> Result<Matrix> {
    let mut by_index: BTreeMap<usize, &[f32]> = BTreeMap::new();
    for p in &scene.extras.properties {
        if let Some(index) = p.name.strip_prefix(prefix)
            && let Ok(index) = index.parse::<usize>()
        {
            by_index.insert(index, &p.values);
        }
    }
    let dim = by_index.len();
    if dim == 0 {
        return Err(SemanticError::MissingData {
            source_kind,
            detail: format!(
                "the scene has no {prefix}* properties ({what}): give the point_cloud.ply the \
                 method saved"
            ),
        });
    }
    if let Some(missing) = (0..dim).find(|i| !by_index.contains_key(i)) {
        return Err(SemanticError::MissingData {
            source_kind,
            detail: format!(
                "the scene has {dim} {prefix}* properties but no {prefix}{missing}: they must \
                 be numbered 0..{}",
                dim - 1
            ),
        });
    }
    let n = scene.len();
    let mut values = vec![0.0f32; n * dim];
    for (&k, column) in &by_index {
        if column.len() != n {
            return Err(SemanticError::Mismatch(format!(
                "property {prefix}{k} has {} values for a scene of {n} Gaussians",
                column.len()
            )));
        }
        for (i, &v) in column.iter().enumerate() {
            if !v.is_finite() {
                return Err(SemanticError::NonFinite {
                    what: format!("property {prefix}{k} of Gaussian {i}"),
                    value: v,
                });
            }
            values[i * dim + k] = v;
        }
    }
    Ok(Matrix {
        source: format!("the scene's {prefix}0..{} properties", dim - 1),
        rows: n,
        dim,
        values,
    })
}
