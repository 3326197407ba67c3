//! The f32 tile kernels in 8 lanes: AVX2 + FMA, chosen at run time ([`Lanes::new`]).
//!
//! Each Gaussian of a tile's list is evaluated on half a tile row (8 pixels) at a time: the
//! lanes of the half rows its 1/255 box covers and whose pixels are open (forward) or replaying
//! (backward), the others masked off. They compute the scalar kernels' numbers bit for bit:
//! - every rule is the same comparison (an ordered compare where the scalar `<` or `>` is false
//!   on NaN), so every decision is too (skip below 1/255, the α clamp at 0.99, the power clamp
//!   at 0, the stop before T < the stop transmittance, the tile's early exit);
//! - every value is the same IEEE operations in the same order, with no fused multiply–add
//!   (Rust does not contract the scalar code either), e^x included ([`super::lanes_exp`]);
//! - the backward's per-Gaussian sums are added pixel after pixel in the scalar order
//!   ([`SlotTerms`]); the per-pixel work before them is in lanes.
//!
//! Bit-identical results keep the optimiser's path, and the figures of runs, where they were:
//! an ulp in a gradient sum moves a trajectory's TCE visibly (`docs/rasterizer.md`).
//!
//! Written with `std::arch` rather than a SIMD crate: the kernels need masked blends, movemask,
//! a 64-bit gather and f32↔f64 conversions, which the portable crates wrap no more simply.

use std::arch::x86_64::*;
use std::ops::Range;

use super::lanes_exp::exp;
use super::{
    Corner, Footprint, Gathered, HostSplats, Replay, RowBits, Splat, TileForward, Walk,
    column_bits, valid_bits,
};
use crate::fused::plan::CompositePlan;
use crate::rasterize::{MAX_ALPHA, MIN_ALPHA};
use crate::tiles::{TILE_PIXELS, TILE_SIZE};

/// Lanes of a vector: half a tile row.
const LANES: usize = 8;

/// Proof that the processor has AVX2 and FMA: only [`Lanes::new`] makes one.
#[derive(Debug, Clone, Copy)]
pub(super) struct Lanes(());

impl Lanes {
    /// `Some` where the processor has AVX2 and FMA (the check is cached by the standard
    /// library: an atomic load).
    pub(super) fn new() -> Option<Self> {
        (is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")).then_some(Lanes(()))
    }

    /// The forward of work tile `w` (as `cpu::forward_tile`).
    pub(super) fn forward_tile(
        self,
        splats: &HostSplats<f32>,
        footprints: &[Footprint<f32>],
        plan: &CompositePlan,
        w: usize,
    ) -> TileForward<f32> {
        // SAFETY: `self` exists only where the processor has AVX2 and FMA.
        unsafe { forward_tile(splats, footprints, plan, w) }
    }

    /// The gradient slots of work tile `w` (as `cpu::backward_tile`), from its pixels' output
    /// gradients `v_planes` `[C + 1, 256]`.
    pub(super) fn backward_tile(
        self,
        splats: &HostSplats<f32>,
        plan: &CompositePlan,
        state: &super::ForwardState<f32>,
        v_planes: Vec<f32>,
        w: usize,
    ) -> Vec<f32> {
        // SAFETY: as above.
        unsafe { backward_tile(splats, plan, state, v_planes, w) }
    }
}

/// Eight values of `values` from `at`.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn load(values: &[f32], at: usize) -> __m256 {
    let lanes: &[f32; LANES] = values[at..at + LANES].try_into().expect("8 values");
    // SAFETY: `lanes` is 8 readable f32.
    unsafe { _mm256_loadu_ps(lanes.as_ptr()) }
}

/// Writes eight values into `values` from `at`.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn store(values: &mut [f32], at: usize, v: __m256) {
    let lanes: &mut [f32; LANES] = (&mut values[at..at + LANES]).try_into().expect("8 values");
    // SAFETY: `lanes` is 8 writable f32.
    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), v) }
}

