//! [`Camera::decide`] on four Gaussians at once, in f64 lanes (AVX, chosen at run time).
//!
//! Deciding is a chain of divisions and square roots per Gaussian (the perspective divide, the
//! reach bound, the eigenvalue and the radius), which one Gaussian after another left the
//! processor waiting on: a first-try guitar step spent 30 ms of one thread deciding 0.77 M
//! Gaussians. In lanes the same operations run on four Gaussians side by side.
//!
//! The lanes compute the scalar decision bit for bit, so tile lists, depth order and every
//! pixel stay where they were:
//! - every value is the same IEEE operation in the same order (glam's dot products are
//!   `(x·x') + (y·y') + (z·z')`), with no fused multiply–add (Rust does not contract the scalar
//!   code either), and the rounding up of the radius is the exact `roundpd` towards +∞;
//! - every test is the same comparison, ordered where the scalar `<`, `<=`, `>` is false on NaN;
//! - `f64::max(z, near)` and `f64::max(x, 0)` give the other operand for a NaN, as `maxpd` does
//!   with the NaN first; `f64::clamp` keeps a NaN, so it is two ordered compares and blends.
//!
//! Written with `std::arch`, like the compositing kernels (`fused/cpu/simd.rs`).

use std::arch::x86_64::*;

use glam::DVec3;

use super::{Camera, Decided, HostGeometry, Reach};
use crate::alpha_reach::AlphaReach;
use crate::project::{LOW_PASS, NORMALISED_DET_FLOOR};

/// Gaussians decided side by side.
const LANES: usize = 4;

/// Proof that the processor has AVX: only [`Lanes::new`] makes one.
#[derive(Debug, Clone, Copy)]
pub(super) struct Lanes(());

impl Lanes {
    /// `Some` where the processor has AVX (the check is cached by the standard library).
    pub(super) fn new() -> Option<Self> {
        is_x86_feature_detected!("avx").then_some(Lanes(()))
    }

    /// The decisions of `camera` on the Gaussians at sorted positions `positions` that it
    /// keeps, in their order, appended to `kept` (as [`Camera::kept`] one by one).
    pub(super) fn decide(
        self,
        camera: &Camera,
        geometry: &HostGeometry,
        positions: impl Iterator<Item = usize>,
        reach: Reach,
        kept: &mut Vec<Decided>,
    ) {
        let mut group = [0usize; LANES];
        let mut filled = 0;
        for k in positions {
            group[filled] = k;
            filled += 1;
            if filled == LANES {
                // SAFETY: `self` exists only where the processor has AVX.
                unsafe { decide_four(camera, geometry, group, reach, kept) };
                filled = 0;
            }
        }
        kept.extend(
            group[..filled]
                .iter()
                .filter_map(|&k| camera.kept(geometry, k as u32, reach)),
        );
    }
}

/// The entries `ks` of `table`. Written out, not `ks.map(..)`: LLVM kept the array maps out
/// of line, and their calls were a third of the lanes' time.
#[inline(always)]
fn rows_of<T: Copy>(table: &[T], ks: [usize; LANES]) -> [T; LANES] {
    [table[ks[0]], table[ks[1]], table[ks[2]], table[ks[3]]]
}

/// Entry `i` of each of four rows, as f64 lanes (the exact widening `f64::from` is).
#[target_feature(enable = "avx")]
#[inline]
fn column<const W: usize>(rows: &[[f32; W]; LANES], i: usize) -> __m256d {
    _mm256_cvtps_pd(_mm_setr_ps(rows[0][i], rows[1][i], rows[2][i], rows[3][i]))
}

/// The lanes' values.
#[target_feature(enable = "avx")]
#[inline]
fn values(v: __m256d) -> [f64; LANES] {
    let mut out = [0.0; LANES];
    // SAFETY: `out` is 4 writable f64.
    unsafe { _mm256_storeu_pd(out.as_mut_ptr(), v) };
    out
}

/// `a·b` lane by lane (short, for the formulas below).
#[target_feature(enable = "avx")]
#[inline]
fn mul(a: __m256d, b: __m256d) -> __m256d {
    _mm256_mul_pd(a, b)
}

/// `a + b` lane by lane.
#[target_feature(enable = "avx")]
#[inline]
fn add(a: __m256d, b: __m256d) -> __m256d {
    _mm256_add_pd(a, b)
}

/// `(x0·y0) + (x1·y1) + (x2·y2)`, glam's dot product.
#[target_feature(enable = "avx")]
#[inline]
fn dot(x: [__m256d; 3], y: [__m256d; 3]) -> __m256d {
    add(add(mul(x[0], y[0]), mul(x[1], y[1])), mul(x[2], y[2]))
}

