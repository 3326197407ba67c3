//! The f32 projection of eight rows at once (AVX, chosen at run time), for the forward.
//!
//! A row's projection is a chain of about 60 operations with two divisions and two
//! reciprocals; one row after another it was 5–6 % of an optimisation step's time on one
//! thread. In lanes the same chain runs on eight rows of a pose side by side.
//!
//! The lanes compute `project_row`'s packed output bit for bit: every value is the same IEEE
//! operation in the same order (no fused multiply–add; Rust does not contract the scalar code
//! either), and its `max` / `min` (`if a < b { b } else { a }`, which keeps a NaN first operand)
//! are an ordered compare and a blend. The backward keeps the scalar rows: it skips the rows no
//! pixel read, one by one.
//!
//! Written with `std::arch`, like the compositing kernels (`fused/cpu/simd.rs`).

use std::arch::x86_64::*;

use super::{Frame, Lens, SceneRows};
use crate::fused::projection::SPLAT_COLUMNS;
use crate::project::{LOW_PASS, NORMALISED_DET_FLOOR};

/// Rows projected side by side.
pub(super) const LANES: usize = 8;

/// Proof that the processor has AVX: only [`Lanes::new`] makes one.
#[derive(Debug, Clone, Copy)]
pub(super) struct Lanes(());

impl Lanes {
    /// `Some` where the processor has AVX (the check is cached by the standard library).
    pub(super) fn new() -> Option<Self> {
        is_x86_feature_detected!("avx").then_some(Lanes(()))
    }

    /// The packed rows `[8, 7]` of Gaussians `gaussians` seen through `frame` and `lens`,
    /// written into `out`.
    pub(super) fn project(
        self,
        scene: SceneRows<'_, f32>,
        gaussians: [usize; LANES],
        frame: &Frame<f32>,
        lens: &Lens<f32>,
        out: &mut [f32; LANES * SPLAT_COLUMNS],
    ) {
        // SAFETY: `self` exists only where the processor has AVX.
        unsafe { project_eight(scene, gaussians, frame, lens, out) }
    }
}

/// `a·b` lane by lane (short, for the formulas below).
#[target_feature(enable = "avx")]
#[inline]
fn mul(a: __m256, b: __m256) -> __m256 {
    _mm256_mul_ps(a, b)
}

/// `a + b` lane by lane.
#[target_feature(enable = "avx")]
#[inline]
fn add(a: __m256, b: __m256) -> __m256 {
    _mm256_add_ps(a, b)
}

/// `p0·q0 + p1·q1 + p2·q2`, left to right (`cpu::dot`).
#[target_feature(enable = "avx")]
#[inline]
fn dot(p: [__m256; 3], q: [__m256; 3]) -> __m256 {
    add(add(mul(p[0], q[0]), mul(p[1], q[1])), mul(p[2], q[2]))
}

/// `cpu::max`: `b` where `a < b`, else `a` (a NaN `a` stays).
#[target_feature(enable = "avx")]
#[inline]
fn max(a: __m256, b: __m256) -> __m256 {
    _mm256_blendv_ps(a, b, _mm256_cmp_ps::<_CMP_LT_OQ>(a, b))
}

/// `cpu::min`: `b` where `b < a`, else `a`.
#[target_feature(enable = "avx")]
#[inline]
fn min(a: __m256, b: __m256) -> __m256 {
    _mm256_blendv_ps(a, b, _mm256_cmp_ps::<_CMP_LT_OQ>(b, a))
}

/// A value in every lane, per axis.
#[target_feature(enable = "avx")]
#[inline]
fn splat(axis: [f32; 3]) -> [__m256; 3] {
    [
        _mm256_set1_ps(axis[0]),
        _mm256_set1_ps(axis[1]),
        _mm256_set1_ps(axis[2]),
    ]
}

/// `j·p + k·q` per axis (`cpu::project_row`'s t1, t2).
#[target_feature(enable = "avx")]
#[inline]
fn combine(j: __m256, p: [__m256; 3], k: __m256, q: [__m256; 3]) -> [__m256; 3] {
    [
        add(mul(j, p[0]), mul(k, q[0])),
        add(mul(j, p[1]), mul(k, q[1])),
        add(mul(j, p[2]), mul(k, q[2])),
    ]
}

/// Σ·t for Σ = (xx, xy, xz, yy, yz, zz), each row's sum left to right (`cpu::sigma_times`).
#[target_feature(enable = "avx")]
#[inline]
fn sigma_times(s: &[__m256; 6], t: [__m256; 3]) -> [__m256; 3] {
    [
        add(add(mul(s[0], t[0]), mul(s[1], t[1])), mul(s[2], t[2])),
        add(add(mul(s[1], t[0]), mul(s[3], t[1])), mul(s[4], t[2])),
        add(add(mul(s[2], t[0]), mul(s[4], t[1])), mul(s[5], t[2])),
    ]
}

