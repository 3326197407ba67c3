//! GaussianSplats3D's `.ksplat` (mkkellogg/GaussianSplats3D, the three.js viewer's own format).
//!
//! Written from its source: `src/loaders/SplatBuffer.js` (header, section headers, compression
//! levels, how values are read back), `SplatBufferGenerator.js`/`PlyParserUtils.js` (how they
//! are written, the SH order) and `ksplat/KSplatLoader.js` (the version check); checked against
//! files that its own converter (`util/create-ksplat.js`) wrote, see `scripts/make_splat_fixtures.py`.
//!
//! # Layout (all little-endian)
//!
//! - Main header, 4096 bytes: u8 major version (0), u8 minor version (≥ 1), 2 unused bytes,
//!   u32 max section count, u32 section count, u32 max splat count, u32 splat count, u16
//!   compression level (0-2) at byte 20, f32 × 3 scene centre at 24, f32 min and max SH value
//!   at 36 and 40 (0 means the default ∓1.5).
//! - `max section count` section headers of 1024 bytes: u32 splat count, u32 max splat count,
//!   u32 bucket size, u32 bucket count, f32 bucket block size, u16 bucket storage bytes (at 20),
//!   u32 compression scale range (at 24; 0 means the level's default), u32 storage bytes, u32 full
//!   bucket count, u32 partially filled bucket count, u16 SH degree (at 40).
//! - Then each section's data: u32 length of each partially filled bucket, the buckets' centres
//!   (`bucket storage bytes` each, 3 × f32), then `max splat count` records. Full buckets hold
//!   `bucket size` splats each and come first, partial buckets follow in order.
//!
//! # Records
//!
//! | level | position | scale (linear) | rotation (w, x, y, z) | colour | SH value |
//! |---|---|---|---|---|---|
//! | 0 | 3 × f32 | 3 × f32 | 4 × f32 | 4 × u8 | f32 |
//! | 1 | 3 × u16 | 3 × f16 | 4 × f16 | 4 × u8 | f16 |
//! | 2 | 3 × u16 | 3 × f16 | 4 × f16 | 4 × u8 | u8 in [min, max] SH |
//!
//! A u16 position is `(v − range) · (block size / 2) / range + bucket centre`. Colour is
//! `(0.5 + C0 · f_dc) · 255` and the activated opacity × 255. SH (degree 1: 9 values, 2: 24)
//! are stored band by band, channel-major inside a band: R of band 1's three coefficients, then
//! G, then B, then band 2's five the same way.
//!
//! Not read: SH degree 3 (the generator and reader only define degrees 0-2, so its order is not
//! documented) and files of another major version. Axes are the PLY's own (no conversion).

use std::path::Path;

use super::bytes::{dc_from_color_byte, f16_to_f32, read_f32, read_u16, read_u32};
use crate::error::{Result, SceneError};
use crate::scene::{Extras, Scene, sh_coeffs_for_degree};

/// Bytes of the main header.
pub const HEADER_LEN: usize = 4096;
/// Bytes of each section header.
pub const SECTION_HEADER_LEN: usize = 1024;
/// The GaussianSplats3D default for 8-bit SH when the header stores 0: ±3 / 2.
const DEFAULT_SH_HALF_RANGE: f32 = 1.5;
/// The highest SH degree whose layout GaussianSplats3D defines.
const MAX_SH_DEGREE: u8 = 2;
/// Far above any trained scene; a corrupt count is refused before anything is allocated.
const MAX_SPLATS: usize = 100_000_000;

/// Per-record byte layout of a compression level.
#[derive(Debug, Clone, Copy)]
struct Level {
    /// Bytes per value of the position, scale and rotation (4: f32, 2: u16 or f16).
    geometry: usize,
    /// Bytes per SH value (4: f32, 2: f16, 1: u8).
    sh: usize,
    /// Default compression scale range of positions.
    scale_range: u32,
}

const LEVELS: [Level; 3] = [
    Level {
        geometry: 4,
        sh: 4,
        scale_range: 1,
    },
    Level {
        geometry: 2,
        sh: 2,
        scale_range: 32767,
    },
    Level {
        geometry: 2,
        sh: 1,
        scale_range: 32767,
    },
];

impl Level {
    /// Byte offset of the colour in a record: 3 position, 3 scale and 4 rotation values.
    fn color_offset(&self) -> usize {
        10 * self.geometry
    }
    fn record_len(&self, sh_degree: u8) -> usize {
        self.color_offset() + 4 + sh_values(sh_degree) * self.sh
    }
}

/// SH values per splat beyond the DC term: 3 channels × (coefficients − 1).
fn sh_values(degree: u8) -> usize {
    3 * (sh_coeffs_for_degree(degree) - 1)
}

/// One section, its sizes checked against the file.
#[derive(Debug, Clone)]
struct Section {
    splats: usize,
    bucket_size: usize,
    full_buckets: usize,
    /// Lengths of the partially filled buckets, after the full ones.
    partial_lengths: Vec<usize>,
    /// Byte offset of the first bucket centre, and the stride between centres.
    centres_at: usize,
    centre_stride: usize,
    block_size: f32,
    scale_range: u32,
    sh_degree: u8,
    /// Byte offset of the first record.
    data_at: usize,
}

