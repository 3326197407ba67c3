//! The fused colours' kernels in plain Rust: one row (pose, Gaussian) at a time, in parallel
//! over fixed chunks of rows with rayon, generic over f32 and f64.
//!
//! Every step mirrors the tensor path (`crate::sh`) in the same order with the same clamps: the
//! view direction's length floored at 1e-12, the colour max(0, 0.5 + Σ), and a clamp passes
//! the gradient where the value lies on or inside its bound, as burn's `clamp_min` does. So
//! in f64 the two agree to rounding (`tests/fused_colours.rs`). The backward is those steps
//! reversed by hand: each row's colour gradient through the basis functions' gradients and
//! the normalisation to the camera centre, summed per pose in f64 in a fixed chunk order (the
//! same numbers on every thread count).

use rayon::prelude::*;

use crate::fused::projection::ProjectionPlan;
use crate::fused::real::Real;
use crate::sh::{C0, C1, C2, C3};

/// Rows per parallel chunk: fixed, so that the sums do not depend on the thread count.
const ROWS_PER_CHUNK: usize = 4096;

/// The most SH basis functions a Gaussian has (degree 3).
const MAX_BASIS: usize = 16;

/// The squared length below which the view direction is divided by 1e-12 instead of its
/// length (the tensor path's floor: a camera on a mean gets a finite, arbitrary colour).
const SQUARED_LENGTH_FLOOR: f64 = 1e-24;

/// What the kernels read of the scene: the component rows `[9, N]` (the centres are rows 0–2)
/// and the SH coefficients `[N, K, 3]`.
#[derive(Debug, Clone, Copy)]
pub struct ShRows<'a, E> {
    /// `[9, N]`
    pub components: &'a [E],
    /// `[N, K, 3]`
    pub coeffs: &'a [E],
    /// Basis functions a Gaussian has: K = (degree + 1)².
    pub basis: usize,
}

impl<E: Real> ShRows<'_, E> {
    fn len(&self) -> usize {
        self.components.len() / 9
    }

    fn centre(&self, g: usize) -> [E; 3] {
        let n = self.len();
        std::array::from_fn(|e| self.components[e * n + g])
    }

    /// Gaussian g's coefficients `[K, 3]`.
    fn coeffs_of(&self, g: usize) -> &[E] {
        &self.coeffs[g * self.basis * 3..(g + 1) * self.basis * 3]
    }
}

/// A Gaussian seen from a camera centre: the unit direction and the length it was divided by.
struct View<E> {
    d: [E; 3],
    length: E,
    /// Whether the length was floored (then it is a constant: no gradient through it).
    floored: bool,
}

fn view<E: Real>(mean: [E; 3], centre: [E; 3]) -> View<E> {
    let raw: [E; 3] = std::array::from_fn(|e| mean[e] - centre[e]);
    let squared = raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2];
    let floor = E::of(SQUARED_LENGTH_FLOOR);
    let floored = squared < floor;
    let length = if floored { floor } else { squared }.sqrt();
    View {
        d: std::array::from_fn(|e| raw[e] / length),
        length,
        floored,
    }
}

/// The first `k` basis functions at the unit direction `d`, in the tensor path's order of
/// operations.
fn basis<E: Real>(d: [E; 3], k: usize) -> [E; MAX_BASIS] {
    let [x, y, z] = d;
    let c = E::of;
    let mut b = [E::ZERO; MAX_BASIS];
    b[0] = c(C0);
    if k > 1 {
        b[1] = y * c(-C1);
        b[2] = z * c(C1);
        b[3] = x * c(-C1);
    }
    if k > 4 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b[4] = x * y * c(C2[0]);
        b[5] = y * z * c(C2[1]);
        b[6] = (zz * c(2.0) - xx - yy) * c(C2[2]);
        b[7] = x * z * c(C2[3]);
        b[8] = (xx - yy) * c(C2[4]);
        if k > 9 {
            b[9] = y * (xx * c(3.0) - yy) * c(C3[0]);
            b[10] = x * y * z * c(C3[1]);
            b[11] = y * (zz * c(4.0) - xx - yy) * c(C3[2]);
            b[12] = z * (zz * c(2.0) - xx * c(3.0) - yy * c(3.0)) * c(C3[3]);
            b[13] = x * (zz * c(4.0) - xx - yy) * c(C3[4]);
            b[14] = z * (xx - yy) * c(C3[5]);
            b[15] = x * (xx - yy * c(3.0)) * c(C3[6]);
        }
    }
    b
}