/// Component `k` of `components` `[9, N]` for the eight Gaussians `g`.
#[target_feature(enable = "avx")]
#[inline]
fn gather(components: &[f32], n: usize, k: usize, g: &[usize; LANES]) -> __m256 {
    let row = &components[k * n..(k + 1) * n];
    _mm256_setr_ps(
        row[g[0]], row[g[1]], row[g[2]], row[g[3]], row[g[4]], row[g[5]], row[g[6]], row[g[7]],
    )
}

/// `cpu::project_row`'s packed output for eight Gaussians.
#[target_feature(enable = "avx")]
fn project_eight(
    scene: SceneRows<'_, f32>,
    g: [usize; LANES],
    frame: &Frame<f32>,
    lens: &Lens<f32>,
    out: &mut [f32; LANES * SPLAT_COLUMNS],
) {
    let n = scene.opacities.len();
    let [r0, r1, r2] = frame.axes;
    let (r0, r1, r2) = (splat(r0), splat(r1), splat(r2));
    let d = [
        _mm256_sub_ps(
            gather(scene.components, n, 0, &g),
            _mm256_set1_ps(frame.centre[0]),
        ),
        _mm256_sub_ps(
            gather(scene.components, n, 1, &g),
            _mm256_set1_ps(frame.centre[1]),
        ),
        _mm256_sub_ps(
            gather(scene.components, n, 2, &g),
            _mm256_set1_ps(frame.centre[2]),
        ),
    ];
    let (x, y, z) = (dot(r0, d), dot(r1, d), dot(r2, d));
    let one = _mm256_set1_ps(1.0);
    let inv_z = _mm256_div_ps(one, max(z, _mm256_set1_ps(lens.near)));
    let x_over_z = mul(x, inv_z);
    let y_over_z = mul(y, inv_z);
    let (fx, fy) = (_mm256_set1_ps(lens.fx), _mm256_set1_ps(lens.fy));
    let u = add(mul(x_over_z, fx), _mm256_set1_ps(lens.cx));
    let v = add(mul(y_over_z, fy), _mm256_set1_ps(lens.cy));
    let zoom = _mm256_set1_ps(lens.zoom);
    let (lim_x, lim_y) = (_mm256_set1_ps(lens.lim_x), _mm256_set1_ps(lens.lim_y));
    let tx = _mm256_div_ps(
        max(min(mul(x_over_z, zoom), lim_x), _mm256_set1_ps(-lens.lim_x)),
        zoom,
    );
    let ty = _mm256_div_ps(
        max(min(mul(y_over_z, zoom), lim_y), _mm256_set1_ps(-lens.lim_y)),
        zoom,
    );
    let j00 = mul(inv_z, fx);
    let j11 = mul(inv_z, fy);
    let j02 = mul(mul(tx, inv_z), _mm256_set1_ps(-lens.fx));
    let j12 = mul(mul(ty, inv_z), _mm256_set1_ps(-lens.fy));
    let t1 = combine(j00, r0, j02, r2);
    let t2 = combine(j11, r1, j12, r2);
    let s = [
        gather(scene.components, n, 3, &g),
        gather(scene.components, n, 4, &g),
        gather(scene.components, n, 5, &g),
        gather(scene.components, n, 6, &g),
        gather(scene.components, n, 7, &g),
        gather(scene.components, n, 8, &g),
    ];
    let sigma_t1 = sigma_times(&s, t1);
    let sigma_t2 = sigma_times(&s, t2);
    let low_pass = _mm256_set1_ps(LOW_PASS as f32);
    let a = add(dot(t1, sigma_t1), low_pass);
    let b = dot(t2, sigma_t1);
    let c = add(dot(t2, sigma_t2), low_pass);
    let trace = add(a, c);
    let inv_trace = _mm256_div_ps(one, trace);
    let (an, bn, cn) = (mul(a, inv_trace), mul(b, inv_trace), mul(c, inv_trace));
    let det_n = _mm256_sub_ps(mul(an, cn), mul(bn, bn));
    let det_kept = max(det_n, _mm256_set1_ps(NORMALISED_DET_FLOOR as f32));
    let scale = _mm256_div_ps(one, mul(det_kept, trace));
    let opacity = _mm256_setr_ps(
        scene.opacities[g[0]],
        scene.opacities[g[1]],
        scene.opacities[g[2]],
        scene.opacities[g[3]],
        scene.opacities[g[4]],
        scene.opacities[g[5]],
        scene.opacities[g[6]],
        scene.opacities[g[7]],
    );
    let columns = [
        u,
        v,
        mul(cn, scale),
        _mm256_xor_ps(mul(bn, scale), _mm256_set1_ps(-0.0)),
        mul(an, scale),
        opacity,
        z,
    ];
    // Column-major lanes to row-major rows.
    let mut lanes = [[0.0f32; LANES]; SPLAT_COLUMNS];
    for (lane, column) in lanes.iter_mut().zip(columns) {
        // SAFETY: `lane` is 8 writable f32.
        unsafe { _mm256_storeu_ps(lane.as_mut_ptr(), column) };
    }
    for (i, row) in out.chunks_exact_mut(SPLAT_COLUMNS).enumerate() {
        for (value, lane) in row.iter_mut().zip(&lanes) {
            *value = lane[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Intrinsics;
    use crate::fused::projection::ProjectionCamera;
    use crate::rodrigues::Rotation;

    /// Eight rows in lanes give `project_row`'s packed output bit for bit, on rows built to
    /// reach every branch: in front of, straddling and behind the near plane, inside and beyond
    /// the clamp of x/z and y/z, needles and discs from 10⁻⁶ to 10³ across, zoomed and not,
    /// and non-finite centres, covariances and opacities.
    #[test]
    fn eight_lanes_project_what_one_by_one_projects_bit_for_bit() {
        let Some(lanes) = Lanes::new() else {
            return; // no AVX: the scalar rows are the only ones
        };
        let mut next = crate::test_random::uniform(0x9a0e_c7ed_u64);
        let n = 4000;
        let mut components = vec![0.0f32; 9 * n];
        let mut opacities = vec![0.0f32; n];
        let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, 1e30];
        for g in 0..n {
            let spread = if g % 3 == 0 { 40.0 } else { 4.0 };
            for e in 0..3 {
                components[e * n + g] = ((next() - 0.5) * spread) as f32;
            }
            // Along the view axis (z from the eye at −5): around the near plane for some.
            if g % 5 == 0 {
                components[2 * n + g] = (-5.0 + (next() - 0.5) * 0.02) as f32;
            }
            // Σ = M·Mᵀ of a random M of size 10⁻⁶ … 10³.
            let size = 10f64.powf(-6.0 + 9.0 * next());
            let m: [f64; 9] = std::array::from_fn(|_| (next() - 0.5) * size);
            let entry = |i: usize, j: usize| {
                (0..3).map(|k| m[3 * i + k] * m[3 * j + k]).sum::<f64>() as f32
            };
            let sigma = [
                entry(0, 0),
                entry(0, 1),
                entry(0, 2),
                entry(1, 1),
                entry(1, 2),
                entry(2, 2),
            ];
            for (k, value) in sigma.into_iter().enumerate() {
                components[(3 + k) * n + g] = value;
            }
            opacities[g] = next() as f32;
            if g % 61 == 0 {
                let special = specials[(g / 61 / 10) % specials.len()];
                match (g / 61) % 10 {
                    k @ 0..=8 => components[k * n + g] = special,
                    _ => opacities[g] = special,
                }
            }
        }
        let scene = SceneRows {
            components: &components,
            opacities: &opacities,
        };
        let camera = ProjectionCamera::new(&Intrinsics::centred(200.0, 320, 240), 0.01);
        let pose = [0.1, -0.2, 0.05, 0.3, -0.1, -5.0];
        let rotation = Rotation::new([pose[0], pose[1], pose[2]]);
        let frame = Frame::<f32>::new(&pose, &rotation);
        for zoom in [1.0, 2.5] {
            let lens = Lens::<f32>::new(&camera, zoom);
            for first in (0..n - LANES).step_by(LANES + 1) {
                let group: [usize; LANES] = std::array::from_fn(|i| first + i);
                let mut packed = [0.0f32; LANES * SPLAT_COLUMNS];
                lanes.project(scene, group, &frame, &lens, &mut packed);
                for (i, &g) in group.iter().enumerate() {
                    let want = scene.project(g, &frame, &lens).out;
                    let got = &packed[i * SPLAT_COLUMNS..(i + 1) * SPLAT_COLUMNS];
                    // A NaN's sign and payload are not kept by LLVM either (it may swap the
                    // operands of a product), and nothing reads them: any NaN is one value.
                    let bits = |v: &[f32]| {
                        v.iter()
                            .map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })
                            .collect::<Vec<_>>()
                    };
                    assert_eq!(
                        bits(got),
                        bits(&want),
                        "row {g}, zoom {zoom}: {got:?} against {want:?}"
                    );
                }
            }
        }
    }
}
