//! Rodrigues' rotation on the host in f64 with its exact derivative ∂R/∂ω, in the branches of
//! the tensor version ([`crate::camera::rotation_matrices`]: a series in θ² below
//! `SERIES_BELOW_THETA_SQ`, sin and cos above), so that a hand-written backward agrees with
//! autodiff of the tensor path to rounding. The fused projection's host kernels and the costs
//! computed on the host (the motion limits' turning rate, the prior, uprightness) take their
//! gradients through it.

use crate::camera::SERIES_BELOW_THETA_SQ;

/// Rodrigues' rotation R(ω) and its derivative, with the tensor path's branches (a series in
/// θ² below `SERIES_BELOW_THETA_SQ`, sin and cos above).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rotation {
    /// R_wc, row-major: `matrix[i][j]`; column k is camera axis k in world coordinates.
    pub matrix: [[f64; 3]; 3],
    /// ∂R/∂ω_m: `derivative[m][i][j]`.
    pub derivative: [[[f64; 3]; 3]; 3],
}

/// [ω]ₓ, row-major (so that [ω]ₓ v = ω × v).
fn skew(w: [f64; 3]) -> [[f64; 3]; 3] {
    [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
}

fn matmul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

impl Rotation {
    /// R(ω) = I + A(θ²)·K + B(θ²)·K² with K = \[ω\]ₓ, A = sin θ/θ, B = (1 − cos θ)/θ², and
    /// ∂R/∂ω_m = 2ω_m (A'·K + B'·K²) + A·E_m + B·(E_m K + K E_m), E_m = \[e_m\]ₓ.
    pub fn new(omega: [f64; 3]) -> Self {
        let s = omega.iter().map(|w| w * w).sum::<f64>();
        let (a, b, da, db) = if s < SERIES_BELOW_THETA_SQ {
            // The truncated series and their exact derivatives (what autodiff differentiates).
            (
                1.0 - s / 6.0 + s * s / 120.0 - s * s * s / 5040.0,
                0.5 - s / 24.0 + s * s / 720.0 - s * s * s / 40320.0,
                -1.0 / 6.0 + s / 60.0 - s * s / 1680.0,
                -1.0 / 24.0 + s / 360.0 - s * s / 13440.0,
            )
        } else {
            let theta = s.sqrt();
            let (sin, cos) = theta.sin_cos();
            let dtheta = 0.5 / theta;
            (
                sin / theta,
                (1.0 - cos) / s,
                (cos / theta - sin / s) * dtheta,
                sin * dtheta / s - (1.0 - cos) / (s * s),
            )
        };
        let k = skew(omega);
        let k2 = matmul(&k, &k);
        let matrix = std::array::from_fn(|i| {
            std::array::from_fn(|j| f64::from(u8::from(i == j)) + a * k[i][j] + b * k2[i][j])
        });
        let derivative = std::array::from_fn(|m| {
            let mut unit = [0.0; 3];
            unit[m] = 1.0;
            let e = skew(unit);
            let (ek, ke) = (matmul(&e, &k), matmul(&k, &e));
            std::array::from_fn(|i| {
                std::array::from_fn(|j| {
                    2.0 * omega[m] * (da * k[i][j] + db * k2[i][j])
                        + a * e[i][j]
                        + b * (ek[i][j] + ke[i][j])
                })
            })
        });
        Rotation { matrix, derivative }
    }

    /// d L/dω from d L/dR (row-major).
    pub fn omega_gradient(&self, v_matrix: &[[f64; 3]; 3]) -> [f64; 3] {
        std::array::from_fn(|m| {
            (0..3)
                .flat_map(|i| (0..3).map(move |j| (i, j)))
                .map(|(i, j)| v_matrix[i][j] * self.derivative[m][i][j])
                .sum()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Rotation;

    /// ∂R/∂ω against central differences of R itself, on both branches and near the switch.
    #[test]
    fn rotation_derivative_matches_finite_differences() {
        for omega in [
            [0.0, 0.0, 0.0],
            [0.03, -0.05, 0.04],
            [0.0577, 0.0577, 0.0577],
            [0.4, -1.2, 0.7],
            [2.0, 1.0, -2.2],
        ] {
            let r = Rotation::new(omega);
            for m in 0..3 {
                let h = 1e-6;
                let (mut plus, mut minus) = (omega, omega);
                plus[m] += h;
                minus[m] -= h;
                let (p, q) = (Rotation::new(plus).matrix, Rotation::new(minus).matrix);
                for i in 0..3 {
                    for j in 0..3 {
                        let numeric = (p[i][j] - q[i][j]) / (2.0 * h);
                        let analytic = r.derivative[m][i][j];
                        assert!(
                            (numeric - analytic).abs() < 1e-8,
                            "ω = {omega:?}, ∂R[{i}][{j}]/∂ω{m}: {analytic} vs {numeric}"
                        );
                    }
                }
            }
            // And R is a rotation: RᵀR = I.
            let m = r.matrix;
            for i in 0..3 {
                for j in 0..3 {
                    let g: f64 = (0..3).map(|k| m[k][i] * m[k][j]).sum();
                    let expected = if i == j { 1.0 } else { 0.0 };
                    assert!(
                        (g - expected).abs() < 1e-12,
                        "ω = {omega:?}: RᵀR[{i}][{j}] = {g}"
                    );
                }
            }
        }
    }
}
