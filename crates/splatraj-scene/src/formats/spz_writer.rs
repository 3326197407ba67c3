//! Niantic SPZ writer: version 3 (one gzip stream), as Niantic's reference library
//! (`nianticlabs/spz`, `src/cc/load-spz.cc`: `packGaussians`, `serializePackedGaussians`)
//! writes it with its default options.
//!
//! Version 3 rather than 4: every SPZ reader in use reads it (Niantic's, splat-transform's,
//! ours), it needs only gzip, and its quantisation is the same as version 4's (which differs
//! only in the container: zstd streams behind a plain header).
//!
//! What is stored (the encodings are in [`super::spz`]'s module docs):
//! - positions as 24-bit fixed point with 12 fractional bits (1/4096 of a unit), the reference's
//!   choice; a scene reaching beyond ±2048 units gets fewer fractional bits (the header says how
//!   many) where the reference would silently wrap;
//! - activated opacity, the DC colour (scale 0.15) and log-scales as bytes (log-scales saturate
//!   outside about [−10, 5.9]);
//! - rotations as "smallest three" (2 + 3 × 10 bits);
//! - SH of degree 1 kept to 5 bits, degrees 2-3 to 4 bits (the reference's `sh1Bits`,
//!   `shRestBits` defaults), in the 8-bit `128 + 128·v` encoding;
//! - axes RUB, the format's default, so no coordinate-system extension is written: the scene's
//!   RDF y and z change sign (rotations and SH change with them).
//!
//! Nothing else fits in the format: labels, features and other extras are not written, and the
//! antialiasing flag is left clear (a [`Scene`] does not record it).

use std::io::Write;
use std::path::Path;

use super::spz::{
    AxisFlips, MAGIC_BYTES, dc_to_byte, log_scale_to_byte, pack_quaternion_smallest_three,
    sh_to_byte, to_byte,
};
use crate::atomic::write_atomically;
use crate::error::{Result, SceneError};
use crate::scene::Scene;

/// The SPZ version written.
pub const WRITTEN_VERSION: u32 = 3;
/// Fractional bits of positions when the scene fits (the reference writer's fixed choice).
pub const FRACTIONAL_BITS: u8 = 12;
/// Significant bits kept of degree-1 SH coefficients (the reference's default).
pub const SH1_BITS: u32 = 5;
/// Significant bits kept of degree-2 and -3 SH coefficients (the reference's default).
pub const SH_REST_BITS: u32 = 4;

/// Largest magnitude of a 24-bit signed fixed-point value.
const MAX_FIXED: f64 = ((1 << 23) - 1) as f64;

/// Writes `scene` as a gzip-wrapped SPZ version 3 file (whole or not at all).
pub fn write_spz(scene: &Scene, path: &Path) -> Result<()> {
    let content = encode_spz_content(scene, path)?;
    write_atomically(path, |out| {
        let mut gz = flate2::write::GzEncoder::new(out, flate2::Compression::default());
        gz.write_all(&content)?;
        gz.finish()?;
        Ok(())
    })
    .map_err(|e| SceneError::io(path, e))
}

/// The uncompressed content of a version 3 file (header and the six arrays): what is gzipped.
/// `path` only names the file in errors.
pub fn encode_spz_content(scene: &Scene, path: &Path) -> Result<Vec<u8>> {
    let n = scene.len();
    let count = u32::try_from(n).map_err(|_| {
        SceneError::malformed(path, format!("{n} Gaussians do not fit an SPZ header"))
    })?;
    let fractional_bits = fractional_bits_for(scene, path)?;
    let flips = AxisFlips::RUB_TO_RDF;
    let coeffs = scene.sh_coeffs();
    let sh_dim = coeffs - 1;

    let mut out = Vec::with_capacity(16 + n * (9 + 1 + 3 + 3 + 4 + 3 * sh_dim));
    out.extend_from_slice(MAGIC_BYTES);
    out.extend_from_slice(&WRITTEN_VERSION.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    // sh degree, fractional bits, flags (not antialiased, no extensions), reserved.
    out.extend_from_slice(&[scene.sh_degree, fractional_bits, 0, 0]);

    let unit = f64::from(1u32 << fractional_bits);
    for mean in &scene.means {
        for (v, f) in mean.iter().zip(flips.0) {
            // In range by `fractional_bits_for`; the low three bytes are the 24-bit two's complement.
            let fixed = (f64::from(v * f) * unit).round() as i32;
            out.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    out.extend(scene.opacities.iter().map(|&a| to_byte(a * 255.0)));
    for i in 0..n {
        out.extend(scene.sh_of(i)[..3].iter().map(|&dc| dc_to_byte(dc)));
    }
    for s in &scene.scales {
        out.extend(s.iter().map(|&s| log_scale_to_byte(s.ln())));
    }
    let q_signs = flips.quaternion_signs();
    for &[w, x, y, z] in &scene.rotations {
        let norm = (w * w + x * x + y * y + z * z).sqrt();
        let q = [x * q_signs[0], y * q_signs[1], z * q_signs[2], w].map(|c| c / norm);
        out.extend_from_slice(&pack_quaternion_smallest_three(q));
    }
    if sh_dim > 0 {
        let signs = flips.sh_signs();
        for i in 0..n {
            let sh = &scene.sh_of(i)[3..];
            // The same coefficient-major, channel-fastest layout as the scene's, DC left out.
            for (k, coeff) in sh.chunks_exact(3).enumerate() {
                let bits = if k < 3 { SH1_BITS } else { SH_REST_BITS };
                out.extend(coeff.iter().map(|&v| sh_to_byte(v * signs[k], bits)));
            }
        }
    }
    Ok(out)
}

/// Fractional bits that keep every position inside 24 bits: 12 when the scene fits in ±2048
/// units, fewer for larger scenes (coarser steps, but no wrap-around).
fn fractional_bits_for(scene: &Scene, path: &Path) -> Result<u8> {
    let mut largest = 0f64;
    for (i, mean) in scene.means.iter().enumerate() {
        for &v in mean {
            if !v.is_finite() {
                return Err(SceneError::malformed(
                    path,
                    format!("Gaussian {i}: position {mean:?} is not finite; SPZ cannot store it"),
                ));
            }
            largest = largest.max(f64::from(v).abs());
        }
    }
    (0..=FRACTIONAL_BITS)
        .rev()
        .find(|&bits| (largest * f64::from(1u32 << bits)).round() <= MAX_FIXED)
        .ok_or_else(|| {
            SceneError::malformed(
                path,
                format!(
                    "a position {largest} units from the origin does not fit SPZ's 24-bit \
                     fixed point (at most {MAX_FIXED} units)"
                ),
            )
        })
}
