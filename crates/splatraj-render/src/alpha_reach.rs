//! Where a projected Gaussian can reach α ≥ 1/255 on screen, and which tiles of a tile row that
//! region touches (the binning's tight test).
//!
//! The reference renderer bins a Gaussian into every tile of the square of half-side
//! ⌈3·√λ_max(Σ_2D)⌉ about its mean. For an elongated splat seen at a slant (most of a trained
//! capture) the ellipse fills a small part of that square, and in a close-up, where splats span
//! many tiles, a tile's list held several times the entries that could draw in it: each costs
//! the compositing a footprint test, and in its bounding box a power per pixel, for nothing.
//!
//! α = o·e^power with power = −½·dᵀΣ_2D⁻¹d reaches 1/255 exactly where dᵀΣ_2D⁻¹d ≤ r² with
//! r² = 2·ln(255·o). The binning keeps a tile of the square only where that ellipse, widened
//! by [`SLACK`] and [`MARGIN`], meets the tile: every pixel whose α can reach 1/255 (the rule
//! both rasterizers apply) keeps the Gaussian in its list, so images and gradients are
//! unchanged; only entries that contribute nowhere in their tile go (docs/rasterizer.md,
//! "Tight binning").

use std::ops::Range;

use crate::composite_rules::MIN_ALPHA;
use crate::tile_grid::{TILE_SIZE, floor_small};

/// Relative widening of r²: the compositing kernels evaluate the power in f32 from their own
/// projection, so a pixel on the f64 ellipse's edge may pass there; 5 % of r² covers the f32
/// rounding of an inverse covariance of condition number up to about 10⁵ (λ_max up to 3·10⁴
/// px² over the low-pass floor of 0.3 px²).
pub const SLACK: f64 = 0.05;

/// Widening in pixels on every side: tiles are tested as pixel rectangles, and a pixel centre
/// lies half a pixel inside; a whole pixel more costs a few entries and no reasoning.
pub const MARGIN: f64 = 1.0;

/// The screen region where a Gaussian's α can reach 1/255: {d : dᵀE⁻¹d ≤ 1} about its mean,
/// with E = r²·(1 + [`SLACK`])·Σ_2D (pixels²), or nowhere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlphaReach {
    /// E's entries (xx, xy, yy); all 0 where the Gaussian can reach 1/255 nowhere (o < 1/255),
    /// non-finite where it cannot be told (then every tile of the square is kept).
    ellipse: [f32; 3],
}

impl AlphaReach {
    /// The region of a Gaussian of opacity `opacity` whose screen covariance (low-pass
    /// included) is `covariance` = (xx, xy, yy).
    pub fn new(covariance: [f64; 3], opacity: f64) -> Self {
        Self::scaled(covariance, SquaredReach::of_opacity(opacity))
    }

    /// [`AlphaReach::new`] from the opacity's [`SquaredReach`], computed once per Gaussian:
    /// a pass decides the same Gaussian from many poses, and the logarithm was a tenth of a
    /// decision.
    pub fn scaled(covariance: [f64; 3], reach: SquaredReach) -> Self {
        match reach.r2() {
            Some(r2) => AlphaReach {
                ellipse: covariance.map(|v| (r2 * v) as f32),
            },
            None => AlphaReach { ellipse: [0.0; 3] },
        }
    }

    /// E's entries (xx, xy, yy), for tests that compare bits.
    #[cfg(test)]
    pub(crate) fn ellipse_for_tests(&self) -> [f32; 3] {
        self.ellipse
    }

