//! antimatter15's `.splat`: the web viewers' format (antimatter15/splat, and most web viewers
//! after it).
//!
//! Written from antimatter15/splat (`convert.py`, the reference writer, and `main.js`, the
//! reference reader). The file is a bare array of 32-byte little-endian records, one per
//! Gaussian, with no header:
//!
//! | bytes | content |
//! |---|---|
//! | 0-11 | position, 3 × f32 |
//! | 12-23 | scale, 3 × f32, *linear* (the writer takes `exp` of the PLY's log-scales) |
//! | 24-27 | colour R, G, B = `(0.5 + C0 · f_dc) · 255` clipped and truncated to u8; A = the activated opacity × 255 |
//! | 28-31 | rotation (w, x, y, z) of the normalised quaternion as `q · 128 + 128` clipped to u8 |
//!
//! `main.js` decodes rotations as `(b − 128) / 128`, which we follow (splat-transform's
//! `b / 255 · 2 − 1` differs by under 1/128); validation then normalises them. SH of degree > 0
//! is not stored, and the axes are the PLY's own (the writer copies x, y, z).
//!
//! Having no header, a `.splat` file is recognised by its extension, a size that is a multiple
//! of 32, and records that look like Gaussians ([`looks_like_splat`]), never by bytes alone.

use std::path::Path;

use super::bytes::{dc_from_color_byte, read_f32};
use crate::error::{Result, SceneError};
use crate::scene::{Extras, Scene};

/// Bytes per Gaussian.
pub const RECORD_LEN: usize = 32;

/// Records looked at to decide whether a file is plausibly a `.splat`.
const SAMPLE_RECORDS: usize = 1024;
/// Coordinates beyond this are not a scene (and a random binary read as f32 is often huge).
const MAX_PLAUSIBLE_COORD: f32 = 1e7;

/// True when `bytes` can be a `.splat` file: a non-zero multiple of 32 bytes whose first records
/// (most of them: a real capture may hold a few invalid Gaussians, which validation reports)
/// have finite positions and positive finite scales.
pub fn looks_like_splat(bytes: &[u8]) -> bool {
    if bytes.is_empty() || !bytes.len().is_multiple_of(RECORD_LEN) {
        return false;
    }
    let sampled = (bytes.len() / RECORD_LEN).min(SAMPLE_RECORDS);
    let plausible = bytes
        .chunks_exact(RECORD_LEN)
        .take(sampled)
        .filter(|r| {
            let f = |k: usize| read_f32(r, 4 * k).unwrap_or(f32::NAN);
            (0..3).all(|k| f(k).is_finite() && f(k).abs() < MAX_PLAUSIBLE_COORD)
                && (3..6).all(|k| f(k).is_finite() && f(k) > 0.0 && f(k) < MAX_PLAUSIBLE_COORD)
        })
        .count();
    plausible * 10 >= sampled * 9
}

/// Decodes a `.splat` file into an unvalidated scene (SH degree 0).
pub fn decode_splat(bytes: &[u8], path: &Path) -> Result<Scene> {
    if bytes.is_empty() || !bytes.len().is_multiple_of(RECORD_LEN) {
        return Err(SceneError::malformed(
            path,
            format!(
                "a .splat file is a whole number of {RECORD_LEN}-byte records; this one has {} \
                 bytes ({} records and {} bytes over: truncated or not a .splat)",
                bytes.len(),
                bytes.len() / RECORD_LEN,
                bytes.len() % RECORD_LEN
            ),
        ));
    }
    let n = bytes.len() / RECORD_LEN;
    let mut scene = Scene {
        means: Vec::with_capacity(n),
        scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
        opacities: Vec::with_capacity(n),
        sh_degree: 0,
        sh: Vec::with_capacity(3 * n),
        extras: Extras::default(),
    };
    for r in bytes.chunks_exact(RECORD_LEN) {
        // In bounds: every record is 32 bytes.
        let f = |k: usize| read_f32(r, 4 * k).unwrap_or(f32::NAN);
        scene.means.push([f(0), f(1), f(2)]);
        scene.scales.push([f(3), f(4), f(5)]);
        scene.sh.extend((24..27).map(|b| dc_from_color_byte(r[b])));
        scene.opacities.push(f32::from(r[27]) / 255.0);
        scene.rotations.push(std::array::from_fn(|k| {
            (f32::from(r[28 + k]) - 128.0) / 128.0
        }));
    }
    Ok(scene)
}
