//! Host-side resampling: images to the tower's input (bilinear, antialiased when shrinking),
//! the position-embedding grid to another patch grid (bicubic as PyTorch's
//! `F.interpolate(mode="bicubic", align_corners=False)`), and images cut into patches.
//!
//! They run on the host because they are small (a few hundred thousand values) and because
//! burn's interpolation need not match PyTorch's to the 1e-4 the parity tests ask for.

/// Source taps and weights of a 1-D resampling from `input` to `output` samples by a
/// triangle (bilinear) filter on pixel centres (align_corners = false). When shrinking, the
/// filter widens by the scale (as PIL and `antialias=True` do) so that every input pixel
/// counts; when enlarging or at the same size it is plain bilinear (same size: identity).
fn triangle_taps(input: usize, output: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = input as f64 / output as f64;
    let support = scale.max(1.0);
    (0..output)
        .map(|o| {
            let centre = (o as f64 + 0.5) * scale;
            let lo = (centre - support).floor().max(0.0) as usize;
            let hi = ((centre + support).ceil() as usize).min(input);
            let mut taps: Vec<(usize, f64)> = (lo..hi)
                .map(|i| {
                    let d = ((i as f64 + 0.5 - centre) / support).abs();
                    (i, (1.0 - d).max(0.0))
                })
                .filter(|&(_, w)| w > 0.0)
                .collect();
            // Taps beyond the border are dropped and the rest renormalised: the same as
            // clamping the coordinate to the border pixel.
            let total: f64 = taps.iter().map(|t| t.1).sum();
            if taps.is_empty() || total <= 0.0 {
                taps = vec![(
                    ((centre - 0.5).round().max(0.0) as usize).min(input - 1),
                    1.0,
                )];
            }
            let total: f64 = taps.iter().map(|t| t.1).sum();
            taps.into_iter()
                .map(|(i, w)| (i, (w / total) as f32))
                .collect()
        })
        .collect()
}

/// `pixels` `[h, w, 3]` resampled to `[height, width, 3]` (bilinear; antialiased when
/// shrinking; the whole view, aspect ratio not kept).
pub fn resize_bilinear(
    pixels: &[f32],
    w: usize,
    h: usize,
    width: usize,
    height: usize,
) -> Vec<f32> {
    if (w, h) == (width, height) {
        return pixels.to_vec();
    }
    let xs = triangle_taps(w, width);
    let ys = triangle_taps(h, height);
    // Rows first: [h, width, 3].
    let mut rows = vec![0.0f32; h * width * 3];
    for y in 0..h {
        for (x, taps) in xs.iter().enumerate() {
            let mut acc = [0.0f32; 3];
            for &(i, wt) in taps {
                let p = &pixels[(y * w + i) * 3..(y * w + i) * 3 + 3];
                for c in 0..3 {
                    acc[c] += wt * p[c];
                }
            }
            rows[(y * width + x) * 3..(y * width + x) * 3 + 3].copy_from_slice(&acc);
        }
    }
    let mut out = vec![0.0f32; height * width * 3];
    for (y, taps) in ys.iter().enumerate() {
        let dst = &mut out[y * width * 3..(y + 1) * width * 3];
        for &(i, wt) in taps {
            let src = &rows[i * width * 3..(i + 1) * width * 3];
            for (d, s) in dst.iter_mut().zip(src) {
                *d += wt * s;
            }
        }
    }
    out
}

/// PyTorch's cubic convolution kernel with `A = -0.75` (`upsample_bicubic2d`).
fn cubic_weights(t: f64) -> [f64; 4] {
    const A: f64 = -0.75;
    let near = |x: f64| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f64| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)]
}

/// Source taps and weights of PyTorch's bicubic resampling from `input` to `output` samples
/// (`align_corners=False`, output size given, no antialias): source coordinate
/// `(o + 0.5)·input/output − 0.5`, four taps clamped to the border.
fn cubic_taps(input: usize, output: usize) -> Vec<[(usize, f64); 4]> {
    let scale = input as f64 / output as f64;
    (0..output)
        .map(|o| {
            let real = scale * (o as f64 + 0.5) - 0.5;
            let base = real.floor();
            let weights = cubic_weights(real - base);
            let mut taps = [(0usize, 0.0f64); 4];
            for (k, tap) in taps.iter_mut().enumerate() {
                let i = (base as i64 - 1 + k as i64).clamp(0, input as i64 - 1) as usize;
                *tap = (i, weights[k]);
            }
            taps
        })
        .collect()
}

