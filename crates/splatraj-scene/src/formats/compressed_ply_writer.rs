//! PlayCanvas/SuperSplat compressed PLY writer, following PlayCanvas's splat-transform
//! (`src/lib/writers/write-compressed-ply.ts` and `compressed-chunk.ts`), the format's
//! reference writer.
//!
//! - Gaussians are first put in Morton (Z-curve) order of their centres, as the reference does
//!   ([`morton_order`]): neighbours then share a chunk, so the chunks' ranges are small and the
//!   quantisation steps fine. The file's Gaussians are therefore in another order than the
//!   scene's.
//! - Chunks of 256 store min/max of x, y, z, of the log-scales (clamped to [−20, 20]) and of the
//!   base colours `0.5 + C0·f_dc`; each Gaussian stores, inside its chunk's ranges, 11/10/11-bit
//!   position and log-scale, a 2-10-10-10 "smallest three" rotation and 8-bit r, g, b with the
//!   activated opacity (see [`super::compressed_ply`] for the bit layout).
//! - With SH degree ≥ 1, an `sh` element holds `f_rest_*` as bytes ([-4, 4] in 256 steps), in
//!   INRIA order (grouped by colour channel).
//!
//! Labels, features and other extras are not written (the format has no place for them).

use std::io::Write;
use std::path::Path;

use super::compressed_ply::{CHUNK_SIZE, encode_sh_byte, pack_111011, pack_rotation, pack_unorm};
use crate::atomic::write_atomically;
use crate::error::{Result, SceneError};
use crate::scene::{SH_C0, Scene};

/// Chunk properties, in the reference's order.
const CHUNK_PROPERTIES: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];

/// Log-scales are clamped to this range for the chunk bounds ("sometimes values are at
/// infinity", says the reference).
const LOG_SCALE_LIMIT: f32 = 20.0;
/// A range narrower than this stores every value as its minimum (the reference's threshold).
const MIN_RANGE: f64 = 0.00001;
/// Morton cells per axis (10 bits each, 30-bit codes).
const MORTON_CELLS: f64 = 1024.0;

/// Writes `scene` as a compressed PLY (whole or not at all), Gaussians in Morton order.
pub fn write_compressed_ply(scene: &Scene, path: &Path) -> Result<()> {
    write_atomically(path, |out| write_compressed_ply_to(scene, out))
        .map_err(|e| SceneError::io(path, e))
}

/// Writes the compressed PLY to any writer.
pub fn write_compressed_ply_to(scene: &Scene, out: &mut dyn Write) -> std::io::Result<()> {
    let n = scene.len();
    let chunks = n.div_ceil(CHUNK_SIZE);
    let rest = 3 * (scene.sh_coeffs() - 1);
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by splatraj\nelement chunk \
         {chunks}\n"
    );
    for name in CHUNK_PROPERTIES {
        header += &format!("property float {name}\n");
    }
    header += &format!("element vertex {n}\n");
    for name in [
        "packed_position",
        "packed_rotation",
        "packed_scale",
        "packed_color",
    ] {
        header += &format!("property uint {name}\n");
    }
    if rest > 0 {
        header += &format!("element sh {n}\n");
        for j in 0..rest {
            header += &format!("property uchar f_rest_{j}\n");
        }
    }
    header += "end_header\n";
    out.write_all(header.as_bytes())?;

    let order = morton_order(&scene.means);
    let mut packed: Vec<u8> = Vec::with_capacity(n * 16);
    let mut ranges: Vec<u8> = Vec::with_capacity(chunks * CHUNK_PROPERTIES.len() * 4);
    for members in order.chunks(CHUNK_SIZE) {
        let chunk = Chunk::new(scene, members);
        for v in chunk.ranges() {
            ranges.extend_from_slice(&v.to_le_bytes());
        }
        for &i in members {
            for word in chunk.pack(scene, i as usize) {
                packed.extend_from_slice(&word.to_le_bytes());
            }
        }
    }
    out.write_all(&ranges)?;
    out.write_all(&packed)?;
    if rest > 0 {
        let coeffs = scene.sh_coeffs();
        let mut row = Vec::with_capacity(rest);
        for &i in &order {
            let sh = scene.sh_of(i as usize);
            row.clear();
            // INRIA order: all red coefficients, then green, then blue.
            for c in 0..3 {
                row.extend((1..coeffs).map(|k| encode_sh_byte(sh[k * 3 + c])));
            }
            out.write_all(&row)?;
        }
    }
    Ok(())
}

/// Min/max of one quantity over a chunk.
#[derive(Debug, Clone, Copy)]
struct Range {
    min: f32,
    max: f32,
}

impl Range {
    fn of(values: impl Iterator<Item = f32>) -> Self {
        values.fold(
            Range {
                min: f32::INFINITY,
                max: f32::NEG_INFINITY,
            },
            |r, v| Range {
                min: r.min.min(v),
                max: r.max.max(v),
            },
        )
    }

    fn clamped(self, limit: f32) -> Self {
        Range {
            min: self.min.clamp(-limit, limit),
            max: self.max.clamp(-limit, limit),
        }
    }

    /// `v` as a fraction of the range, as the reference normalises (ends saturate, a
    /// degenerate range gives 0).
    fn fraction(self, v: f32) -> f64 {
        let (v, min, max) = (f64::from(v), f64::from(self.min), f64::from(self.max));
        if v <= min {
            0.0
        } else if v >= max {
            1.0
        } else if max - min < MIN_RANGE {
            0.0
        } else {
            (v - min) / (max - min)
        }
    }
}