/// The whole file's structure.
#[derive(Debug, Clone)]
struct Layout {
    level: Level,
    splats: usize,
    sh_range: (f32, f32),
    sections: Vec<Section>,
}

/// True when `bytes` start with a `.ksplat` header whose sections fit the file.
pub fn looks_like_ksplat(bytes: &[u8]) -> bool {
    parse_layout(bytes).is_ok()
}

/// Decodes a `.ksplat` file into an unvalidated scene.
pub fn decode_ksplat(bytes: &[u8], path: &Path) -> Result<Scene> {
    let layout = parse_layout(bytes).map_err(|detail| SceneError::malformed(path, detail))?;
    let level = layout.level;
    let sh_degree = layout
        .sections
        .iter()
        .map(|s| s.sh_degree)
        .max()
        .unwrap_or(0);
    let coeffs = sh_coeffs_for_degree(sh_degree);
    let n = layout.splats;
    let mut scene = Scene {
        means: Vec::with_capacity(n),
        scales: Vec::with_capacity(n),
        rotations: Vec::with_capacity(n),
        opacities: Vec::with_capacity(n),
        sh_degree,
        sh: vec![0.0; n * coeffs * 3],
        extras: Extras::default(),
    };
    // Geometry value `k` of a record (0-2 position, 3-5 scale, 6-9 rotation), as stored.
    let float = |record: &[u8], k: usize| -> f32 {
        if level.geometry == 4 {
            read_f32(record, 4 * k).unwrap_or(f32::NAN)
        } else {
            f16_to_f32(read_u16(record, 2 * k).unwrap_or(0x7e00))
        }
    };
    let (sh_min, sh_max) = layout.sh_range;
    let sh_value = |record: &[u8], v: usize| -> f32 {
        let at = level.color_offset() + 4 + v * level.sh;
        match level.sh {
            4 => read_f32(record, at).unwrap_or(f32::NAN),
            2 => f16_to_f32(read_u16(record, at).unwrap_or(0x7e00)),
            _ => sh_min + f32::from(record[at]) / 255.0 * (sh_max - sh_min),
        }
    };
    for section in &layout.sections {
        let record_len = level.record_len(section.sh_degree);
        let rest = sh_coeffs_for_degree(section.sh_degree) - 1;
        let scale_factor = section.block_size / 2.0 / section.scale_range as f32;
        let mut bucket = 0usize;
        let mut bucket_end = section.bucket_size * section.full_buckets;
        let mut next_partial = 0usize;
        for i in 0..section.splats {
            let at = section.data_at + i * record_len;
            let record = &bytes[at..at + record_len];
            let position = if level.geometry == 4 {
                [float(record, 0), float(record, 1), float(record, 2)]
            } else {
                // Full buckets first, `bucket_size` each; then the partial buckets in order.
                if i < section.bucket_size * section.full_buckets {
                    bucket = i / section.bucket_size;
                } else {
                    while i >= bucket_end {
                        bucket = section.full_buckets + next_partial;
                        bucket_end += section.partial_lengths[next_partial];
                        next_partial += 1;
                    }
                }
                let centre = section.centres_at + bucket * section.centre_stride;
                std::array::from_fn(|k| {
                    let v = f32::from(read_u16(record, 2 * k).unwrap_or(0));
                    let c = read_f32(bytes, centre + 4 * k).unwrap_or(f32::NAN);
                    (v - section.scale_range as f32) * scale_factor + c
                })
            };
            scene.means.push(position);
            scene
                .scales
                .push([float(record, 3), float(record, 4), float(record, 5)]);
            scene.rotations.push([
                float(record, 6),
                float(record, 7),
                float(record, 8),
                float(record, 9),
            ]);
            let color = &record[level.color_offset()..level.color_offset() + 4];
            let g = scene.opacities.len();
            scene.opacities.push(f32::from(color[3]) / 255.0);
            let sh = &mut scene.sh[g * coeffs * 3..(g + 1) * coeffs * 3];
            for c in 0..3 {
                sh[c] = dc_from_color_byte(color[c]);
            }
            // Band by band, channel-major inside a band (see the module docs).
            let mut v = 0;
            for (first, len) in [(1, 3), (4, 5)] {
                if first > rest {
                    break;
                }
                for c in 0..3 {
                    for j in 0..len {
                        sh[(first + j) * 3 + c] = sh_value(record, v);
                        v += 1;
                    }
                }
            }
        }
    }
    Ok(scene)
}

