//! The f32 projection of eight rows at once (AVX, chosen at run time), forward and backward.
//!
//! A row's projection is a chain of about 60 operations with two divisions and two
//! reciprocals; one row after another it was 5–6 % of an optimisation step's time on one
//! thread, and its backward (which recomputes the row) another 5 %. In lanes the same chains
//! run on eight rows of a pose side by side.
//!
//! The lanes compute `project_row`'s packed output and `backward_row`'s gradient terms bit for
//! bit: every value is the same IEEE operation in the same order (no fused multiply–add; Rust
//! does not contract the scalar code either), its `max` / `min` (`if a < b { b } else { a }`,
//! which keeps a NaN first operand) are an ordered compare and a blend, and the backward's
//! conditional steps (the clamps' gradients, the near plane) are blends on the same
//! comparisons. The caller adds the terms to the pose's sums row after row, as before.
//!
//! Written with `std::arch`, like the compositing kernels (`fused/cpu/simd.rs`).

use std::arch::x86_64::*;

use super::{Frame, Lens, SceneRows};
use crate::fused::projection::{PackedColumn, SPLAT_COLUMNS};
use crate::project::{LOW_PASS, NORMALISED_DET_FLOOR};

/// Rows projected side by side.
pub(super) const LANES: usize = 8;

