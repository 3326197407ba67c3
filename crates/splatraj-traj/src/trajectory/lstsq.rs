//! Small dense ridge least squares on the host, f64, by Householder QR.
//!
//! Problem sizes are tiny (K ≤ a few hundred bases, six right-hand sides), so a hand-written QR
//! beats pulling in a linear-algebra crate. QR on the augmented matrix [Ψ; μI] solves
//! min ‖ΨW − Y‖² + μ²‖W‖² without forming ΨᵀΨ, whose condition number is the square of Ψ's
//! (the monomial basis would lose ~7 digits there).

use super::{POSE_DIM, Pose};

/// Default relative ridge: μ = this × the largest column norm of Ψ.
///
/// Small enough not to show in a well-posed fit (the tests' fits of poses in a model's span are
/// exact to 1e-9), large enough that a basis function no sample reaches (an all-zero column)
/// gets weight 0 instead of a division by zero.
pub const DEFAULT_RIDGE: f64 = 1e-8;

/// Weights `[K][6]` minimising ‖ΨW − Y‖² + μ²‖W‖², μ = `ridge` × max column norm of Ψ.
///
/// `basis` is Ψ row-major `[rows, k]`, `targets` is Y row-major `[rows, 6]`.
pub(crate) fn ridge_lstsq(
    basis: &[f64],
    rows: usize,
    k: usize,
    targets: &[f64],
    ridge: f64,
) -> Vec<Pose> {
    debug_assert_eq!(basis.len(), rows * k);
    debug_assert_eq!(targets.len(), rows * POSE_DIM);
    let max_norm = (0..k)
        .map(|j| {
            (0..rows)
                .map(|i| basis[i * k + j].powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    let mu = ridge * max_norm;

    // Augmented system: rows of Ψ then μI (targets 0), row-major.
    let total = rows + k;
    let mut a = vec![0.0; total * k];
    a[..rows * k].copy_from_slice(basis);
    for j in 0..k {
        a[(rows + j) * k + j] = mu;
    }
    let mut y = vec![0.0; total * POSE_DIM];
    y[..rows * POSE_DIM].copy_from_slice(targets);

    // Householder QR: reflect column j's tail onto its first entry, apply to A and Y.
    let mut v = vec![0.0; total];
    for j in 0..k.min(total) {
        let norm = (j..total).map(|i| a[i * k + j].powi(2)).sum::<f64>().sqrt();
        if norm == 0.0 {
            continue; // Column already zero below the diagonal: nothing to reflect.
        }
        let x0 = a[j * k + j];
        let alpha = if x0 > 0.0 { -norm } else { norm }; // Opposite sign: no cancellation.
        for i in j..total {
            v[i] = a[i * k + j];
        }
        v[j] -= alpha;
        let v_norm2: f64 = (j..total).map(|i| v[i] * v[i]).sum();
        if v_norm2 == 0.0 {
            continue;
        }
        for c in j..k {
            let dot: f64 = (j..total).map(|i| v[i] * a[i * k + c]).sum();
            let scale = 2.0 * dot / v_norm2;
            for i in j..total {
                a[i * k + c] -= scale * v[i];
            }
        }
        for c in 0..POSE_DIM {
            let dot: f64 = (j..total).map(|i| v[i] * y[i * POSE_DIM + c]).sum();
            let scale = 2.0 * dot / v_norm2;
            for i in j..total {
                y[i * POSE_DIM + c] -= scale * v[i];
            }
        }
    }

    // Back substitution R W = (QᵀY)[..k]; a zero pivot (only possible with ridge 0 and an
    // unreached basis) leaves that weight at 0, the minimum-norm choice for it.
    let mut w = vec![[0.0; POSE_DIM]; k];
    for j in (0..k).rev() {
        let pivot = a[j * k + j];
        if pivot == 0.0 {
            continue;
        }
        for c in 0..POSE_DIM {
            let mut s = y[j * POSE_DIM + c];
            for (l, wl) in w.iter().enumerate().skip(j + 1) {
                s -= a[j * k + l] * wl[c];
            }
            w[j][c] = s / pivot;
        }
    }
    w
}