/// `old + addend` where `mask`, else `old`, written into `values` from `at` (`old` being what
/// `values` holds there).
///
/// The lanes outside `mask` add +0, which leaves every value as it was (no sum here is −0:
/// they start at +0). Blending the stored value with the loaded one instead has LLVM turn the
/// store into a masked store (`vmaskmovps`), from which AMD processors cannot forward to the
/// next entry's load of the same pixels: that stall was about a third of a 720p frame's
/// forward (66–72 → 41–45 ms, `docs/results.md`).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn add_where(values: &mut [f32], at: usize, old: __m256, addend: __m256, mask: __m256) {
    store(values, at, _mm256_add_ps(old, _mm256_and_ps(addend, mask)));
}

/// −v.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn negate(v: __m256) -> __m256 {
    _mm256_xor_ps(v, _mm256_set1_ps(-0.0))
}

/// The lane mask of the low 8 bits of `bits` (lane i set where bit i is).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn mask_of(bits: u32) -> __m256 {
    let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), bit);
    _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, bit))
}

/// The bits of a lane mask.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn bits_of(mask: __m256) -> u32 {
    _mm256_movemask_ps(mask) as u32
}

/// `a & !b` on masks.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn and_not(a: __m256, b: __m256) -> __m256 {
    _mm256_andnot_ps(b, a)
}

/// The half rows (y, half, lanes) of rows `ys` in which `rows` has a bit among `columns`, with
/// those bits as lanes (bit i for pixel 8·half + i), in row-major order. `rows` is read as it
/// is when called: the forward clears the bits of the row it is in, never of a later one.
fn half_rows(
    rows: RowBits,
    columns: u16,
    ys: Range<usize>,
) -> impl Iterator<Item = (usize, usize, u32)> {
    ys.flat_map(move |y| {
        let bits = u32::from(rows[y] & columns);
        (0..TILE_SIZE / LANES).filter_map(move |half| {
            let lanes = (bits >> (half * LANES)) & 0xff;
            (lanes != 0).then_some((y, half, lanes))
        })
    })
}

/// The Gaussian of one list entry placed on a tile, broadcast to the lanes.
struct SplatLanes {
    mx: __m256,
    my: __m256,
    a: __m256,
    b: __m256,
    c: __m256,
    opacity: __m256,
    skip_below: __m256,
}

/// What a Gaussian is at the 8 pixels of half a tile row (as `Splat::at`).
struct AtLanes {
    /// The lanes asked for whose α is not surely below 1/255 (power ≥ the skip threshold).
    live: __m256,
    dx: __m256,
    dy: __m256,
    /// Before the clamp at 0.
    power: __m256,
    /// e^min(power, 0) (0 in a half of 4 lanes none of which is live).
    exp_power: __m256,
    /// o·e^min(power, 0), before the clamp at 0.99.
    raw: __m256,
    /// min(0.99, raw).
    alpha: __m256,
}

impl SplatLanes {
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn new(splat: &Splat<f32>) -> Self {
        SplatLanes {
            mx: _mm256_set1_ps(splat.mx),
            my: _mm256_set1_ps(splat.my),
            a: _mm256_set1_ps(splat.a),
            b: _mm256_set1_ps(splat.b),
            c: _mm256_set1_ps(splat.c),
            opacity: _mm256_set1_ps(splat.opacity),
            skip_below: _mm256_set1_ps(splat.skip_below),
        }
    }