    /// For each tile row of `rows`, the tile columns that the region about the mean `(u, v)`
    /// (pixels), widened by [`MARGIN`], touches, within `columns` (the square's columns).
    pub fn row_columns(
        &self,
        [u, v]: [f64; 2],
        rows: Range<usize>,
        columns: Range<usize>,
    ) -> impl Iterator<Item = Range<usize>> {
        let [a, b, c] = self.ellipse.map(f64::from);
        let empty = columns.start..columns.start;
        let finite = [a, b, c, u, v].iter().all(|x| x.is_finite());
        let shape = if a == 0.0 && b == 0.0 && c == 0.0 {
            Shape::Nowhere
        } else if !finite || a <= 0.0 || c <= 0.0 {
            Shape::Square // not an ellipse that can be told: keep what the square keeps
        } else {
            // On the ellipse at height dy, x runs over (b/c)·dy ± √(s·(1 − dy²/c)) with
            // s = a − b²/c: concave at the right edge and convex at the left, so each extreme
            // over a band of dy is at the ellipse's own extreme point (dy = ±b/√a, x = ±√a)
            // moved into the band.
            Shape::Ellipse {
                reach_y: c.sqrt(),
                slope: b / c,
                s: (a - b * b / c).max(0.0),
                c,
                turn: b / a.sqrt(),
            }
        };
        let size = TILE_SIZE as f64;
        rows.map(move |ty| match shape {
            Shape::Nowhere => empty.clone(),
            Shape::Square => columns.clone(),
            Shape::Ellipse {
                reach_y,
                slope,
                s,
                c,
                turn,
            } => {
                // The row's band of offsets from the mean, widened; the ellipse spans
                // |dy| ≤ √c.
                let low = (ty as f64 * size - v - MARGIN).max(-reach_y);
                let high = ((ty + 1) as f64 * size - v + MARGIN).min(reach_y);
                if low > high {
                    return empty.clone();
                }
                let edge = |dy: f64, side: f64| {
                    slope * dy + side * (s * (1.0 - dy * dy / c)).max(0.0).sqrt()
                };
                let right = edge(turn.clamp(low, high), 1.0);
                let left = edge((-turn).clamp(low, high), -1.0);
                let first = floor_small(((u + left - MARGIN) / size).clamp(-1.0, 1e9));
                let last = floor_small(((u + right + MARGIN) / size).clamp(-1.0, 1e9));
                let start = (first.max(0) as usize).max(columns.start);
                let end = ((last + 1).max(0) as usize).min(columns.end);
                start..end.max(start)
            }
        })
    }
}

/// r²·(1 + [`SLACK`]) of a Gaussian's opacity, which [`AlphaReach`] scales Σ_2D by, or
/// nowhere (o < 1/255). Pose-independent, so kept per Gaussian: 8 bytes, the nowhere case a
/// negative value (every r² is positive or NaN), since a scene holds millions of them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SquaredReach(f64);

impl SquaredReach {
    /// The squared reach of opacity `opacity` (NaN stays NaN: the square is kept).
    pub fn of_opacity(opacity: f64) -> Self {
        if opacity.is_finite() && opacity < MIN_ALPHA {
            return SquaredReach(-1.0);
        }
        // At o = 1/255 exactly the mean itself still draws: r² = 0 would be a point, so a tiny
        // one is kept (with the margin, the mean's tile).
        let r2 = (2.0 * (opacity / MIN_ALPHA).ln()).max(1e-6) * (1.0 + SLACK);
        SquaredReach(if opacity.is_nan() { f64::NAN } else { r2 })
    }

    /// r², or `None` where α reaches 1/255 nowhere.
    fn r2(self) -> Option<f64> {
        (self.0 >= 0.0 || self.0.is_nan()).then_some(self.0)
    }
}