/// d L/d d: Σ_k w_k ∇b_k(d), the first `k` basis functions' gradients (in d's components as
/// independent variables, as the tensor path differentiates them) weighted by `w`.
fn basis_gradient<E: Real>(d: [E; 3], w: &[E; MAX_BASIS], k: usize) -> [E; 3] {
    let [x, y, z] = d;
    let c = E::of;
    let mut v = [E::ZERO; 3];
    let mut add = |weight: E, g: [E; 3]| {
        for e in 0..3 {
            v[e] += weight * g[e];
        }
    };
    let zero = E::ZERO;
    if k > 1 {
        add(w[1], [zero, c(-C1), zero]);
        add(w[2], [zero, zero, c(C1)]);
        add(w[3], [c(-C1), zero, zero]);
    }
    if k > 4 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        add(w[4] * c(C2[0]), [y, x, zero]);
        add(w[5] * c(C2[1]), [zero, z, y]);
        add(w[6] * c(C2[2]), [x * c(-2.0), y * c(-2.0), z * c(4.0)]);
        add(w[7] * c(C2[3]), [z, zero, x]);
        add(w[8] * c(C2[4]), [x * c(2.0), y * c(-2.0), zero]);
        if k > 9 {
            add(w[9] * c(C3[0]), [x * y * c(6.0), (xx - yy) * c(3.0), zero]);
            add(w[10] * c(C3[1]), [y * z, x * z, x * y]);
            add(
                w[11] * c(C3[2]),
                [
                    x * y * c(-2.0),
                    zz * c(4.0) - xx - yy * c(3.0),
                    y * z * c(8.0),
                ],
            );
            add(
                w[12] * c(C3[3]),
                [
                    x * z * c(-6.0),
                    y * z * c(-6.0),
                    zz * c(6.0) - (xx + yy) * c(3.0),
                ],
            );
            add(
                w[13] * c(C3[4]),
                [
                    zz * c(4.0) - xx * c(3.0) - yy,
                    x * y * c(-2.0),
                    x * z * c(8.0),
                ],
            );
            add(w[14] * c(C3[5]), [x * z * c(2.0), y * z * c(-2.0), xx - yy]);
            add(
                w[15] * c(C3[6]),
                [(xx - yy) * c(3.0), x * y * c(-6.0), zero],
            );
        }
    }
    v
}

/// 0.5 + Σ_k b_k · coeff[k, c] for each channel c, before the clamp at 0.
fn unclamped<E: Real>(b: &[E; MAX_BASIS], coeffs: &[E], k: usize) -> [E; 3] {
    std::array::from_fn(|ch| {
        let mut sum = E::ZERO;
        for (i, b) in b.iter().enumerate().take(k) {
            sum += *b * coeffs[i * 3 + ch];
        }
        sum + E::of(0.5)
    })
}

/// The camera centre of each pose of `poses` (`[B, 6]`, Φ = ω, c) in E.
fn centres<E: Real>(poses: &[f64]) -> Vec<[E; 3]> {
    poses
        .chunks_exact(6)
        .map(|pose| std::array::from_fn(|e| E::of(pose[3 + e])))
        .collect()
}

