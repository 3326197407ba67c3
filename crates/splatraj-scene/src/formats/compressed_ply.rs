//! PlayCanvas/SuperSplat compressed PLY.
//!
//! Gaussians come in chunks of 256; each chunk stores float min/max ranges and each Gaussian
//! stores quantised values inside them:
//! - `packed_position`, `packed_scale`: 11/10/11 bits (x in the top bits), linear in
//!   [min, max] of the chunk; scales are log-scales.
//! - `packed_rotation`: 2 bits naming the largest quaternion component (in the file's
//!   rot_0..rot_3 = w, x, y, z order), then the other three in 10 bits each, mapped from
//!   [-1/√2, 1/√2].
//! - `packed_color`: 8 bits each of r, g, b, opacity; r, g, b are the base colour
//!   0.5 + C0·f_dc, linear in the chunk's colour range when the chunk has one (otherwise in
//!   [0, 1]); opacity is the activated opacity.
//! - an optional `sh` element: `f_rest_*` as uchar, value = (n/256-ish − 0.5)·8 (see
//!   [`decode_sh_byte`]), grouped by channel like INRIA PLY.

use std::path::Path;

use super::inria_ply::numbered_columns;
use super::ply_table::{Column, PlyFile, Table};
use crate::error::{Result, SceneError};
use crate::scene::{Extras, SH_C0, Scene, sh_degree_for_coeffs};

/// Gaussians per chunk.
pub const CHUNK_SIZE: usize = 256;

/// `bits`-bit unsigned field of `value` starting at bit `shift`, mapped to [0, 1].
pub fn unorm(value: u32, shift: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    ((value >> shift) & max) as f32 / max as f32
}

/// The three 11/10/11-bit fractions of a packed position or scale.
pub fn unpack_111011(value: u32) -> [f32; 3] {
    [
        unorm(value, 21, 11),
        unorm(value, 11, 10),
        unorm(value, 0, 11),
    ]
}

/// Quaternion (w, x, y, z) from the 2-10-10-10 "smallest three" encoding.
pub fn unpack_rotation(value: u32) -> [f32; 4] {
    let scale = std::f32::consts::SQRT_2; // components lie in [-1/√2, 1/√2]
    let a = (unorm(value, 20, 10) - 0.5) * scale;
    let b = (unorm(value, 10, 10) - 0.5) * scale;
    let c = (unorm(value, 0, 10) - 0.5) * scale;
    let largest = (1.0 - (a * a + b * b + c * c)).max(0.0).sqrt();
    // The tag indexes the file's rot_0..rot_3 order, (w, x, y, z): SuperSplat packs the
    // PLY's rotation columns as they are (checked against the SPZ copy of biker).
    match value >> 30 {
        0 => [largest, a, b, c],
        1 => [a, largest, b, c],
        2 => [a, b, largest, c],
        _ => [a, b, c, largest],
    }
}

/// An SH coefficient from its quantised byte (SuperSplat's mapping of [-4, 4] to 0..=255).
pub fn decode_sh_byte(byte: u8) -> f32 {
    let n = match byte {
        0 => 0.0,
        255 => 1.0,
        b => (b as f32 + 0.5) / 256.0,
    };
    (n - 0.5) * 8.0
}

/// `value` in [0, 1] as a `bits`-bit unsigned field (rounded, saturating): the inverse of
/// [`unorm`].
pub fn pack_unorm(value: f64, bits: u32) -> u32 {
    let max = f64::from((1u32 << bits) - 1);
    // NaN saturates to 0 through the cast.
    (value * max + 0.5).floor().clamp(0.0, max) as u32
}

/// Packs three fractions in [0, 1] as 11/10/11 bits: the inverse of [`unpack_111011`].
pub fn pack_111011(v: [f64; 3]) -> u32 {
    (pack_unorm(v[0], 11) << 21) | (pack_unorm(v[1], 10) << 11) | pack_unorm(v[2], 11)
}

/// Packs a quaternion (w, x, y, z), not necessarily normalised, as 2-10-10-10 "smallest
/// three": the inverse of [`unpack_rotation`]. `q` and −q are the same rotation, so the sign is
/// chosen to make the dropped largest component positive.
pub fn pack_rotation(q: [f32; 4]) -> u32 {
    let norm = q
        .iter()
        .map(|&c| f64::from(c) * f64::from(c))
        .sum::<f64>()
        .sqrt();
    let mut a = q.map(|c| f64::from(c) / norm);
    let largest = (1..4).fold(0, |l, i| if a[i].abs() > a[l].abs() { i } else { l });
    if a[largest] < 0.0 {
        a = a.map(|c| -c);
    }
    let mut bits = largest as u32;
    for (_, &c) in a.iter().enumerate().filter(|&(i, _)| i != largest) {
        bits = (bits << 10) | pack_unorm(c * std::f64::consts::FRAC_1_SQRT_2 + 0.5, 10);
    }
    bits
}

/// The byte of an SH coefficient (degree ≥ 1): [-4, 4] in 256 steps, truncated as SuperSplat
/// writes it; [`decode_sh_byte`] returns the middle of the step.
pub fn encode_sh_byte(value: f32) -> u8 {
    ((f64::from(value) / 8.0 + 0.5) * 256.0)
        .trunc()
        .clamp(0.0, 255.0) as u8
}