    /// The Gaussian at the pixels (8·half + i, y) of the lanes i set in `lanes`; `None` where
    /// none of them is live. The operations and their order are `Splat::at`'s and
    /// `clamp_alpha`'s.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn at(&self, y: usize, half: usize, lanes: u32) -> Option<AtLanes> {
        let column = _mm256_add_ps(
            _mm256_setr_ps(0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5),
            _mm256_set1_ps((half * LANES) as f32),
        );
        let dx = _mm256_sub_ps(column, self.mx);
        let dy = _mm256_sub_ps(_mm256_set1_ps(y as f32 + 0.5), self.my);
        // −(½ (a dx dx + c dy dy)) − b dx dy, each product left to right.
        let quadratic = _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(self.a, dx), dx),
            _mm256_mul_ps(_mm256_mul_ps(self.c, dy), dy),
        );
        let power = _mm256_sub_ps(
            negate(_mm256_mul_ps(_mm256_set1_ps(0.5), quadratic)),
            _mm256_mul_ps(_mm256_mul_ps(self.b, dx), dy),
        );
        // Skipped where power < skip_below (false on NaN, as in the scalar code).
        let skip = _mm256_cmp_ps::<_CMP_LT_OQ>(power, self.skip_below);
        let live = and_not(mask_of(lanes), skip);
        if bits_of(live) == 0 {
            return None;
        }
        let zero = _mm256_setzero_ps();
        let clamped = _mm256_blendv_ps(power, zero, _mm256_cmp_ps::<_CMP_GT_OQ>(power, zero));
        let exp_power = exp(clamped, bits_of(live));
        let raw = _mm256_mul_ps(self.opacity, exp_power);
        let max_alpha = _mm256_set1_ps(MAX_ALPHA as f32);
        let alpha = _mm256_blendv_ps(raw, max_alpha, _mm256_cmp_ps::<_CMP_GT_OQ>(raw, max_alpha));
        let faint = _mm256_cmp_ps::<_CMP_LT_OQ>(alpha, _mm256_set1_ps(MIN_ALPHA as f32));
        let live = and_not(live, faint);
        (bits_of(live) != 0).then_some(AtLanes {
            live,
            dx,
            dy,
            power,
            exp_power,
            raw,
            alpha,
        })
    }
}

/// `cpu::forward_tile` in 8 lanes.
#[target_feature(enable = "avx2,fma")]
fn forward_tile(
    splats: &HostSplats<f32>,
    footprints: &[Footprint<f32>],
    plan: &CompositePlan,
    w: usize,
) -> TileForward<f32> {
    let channels = splats.channels;
    let corner = Corner::new(plan.tile_origin(plan.tiles[w]));
    let one = _mm256_set1_ps(1.0);
    let min_t = _mm256_set1_ps(plan.stop_transmittance as f32);

    let (mut open, mut open_count) = valid_bits(plan, plan.tiles[w]);
    let mut t = vec![1.0f32; TILE_PIXELS];
    let mut last = vec![0u32; TILE_PIXELS];
    let mut planes = vec![0.0f32; (channels + 1) * TILE_PIXELS];
    let list = plan.list(w);
    let mut gathered = Gathered::new(footprints, list, Walk::FrontToBack);
    for (j, &row) in list.iter().enumerate() {
        if open_count == 0 {
            break;
        }
        let row = row as usize;
        let Some((splat, xs, ys)) = gathered.get(j).on_tile(corner) else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        let lanes = SplatLanes::new(&splat);
        let columns = column_bits(&xs);
        // The count saved where this entry contributes, as the lanes of `last` hold it.
        let count = _mm256_set1_epi32(j as i32 + 1);
        for (y, half, asked) in half_rows(open, columns, ys) {
            let Some(at) = lanes.at(y, half, asked) else {
                continue;
            };
            let base = y * TILE_SIZE + half * LANES;
            let t_old = load(&t, base);
            let t_next = _mm256_mul_ps(t_old, _mm256_sub_ps(one, at.alpha));
            let stop = _mm256_and_ps(at.live, _mm256_cmp_ps::<_CMP_LT_OQ>(t_next, min_t));
            let stopped = bits_of(stop);
            open[y] &= !((stopped as u16) << (half * LANES));
            open_count -= stopped.count_ones() as usize;
            let add = and_not(at.live, stop);
            if bits_of(add) == 0 {
                continue;
            }
            let weight = _mm256_mul_ps(at.alpha, t_old);
            for (k, &value) in values.iter().enumerate() {
                let at_k = k * TILE_PIXELS + base;
                let old = load(&planes, at_k);
                add_where(
                    &mut planes,
                    at_k,
                    old,
                    _mm256_mul_ps(_mm256_set1_ps(value), weight),
                    add,
                );
            }
            // T·(1 − α) where the entry adds, T·(1 − 0) = T exactly elsewhere (no blend with
            // the loaded T: see `add_where`).
            let kept = _mm256_sub_ps(one, _mm256_and_ps(at.alpha, add));
            store(&mut t, base, _mm256_mul_ps(t_old, kept));
            let last_lanes: &mut [u32; LANES] = (&mut last[base..base + LANES])
                .try_into()
                .expect("8 counts");
            // SAFETY: `last_lanes` is 8 readable and writable u32.
            unsafe {
                let ptr = last_lanes.as_mut_ptr() as *mut __m256i;
                let old = _mm256_loadu_si256(ptr);
                // The count (j + 1) is above every count saved before it, and the lanes outside
                // `add` offer 0: the maximum is the blend, without a masked store.
                let offered = _mm256_and_si256(count, _mm256_castps_si256(add));
                _mm256_storeu_si256(ptr, _mm256_max_epu32(old, offered));
            }
        }
    }
    for p in 0..TILE_PIXELS {
        planes[channels * TILE_PIXELS + p] = 1.0 - t[p];
    }
    TileForward {
        planes,
        final_t: t,
        last,
    }
}

