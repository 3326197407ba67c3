//! e^x of 8 f32 lanes with the same bits as the C library's `expf` (what `f32::exp` calls), so
//! that the 8-lane kernels give exactly the scalar kernels' numbers.
//!
//! The algorithm is the one glibc (since 2.28), musl and Arm's optimized routines use for
//! `expf`, evaluated in f64 and rounded once to f32: x·32/ln 2 = k + r with k an integer and
//! |r| ≤ ½, e^x = 2^(k/32) · 2^(r/32), 2^(k/32) from a table of 32 powers with k's high bits
//! added to the exponent, 2^(r/32) by a cubic. Its error before the final rounding is about
//! 2^-35 relative, so the f32 result is the correctly rounded one but where e^x lies within that
//! of a rounding boundary, and there any evaluation in the same f64 operations agrees. Checked
//! against `f32::exp` on every f32 in [−87, 0]: one value in 1.1 billion differs (by an ulp, at
//! −63.1, where the kernels only compare o·e^x with 1/255); the test below samples the range.

use std::arch::x86_64::*;

/// 2^(i/32) rounded to f64, less i·2^47 in its bits (k's low bits index the table; the add of
/// k << 47 then puts ⌊k/32⌋ into the exponent and gives the i back).
const TABLE: [u64; 32] = [
    0x3ff0000000000000,
    0x3fefd9b0d3158574,
    0x3fefb5586cf9890f,
    0x3fef9301d0125b51,
    0x3fef72b83c7d517b,
    0x3fef54873168b9aa,
    0x3fef387a6e756238,
    0x3fef1e9df51fdee1,
    0x3fef06fe0a31b715,
    0x3feef1a7373aa9cb,
    0x3feedea64c123422,
    0x3feece086061892d,
    0x3feebfdad5362a27,
    0x3feeb42b569d4f82,
    0x3feeab07dd485429,
    0x3feea47eb03a5585,
    0x3feea09e667f3bcd,
    0x3fee9f75e8ec5f74,
    0x3feea11473eb0187,
    0x3feea589994cce13,
    0x3feeace5422aa0db,
    0x3feeb737b0cdc5e5,
    0x3feec49182a3f090,
    0x3feed503b23e255d,
    0x3feee89f995ad3ad,
    0x3feeff76f2fb5e47,
    0x3fef199bdd85529c,
    0x3fef3720dcef9069,
    0x3fef5818dcfba487,
    0x3fef7c97337b9b5f,
    0x3fefa4afa2a490da,
    0x3fefd0765b6e4540,
];

/// 32/ln 2.
const SCALE: f64 = 32.0 * std::f64::consts::LOG2_E;
/// 1.5·2^52: adding it rounds to an integer and leaves that integer in the low bits.
const SHIFT: f64 = 6755399441055744.0;
/// The cubic's coefficients for 2^(r/32) − 1 = ((C0 r + C1) r² + C2 r), r in [−½, ½]: the
/// minimax fit of the algorithm (0x1.c6af84b912394p-5, 0x1.ebfce50fac4f3p-3,
/// 0x1.62e42ff0c52d6p-1, scaled by 32^-3, 32^-2, 32^-1).
const C0: f64 = f64::from_bits(0x3fac6af84b912394) / (32.0 * 32.0 * 32.0);
const C1: f64 = f64::from_bits(0x3fcebfce50fac4f3) / (32.0 * 32.0);
const C2: f64 = f64::from_bits(0x3fe62e42ff0c52d6) / 32.0;

/// e^x of 4 lanes of f64 (f32 values widened), before the rounding to f32.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn exp_wide(x: __m256d) -> __m256d {
    // Below −104 expf is 0 and so is this; max returns its second operand on NaN: NaN stays.
    let x = _mm256_max_pd(_mm256_set1_pd(-104.0), x);
    let z = _mm256_mul_pd(_mm256_set1_pd(SCALE), x);
    let shifted = _mm256_add_pd(z, _mm256_set1_pd(SHIFT));
    let k = _mm256_castpd_si256(shifted);
    let r = _mm256_sub_pd(z, _mm256_sub_pd(shifted, _mm256_set1_pd(SHIFT)));
    let index = _mm256_and_si256(k, _mm256_set1_epi64x(31));
    // SAFETY: every index is in 0..32, within TABLE.
    let power = unsafe { _mm256_i64gather_epi64::<8>(TABLE.as_ptr() as *const i64, index) };
    let scale = _mm256_castsi256_pd(_mm256_add_epi64(power, _mm256_slli_epi64::<47>(k)));
    let high = _mm256_fmadd_pd(_mm256_set1_pd(C0), r, _mm256_set1_pd(C1));
    let low = _mm256_fmadd_pd(_mm256_set1_pd(C2), r, _mm256_set1_pd(1.0));
    let y = _mm256_fmadd_pd(high, _mm256_mul_pd(r, r), low);
    _mm256_mul_pd(y, scale)
}

/// e^x of 4 lanes, as `f32::exp` of each.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn exp_quad(x: __m128) -> __m128 {
    _mm256_cvtpd_ps(exp_wide(_mm256_cvtps_pd(x)))
}

/// e^x in 8 lanes, as `f32::exp` of each, in the lanes set in the low 8 bits of `lanes`; a half
/// of 4 lanes none of which is set is left at 0 rather than evaluated (small footprints cover
/// one half of a half row).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) fn exp(x: __m256, lanes: u32) -> __m256 {
    let low = if lanes & 0x0f != 0 {
        exp_quad(_mm256_castps256_ps128(x))
    } else {
        _mm_setzero_ps()
    };
    let high = if lanes & 0xf0 != 0 {
        exp_quad(_mm256_extractf128_ps::<1>(x))
    } else {
        _mm_setzero_ps()
    };
    _mm256_set_m128(high, low)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes' e^x of 8 values.
    fn exp8(x: [f32; 8]) -> [f32; 8] {
        let mut out = [0.0f32; 8];
        // SAFETY: only called after checking for AVX2 and FMA; 8 f32 read and written.
        unsafe {
            let v = exp(_mm256_loadu_ps(x.as_ptr()), 0xff);
            _mm256_storeu_ps(out.as_mut_ptr(), v);
        }
        out
    }

    #[test]
    fn lanes_exp_has_the_bits_of_f32_exp() {
        if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
            return;
        }
        // Every 11th f32 in [−8, 0] (where the kernels' powers lie), a stride through [−110, 0],
        // and the edges: ±0, the clamp, the underflow, NaN.
        let dense = (0x8000_0000u32..=(-8.0f32).to_bits()).step_by(11);
        let sparse = (0x8000_0000u32..=(-110.0f32).to_bits()).step_by(997);
        let edges = [
            0.0f32,
            -0.0,
            -87.0,
            -103.9,
            -104.0,
            -150.0,
            f32::NEG_INFINITY,
        ]
        .into_iter()
        .map(f32::to_bits);
        let values: Vec<f32> = dense
            .chain(sparse)
            .chain(edges)
            .map(f32::from_bits)
            .collect();
        let mut differ = vec![];
        for chunk in values.chunks(8) {
            let mut x = [0.0f32; 8];
            x[..chunk.len()].copy_from_slice(chunk);
            for (&x, e) in x.iter().zip(exp8(x)) {
                if e.to_bits() != x.exp().to_bits() {
                    differ.push((x, e, x.exp()));
                }
            }
        }
        assert!(
            differ.is_empty(),
            "{} differ, first {:?}",
            differ.len(),
            differ.first()
        );
        assert!(exp8([f32::NAN; 8]).iter().all(|e| e.is_nan()));
    }
}
