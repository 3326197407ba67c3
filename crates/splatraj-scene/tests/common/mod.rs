//! Helpers shared by the scene crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

#[path = "shared_data.rs"]
mod shared;
#[allow(unused_imports)] // as dead_code above: not every test binary reads shared data
pub use shared::shared_data;

use std::path::PathBuf;

use serde_json::Value;
use splatraj_scene::Scene;

/// A fixture copied into the repository (`tests/data/NAME`).
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// Offset of the first payload byte of a PLY file (just after `end_header\n`).
pub fn payload_offset(bytes: &[u8]) -> usize {
    let marker = b"end_header\n";
    bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("PLY has end_header")
        + marker.len()
}

/// Little-endian f32 at byte `at`.
pub fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// Little-endian u32 at byte `at`.
pub fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// A JSON reference fixture (`tests/data/NAME`).
pub fn reference(name: &str) -> Value {
    let text = std::fs::read_to_string(fixture(name)).expect("reference fixture");
    serde_json::from_str(&text).expect("reference JSON")
}

/// Every number of a (nested) JSON array, flattened.
pub fn floats(v: &Value) -> Vec<f32> {
    v.as_array()
        .expect("array")
        .iter()
        .flat_map(|x| match x {
            Value::Array(_) => floats(x),
            x => vec![x.as_f64().expect("number") as f32],
        })
        .collect()
}

/// How far ours may be from the reference decoding, per quantity.
#[derive(Clone, Copy)]
pub struct Tolerance {
    /// Absolute on positions.
    pub mean: f32,
    /// Relative on scales.
    pub scale: f32,
    /// On 1 − |q·q'| of unit quaternions.
    pub rotation: f32,
    /// Absolute on opacities.
    pub opacity: f32,
    /// Absolute on SH coefficients.
    pub sh: f32,
}

/// The float-for-float decodings of the same bytes (both read the codebook or the float).
pub const SAME_BYTES: Tolerance = Tolerance {
    mean: 1e-5,
    scale: 1e-5,
    rotation: 1e-6,
    opacity: 1e-5,
    sh: 1e-5,
};

/// Compares the Gaussians a reference decoded (`[{index, mean, scale, rotation, opacity, sh}]`)
/// with ours; prints the largest differences, returns how many Gaussians were compared.
pub fn check_against(scene: &Scene, gaussians: &Value, tol: Tolerance, what: &str) -> usize {
    let list = gaussians.as_array().expect("list of Gaussians");
    let mut worst = [0.0f32; 5];
    for g in list {
        let i = g["index"].as_u64().expect("index") as usize;
        let ctx = format!("{what}: Gaussian {i}");
        let mean = floats(&g["mean"]);
        for k in 0..3 {
            let d = (scene.means[i][k] - mean[k]).abs();
            worst[0] = worst[0].max(d);
            assert!(
                d <= tol.mean * (1.0 + mean[k].abs()),
                "{ctx}: mean {:?} vs reference {mean:?}",
                scene.means[i]
            );
        }
        let scale = floats(&g["scale"]);
        for k in 0..3 {
            let d = (scene.scales[i][k] - scale[k]).abs();
            worst[1] = worst[1].max(d / scale[k]);
            assert!(
                d <= tol.scale * scale[k],
                "{ctx}: scale {:?} vs reference {scale:?}",
                scene.scales[i]
            );
        }
        let q = floats(&g["rotation"]);
        let dot: f32 = (0..4).map(|k| scene.rotations[i][k] * q[k]).sum();
        worst[2] = worst[2].max(1.0 - dot.abs());
        assert!(
            1.0 - dot.abs() <= tol.rotation,
            "{ctx}: rotation {:?} vs reference {q:?}",
            scene.rotations[i]
        );
        let opacity = g["opacity"].as_f64().unwrap() as f32;
        worst[3] = worst[3].max((scene.opacities[i] - opacity).abs());
        assert!(
            (scene.opacities[i] - opacity).abs() <= tol.opacity,
            "{ctx}: opacity {} vs reference {opacity}",
            scene.opacities[i]
        );
        let sh = floats(&g["sh"]);
        assert_eq!(sh.len(), scene.sh_of(i).len(), "{ctx}: SH length");
        for (k, (ours, theirs)) in scene.sh_of(i).iter().zip(&sh).enumerate() {
            worst[4] = worst[4].max((ours - theirs).abs());
            assert!(
                (ours - theirs).abs() <= tol.sh,
                "{ctx}: SH value {k} (coefficient {}, channel {}) is {ours}, reference {theirs}",
                k / 3,
                k % 3
            );
        }
    }
    eprintln!(
        "{what}: {} Gaussians, largest differences: mean {:.2e}, scale (relative) {:.2e}, \
         rotation (1-|q.q'|) {:.2e}, opacity {:.2e}, SH {:.2e}",
        list.len(),
        worst[0],
        worst[1],
        worst[2],
        worst[3],
        worst[4]
    );
    list.len()
}
