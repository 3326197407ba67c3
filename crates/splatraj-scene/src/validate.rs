//! Checks a freshly read scene and normalises its quaternions, in one place for every format.

use std::path::Path;

use crate::error::{Result, SceneError};
use crate::scene::Scene;

/// What to do with Gaussians that cannot be rendered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InvalidPolicy {
    /// Stop with an error naming the first invalid Gaussian (the default).
    #[default]
    Reject,
    /// Drop invalid Gaussians, log a warning with their count, keep the rest.
    Drop,
}

/// Quaternions with a squared norm below this are treated as zero (no rotation defined).
const MIN_QUAT_NORM_SQ: f32 = 1e-20;

/// What `validate` found and did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ValidationReport {
    /// Gaussians dropped under [`InvalidPolicy::Drop`].
    pub dropped: usize,
}

/// The first problem of Gaussian `i`, as (property, problem), or `None` if it is fine.
fn problem_of(scene: &Scene, i: usize) -> Option<(String, String)> {
    let finite3 = |v: [f32; 3]| v.iter().all(|x| x.is_finite());
    if !finite3(scene.means[i]) {
        return Some((
            "x/y/z".into(),
            format!("is not finite: {:?}", scene.means[i]),
        ));
    }
    let s = scene.scales[i];
    if let Some(k) = (0..3).find(|&k| !(s[k].is_finite() && s[k] > 0.0)) {
        return Some((
            format!("scale_{k}"),
            format!("is {} after activation (must be finite and > 0)", s[k]),
        ));
    }
    let q = scene.rotations[i];
    if !q.iter().all(|x| x.is_finite()) {
        return Some(("rot_0..3".into(), format!("is not finite: {q:?}")));
    }
    let norm_sq: f32 = q.iter().map(|x| x * x).sum();
    if norm_sq < MIN_QUAT_NORM_SQ {
        return Some((
            "rot_0..3".into(),
            format!("has zero norm ({q:?}): no rotation is defined"),
        ));
    }
    let o = scene.opacities[i];
    if !(o.is_finite() && (0.0..=1.0).contains(&o)) {
        return Some((
            "opacity".into(),
            format!("is {o} after activation (must be in [0, 1])"),
        ));
    }
    let stride = 3 * scene.sh_coeffs();
    if let Some(k) = scene.sh[i * stride..(i + 1) * stride]
        .iter()
        .position(|x| !x.is_finite())
    {
        let (coeff, channel) = (k / 3, k % 3);
        let name = if coeff == 0 {
            format!("f_dc_{channel}")
        } else {
            format!("f_rest_{}", channel * (scene.sh_coeffs() - 1) + coeff - 1)
        };
        return Some((name, "is not finite".into()));
    }
    if let Some(f) = &scene.extras.features
        && let Some(k) = f.row(i).iter().position(|x| !x.is_finite())
    {
        return Some((
            f.names.get(k).cloned().unwrap_or_default(),
            "is not finite".into(),
        ));
    }
    None
}

/// Checks array lengths and every Gaussian, then normalises quaternions.
///
/// `path` is only used in messages. Under [`InvalidPolicy::Reject`] the first invalid Gaussian
/// is an error; under [`InvalidPolicy::Drop`] invalid ones are removed and counted.
pub fn validate(scene: &mut Scene, path: &Path, policy: InvalidPolicy) -> Result<ValidationReport> {
    let n = scene.len();
    let lengths = [
        ("scales", scene.scales.len()),
        ("rotations", scene.rotations.len()),
        ("opacities", scene.opacities.len()),
        ("sh", scene.sh.len() / (3 * scene.sh_coeffs())),
    ];
    for (name, len) in lengths {
        if len != n {
            return Err(SceneError::malformed(
                path,
                format!("{name} has {len} entries for {n} Gaussians"),
            ));
        }
    }
    if scene.sh_degree > 3 {
        return Err(SceneError::malformed(
            path,
            format!("SH degree {} is above 3", scene.sh_degree),
        ));
    }

    let mut keep = vec![true; n];
    let mut dropped = 0;
    for (i, keep_i) in keep.iter_mut().enumerate() {
        if let Some((property, problem)) = problem_of(scene, i) {
            match policy {
                InvalidPolicy::Reject => {
                    return Err(SceneError::InvalidGaussian {
                        path: path.to_path_buf(),
                        index: i,
                        property,
                        problem,
                    });
                }
                InvalidPolicy::Drop => {
                    if dropped == 0 {
                        tracing::warn!(
                            "{}: dropping Gaussian {i}: {property} {problem}",
                            path.display()
                        );
                    }
                    *keep_i = false;
                    dropped += 1;
                }
            }
        }
    }
    if dropped > 0 {
        tracing::warn!(
            "{}: dropped {dropped} of {n} Gaussians with invalid values",
            path.display()
        );
        scene.retain(&keep);
    }
    for q in &mut scene.rotations {
        let norm = q.iter().map(|x| x * x).sum::<f32>().sqrt();
        q.iter_mut().for_each(|x| *x /= norm);
    }
    Ok(ValidationReport { dropped })
}
