//! A k-dimensional principal subspace of many unit feature vectors.
//!
//! The lifted field stores each Gaussian's feature compressed to `k` numbers (its coordinates
//! in this subspace, around the mean) so that memory stays `k` floats per Gaussian whatever
//! the embedding's length. Lifting is linear, so lifting the coordinates and expanding them
//! afterwards equals lifting the full features and projecting them.

use rayon::prelude::*;

/// Mean and orthonormal basis of a principal subspace.
#[derive(Debug, Clone, PartialEq)]
pub struct Subspace {
    /// Feature length.
    pub dim: usize,
    /// Mean feature. `[dim]`
    pub mean: Vec<f32>,
    /// Orthonormal rows spanning the subspace. `[k, dim]`
    pub basis: Vec<f32>,
    /// Share of the features' variance around the mean the subspace holds, in [0, 1].
    pub explained: f64,
}

/// Sweeps of subspace iteration: the subspace converges at the rate λ_{k+1}/λ_k per sweep,
/// and CLIP features' spectra fall slowly enough that 60 sweeps settle it (cheap: k·dim²).
const SWEEPS: usize = 60;

impl Subspace {
    /// Number of components.
    pub fn components(&self) -> usize {
        self.basis.len() / self.dim.max(1)
    }

    /// The principal subspace of the rows of `samples` (`[rows, dim]`) of `k` components
    /// (at most `dim`), by subspace iteration on their covariance.
    pub fn fit(samples: &[f32], dim: usize, k: usize) -> Subspace {
        let rows = samples.len() / dim.max(1);
        let k = k.min(dim).max(1);
        let mut mean = vec![0f64; dim];
        for row in samples.chunks_exact(dim) {
            for (m, &v) in mean.iter_mut().zip(row) {
                *m += f64::from(v);
            }
        }
        mean.iter_mut().for_each(|m| *m /= rows.max(1) as f64);
        // Covariance, accumulated per thread over blocks of rows. [dim, dim]
        let covariance = samples
            .par_chunks(dim * 256)
            .map(|block| {
                let mut c = vec![0f64; dim * dim];
                for row in block.chunks_exact(dim) {
                    let centred: Vec<f64> = row
                        .iter()
                        .zip(&mean)
                        .map(|(&v, m)| f64::from(v) - m)
                        .collect();
                    for (a, &x) in centred.iter().enumerate() {
                        let line = &mut c[a * dim..(a + 1) * dim];
                        for (slot, &y) in line.iter_mut().zip(&centred) {
                            *slot += x * y;
                        }
                    }
                }
                c
            })
            .reduce(
                || vec![0f64; dim * dim],
                |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                    a
                },
            );
        let trace: f64 = (0..dim).map(|a| covariance[a * dim + a]).sum();
        // Start from a fixed, well-spread basis (deterministic: same field for the same input).
        let mut q: Vec<Vec<f64>> = (0..k)
            .map(|j| {
                (0..dim)
                    .map(|a| ((a * 7919 + j * 104_729) as f64 * 0.618_033_988_75).fract() - 0.5)
                    .collect()
            })
            .collect();
        orthonormalise(&mut q);
        for _ in 0..SWEEPS {
            q = q.par_iter().map(|v| times(&covariance, v, dim)).collect();
            orthonormalise(&mut q);
        }
        let held: f64 = q
            .iter()
            .map(|v| {
                let cv = times(&covariance, v, dim);
                v.iter().zip(&cv).map(|(a, b)| a * b).sum::<f64>()
            })
            .sum();
        Subspace {
            dim,
            mean: mean.iter().map(|&m| m as f32).collect(),
            basis: q.iter().flatten().map(|&v| v as f32).collect(),
            explained: if trace > 0.0 { held / trace } else { 1.0 },
        }
    }

    /// Coordinates of `feature` (`[dim]`) around the mean. `[k]`
    pub fn project(&self, feature: &[f32]) -> Vec<f32> {
        self.basis
            .chunks_exact(self.dim)
            .map(|b| {
                b.iter()
                    .zip(feature.iter().zip(&self.mean))
                    .map(|(&b, (&f, &m))| f64::from(b) * f64::from(f - m))
                    .sum::<f64>() as f32
            })
            .collect()
    }

    /// Coordinates of a vector itself (no mean removed), for dot products with codes. `[k]`
    pub fn coordinates(&self, v: &[f32]) -> Vec<f32> {
        self.basis
            .chunks_exact(self.dim)
            .map(|b| {
                b.iter()
                    .zip(v)
                    .map(|(&b, &x)| f64::from(b) * f64::from(x))
                    .sum::<f64>() as f32
            })
            .collect()
    }
}

/// `m · v` for a symmetric `[dim, dim]` matrix.
fn times(m: &[f64], v: &[f64], dim: usize) -> Vec<f64> {
    m.chunks_exact(dim)
        .map(|row| row.iter().zip(v).map(|(a, b)| a * b).sum())
        .collect()
}

/// Modified Gram–Schmidt. A vector that collapses (the samples have fewer directions than
/// components) is replaced by the first unit axis that survives orthogonalisation against the
/// earlier vectors, so the basis stays orthonormal.
fn orthonormalise(q: &mut [Vec<f64>]) {
    let dim = q.first().map_or(0, Vec::len);
    for j in 0..q.len() {
        let (done, rest) = q.split_at_mut(j);
        let candidates = std::iter::once(rest[0].clone()).chain((0..dim).map(|a| {
            (0..dim)
                .map(|b| f64::from(u8::from(a == b)))
                .collect::<Vec<f64>>()
        }));
        for mut v in candidates {
            for u in done.iter() {
                let d: f64 = u.iter().zip(&v).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(u).for_each(|(x, y)| *x -= d * y);
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-6 {
                rest[0] = v.iter().map(|x| x / norm).collect();
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a tilted plane in 5-D: two components hold all the variance, and the basis
    /// spans the plane (checked against the plane's own axes).
    #[test]
    fn finds_the_plane_the_samples_lie_in() {
        let a = [1.0f32, 2.0, 0.0, -1.0, 0.5];
        let b = [0.0f32, 1.0, 1.0, 1.0, -2.0];
        let mut samples = Vec::new();
        for i in 0..200 {
            let (s, t) = ((i as f32 * 0.37).sin() * 3.0, (i as f32 * 0.11).cos());
            for d in 0..5 {
                samples.push(1.0 + s * a[d] + t * b[d]);
            }
        }
        let sub = Subspace::fit(&samples, 5, 2);
        assert!((sub.explained - 1.0).abs() < 1e-6, "{}", sub.explained);
        // Five components of rank-2 samples: still an orthonormal basis.
        let all = Subspace::fit(&samples, 5, 5);
        for i in 0..5 {
            for j in 0..5 {
                let d: f32 = (0..5)
                    .map(|k| all.basis[i * 5 + k] * all.basis[j * 5 + k])
                    .sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-5, "basis {i}·{j} = {d}");
            }
        }
        for v in [a, b] {
            let c = sub.coordinates(&v);
            let back: f32 = c.iter().map(|x| x * x).sum();
            let len: f32 = v.iter().map(|x| x * x).sum();
            assert!((back - len).abs() < 1e-3 * len, "{back} vs {len}");
        }
    }
}