/// Terms of a row's gradient: d L/d axes (9), d L/d centre (3), d L/ds (1).
pub(super) const TERMS: usize = 13;

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

    /// The gradient terms `[13][8]` (d L/d axes, d L/d centre, d L/ds; term, lane) of the
    /// rows of Gaussians `gaussians` whose output gradients are `v_rows` `[8, 7]`.
    pub(super) fn backward(
        self,
        scene: SceneRows<'_, f32>,
        gaussians: [usize; LANES],
        v_rows: &[[f32; SPLAT_COLUMNS]; LANES],
        frame: &Frame<f32>,
        lens: &Lens<f32>,
    ) -> [[f32; LANES]; TERMS] {
        // SAFETY: as above.
        unsafe { backward_eight(scene, gaussians, v_rows, frame, lens) }
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

/// `j·p + k·q` per axis (`cpu::project_row`'s t1, t2; `cpu::backward_row`'s v_t1, v_t2 and
/// v_axes[2]).
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

/// Component `k` of `components` `[K, N]` (the scene's `[9, N]` rows, or its `[1, N]`
/// opacities) for the eight Gaussians `g`.
#[target_feature(enable = "avx")]
#[inline]
fn gather(components: &[f32], n: usize, k: usize, g: &[usize; LANES]) -> __m256 {
    let row = &components[k * n..(k + 1) * n];
    _mm256_setr_ps(
        row[g[0]], row[g[1]], row[g[2]], row[g[3]], row[g[4]], row[g[5]], row[g[6]], row[g[7]],
    )
}

/// Every intermediate of eight rows' projection that the output and the backward read
/// (`cpu::Row` in lanes).
struct RowLanes {
    d: [__m256; 3],
    x: __m256,
    y: __m256,
    z: __m256,
    inv_z: __m256,
    x_over_z: __m256,
    y_over_z: __m256,
    tx: __m256,
    ty: __m256,
    j00: __m256,
    j11: __m256,
    j02: __m256,
    j12: __m256,
    sigma_t1: [__m256; 3],
    sigma_t2: [__m256; 3],
    a: __m256,
    b: __m256,
    c: __m256,
    inv_trace: __m256,
    trace: __m256,
    an: __m256,
    bn: __m256,
    cn: __m256,
    det_n: __m256,
    det_kept: __m256,
    scale: __m256,
    u: __m256,
    v: __m256,
}

/// `cpu::project_row` for eight Gaussians `g`, step by step in the same order.
#[target_feature(enable = "avx")]
fn row_eight(
    scene: SceneRows<'_, f32>,
    g: &[usize; LANES],
    frame: &Frame<f32>,
    lens: &Lens<f32>,
) -> RowLanes {
    let n = scene.opacities.len();
    let [r0, r1, r2] = frame.axes;
    let (r0, r1, r2) = (splat(r0), splat(r1), splat(r2));
    let d = [
        _mm256_sub_ps(
            gather(scene.components, n, 0, g),
            _mm256_set1_ps(frame.centre[0]),
        ),
        _mm256_sub_ps(
            gather(scene.components, n, 1, g),
            _mm256_set1_ps(frame.centre[1]),
        ),
        _mm256_sub_ps(
            gather(scene.components, n, 2, g),
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
        gather(scene.components, n, 3, g),
        gather(scene.components, n, 4, g),
        gather(scene.components, n, 5, g),
        gather(scene.components, n, 6, g),
        gather(scene.components, n, 7, g),
        gather(scene.components, n, 8, g),
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
    RowLanes {
        d,
        x,
        y,
        z,
        inv_z,
        x_over_z,
        y_over_z,
        tx,
        ty,
        j00,
        j11,
        j02,
        j12,
        sigma_t1,
        sigma_t2,
        a,
        b,
        c,
        inv_trace,
        trace,
        an,
        bn,
        cn,
        det_n,
        det_kept,
        scale,
        u,
        v,
    }
}

/// −v.
#[target_feature(enable = "avx")]
#[inline]
fn negate(v: __m256) -> __m256 {
    _mm256_xor_ps(v, _mm256_set1_ps(-0.0))
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
    let row = row_eight(scene, &g, frame, lens);
    let opacity = gather(scene.opacities, scene.opacities.len(), 0, &g);
    let columns = [
        row.u,
        row.v,
        mul(row.cn, row.scale),
        negate(mul(row.bn, row.scale)),
        mul(row.an, row.scale),
        opacity,
        row.z,
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

/// Eight values as lanes.
#[target_feature(enable = "avx")]
#[inline]
fn load(values: &[f32; LANES]) -> __m256 {
    // SAFETY: `values` is 8 readable f32.
    unsafe { _mm256_loadu_ps(values.as_ptr()) }
}

/// `b` where `mask`, else `a`.
#[target_feature(enable = "avx")]
#[inline]
fn select(mask: __m256, a: __m256, b: __m256) -> __m256 {
    _mm256_blendv_ps(a, b, mask)
}

/// `cpu::backward_row` for eight rows: their gradients d L/d axes `[k][e]` (9), d L/d centre
/// (3) and d L/ds (1), as terms `[13][8]` (term, lane), from the rows' output gradients
/// `v_rows` `[8, 7]` (row-major).
#[target_feature(enable = "avx")]
fn backward_eight(
    scene: SceneRows<'_, f32>,
    g: [usize; LANES],
    v_rows: &[[f32; SPLAT_COLUMNS]; LANES],
    frame: &Frame<f32>,
    lens: &Lens<f32>,
) -> [[f32; LANES]; TERMS] {
    let row = row_eight(scene, &g, frame, lens);
    let [r0, r1, r2] = frame.axes;
    let (r0, r1, r2) = (splat(r0), splat(r1), splat(r2));
    let zero = _mm256_setzero_ps();
    let two = _mm256_set1_ps(2.0);
    let column = |k: usize| -> [f32; LANES] { std::array::from_fn(|i| v_rows[i][k]) };
    let (vu, vv) = (load(&column(0)), load(&column(1)));
    let (va_out, vb_out, vc_out) = (load(&column(2)), load(&column(3)), load(&column(4)));
    let v_depth = load(&column(PackedColumn::Depth as usize));

    // conic = (cn, −bn, an) · scale, scale = 1 / (max(det_n, floor) · trace)
    let v_scale = add(
        _mm256_sub_ps(mul(va_out, row.cn), mul(vb_out, row.bn)),
        mul(vc_out, row.an),
    );
    let mut v_cn = mul(va_out, row.scale);
    let mut v_bn = negate(mul(vb_out, row.scale));
    let mut v_an = mul(vc_out, row.scale);
    let q = mul(row.det_kept, row.trace);
    let v_q = negate(_mm256_div_ps(v_scale, mul(q, q)));
    let v_det_kept = mul(v_q, row.trace);
    let mut v_trace = mul(v_q, row.det_kept);
    let floor = _mm256_set1_ps(NORMALISED_DET_FLOOR as f32);
    let v_det = select(
        _mm256_cmp_ps::<_CMP_LT_OQ>(row.det_n, floor),
        v_det_kept,
        zero,
    );
    v_an = add(v_an, mul(v_det, row.cn));
    v_cn = add(v_cn, mul(v_det, row.an));
    v_bn = add(v_bn, negate(mul(mul(two, row.bn), v_det)));
    let v_inv_trace = add(add(mul(v_an, row.a), mul(v_bn, row.b)), mul(v_cn, row.c));
    v_trace = add(
        v_trace,
        negate(mul(mul(v_inv_trace, row.inv_trace), row.inv_trace)),
    );
    let v_a = add(mul(v_an, row.inv_trace), v_trace);
    let v_b = mul(v_bn, row.inv_trace);
    let v_c = add(mul(v_cn, row.inv_trace), v_trace);

    // a = t1ᵀΣt1, b = t2ᵀΣt1, c = t2ᵀΣt2 (Σ symmetric)
    let (two_v_a, two_v_c) = (mul(two, v_a), mul(two, v_c));
    let v_t1 = combine(two_v_a, row.sigma_t1, v_b, row.sigma_t2);
    let v_t2 = combine(v_b, row.sigma_t1, two_v_c, row.sigma_t2);

    // t1 = j00·r0 + j02·r2, t2 = j11·r1 + j12·r2
    let v_j00 = dot(v_t1, r0);
    let v_j02 = dot(v_t1, r2);
    let v_j11 = dot(v_t2, r1);
    let v_j12 = dot(v_t2, r2);
    let mut v_axes = [
        [
            mul(row.j00, v_t1[0]),
            mul(row.j00, v_t1[1]),
            mul(row.j00, v_t1[2]),
        ],
        [
            mul(row.j11, v_t2[0]),
            mul(row.j11, v_t2[1]),
            mul(row.j11, v_t2[2]),
        ],
        combine(row.j02, v_t1, row.j12, v_t2),
    ];

    // j00 = fx/z, j11 = fy/z, j02 = −fx·tx/z, j12 = −fy·ty/z; tx = clamp(s·x/z, ±lim)/s
    let (fx, fy) = (_mm256_set1_ps(lens.fx), _mm256_set1_ps(lens.fy));
    let mut v_inv_z = _mm256_sub_ps(
        _mm256_sub_ps(
            add(mul(fx, v_j00), mul(fy, v_j11)),
            mul(mul(fx, row.tx), v_j02),
        ),
        mul(mul(fy, row.ty), v_j12),
    );
    let v_tx = negate(mul(mul(fx, row.inv_z), v_j02));
    let v_ty = negate(mul(mul(fy, row.inv_z), v_j12));
    let v_fx = _mm256_sub_ps(
        add(mul(vu, row.x_over_z), mul(v_j00, row.inv_z)),
        mul(mul(v_j02, row.tx), row.inv_z),
    );
    let v_fy = _mm256_sub_ps(
        add(mul(vv, row.y_over_z), mul(v_j11, row.inv_z)),
        mul(mul(v_j12, row.ty), row.inv_z),
    );
    let mut v_zoom = add(
        mul(v_fx, _mm256_set1_ps(lens.fx0)),
        mul(v_fy, _mm256_set1_ps(lens.fy0)),
    );
    let s = _mm256_set1_ps(lens.zoom);
    let v_kx = _mm256_div_ps(v_tx, s);
    let v_ky = _mm256_div_ps(v_ty, s);
    v_zoom = add(
        v_zoom,
        _mm256_sub_ps(
            negate(_mm256_div_ps(mul(v_tx, row.tx), s)),
            _mm256_div_ps(mul(v_ty, row.ty), s),
        ),
    );
    let mut v_x_over_z = mul(fx, vu);
    let inside_x = inside(mul(row.x_over_z, s), lens.lim_x);
    v_x_over_z = select(inside_x, v_x_over_z, add(v_x_over_z, mul(v_kx, s)));
    v_zoom = select(inside_x, v_zoom, add(v_zoom, mul(v_kx, row.x_over_z)));
    let mut v_y_over_z = mul(fy, vv);
    let inside_y = inside(mul(row.y_over_z, s), lens.lim_y);
    v_y_over_z = select(inside_y, v_y_over_z, add(v_y_over_z, mul(v_ky, s)));
    v_zoom = select(inside_y, v_zoom, add(v_zoom, mul(v_ky, row.y_over_z)));
    let v_x = mul(v_x_over_z, row.inv_z);
    let v_y = mul(v_y_over_z, row.inv_z);
    v_inv_z = add(v_inv_z, add(mul(v_x_over_z, row.x), mul(v_y_over_z, row.y)));
    let in_front = _mm256_cmp_ps::<_CMP_GE_OQ>(row.z, _mm256_set1_ps(lens.near));
    let v_z = select(
        in_front,
        v_depth,
        add(v_depth, negate(mul(mul(v_inv_z, row.inv_z), row.inv_z))),
    );

    // (x, y, z) = (r0·d, r1·d, r2·d), d = p − c
    for (v_axis, v_coordinate) in v_axes.iter_mut().zip([v_x, v_y, v_z]) {
        for (v, d) in v_axis.iter_mut().zip(row.d) {
            *v = add(*v, mul(v_coordinate, d));
        }
    }
    let v_centre = [
        negate(add(add(mul(v_x, r0[0]), mul(v_y, r1[0])), mul(v_z, r2[0]))),
        negate(add(add(mul(v_x, r0[1]), mul(v_y, r1[1])), mul(v_z, r2[1]))),
        negate(add(add(mul(v_x, r0[2]), mul(v_y, r1[2])), mul(v_z, r2[2]))),
    ];
    let [[a0, a1, a2], [a3, a4, a5], [a6, a7, a8]] = v_axes;
    let terms = [
        a0,
        a1,
        a2,
        a3,
        a4,
        a5,
        a6,
        a7,
        a8,
        v_centre[0],
        v_centre[1],
        v_centre[2],
        v_zoom,
    ];
    let mut out = [[0.0f32; LANES]; TERMS];
    for (lane, term) in out.iter_mut().zip(terms) {
        // SAFETY: `lane` is 8 writable f32.
        unsafe { _mm256_storeu_ps(lane.as_mut_ptr(), term) };
    }
    out
}

/// Lanes where `!(t > lim || t < −lim)` (`cpu::backward_row`'s `inside`: NaN is inside).
#[target_feature(enable = "avx")]
#[inline]
fn inside(t: __m256, lim: f32) -> __m256 {
    let outside = _mm256_or_ps(
        _mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_set1_ps(lim)),
        _mm256_cmp_ps::<_CMP_LT_OQ>(t, _mm256_set1_ps(-lim)),
    );
    _mm256_andnot_ps(outside, _mm256_castsi256_ps(_mm256_set1_epi32(-1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Intrinsics;
    use crate::fused::projection::ProjectionCamera;
    use crate::rodrigues::Rotation;

    /// The bits of `values`, every NaN as one value: a NaN's sign and payload are not kept by
    /// LLVM either (it may swap the operands of a product), and nothing reads them.
    fn nan_as_one(values: &[f32]) -> Vec<u32> {
        values
            .iter()
            .map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })
            .collect()
    }

    /// Eight rows in lanes give `project_row`'s packed output, and `backward_row`'s gradient
    /// terms, bit for bit, on rows built to
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
        let v_rows: Vec<[f32; SPLAT_COLUMNS]> = (0..n)
            .map(|_| std::array::from_fn(|_| ((next() - 0.5) * 4.0) as f32))
            .collect();
        for zoom in [1.0, 2.5] {
            let lens = Lens::<f32>::new(&camera, zoom);
            // The backward's terms, lane by lane against `backward_row`.
            for first in (0..n - LANES).step_by(LANES + 3) {
                let group: [usize; LANES] = std::array::from_fn(|i| first + i);
                let v = group.map(|g| v_rows[g]);
                let terms = lanes.backward(scene, group, &v, &frame, &lens);
                for (i, &g) in group.iter().enumerate() {
                    let row = scene.project(g, &frame, &lens);
                    let (v_axes, v_centre, v_zoom) =
                        super::super::backward_row(&row, &v_rows[g], &frame, &lens);
                    let want: Vec<f32> = v_axes
                        .iter()
                        .flatten()
                        .chain(&v_centre)
                        .chain([&v_zoom])
                        .copied()
                        .collect();
                    let got: Vec<f32> = terms.iter().map(|term| term[i]).collect();
                    assert_eq!(
                        nan_as_one(&got),
                        nan_as_one(&want),
                        "backward row {g}, zoom {zoom}: {got:?} against {want:?}"
                    );
                }
            }
            for first in (0..n - LANES).step_by(LANES + 1) {
                let group: [usize; LANES] = std::array::from_fn(|i| first + i);
                let mut packed = [0.0f32; LANES * SPLAT_COLUMNS];
                lanes.project(scene, group, &frame, &lens, &mut packed);
                for (i, &g) in group.iter().enumerate() {
                    let want = scene.project(g, &frame, &lens).out;
                    let got = &packed[i * SPLAT_COLUMNS..(i + 1) * SPLAT_COLUMNS];
                    assert_eq!(
                        nan_as_one(got),
                        nan_as_one(&want),
                        "row {g}, zoom {zoom}: {got:?} against {want:?}"
                    );
                }
            }
        }
    }
}