/// A `[rows_in, cols_in, dim]` grid resampled bicubically to `[rows, cols, dim]`, as
/// `F.interpolate(grid, size=(rows, cols), mode="bicubic", align_corners=False)` (computed
/// in f64). Used for the patch position embeddings at another input size.
pub fn resize_bicubic(
    grid: &[f32],
    rows_in: usize,
    cols_in: usize,
    dim: usize,
    rows: usize,
    cols: usize,
) -> Vec<f32> {
    let xs = cubic_taps(cols_in, cols);
    let ys = cubic_taps(rows_in, rows);
    // Along columns first: [rows_in, cols, dim].
    let mut across = vec![0.0f64; rows_in * cols * dim];
    for r in 0..rows_in {
        for (c, taps) in xs.iter().enumerate() {
            let dst = &mut across[(r * cols + c) * dim..(r * cols + c + 1) * dim];
            for &(i, wt) in taps {
                let src = &grid[(r * cols_in + i) * dim..(r * cols_in + i + 1) * dim];
                for (d, s) in dst.iter_mut().zip(src) {
                    *d += wt * f64::from(*s);
                }
            }
        }
    }
    let mut out = vec![0.0f32; rows * cols * dim];
    for (r, taps) in ys.iter().enumerate() {
        for c in 0..cols {
            let dst = &mut out[(r * cols + c) * dim..(r * cols + c + 1) * dim];
            for (k, d) in dst.iter_mut().enumerate() {
                let v: f64 = taps
                    .iter()
                    .map(|&(i, wt)| wt * across[(i * cols + c) * dim + k])
                    .sum();
                *d = v as f32;
            }
        }
    }
    out
}

/// CLIP's normalisation (OpenAI's dataset mean and standard deviation per channel, which
/// open_clip's ViT-B/16 towers use too).
pub const MEAN: [f32; 3] = [0.481_454_66, 0.457_827_5, 0.408_210_73];
/// See [`MEAN`].
// open_clip's digits as it writes them (`OPENAI_DATASET_STD`), beyond f32's precision.
#[allow(clippy::excessive_precision)]
pub const STD: [f32; 3] = [0.268_629_54, 0.261_302_58, 0.275_777_11];

/// `pixels` `[rows·patch, cols·patch, 3]` in [0, 1], normalised with [`MEAN`] and [`STD`] and
/// cut into patches `[rows·cols, 3·patch·patch]`, each flattened as (channel, y, x) to match
/// the patch convolution's `[width, 3, patch, patch]` weight; patches in row-major order, as
/// the convolution's output grid is flattened.
pub fn patches(pixels: &[f32], rows: usize, cols: usize, patch: usize) -> Vec<f32> {
    let width = cols * patch;
    let len = 3 * patch * patch;
    let mut out = vec![0.0f32; rows * cols * len];
    for r in 0..rows {
        for c in 0..cols {
            let dst = &mut out[(r * cols + c) * len..(r * cols + c + 1) * len];
            for ch in 0..3 {
                for y in 0..patch {
                    for x in 0..patch {
                        let p = pixels[((r * patch + y) * width + c * patch + x) * 3 + ch];
                        dst[(ch * patch + y) * patch + x] = (p - MEAN[ch]) / STD[ch];
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_size_is_identity_and_constants_stay() {
        let px: Vec<f32> = (0..5 * 4 * 3).map(|i| i as f32 / 60.0).collect();
        assert_eq!(resize_bilinear(&px, 5, 4, 5, 4), px);
        let grid: Vec<f32> = (0..3 * 3 * 2).map(|i| i as f32).collect();
        let same = resize_bicubic(&grid, 3, 3, 2, 3, 3);
        for (a, b) in same.iter().zip(&grid) {
            assert!((a - b).abs() < 1e-5);
        }
        let flat = vec![0.25f32; 7 * 3 * 3];
        for v in resize_bilinear(&flat, 7, 3, 2, 5) {
            assert!((v - 0.25).abs() < 1e-6);
        }
        for v in resize_bicubic(&flat, 7, 3, 3, 10, 4) {
            assert!((v - 0.25).abs() < 1e-6);
        }
    }
}