/// `f64::clamp(x, lo, hi)`: a NaN stays NaN.
#[target_feature(enable = "avx")]
#[inline]
fn clamp(x: __m256d, lo: f64, hi: f64) -> __m256d {
    let (lo, hi) = (_mm256_set1_pd(lo), _mm256_set1_pd(hi));
    let x = _mm256_blendv_pd(x, lo, _mm256_cmp_pd::<_CMP_LT_OQ>(x, lo));
    _mm256_blendv_pd(x, hi, _mm256_cmp_pd::<_CMP_GT_OQ>(x, hi))
}

/// Lanes where `x` is finite.
#[target_feature(enable = "avx")]
#[inline]
fn finite(x: __m256d) -> __m256d {
    let magnitude = _mm256_andnot_pd(_mm256_set1_pd(-0.0), x);
    _mm256_cmp_pd::<_CMP_LT_OQ>(magnitude, _mm256_set1_pd(f64::INFINITY))
}

/// A value in every lane, per axis.
#[target_feature(enable = "avx")]
#[inline]
fn splat(axis: DVec3) -> [__m256d; 3] {
    [
        _mm256_set1_pd(axis.x),
        _mm256_set1_pd(axis.y),
        _mm256_set1_pd(axis.z),
    ]
}

/// `p·s + q·t` per axis (glam's `p * s + q * t`).
#[target_feature(enable = "avx")]
#[inline]
fn combine(p: [__m256d; 3], s: __m256d, q: [__m256d; 3], t: __m256d) -> [__m256d; 3] {
    [
        add(mul(p[0], s), mul(q[0], t)),
        add(mul(p[1], s), mul(q[1], t)),
        add(mul(p[2], s), mul(q[2], t)),
    ]
}

/// Σ·t for the symmetric Σ = (xx, xy, xz, yy, yz, zz), each row's sum left to right.
#[target_feature(enable = "avx")]
#[inline]
fn times_covariance(sigma: [__m256d; 6], t: [__m256d; 3]) -> [__m256d; 3] {
    let [sxx, sxy, sxz, syy, syz, szz] = sigma;
    [
        add(add(mul(sxx, t[0]), mul(sxy, t[1])), mul(sxz, t[2])),
        add(add(mul(sxy, t[0]), mul(syy, t[1])), mul(syz, t[2])),
        add(add(mul(sxz, t[0]), mul(syz, t[1])), mul(szz, t[2])),
    ]
}

/// Lanes set in any of `masks`.
#[target_feature(enable = "avx")]
#[inline]
fn any<const M: usize>(masks: [__m256d; M]) -> __m256d {
    let mut any = _mm256_setzero_pd();
    for mask in masks {
        any = _mm256_or_pd(any, mask);
    }
    any
}

/// Lanes set in all of `masks`.
#[target_feature(enable = "avx")]
#[inline]
fn all<const M: usize>(masks: [__m256d; M]) -> __m256d {
    let mut all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    for mask in masks {
        all = _mm256_and_pd(all, mask);
    }
    all
}