/// A Gaussian's gradient terms at the 8 pixels of half a tile row, added into its slot pixel
/// after pixel in the scalar kernel's order (row-major), so the sums have its bits: summed per
/// lane and then across, they moved by an ulp, and the optimiser's path with them (see
/// `docs/rasterizer.md`).
struct SlotTerms {
    /// v_mx, v_my, v_a, v_b, v_c, v_o of each lane (0 where a rule gives none).
    geometry: [[f32; LANES]; 6],
    /// v_values of each lane. `[C, 8]`
    values: Vec<f32>,
}

impl SlotTerms {
    /// Keeps `term` (0 outside `mask`) as geometry term `g`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn set(&mut self, g: usize, term: __m256, mask: __m256) {
        let masked = _mm256_and_ps(term, mask);
        // SAFETY: `geometry[g]` is 8 writable f32.
        unsafe { _mm256_storeu_ps(self.geometry[g].as_mut_ptr(), masked) };
    }

    /// Keeps `term` (0 outside `mask`) as the term of channel `k`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn set_value(&mut self, k: usize, term: __m256, mask: __m256) {
        store(&mut self.values, k * LANES, _mm256_and_ps(term, mask));
    }

    /// Adds the terms of the lanes set in `lanes`, lane after lane, to `geometry` and to the
    /// slot's channel sums `values` `[C]`. A lane whose rule gave no term adds +0, which
    /// leaves any sum as it was (no sum here is −0: they start at +0).
    #[inline(always)]
    fn add_to(&self, mut lanes: u32, geometry: &mut [f32; 6], values: &mut [f32]) {
        let channels = values.len();
        while lanes != 0 {
            let i = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            for (sum, terms) in geometry.iter_mut().zip(&self.geometry) {
                *sum += terms[i];
            }
            for (k, sum) in values.iter_mut().enumerate().take(channels) {
                *sum += self.values[k * LANES + i];
            }
        }
    }
}