/// What [`AlphaReach::row_columns`] works from, computed once per Gaussian.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// Reaches 1/255 nowhere.
    Nowhere,
    /// Cannot be told: the whole square.
    Square,
    /// The ellipse's constants (see `row_columns`).
    Ellipse {
        reach_y: f64,
        slope: f64,
        s: f64,
        c: f64,
        turn: f64,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the columns of row `ty` holding a pixel centre where the Gaussian's α
    /// reaches 1/255 (f64, the compositing rule), among `columns`.
    fn drawn_columns(covariance: [f64; 3], opacity: f64, mean: [f64; 2], ty: usize) -> Vec<usize> {
        let [a, b, c] = covariance;
        let det = a * c - b * b;
        let (qa, qb, qc) = (c / det, -b / det, a / det);
        (0..64)
            .filter(|&tx| {
                (0..TILE_SIZE).any(|py| {
                    (0..TILE_SIZE).any(|px| {
                        let dx = (tx * TILE_SIZE + px) as f64 + 0.5 - mean[0];
                        let dy = (ty * TILE_SIZE + py) as f64 + 0.5 - mean[1];
                        let power = -0.5 * (qa * dx * dx + qc * dy * dy) - qb * dx * dy;
                        (opacity * power.exp()).min(0.99) >= MIN_ALPHA
                    })
                })
            })
            .collect()
    }

    #[test]
    fn every_tile_where_alpha_reaches_1_255_is_kept_and_few_others() {
        let mut random = crate::test_random::uniform(0x5eed_u64);
        let (mut kept, mut drawn, mut square) = (0usize, 0usize, 0usize);
        for _ in 0..400 {
            // Elongated, rotated ellipses of 1–60 px, opacities from below 1/255 to 1.
            let (long, short) = (1.0 + 60.0 * random(), 0.3 + 6.0 * random());
            let angle = std::f64::consts::PI * random();
            let (cos, sin) = (angle.cos(), angle.sin());
            let covariance = [
                long * long * cos * cos + short * short * sin * sin + 0.3,
                (long * long - short * short) * cos * sin,
                long * long * sin * sin + short * short * cos * cos + 0.3,
            ];
            let opacity = random().powi(2);
            let mean = [200.0 + 600.0 * random(), 100.0 + 300.0 * random()];
            let reach = AlphaReach::new(covariance, opacity);
            for ty in 0..40 {
                let want = drawn_columns(covariance, opacity, mean, ty);
                let got = reach.row_columns(mean, ty..ty + 1, 0..64).next().unwrap();
                for tx in &want {
                    assert!(
                        got.contains(tx),
                        "tile ({tx}, {ty}) draws but is not kept: {covariance:?}, o {opacity}, mean {mean:?}, kept {got:?}"
                    );
                }
                kept += got.len();
                drawn += want.len();
                let radius = 3.0
                    * (0.5 * (covariance[0] + covariance[2])
                        + (0.25 * (covariance[0] - covariance[2]).powi(2) + covariance[1].powi(2))
                            .sqrt())
                    .sqrt();
                let rows = (mean[1] - radius) / 16.0..(mean[1] + radius) / 16.0;
                if rows.start.floor() <= ty as f64 && (ty as f64) < rows.end.ceil() {
                    square += (((mean[0] + radius) / 16.0).ceil()
                        - ((mean[0] - radius) / 16.0).floor())
                        as usize;
                }
            }
        }
        // The test's point beside safety: the kept tiles are near what draws, and well under
        // the square (measured here: 1.16× the tiles that draw, an eighth of the square's).
        assert!(
            kept as f64 <= 1.6 * drawn as f64,
            "kept {kept} tiles for {drawn} that draw"
        );
        assert!(
            kept * 4 <= square,
            "kept {kept} tiles against the square's {square}"
        );
    }

    #[test]
    fn below_1_255_nowhere_and_nan_everywhere() {
        let covariance = [100.0, 0.0, 100.0];
        let nowhere = AlphaReach::new(covariance, 0.5 / 255.0);
        let row = |reach: AlphaReach, ty: usize, columns| {
            reach
                .row_columns([100.0, 100.0], ty..ty + 1, columns)
                .next()
                .unwrap()
        };
        assert!(row(nowhere, 6, 0..20).is_empty());
        let unknown = AlphaReach::new(covariance, f64::NAN);
        assert_eq!(row(unknown, 0, 3..9), 3..9);
        // At exactly 1/255 the mean's own pixel draws.
        let point = AlphaReach::new(covariance, MIN_ALPHA);
        assert!(row(point, 6, 0..20).contains(&6));
    }
}
