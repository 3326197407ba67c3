//! The page's binary data as text: depth images quantised to 16 bits on a log scale, and
//! Gaussian centres as float32; both little-endian, then base64.
//!
//! A depth level q ∈ 1..=65535 stands for z = near · (far / near)^((q − 1) / 65534), so the
//! relative error of a decoded depth is at most ln(far / near) / 131068 (under 10⁻⁴ for a
//! thousandfold range); q = 0 is a pixel with no surface. A log scale keeps that relative
//! error the same near and far, which linear levels would not in a room seen from inside.

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use serde::{Deserialize, Serialize};

/// The level of a pixel with no surface under it.
pub const NO_SURFACE: u16 = 0;
/// Steps between the nearest and the farthest depth (levels 1..=65535).
const STEPS: f64 = 65534.0;

/// A depth image as the page holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EncodedDepth {
    /// Smallest depth in the image (level 1).
    pub near: f64,
    /// Largest depth in the image (level 65535).
    pub far: f64,
    /// One u16 level per pixel, row-major, little-endian, base64.
    pub levels: String,
}

/// `depth` (camera z per pixel; not finite or ≤ 0 where no surface) as levels.
pub fn encode_depth(depth: &[f32]) -> EncodedDepth {
    let valid = |z: f32| z.is_finite() && z > 0.0;
    let (near, far) = depth
        .iter()
        .filter(|&&z| valid(z))
        .fold((f64::INFINITY, 0f64), |(lo, hi), &z| {
            (lo.min(f64::from(z)), hi.max(f64::from(z)))
        });
    let (near, far) = if near.is_finite() {
        (near, far)
    } else {
        (1.0, 1.0)
    };
    let span = (far / near).ln();
    let mut bytes = Vec::with_capacity(depth.len() * 2);
    for &z in depth {
        let level = if !valid(z) {
            NO_SURFACE
        } else if span > 0.0 {
            let step = ((f64::from(z) / near).ln() / span * STEPS).round();
            1 + step.clamp(0.0, STEPS) as u16
        } else {
            1
        };
        bytes.extend(level.to_le_bytes());
    }
    EncodedDepth {
        near,
        far,
        levels: BASE64.encode(bytes),
    }
}

impl EncodedDepth {
    /// The depths back (`None` where no surface), as the page's script decodes them.
    pub fn decode(&self) -> Result<Vec<Option<f64>>, base64::DecodeError> {
        let bytes = BASE64.decode(&self.levels)?;
        let ratio = self.far / self.near;
        Ok(bytes
            .chunks_exact(2)
            .map(|b| match u16::from_le_bytes([b[0], b[1]]) {
                NO_SURFACE => None,
                q => Some(self.near * ratio.powf(f64::from(q - 1) / STEPS)),
            })
            .collect())
    }
}

/// Points as float32 triples, little-endian, base64.
pub fn encode_points(points: &[[f32; 3]]) -> String {
    let bytes: Vec<u8> = points
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    BASE64.encode(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_round_trips_within_the_stated_error() {
        let depth = [0.5f32, f32::NAN, 2.0, 500.0, 0.0, 7.25];
        let encoded = encode_depth(&depth);
        assert_eq!((encoded.near, encoded.far), (0.5, 500.0));
        let decoded = encoded.decode().unwrap();
        let bound = (1000f64).ln() / 131068.0 + 1e-12;
        for (z, d) in depth.iter().zip(&decoded) {
            match d {
                Some(d) => assert!((d / f64::from(*z) - 1.0).abs() <= bound, "{z} → {d}"),
                None => assert!(!(z.is_finite() && *z > 0.0)),
            }
        }
        assert_eq!(decoded[0], Some(0.5));
        assert!((decoded[3].unwrap() - 500.0).abs() < 1e-9);
    }

    #[test]
    fn flat_and_empty_depths_decode() {
        let flat = encode_depth(&[3.0, 3.0]).decode().unwrap();
        assert_eq!(flat, vec![Some(3.0), Some(3.0)]);
        let empty = encode_depth(&[f32::NAN, -1.0]).decode().unwrap();
        assert_eq!(empty, vec![None, None]);
    }

    #[test]
    fn points_are_little_endian_float32() {
        let text = encode_points(&[[1.0, -2.0, 0.5]]);
        let bytes = BASE64.decode(text).unwrap();
        assert_eq!(&bytes[0..4], &1f32.to_le_bytes());
        assert_eq!(&bytes[4..8], &(-2f32).to_le_bytes());
        assert_eq!(bytes.len(), 12);
    }
}