/// Parses and checks the headers; the error says what does not fit.
fn parse_layout(bytes: &[u8]) -> std::result::Result<Layout, String> {
    if bytes.len() < HEADER_LEN {
        return Err(format!(
            "truncated: the file has {} bytes, a .ksplat header alone has {HEADER_LEN}",
            bytes.len()
        ));
    }
    let u32_at = |at: usize| read_u32(bytes, at).unwrap_or(0) as usize;
    let (major, minor) = (bytes[0], bytes[1]);
    if major != 0 || minor < 1 || bytes[2] != 0 || bytes[3] != 0 {
        return Err(format!(
            "not a .ksplat version GaussianSplats3D writes: header version {major}.{minor} \
             (0.1 or later 0.x expected)"
        ));
    }
    let max_sections = u32_at(4);
    let splats = u32_at(16);
    let level_index = read_u16(bytes, 20).unwrap_or(u16::MAX);
    let level = *LEVELS
        .get(level_index as usize)
        .ok_or_else(|| format!("compression level {level_index} is not one of 0, 1, 2"))?;
    if splats > MAX_SPLATS {
        return Err(format!(
            "the header claims {splats} splats; splatraj reads at most {MAX_SPLATS} (the \
             count is most likely corrupt)"
        ));
    }
    let headers_end = max_sections
        .checked_mul(SECTION_HEADER_LEN)
        .and_then(|s| s.checked_add(HEADER_LEN))
        .filter(|&end| max_sections > 0 && end <= bytes.len())
        .ok_or_else(|| {
            format!(
                "the header names {max_sections} sections, whose 1024-byte headers do not fit \
                 the file's {} bytes",
                bytes.len()
            )
        })?;
    let sh_limit = |at: usize, default: f32| match read_f32(bytes, at) {
        Some(v) if v != 0.0 && v.is_finite() => v,
        _ => default,
    };
    let sh_range = (
        sh_limit(36, -DEFAULT_SH_HALF_RANGE),
        sh_limit(40, DEFAULT_SH_HALF_RANGE),
    );

    let mut sections = Vec::new();
    let mut at = headers_end;
    let mut total = 0usize;
    for s in 0..max_sections {
        let h = HEADER_LEN + s * SECTION_HEADER_LEN;
        let field = |offset: usize| u32_at(h + offset);
        let (count, max_count) = (field(0), field(4));
        let sh_degree = read_u16(bytes, h + 40).unwrap_or(0);
        if sh_degree > u16::from(MAX_SH_DEGREE) {
            return Err(format!(
                "section {s}: SH degree {sh_degree}; GaussianSplats3D defines the layout of \
                 degrees 0-{MAX_SH_DEGREE} only"
            ));
        }
        let sh_degree = sh_degree as u8;
        if count > max_count || max_count > MAX_SPLATS {
            return Err(format!(
                "section {s}: {count} splats in room for {max_count}: the section header is \
                 corrupt"
            ));
        }
        let (bucket_size, bucket_count) = (field(8), field(12));
        let centre_stride = read_u16(bytes, h + 20).unwrap_or(0) as usize;
        let (full_buckets, partial_buckets) = (field(32), field(36));
        let compressed = level.geometry == 2;
        if compressed
            && (bucket_size == 0
                || centre_stride < 12
                || full_buckets + partial_buckets > bucket_count
                || full_buckets.saturating_mul(bucket_size) > count.max(max_count))
        {
            return Err(format!(
                "section {s}: its buckets do not add up ({bucket_count} buckets of {bucket_size} \
                 splats, {full_buckets} full, {partial_buckets} partial, {centre_stride}-byte \
                 centres)"
            ));
        }
        let bucket_bytes = 4 * partial_buckets + centre_stride * bucket_count;
        let record_len = level.record_len(sh_degree);
        let data_bytes = record_len.checked_mul(max_count);
        let end = data_bytes
            .and_then(|d| d.checked_add(bucket_bytes))
            .and_then(|d| d.checked_add(at))
            .filter(|&end| end <= bytes.len())
            .ok_or_else(|| {
                format!(
                    "truncated: section {s} needs {bucket_bytes} bytes of buckets and {max_count} \
                     records of {record_len} bytes from byte {at}; the file has {} bytes",
                    bytes.len()
                )
            })?;
        let partial_lengths: Vec<usize> =
            (0..partial_buckets).map(|b| u32_at(at + 4 * b)).collect();
        if compressed {
            let in_buckets = full_buckets * bucket_size + partial_lengths.iter().sum::<usize>();
            if in_buckets < count {
                return Err(format!(
                    "section {s}: its buckets hold {in_buckets} splats, fewer than its {count}"
                ));
            }
        }
        let block_size = read_f32(bytes, h + 16).unwrap_or(0.0);
        let scale_range = match field(24) {
            0 => level.scale_range,
            r => r as u32,
        };
        sections.push(Section {
            splats: count,
            bucket_size,
            full_buckets,
            partial_lengths,
            centres_at: at + 4 * partial_buckets,
            centre_stride,
            block_size,
            scale_range,
            sh_degree,
            data_at: at + bucket_bytes,
        });
        total += count;
        at = end;
    }
    if total != splats {
        return Err(format!(
            "the header counts {splats} splats, its sections hold {total}"
        ));
    }
    Ok(Layout {
        level,
        splats,
        sh_range,
        sections,
    })
}