/// The ranges of one chunk.
struct Chunk {
    position: [Range; 3],
    log_scale: [Range; 3],
    color: [Range; 3],
}

/// A Gaussian's base colour channel `0.5 + C0·f_dc` (rounded to f32, as the reference stores
/// it before taking ranges).
fn base_color(scene: &Scene, i: usize, c: usize) -> f32 {
    (f64::from(scene.sh_of(i)[c]) * f64::from(SH_C0) + 0.5) as f32
}

impl Chunk {
    fn new(scene: &Scene, members: &[u32]) -> Self {
        let over = |f: &dyn Fn(usize) -> f32| Range::of(members.iter().map(|&i| f(i as usize)));
        Chunk {
            position: std::array::from_fn(|k| over(&|i| scene.means[i][k])),
            log_scale: std::array::from_fn(|k| {
                over(&|i| scene.scales[i][k].ln()).clamped(LOG_SCALE_LIMIT)
            }),
            color: std::array::from_fn(|c| over(&|i| base_color(scene, i, c))),
        }
    }

    /// The 18 chunk properties, in [`CHUNK_PROPERTIES`] order.
    fn ranges(&self) -> [f32; 18] {
        let mut v = [0.0; 18];
        for (block, ranges) in [self.position, self.log_scale, self.color]
            .iter()
            .enumerate()
        {
            for k in 0..3 {
                v[block * 6 + k] = ranges[k].min;
                v[block * 6 + 3 + k] = ranges[k].max;
            }
        }
        v
    }

    /// Gaussian `i`'s packed position, rotation, scale and colour.
    fn pack(&self, scene: &Scene, i: usize) -> [u32; 4] {
        let fractions = |ranges: &[Range; 3], v: [f32; 3]| -> [f64; 3] {
            std::array::from_fn(|k| ranges[k].fraction(v[k]))
        };
        let position = pack_111011(fractions(&self.position, scene.means[i]));
        let scale = pack_111011(fractions(&self.log_scale, scene.scales[i].map(f32::ln)));
        let rgb = fractions(
            &self.color,
            std::array::from_fn(|c| base_color(scene, i, c)),
        );
        let color = (pack_unorm(rgb[0], 8) << 24)
            | (pack_unorm(rgb[1], 8) << 16)
            | (pack_unorm(rgb[2], 8) << 8)
            | pack_unorm(f64::from(scene.opacities[i]), 8);
        [position, pack_rotation(scene.rotations[i]), scale, color]
    }
}

/// Indices of `points` in Morton (Z-curve) order, as splat-transform orders them: 10-bit cells
/// per axis over the points' bounding box, a stable sort by code, and each run of more than 256
/// points sharing a code ordered again over its own (smaller) box.
pub fn morton_order(points: &[[f32; 3]]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    refine(points, &mut order);
    order
}

fn refine(points: &[[f32; 3]], indices: &mut [u32]) {
    if indices.is_empty() {
        return;
    }
    let mut min = [f64::INFINITY; 3];
    let mut max = [f64::NEG_INFINITY; 3];
    for &i in indices.iter() {
        for k in 0..3 {
            let v = f64::from(points[i as usize][k]);
            min[k] = min[k].min(v);
            max[k] = max[k].max(v);
        }
    }
    let len: [f64; 3] = std::array::from_fn(|k| max[k] - min[k]);
    if len.iter().any(|l| !l.is_finite()) || len.iter().all(|&l| l == 0.0) {
        return;
    }
    let mul = len.map(|l| if l == 0.0 { 0.0 } else { MORTON_CELLS / l });
    let code = |i: u32| -> u32 {
        let cell = |k: usize| -> u32 {
            // Saturating float-to-int cast: NaN gives 0, as the reference's `>>> 0` does.
            ((f64::from(points[i as usize][k]) - min[k]) * mul[k]).min(MORTON_CELLS - 1.0) as u32
        };
        (spread_bits(cell(2)) << 2) | (spread_bits(cell(1)) << 1) | spread_bits(cell(0))
    };
    let mut keyed: Vec<(u32, u32)> = indices.iter().map(|&i| (code(i), i)).collect();
    keyed.sort_by_key(|&(c, _)| c);
    for (slot, &(_, i)) in indices.iter_mut().zip(&keyed) {
        *slot = i;
    }
    let mut start = 0;
    while start < keyed.len() {
        let end = start + keyed[start..].partition_point(|&(c, _)| c == keyed[start].0);
        if end - start > CHUNK_SIZE {
            refine(points, &mut indices[start..end]);
        }
        start = end;
    }
}

/// The low 10 bits of `v` spread out to every third bit (bit k to bit 3k).
fn spread_bits(v: u32) -> u32 {
    let mut v = v & 0x3ff;
    v = (v ^ (v << 16)) & 0xff00_00ff;
    v = (v ^ (v << 8)) & 0x0300_f00f;
    v = (v ^ (v << 4)) & 0x030c_30c3;
    (v ^ (v << 2)) & 0x0924_9249
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_bits_interleaves() {
        assert_eq!(spread_bits(0b1), 0b1);
        assert_eq!(spread_bits(0b11), 0b1001);
        assert_eq!(spread_bits(0x3ff), 0x0924_9249);
    }

    #[test]
    fn morton_order_follows_the_z_curve() {
        // Corners of a unit square in z = 0: the curve visits (0,0), (1,0), (0,1), (1,1).
        let points = [
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
        ];
        assert_eq!(morton_order(&points), vec![3, 2, 1, 0]);
    }
}
