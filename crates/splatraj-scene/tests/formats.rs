//! Readers and writer on real files, checked against values decoded by hand from the bytes.

mod common;

use common::{f32_at, fixture, payload_offset, shared_data, u32_at};
use splatraj_scene::formats::{LoadedScene, ReadOptions, SceneFormat};
use splatraj_scene::{Scene, read_scene, write_inria_ply};

fn read(path: &std::path::Path) -> LoadedScene {
    read_scene(path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn sigmoid64(x: f32) -> f32 {
    (1.0 / (1.0 + (-(x as f64)).exp())) as f32
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

/// fruit_drops vertex layout: x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity scale_0..2
/// rot_0..3 transform — 63 floats.
const FRUIT_STRIDE: usize = 63 * 4;

#[test]
fn fruit_drops_counts_degree_and_extras() {
    let loaded = read(&fixture("fruit_drops_minimal.ply"));
    assert_eq!(loaded.format, SceneFormat::InriaPly);
    let scene = &loaded.scene;
    assert_eq!(scene.len(), 4721);
    assert_eq!(scene.sh_degree, 3);
    assert_eq!(scene.sh.len(), 4721 * 16 * 3);
    // `transform` is neither a label nor a feature: it is kept by name.
    let names: Vec<&str> = scene
        .extras
        .properties
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(names, ["transform"]);
    assert!(scene.extras.labels.is_none() && scene.extras.features.is_none());
}

#[test]
fn fruit_drops_spot_values_match_the_raw_bytes() {
    let path = fixture("fruit_drops_minimal.ply");
    let bytes = std::fs::read(&path).unwrap();
    let start = payload_offset(&bytes);
    assert_eq!(
        bytes.len() - start,
        4721 * FRUIT_STRIDE,
        "fixture has the layout we assume"
    );
    let scene = read(&path).scene;
    for i in [0usize, 1, 2357, 4720] {
        let raw = |k: usize| f32_at(&bytes, start + i * FRUIT_STRIDE + 4 * k);
        assert_eq!(scene.means[i], [raw(0), raw(1), raw(2)]);
        for k in 0..3 {
            assert!(close(
                scene.scales[i][k],
                (raw(55 + k) as f64).exp() as f32,
                1e-6
            ));
        }
        assert!(close(scene.opacities[i], sigmoid64(raw(54)), 1e-6));
        let q = [raw(58), raw(59), raw(60), raw(61)];
        let norm = q.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt() as f32;
        for (got, raw) in scene.rotations[i].iter().zip(q) {
            assert!(close(*got, raw / norm, 1e-6));
        }
        let sh = scene.sh_of(i);
        // DC terms, then f_rest grouped by channel: f_rest_j is channel j / 15, coefficient
        // j % 15 + 1, stored at [coefficient][channel].
        assert_eq!(&sh[..3], &[raw(6), raw(7), raw(8)]);
        assert_eq!(sh[3], raw(9)); // f_rest_0: red, coefficient 1
        assert_eq!(sh[3 * 2 + 1], raw(9 + 16)); // f_rest_16: green, coefficient 2
        assert_eq!(sh[3 * 15 + 2], raw(9 + 44)); // f_rest_44: blue, coefficient 15
        assert_eq!(scene.extras.properties[0].values[i], raw(62));
    }
}

#[test]
fn fruit_drops_label_sidecar() {
    let options = ReadOptions {
        labels: Some(fixture("fruit_drops_minimal.json")),
        ..Default::default()
    };
    let scene = read_scene(&fixture("fruit_drops_minimal.ply"), &options)
        .unwrap()
        .scene;
    let labels = scene.extras.labels.expect("labels attached");
    // Counts tallied independently from the JSON with Python's collections.Counter.
    let expected = [
        (0, 229),
        (1, 542),
        (2, 680),
        (3, 398),
        (4, 1038),
        (5, 616),
        (6, 396),
        (7, 556),
        (8, 266),
    ];
    assert_eq!(labels.counts().into_iter().collect::<Vec<_>>(), expected);
    assert_eq!(labels.names.get(&3).map(String::as_str), Some("Category 3"));
    assert!(!labels.names.contains_key(&0), "0 is unlabelled");
}

#[test]
fn donut_without_normals_or_rest() {
    let Some(path) = shared_data("donut_fused.ply") else {
        return;
    };
    let scene = read(&path).scene;
    assert_eq!(scene.len(), 45624);
    assert_eq!(scene.sh_degree, 0);
    assert!(scene.extras.properties.is_empty());
    // 14 floats per vertex: x y z f_dc_0..2 opacity scale_0..2 rot_0..3.
    let bytes = std::fs::read(&path).unwrap();
    let start = payload_offset(&bytes);
    assert_eq!(bytes.len() - start, 45624 * 14 * 4);
    let i = 12345;
    let raw = |k: usize| f32_at(&bytes, start + i * 56 + 4 * k);
    assert_eq!(scene.means[i], [raw(0), raw(1), raw(2)]);
    assert_eq!(&scene.sh_of(i)[..3], &[raw(3), raw(4), raw(5)]);
    assert!(close(scene.opacities[i], sigmoid64(raw(6)), 1e-6));
}

/// Decodes Gaussian `i` of a compressed PLY straight from the format's definition: chunk
/// records of 18 floats (position, log-scale and colour ranges), then 4 packed u32 per vertex.
/// Returns (position, log-scale, base colour, opacity).
fn decode_compressed_by_hand(
    bytes: &[u8],
    chunks: usize,
    i: usize,
) -> ([f32; 3], [f32; 3], [f32; 3], f32) {
    let start = payload_offset(bytes);
    let chunk = |k: usize| f32_at(bytes, start + (i / 256) * 72 + 4 * k);
    let vertex = start + chunks * 72 + i * 16;
    let (pos, scale, color) = (
        u32_at(bytes, vertex),
        u32_at(bytes, vertex + 8),
        u32_at(bytes, vertex + 12),
    );
    let eleven_ten_eleven = |v: u32| {
        [
            (v >> 21) as f32 / 2047.0,
            ((v >> 11) & 1023) as f32 / 1023.0,
            (v & 2047) as f32 / 2047.0,
        ]
    };
    let (p, s) = (eleven_ten_eleven(pos), eleven_ten_eleven(scale));
    let lerp = |lo: f32, hi: f32, t: f32| lo + (hi - lo) * t;
    let position = [
        lerp(chunk(0), chunk(3), p[0]),
        lerp(chunk(1), chunk(4), p[1]),
        lerp(chunk(2), chunk(5), p[2]),
    ];
    let log_scale = [
        lerp(chunk(6), chunk(9), s[0]),
        lerp(chunk(7), chunk(10), s[1]),
        lerp(chunk(8), chunk(11), s[2]),
    ];
    let byte = |shift: u32| ((color >> shift) & 255) as f32 / 255.0;
    let rgb = [
        lerp(chunk(12), chunk(15), byte(24)),
        lerp(chunk(13), chunk(16), byte(16)),
        lerp(chunk(14), chunk(17), byte(8)),
    ];
    (position, log_scale, rgb, byte(0))
}

fn check_compressed_spot_values(path: &std::path::Path, chunks: usize, indices: &[usize]) {
    let bytes = std::fs::read(path).unwrap();
    let scene = read(path).scene;
    for &i in indices {
        let (position, log_scale, rgb, opacity) = decode_compressed_by_hand(&bytes, chunks, i);
        for k in 0..3 {
            assert!(
                close(scene.means[i][k], position[k], 1e-5),
                "Gaussian {i} axis {k}"
            );
            assert!(close(scene.scales[i][k], log_scale[k].exp(), 1e-5));
            assert!(close(scene.base_color(i)[k], rgb[k].max(0.0), 1e-5));
        }
        assert!(close(scene.opacities[i], opacity, 1e-6));
    }
}

#[test]
fn biker_compressed_counts_and_spot_values() {
    let Some(path) = shared_data("biker.compressed.ply") else {
        return;
    };
    let loaded = read(&path);
    assert_eq!(loaded.format, SceneFormat::CompressedPly);
    assert_eq!(loaded.scene.len(), 152_746);
    assert_eq!(loaded.scene.sh_degree, 0);
    check_compressed_spot_values(&path, 597, &[0, 255, 256, 100_000, 152_745]);
}

#[test]
fn guitar_compressed_counts_and_spot_values() {
    let Some(path) = shared_data("guitar.compressed.ply") else {
        return;
    };
    let loaded = read(&path);
    assert_eq!(loaded.scene.len(), 90_854);
    check_compressed_spot_values(&path, 355, &[0, 4242, 90_853]);
}

#[test]
fn test_compressed_with_sh_element() {
    let path = fixture("test.compressed.ply");
    let scene = read(&path).scene;
    assert_eq!(scene.len(), 64);
    assert_eq!(scene.sh_degree, 3);
    check_compressed_spot_values(&path, 1, &[0, 17, 63]);
    // The `sh` element follows the vertices: 45 uchar per Gaussian, grouped by channel.
    // Byte b means (b + 0.5)/256 (0 and 255 map to 0 and 1) scaled to [-4, 4].
    let bytes = std::fs::read(&path).unwrap();
    let sh_start = payload_offset(&bytes) + 72 + 64 * 16;
    let decode = |b: u8| {
        let n = match b {
            0 => 0.0,
            255 => 1.0,
            b => (b as f32 + 0.5) / 256.0,
        };
        (n - 0.5) * 8.0
    };
    for i in [0usize, 40] {
        let raw = |j: usize| bytes[sh_start + i * 45 + j];
        let sh = scene.sh_of(i);
        assert_eq!(sh[3], decode(raw(0))); // red, coefficient 1
        assert_eq!(sh[3 * 4 + 1], decode(raw(15 + 3))); // green, coefficient 4
        assert_eq!(sh[3 * 15 + 2], decode(raw(44))); // blue, coefficient 15
    }
}

fn assert_same_scene(a: &Scene, b: &Scene) {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.sh_degree, b.sh_degree);
    assert_eq!(a.means, b.means, "positions are written as they are");
    assert_eq!(a.sh, b.sh, "SH coefficients are written as they are");
    for i in 0..a.len() {
        for k in 0..3 {
            // exp(ln s), sigmoid(logit o) and re-normalising a unit quaternion change a few ulps.
            assert!(close(a.scales[i][k], b.scales[i][k], 1e-6), "scale {i}");
        }
        assert!(
            (a.opacities[i] - b.opacities[i]).abs() <= 2e-7,
            "opacity {i}"
        );
        for k in 0..4 {
            assert!(
                (a.rotations[i][k] - b.rotations[i][k]).abs() <= 1e-6,
                "rotation {i}"
            );
        }
    }
    assert_eq!(a.extras, b.extras);
}

#[test]
fn round_trip_inria_with_labels_and_extras() {
    let options = ReadOptions {
        labels: Some(fixture("fruit_drops_minimal.json")),
        ..Default::default()
    };
    let original = read_scene(&fixture("fruit_drops_minimal.ply"), &options)
        .unwrap()
        .scene;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.ply");
    write_inria_ply(&original, &out).unwrap();
    let mut back = read(&out).scene;
    // The label column is written as `label`; the sidecar path is not a property name.
    let labels = back.extras.labels.as_mut().expect("labels written");
    assert_eq!(labels.source, "label");
    labels.source = original.extras.labels.as_ref().unwrap().source.clone();
    assert_same_scene(&original, &back);
    // No temporary file is left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn round_trip_compressed_to_inria() {
    let path = fixture("test.compressed.ply");
    let original = read(&path).scene;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.ply");
    write_inria_ply(&original, &out).unwrap();
    let back = read(&out);
    assert_eq!(back.format, SceneFormat::InriaPly);
    assert_same_scene(&original, &back.scene);
}

/// Writes the first `n` Gaussians of fruit_drops as ASCII and big-endian PLY by hand (same
/// header, other encodings) and checks that all three read to the same scene.
#[test]
fn ascii_and_big_endian_read_like_little_endian() {
    let path = fixture("fruit_drops_minimal.ply");
    let bytes = std::fs::read(&path).unwrap();
    let start = payload_offset(&bytes);
    let header = std::str::from_utf8(&bytes[..start]).unwrap();
    let n = 50;
    let header = header.replace("element vertex 4721", &format!("element vertex {n}"));
    let values: Vec<f32> = (0..n * 63).map(|k| f32_at(&bytes, start + 4 * k)).collect();

    let dir = tempfile::tempdir().unwrap();
    let little = dir.path().join("le.ply");
    let mut le = header.clone().into_bytes();
    le.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    std::fs::write(&little, le).unwrap();

    let big = dir.path().join("be.ply");
    let mut be = header
        .replace("binary_little_endian", "binary_big_endian")
        .into_bytes();
    be.extend(values.iter().flat_map(|v| v.to_be_bytes()));
    std::fs::write(&big, be).unwrap();

    let ascii = dir.path().join("ascii.ply");
    let mut text = header.replace("binary_little_endian", "ascii");
    for row in values.chunks(63) {
        // `{:?}` prints the shortest text that parses back to the same f32.
        text += &row
            .iter()
            .map(|v| format!("{v:?}"))
            .collect::<Vec<_>>()
            .join(" ");
        text += "\n";
    }
    std::fs::write(&ascii, text).unwrap();

    let reference = read(&little).scene;
    assert_eq!(reference.len(), n);
    assert_eq!(read(&big).scene, reference);
    assert_eq!(read(&ascii).scene, reference);
}