/// `cpu::backward_tile` in 8 lanes, from the tile's output gradients `v_planes` `[C + 1, 256]`.
#[target_feature(enable = "avx2,fma")]
fn backward_tile(
    splats: &HostSplats<f32>,
    plan: &CompositePlan,
    state: &super::ForwardState<f32>,
    v_planes: Vec<f32>,
    w: usize,
) -> Vec<f32> {
    let channels = splats.channels;
    let stride = 6 + channels;
    let corner = Corner::new(plan.tile_origin(plan.tiles[w]));
    let one = _mm256_set1_ps(1.0);
    let zero = _mm256_setzero_ps();
    let half_one = _mm256_set1_ps(0.5);
    let max_alpha = _mm256_set1_ps(MAX_ALPHA as f32);

    let (final_t, last) = state.tile(w);
    let list = plan.list(w);
    let mut slots = vec![0.0f32; list.len() * stride];
    let mut t = final_t.to_vec();
    let mut behind = vec![0.0f32; channels * TILE_PIXELS]; // Σ over later contributors of f·α·T
    let mut terms = SlotTerms {
        geometry: [[0.0; LANES]; 6],
        values: vec![0.0; channels * LANES],
    };
    let mut gathered = Gathered::new(&state.footprints, list, Walk::BackToFront);
    let (mut replay, entries) = Replay::new(last);
    for j in (0..entries).rev() {
        let replaying = replay.at(j);
        let row = list[j] as usize;
        let Some((splat, xs, ys)) = gathered.get(j).on_tile(corner) else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        let lanes = SplatLanes::new(&splat);
        let columns = column_bits(&xs);
        let (geometry_slot, value_slot) = slots[j * stride..(j + 1) * stride].split_at_mut(6);
        let mut geometry = [0.0f32; 6];
        for (y, half, asked) in half_rows(replaying, columns, ys) {
            let Some(at) = lanes.at(y, half, asked) else {
                continue;
            };
            let base = y * TILE_SIZE + half * LANES;
            // 1 − 0 outside the live lanes, so that T is stored back unchanged there without a
            // blend (`add_where`); every term of those lanes is masked off below.
            let keep = _mm256_sub_ps(one, _mm256_and_ps(at.alpha, at.live));
            let t_after = load(&t, base);
            let t_before = _mm256_div_ps(t_after, keep);
            let weight = _mm256_mul_ps(at.alpha, t_before);
            // dL/dα = Σ_k v_k (f_k T_i − S_k / (1 − α)) + v_A · T_final / (1 − α)
            let v_a = load(&v_planes, channels * TILE_PIXELS + base);
            let mut v_alpha = _mm256_div_ps(_mm256_mul_ps(v_a, load(final_t, base)), keep);
            for (k, &value) in values.iter().enumerate() {
                let at_k = k * TILE_PIXELS + base;
                let v_k = load(&v_planes, at_k);
                let value = _mm256_set1_ps(value);
                let old = load(&behind, at_k);
                let seen = _mm256_sub_ps(_mm256_mul_ps(value, t_before), _mm256_div_ps(old, keep));
                v_alpha = _mm256_add_ps(v_alpha, _mm256_mul_ps(v_k, seen));
                terms.set_value(k, _mm256_mul_ps(v_k, weight), at.live);
                add_where(
                    &mut behind,
                    at_k,
                    old,
                    _mm256_mul_ps(value, weight),
                    at.live,
                );
            }
            store(&mut t, base, t_before);
            // No gradient to o and the geometry where α was clamped at 0.99 …
            let unclamped = and_not(at.live, _mm256_cmp_ps::<_CMP_GT_OQ>(at.raw, max_alpha));
            terms.set(5, _mm256_mul_ps(v_alpha, at.exp_power), unclamped);
            // … and none to the geometry where the power was clamped at 0.
            let inside = and_not(unclamped, _mm256_cmp_ps::<_CMP_GT_OQ>(at.power, zero));
            let v_power = _mm256_mul_ps(v_alpha, at.raw);
            let (dx, dy) = (at.dx, at.dy);
            let v_mx = _mm256_add_ps(_mm256_mul_ps(lanes.a, dx), _mm256_mul_ps(lanes.b, dy));
            let v_my = _mm256_add_ps(_mm256_mul_ps(lanes.b, dx), _mm256_mul_ps(lanes.c, dy));
            terms.set(0, _mm256_mul_ps(v_power, v_mx), inside);
            terms.set(1, _mm256_mul_ps(v_power, v_my), inside);
            let v_power_half = _mm256_mul_ps(v_power, half_one);
            terms.set(
                2,
                negate(_mm256_mul_ps(_mm256_mul_ps(v_power_half, dx), dx)),
                inside,
            );
            terms.set(
                3,
                negate(_mm256_mul_ps(_mm256_mul_ps(v_power, dx), dy)),
                inside,
            );
            terms.set(
                4,
                negate(_mm256_mul_ps(_mm256_mul_ps(v_power_half, dy), dy)),
                inside,
            );
            terms.add_to(bits_of(at.live), &mut geometry, value_slot);
        }
        geometry_slot.copy_from_slice(&geometry);
    }
    slots
}