/// Each pose's rows cut into chunks: (pose, the chunk's rows).
fn chunks(plan: &ProjectionPlan) -> Vec<(usize, std::ops::Range<usize>)> {
    let rows = &plan.rows;
    (0..rows.batch())
        .flat_map(|b| {
            let (start, count) = (rows.start(b), rows.count(b));
            (0..count.div_ceil(ROWS_PER_CHUNK)).map(move |c| {
                let first = start + c * ROWS_PER_CHUNK;
                (b, first..(first + ROWS_PER_CHUNK).min(start + count))
            })
        })
        .collect()
}

/// The colours `[R, 3]` of `plan`'s rows seen from `poses`' camera centres.
pub fn forward<E: Real>(poses: &[f64], scene: ShRows<'_, E>, plan: &ProjectionPlan) -> Vec<E> {
    let centres = centres::<E>(poses);
    let mut out = vec![E::ZERO; plan.rows.total() * 3];
    let jobs = chunks(plan);
    let mut rest = out.as_mut_slice();
    let mut outputs = Vec::with_capacity(jobs.len());
    for (_, range) in &jobs {
        let (own, tail) = rest.split_at_mut(range.len() * 3);
        outputs.push(own);
        rest = tail;
    }
    jobs.into_par_iter()
        .zip(outputs)
        .for_each(|((b, range), out)| {
            for (colour, r) in out.chunks_exact_mut(3).zip(range) {
                let g = plan.gaussians[r] as usize;
                let d = view(scene.centre(g), centres[b]).d;
                let sums = unclamped(&basis(d, scene.basis), scene.coeffs_of(g), scene.basis);
                for (out, sum) in colour.iter_mut().zip(sums) {
                    *out = if sum < E::ZERO { E::ZERO } else { sum };
                }
            }
        });
    out
}

/// d L/dΦ `[B, 6]` from the colours' gradient `v_colours` `[R, 3]`: only the camera centre
/// moves a colour, so the rotation's three components are zero.
pub fn backward<E: Real>(
    poses: &[f64],
    scene: ShRows<'_, E>,
    plan: &ProjectionPlan,
    v_colours: &[E],
) -> Vec<f64> {
    let centres = centres::<E>(poses);
    let k = scene.basis;
    let partial: Vec<(usize, [f64; 3])> = chunks(plan)
        .into_par_iter()
        .map(|(b, range)| {
            let mut sum = [0.0f64; 3];
            for r in range {
                let v = &v_colours[r * 3..r * 3 + 3];
                // Rows no pixel read contribute nothing.
                if v.iter().all(|v| v.to_f64() == 0.0) {
                    continue;
                }
                let g = plan.gaussians[r] as usize;
                let coeffs = scene.coeffs_of(g);
                let view = view(scene.centre(g), centres[b]);
                let basis = basis(view.d, k);
                let sums = unclamped(&basis, coeffs, k);
                // w_k = Σ_c v_c · coeff[k, c] over the channels the clamp passes.
                let mut w = [E::ZERO; MAX_BASIS];
                for (ch, sum) in sums.iter().enumerate() {
                    if *sum < E::ZERO {
                        continue;
                    }
                    for (i, w) in w.iter_mut().enumerate().take(k) {
                        *w += v[ch] * coeffs[i * 3 + ch];
                    }
                }
                let v_d = basis_gradient(view.d, &w, k);
                // d = raw / length: through the length too unless it was floored.
                let along = if view.floored {
                    E::ZERO
                } else {
                    view.d[0] * v_d[0] + view.d[1] * v_d[1] + view.d[2] * v_d[2]
                };
                for e in 0..3 {
                    // raw = mean − centre.
                    let v_raw = (v_d[e] - view.d[e] * along) / view.length;
                    sum[e] -= v_raw.to_f64();
                }
            }
            (b, sum)
        })
        .collect();
    // Each pose's chunks summed in order (the same numbers on every thread count).
    let mut v_poses = vec![0.0; centres.len() * 6];
    for (b, sum) in partial {
        for e in 0..3 {
            v_poses[b * 6 + 3 + e] += sum[e];
        }
    }
    v_poses
}