/// Per-chunk ranges of three channels: `[channel][chunk]`.
type ChannelRanges = Vec<Vec<f32>>;

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// Reads a packed `uint` column as u32, checking that the file declared it as an integer.
fn packed(table: &Table, name: &str, path: &Path) -> Result<Vec<u32>> {
    let column: &Column = table.require(name, path)?;
    if !column.is_integer() {
        return Err(SceneError::malformed(
            path,
            format!(
                "property '{name}' of '{}' must be an integer (uint)",
                table.name
            ),
        ));
    }
    Ok((0..table.count).map(|i| column.f64(i) as u32).collect())
}

/// Builds a scene (not yet validated) from a compressed PLY's `chunk`, `vertex` and `sh`.
pub fn scene_from_tables(ply: &PlyFile, path: &Path) -> Result<Scene> {
    let chunk = ply
        .table("chunk")
        .ok_or_else(|| SceneError::malformed(path, "compressed PLY without a 'chunk' element"))?;
    let vertex = ply
        .table("vertex")
        .ok_or_else(|| SceneError::malformed(path, "compressed PLY without a 'vertex' element"))?;
    let n = vertex.count;
    let chunks_needed = n.div_ceil(CHUNK_SIZE);
    if chunk.count < chunks_needed {
        return Err(SceneError::malformed(
            path,
            format!(
                "{n} Gaussians need {chunks_needed} chunks of {CHUNK_SIZE}, the file has {}",
                chunk.count
            ),
        ));
    }
    let range = |name: &str| -> Result<Vec<f32>> { Ok(chunk.require(name, path)?.to_f32_vec()) };
    let axes = ["x", "y", "z"];
    let pos_min: Vec<Vec<f32>> = axes
        .iter()
        .map(|a| range(&format!("min_{a}")))
        .collect::<Result<_>>()?;
    let pos_max: Vec<Vec<f32>> = axes
        .iter()
        .map(|a| range(&format!("max_{a}")))
        .collect::<Result<_>>()?;
    let scale_min: Vec<Vec<f32>> = axes
        .iter()
        .map(|a| range(&format!("min_scale_{a}")))
        .collect::<Result<_>>()?;
    let scale_max: Vec<Vec<f32>> = axes
        .iter()
        .map(|a| range(&format!("max_scale_{a}")))
        .collect::<Result<_>>()?;
    // Older files have no colour ranges: colour bytes are then plain [0, 1] values.
    let color_range: Option<(ChannelRanges, ChannelRanges)> = if chunk.column("min_r").is_some() {
        let channels = ["r", "g", "b"];
        Some((
            channels
                .iter()
                .map(|c| range(&format!("min_{c}")))
                .collect::<Result<_>>()?,
            channels
                .iter()
                .map(|c| range(&format!("max_{c}")))
                .collect::<Result<_>>()?,
        ))
    } else {
        None
    };

    let position = packed(vertex, "packed_position", path)?;
    let rotation = packed(vertex, "packed_rotation", path)?;
    let scale = packed(vertex, "packed_scale", path)?;
    let color = packed(vertex, "packed_color", path)?;

    let (sh_degree, rest) = match ply.table("sh") {
        None => (0, Vec::new()),
        Some(sh) => {
            if sh.count != n {
                return Err(SceneError::malformed(
                    path,
                    format!("element 'sh' has {} rows for {n} Gaussians", sh.count),
                ));
            }
            let rest = numbered_columns(sh, "f_rest_", path)?;
            let degree = (rest.len() % 3 == 0)
                .then(|| sh_degree_for_coeffs(rest.len() / 3 + 1))
                .flatten()
                .ok_or_else(|| {
                    SceneError::malformed(
                        path,
                        format!(
                            "element 'sh' has {} f_rest_* properties (expected 9, 24 or 45)",
                            rest.len()
                        ),
                    )
                })?;
            (degree, rest)
        }
    };
    let coeffs = crate::scene::sh_coeffs_for_degree(sh_degree);

    let mut scene = Scene {
        means: Vec::with_capacity(n),
        scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
        opacities: Vec::with_capacity(n),
        sh_degree,
        sh: vec![0.0; n * coeffs * 3],
        extras: Extras::default(),
    };
    for i in 0..n {
        let c = i / CHUNK_SIZE;
        let p = unpack_111011(position[i]);
        scene.means.push(std::array::from_fn(|k| {
            lerp(pos_min[k][c], pos_max[k][c], p[k])
        }));
        let s = unpack_111011(scale[i]);
        scene.scales.push(std::array::from_fn(|k| {
            lerp(scale_min[k][c], scale_max[k][c], s[k]).exp()
        }));
        scene.rotations.push(unpack_rotation(rotation[i]));
        let rgba = [
            unorm(color[i], 24, 8),
            unorm(color[i], 16, 8),
            unorm(color[i], 8, 8),
            unorm(color[i], 0, 8),
        ];
        scene.opacities.push(rgba[3]);
        let gaussian_sh = &mut scene.sh[i * coeffs * 3..(i + 1) * coeffs * 3];
        for k in 0..3 {
            let base = match &color_range {
                Some((min, max)) => lerp(min[k][c], max[k][c], rgba[k]),
                None => rgba[k],
            };
            gaussian_sh[k] = (base - 0.5) / SH_C0;
        }
        for (j, column) in rest.iter().enumerate() {
            let (channel, k) = (j / (coeffs - 1), j % (coeffs - 1) + 1);
            gaussian_sh[k * 3 + channel] = decode_sh_byte(column.f64(i) as u8);
        }
    }
    Ok(scene)
}