/// [`Camera::kept`] on the Gaussians at sorted positions `ks`, appending the kept ones to
/// `kept` in lane order.
#[target_feature(enable = "avx")]
fn decide_four(
    camera: &Camera,
    geometry: &HostGeometry,
    ks: [usize; LANES],
    reach: Reach,
    kept: &mut Vec<Decided>,
) {
    let bounds = reach.bounds;
    let intrinsics = camera.intrinsics;
    let (fx, fy) = (intrinsics.fx, intrinsics.fy);
    let [r0, r1, r2] = camera.r;
    let (r0, r1, r2) = (splat(r0), splat(r1), splat(r2));
    let near = _mm256_set1_pd(camera.near);
    let means = rows_of(&geometry.means, ks);
    let centre = camera.centre;
    // d = mean − centre, per axis.
    let d = [
        _mm256_sub_pd(column(&means, 0), _mm256_set1_pd(centre.x)),
        _mm256_sub_pd(column(&means, 1), _mm256_set1_pd(centre.y)),
        _mm256_sub_pd(column(&means, 2), _mm256_set1_pd(centre.z)),
    ];
    let (x, y, z) = (dot(d, r0), dot(d, r1), dot(d, r2));
    let z_safe = _mm256_max_pd(z, near);
    let (xz, yz) = (_mm256_div_pd(x, z_safe), _mm256_div_pd(y, z_safe));
    let u = add(mul(_mm256_set1_pd(fx), xz), _mm256_set1_pd(intrinsics.cx));
    let v = add(mul(_mm256_set1_pd(fy), yz), _mm256_set1_pd(intrinsics.cy));
    let (tx, ty) = (
        clamp(xz, -camera.limits.0, camera.limits.0),
        clamp(yz, -camera.limits.1, camera.limits.1),
    );
    let one = _mm256_set1_pd(1.0);
    let j_norm2 = _mm256_div_pd(
        add(
            mul(_mm256_set1_pd(fx * fx), add(one, mul(tx, tx))),
            mul(_mm256_set1_pd(fy * fy), add(one, mul(ty, ty))),
        ),
        mul(z_safe, z_safe),
    );
    let variances = rows_of(&geometry.max_variance, ks);
    let max_variance = _mm256_cvtps_pd(_mm_setr_ps(
        variances[0],
        variances[1],
        variances[2],
        variances[3],
    ));
    let bound = add(
        mul(
            _mm256_set1_pd(3.0),
            _mm256_sqrt_pd(add(mul(j_norm2, max_variance), _mm256_set1_pd(LOW_PASS))),
        ),
        one,
    );
    // The scalar test's rejections, each an ordered compare.
    let stored_depth = _mm256_cvtps_pd(_mm256_cvtpd_ps(z));
    let rejected = any([
        _mm256_cmp_pd::<_CMP_LE_OQ>(z, near),
        _mm256_cmp_pd::<_CMP_GT_OQ>(stored_depth, _mm256_set1_pd(f64::from(reach.max_depth))),
        _mm256_cmp_pd::<_CMP_LT_OQ>(add(u, bound), _mm256_set1_pd(bounds[0])),
        _mm256_cmp_pd::<_CMP_LT_OQ>(add(v, bound), _mm256_set1_pd(bounds[1])),
        _mm256_cmp_pd::<_CMP_GT_OQ>(_mm256_sub_pd(u, bound), _mm256_set1_pd(bounds[2])),
        _mm256_cmp_pd::<_CMP_GT_OQ>(_mm256_sub_pd(v, bound), _mm256_set1_pd(bounds[3])),
    ]);
    if _mm256_movemask_pd(rejected) == 0b1111 {
        return;
    }
    // t1 = r0·(fx/z) + r2·(−fx·tx/z), t2 = r1·(fy/z) + r2·(−fy·ty/z).
    let t1 = combine(
        r0,
        _mm256_div_pd(_mm256_set1_pd(fx), z_safe),
        r2,
        _mm256_div_pd(mul(_mm256_set1_pd(-fx), tx), z_safe),
    );
    let t2 = combine(
        r1,
        _mm256_div_pd(_mm256_set1_pd(fy), z_safe),
        r2,
        _mm256_div_pd(mul(_mm256_set1_pd(-fy), ty), z_safe),
    );
    let covariances = rows_of(&geometry.covariances, ks);
    let sigma = [
        column(&covariances, 0),
        column(&covariances, 1),
        column(&covariances, 2),
        column(&covariances, 3),
        column(&covariances, 4),
        column(&covariances, 5),
    ];
    let s_t1 = times_covariance(sigma, t1);
    let s_t2 = times_covariance(sigma, t2);
    let low_pass = _mm256_set1_pd(LOW_PASS);
    let a = add(dot(t1, s_t1), low_pass);
    let b = dot(t1, s_t2);
    let c = add(dot(t2, s_t2), low_pass);
    // `project::cull_and_radius`.
    let trace = add(a, c);
    let det = _mm256_sub_pd(mul(a, c), mul(b, b));
    let ok = all([
        _mm256_cmp_pd::<_CMP_GT_OQ>(z, near),
        finite(trace),
        finite(b),
        _mm256_cmp_pd::<_CMP_GT_OQ>(trace, _mm256_setzero_pd()),
        _mm256_cmp_pd::<_CMP_GT_OQ>(
            _mm256_div_pd(det, mul(trace, trace)),
            _mm256_set1_pd(NORMALISED_DET_FLOOR),
        ),
    ]);
    let keep = _mm256_movemask_pd(_mm256_andnot_pd(rejected, ok));
    if keep == 0 {
        return;
    }
    let mid = mul(_mm256_set1_pd(0.5), trace);
    let lambda_max = add(
        mid,
        _mm256_sqrt_pd(_mm256_max_pd(
            _mm256_sub_pd(mul(mid, mid), det),
            _mm256_setzero_pd(),
        )),
    );
    let radius = _mm256_round_pd::<{ _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC }>(mul(
        _mm256_set1_pd(3.0),
        _mm256_sqrt_pd(lambda_max),
    ));
    let (u, v, z, radius) = (values(u), values(v), values(z), values(radius));
    let (a, b, c) = (values(a), values(b), values(c));
    for lane in (0..LANES).filter(|lane| keep & (1 << lane) != 0) {
        let k = ks[lane];
        kept.push(Decided {
            gaussian: geometry.scene_from_sorted[k],
            means_2d: [u[lane] as f32, v[lane] as f32],
            depth: z[lane] as f32,
            radius: radius[lane] as f32,
            reach: AlphaReach::scaled([a[lane], b[lane], c[lane]], geometry.squared_reach[k]),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Intrinsics, Pose};
    use splatraj_scene::Scene;

    /// Every field's bits, so that −0 against +0 or a NaN's payload would show.
    fn bits(d: &Decided) -> [u64; 8] {
        let [a, b, c] = d.reach.ellipse_for_tests();
        [
            u64::from(d.gaussian),
            u64::from(d.means_2d[0].to_bits()),
            u64::from(d.means_2d[1].to_bits()),
            u64::from(d.depth.to_bits()),
            u64::from(d.radius.to_bits()),
            u64::from(a.to_bits()),
            u64::from(b.to_bits()),
            u64::from(c.to_bits()),
        ]
    }

    /// The lanes keep exactly the Gaussians the scalar decision keeps, with the same bits,
    /// on Gaussians chosen to hit every branch: behind and straddling the near plane, beside
    /// and beyond the pass's box and depth, needles and discs from 10⁻⁶ to 10³ across,
    /// opacities below 1/255, non-finite means, scales and opacities, and a group count that
    /// leaves a scalar tail.
    #[test]
    fn four_lanes_decide_what_one_by_one_decides_bit_for_bit() {
        let Some(lanes) = Lanes::new() else {
            return; // no AVX: the scalar decision is the only one
        };
        let mut next = crate::test_random::uniform(0xdec1_de00_u64);
        let mut scene = Scene::default();
        let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, 1e30];
        for i in 0..40_003 {
            let mut mean = [0, 1, 2].map(|_| ((next() - 0.5) * 12.0) as f32);
            // Near the camera's plane at z = 4 from the eye: straddling, just behind, just in front.
            if i % 7 == 0 {
                mean[2] = (-4.0 + (next() - 0.5) * 0.2) as f32;
            }
            let size = 10f64.powf(-6.0 + 9.0 * next());
            let mut scales = [0, 1, 2].map(|_| (size * (0.001 + next())) as f32);
            let mut opacity = next().powi(3) as f32;
            if i % 97 == 0 {
                let special = specials[(i / 97 / 3) % specials.len()];
                match (i / 97) % 3 {
                    0 => mean[(i / 3) % 3] = special,
                    1 => scales[(i / 5) % 3] = special,
                    _ => opacity = special,
                }
            }
            scene.means.push(mean);
            scene.scales.push(scales);
            scene
                .rotations
                .push([0, 1, 2, 3].map(|_| (next() - 0.5) as f32));
            scene.opacities.push(opacity);
        }
        let geometry = HostGeometry::new(&scene);
        let intrinsics = Intrinsics::centred(300.0, 320, 240);
        let eye = DVec3::new(0.3, -0.2, -8.0);
        let pose = Pose::look_at(eye, DVec3::ZERO, DVec3::Y).expect("a pose");
        let camera = Camera::new(&pose, &intrinsics, 0.05);
        let reaches = [
            Reach::everywhere([0.0, 0.0, 320.0, 240.0]),
            Reach {
                bounds: [96.0, 48.0, 160.0, 128.0],
                max_depth: 8.5,
            },
        ];
        let mut kept_total = 0;
        for reach in reaches {
            let positions = 0..geometry.len();
            let one_by_one: Vec<Decided> = positions
                .clone()
                .filter_map(|k| camera.kept(&geometry, k as u32, reach))
                .collect();
            let mut four = Vec::new();
            lanes.decide(&camera, &geometry, positions, reach, &mut four);
            assert_eq!(four.len(), one_by_one.len(), "kept {reach:?}");
            for (got, want) in four.iter().zip(&one_by_one) {
                assert_eq!(bits(got), bits(want), "{got:?} against {want:?}");
            }
            kept_total += one_by_one.len();
        }
        // The test's point: both kinds of outcome happen often.
        assert!(kept_total > 10_000, "kept {kept_total}");
        assert!(kept_total < 70_000, "kept {kept_total}");
    }
}
