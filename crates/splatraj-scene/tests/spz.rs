//! SPZ reader tests: the real biker.spz (version 4), an independent hand decode of its raw bytes,
//! agreement with the same scene as a compressed PLY, small hand-written files of every version,
//! and bad input that must give a clear error, never a panic.

use std::f32::consts::FRAC_1_SQRT_2;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use splatraj_scene::formats::spz::{MAGIC_BYTES, decode_spz};
use splatraj_scene::{ReadOptions, Scene, SceneError, SceneFormat, read_scene};

const C0: f32 = 0.282_094_8;
const BIKER_COUNT: usize = 152_746;

#[path = "common/shared_data.rs"]
mod shared_data;

/// Reads a shared data file; a missing file fails the test (nothing is skipped silently).
fn data_file(name: &str) -> (PathBuf, Vec<u8>) {
    let path = shared_data::shared_data(name)
        .unwrap_or_else(|| panic!("{name}: the shared data set is required for this test"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (path, bytes)
}

fn detail_of(err: SceneError) -> String {
    match err {
        SceneError::Malformed { detail, .. } => detail,
        other => panic!("expected SceneError::Malformed, got {other:?}"),
    }
}

/// Decodes `bytes` expecting a Malformed error; returns its detail.
fn expect_error(bytes: &[u8]) -> String {
    let path = Path::new("test.spz");
    match decode_spz(bytes, path) {
        Ok(scene) => panic!("expected an error, decoded {} Gaussians", scene.len()),
        Err(e) => {
            let shown = e.to_string();
            assert!(
                shown.contains("test.spz"),
                "error does not name the file: {shown}"
            );
            detail_of(e)
        }
    }
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

// ---------------------------------------------------------------------------------------------
// 1. The real file.

#[test]
fn biker_spz_count_and_sh_degree() {
    let (path, bytes) = data_file("biker.spz");
    assert!(bytes.starts_with(MAGIC_BYTES));
    let scene = decode_spz(&bytes, &path).expect("biker.spz decodes");
    assert_eq!(scene.len(), BIKER_COUNT);
    assert_eq!(scene.sh_degree, 0);
    assert_eq!(scene.sh.len(), BIKER_COUNT * 3);
    assert_eq!(scene.scales.len(), BIKER_COUNT);
    assert_eq!(scene.rotations.len(), BIKER_COUNT);
    assert_eq!(scene.opacities.len(), BIKER_COUNT);
    assert_eq!(scene.extras, Default::default());

    let loaded = read_scene(&path, &ReadOptions::default()).expect("biker.spz validates");
    assert_eq!(loaded.format, SceneFormat::Spz);
    assert_eq!(loaded.scene.len(), BIKER_COUNT);
    assert_eq!(loaded.dropped, 0);
}

// ---------------------------------------------------------------------------------------------
// 2. Spot values from a separate, minimal decode of the raw bytes.

/// The raw version 4 streams, decompressed with ruzstd's streaming reader.
struct RawV4 {
    fractional_bits: u8,
    streams: Vec<Vec<u8>>,
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

fn raw_v4(bytes: &[u8]) -> RawV4 {
    assert_eq!(&bytes[..4], b"NGSP");
    assert_eq!(le_u32(bytes, 4), 4);
    let n_streams = bytes[15] as usize;
    let toc = le_u32(bytes, 16) as usize;
    let mut at = toc + 16 * n_streams;
    let mut streams = Vec::new();
    for s in 0..n_streams {
        let compressed = le_u64(bytes, toc + 16 * s) as usize;
        let uncompressed = le_u64(bytes, toc + 16 * s + 8) as usize;
        let mut out = Vec::new();
        ruzstd::decoding::StreamingDecoder::new(&bytes[at..at + compressed])
            .unwrap()
            .read_to_end(&mut out)
            .unwrap();
        assert_eq!(out.len(), uncompressed);
        streams.push(out);
        at += compressed;
    }
    assert_eq!(at, bytes.len());
    RawV4 {
        fractional_bits: bytes[13],
        streams,
    }
}

/// Gaussian `i` decoded by hand in the PLY (RDF) convention: mean, scale, (w, x, y, z),
/// opacity, f_dc.
fn hand_decode(raw: &RawV4, i: usize) -> ([f32; 3], [f32; 3], [f32; 4], f32, [f32; 3]) {
    let [pos, alpha, colour, scale, rot] = [0, 1, 2, 3, 4].map(|s| &raw.streams[s]);
    let coord = |k: usize| {
        let b = &pos[9 * i + 3 * k..9 * i + 3 * k + 3];
        let mut v = b[0] as i64 | (b[1] as i64) << 8 | (b[2] as i64) << 16;
        if v >= 1 << 23 {
            v -= 1 << 24;
        }
        v as f64 / f64::from(1u32 << raw.fractional_bits)
    };
    // SPZ is RUB; the scene is RDF: y and z change sign.
    let mean = [coord(0) as f32, -coord(1) as f32, -coord(2) as f32];
    let scale = [0, 1, 2].map(|k| (scale[3 * i + k] as f32 / 16.0 - 10.0).exp());
    let f_dc = [0, 1, 2].map(|k| (colour[3 * i + k] as f32 / 255.0 - 0.5) / 0.15);
    let opacity = alpha[i] as f32 / 255.0;

    let word = le_u32(rot, 4 * i);
    let largest = (word >> 30) as usize;
    // The three 10-bit fields, highest bits first, belong to the other indices in ascending
    // order (x, y, z, w indexing).
    let fields = [(word >> 20) & 0x3ff, (word >> 10) & 0x3ff, word & 0x3ff];
    let others: Vec<usize> = (0..4).filter(|&k| k != largest).collect();
    let mut q = [0.0f32; 4];
    for (field, &k) in fields.iter().zip(&others) {
        let magnitude = (field & 0x1ff) as f32 / 511.0 * FRAC_1_SQRT_2;
        q[k] = if field & 0x200 != 0 {
            -magnitude
        } else {
            magnitude
        };
    }
    q[largest] = (1.0 - q.iter().map(|c| c * c).sum::<f32>()).max(0.0).sqrt();
    let [x, y, z, w] = q;
    (mean, scale, [w, x, -y, -z], opacity, f_dc)
}

#[test]
fn biker_spz_spot_values_match_a_hand_decode() {
    let (path, bytes) = data_file("biker.spz");
    let scene = decode_spz(&bytes, &path).unwrap();
    let raw = raw_v4(&bytes);
    assert_eq!(raw.streams.len(), 5, "SH degree 0: no SH stream");
    for i in [0, 1, 77_777, BIKER_COUNT - 1] {
        let (mean, scale, rotation, opacity, f_dc) = hand_decode(&raw, i);
        for k in 0..3 {
            assert!(
                close(scene.means[i][k], mean[k], 1e-6),
                "mean {i}: {:?} vs {mean:?}",
                scene.means[i]
            );
            assert!(
                close(scene.scales[i][k], scale[k], 1e-6 * scale[k]),
                "scale {i}"
            );
            assert!(close(scene.sh[3 * i + k], f_dc[k], 1e-5), "f_dc {i}");
        }
        for k in 0..4 {
            assert!(
                close(scene.rotations[i][k], rotation[k], 1e-6),
                "rotation {i}: {:?} vs {rotation:?}",
                scene.rotations[i]
            );
        }
        assert!(close(scene.opacities[i], opacity, 1e-7), "opacity {i}");
    }
    // Point 0 by value, so a shared mistake in both decoders would still show.
    assert!(close(scene.means[0][0], -0.104_492_19, 1e-6));
    assert!(close(scene.means[0][1], -2.387_939_5, 1e-6));
    assert!(close(scene.means[0][2], -0.360_839_84, 1e-6));
}

// ---------------------------------------------------------------------------------------------
// 3. The same scene as a PlayCanvas compressed PLY.

/// Per-chunk float ranges of a compressed PLY, read straight from its bytes (18 floats a chunk:
/// min/max position, min/max log-scale, min/max colour).
fn compressed_ply_chunks(bytes: &[u8]) -> Vec<[f32; 18]> {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("PLY header end")
        + 11;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let lines: Vec<&str> = header.lines().collect();
    let chunk_line = lines
        .iter()
        .position(|l| l.starts_with("element chunk "))
        .expect("a chunk element");
    let count: usize = lines[chunk_line]["element chunk ".len()..]
        .trim()
        .parse()
        .unwrap();
    let expected = [
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
    for (k, name) in expected.iter().enumerate() {
        assert_eq!(lines[chunk_line + 1 + k], format!("property float {name}"));
    }
    // The chunk element must be the first element for its data to start right after the header.
    assert!(
        !lines[..chunk_line]
            .iter()
            .any(|l| l.starts_with("element "))
    );
    (0..count)
        .map(|c| {
            std::array::from_fn(|k| {
                let at = end + 72 * c + 4 * k;
                f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
            })
        })
        .collect()
}

#[test]
fn biker_spz_agrees_with_biker_compressed_ply() {
    let (spz_path, _) = data_file("biker.spz");
    let (ply_path, ply_bytes) = data_file("biker.compressed.ply");
    let spz = read_scene(&spz_path, &ReadOptions::default())
        .unwrap()
        .scene;
    let ply = read_scene(&ply_path, &ReadOptions::default())
        .unwrap()
        .scene;
    assert_eq!(spz.len(), ply.len());
    assert_eq!(spz.sh_degree, ply.sh_degree);
    let chunks = compressed_ply_chunks(&ply_bytes);
    assert_eq!(chunks.len(), spz.len().div_ceil(256));

    // Tolerances from the two quantisations, Gaussian by Gaussian in the same order:
    // - SPZ positions are rounded to 1/2^12 (2^-13 at most off); the compressed PLY rounds
    //   each axis to 11/10/11 bits of its chunk's range (half a step at most off).
    // - SPZ stores f_dc in steps of 1/(0.15·255), i.e. colour steps of C0/(0.15·255); the
    //   compressed PLY stores colour in 8 bits of the chunk's colour range.
    // - Both store the activated opacity in 8 bits.
    // - SPZ log-scales are in steps of 1/16 and clamped to [-10, 5.9375]; the compressed PLY
    //   uses 11/10/11 bits of the chunk's log-scale range. Clamped SPZ values are not compared.
    // - Rotations: each stored component is off by at most about 7e-4 in either format, the
    //   recomputed largest one by at most about 6e-3, so 1 − |q·q'| ≤ |Δq|²/2 stays below 5e-5.
    let steps = [2047.0f32, 1023.0, 2047.0];
    let colour_step = C0 / (0.15 * 255.0);
    let mut failures = Vec::new();
    let mut clamped_scales = 0;
    for i in 0..spz.len() {
        let c = &chunks[i / 256];
        for k in 0..3 {
            let tol = 2f32.powi(-13)
                + (c[3 + k] - c[k]) / (2.0 * steps[k])
                + 1e-6 * (1.0 + spz.means[i][k].abs());
            if !close(spz.means[i][k], ply.means[i][k], tol) {
                failures.push(format!(
                    "mean {i}/{k}: {} vs {} (tol {tol})",
                    spz.means[i][k], ply.means[i][k]
                ));
            }
            let colour = |s: &Scene| 0.5 + C0 * s.sh_of(i)[k];
            let tol = colour_step / 2.0 + (c[15 + k] - c[12 + k]) / 510.0 + 1e-5;
            if !close(colour(&spz), colour(&ply), tol) {
                failures.push(format!(
                    "colour {i}/{k}: {} vs {} (tol {tol})",
                    colour(&spz),
                    colour(&ply)
                ));
            }
            let log_spz = spz.scales[i][k].ln();
            if log_spz <= -10.0 + 1e-3 || log_spz >= 255.0 / 16.0 - 10.0 - 1e-3 {
                clamped_scales += 1;
                continue;
            }
            let tol = 1.0 / 32.0 + (c[9 + k] - c[6 + k]) / (2.0 * steps[k]) + 1e-4;
            let log_ply = ply.scales[i][k].ln();
            if !close(log_spz, log_ply, tol) {
                failures.push(format!(
                    "log-scale {i}/{k}: {log_spz} vs {log_ply} (tol {tol})"
                ));
            }
        }
        if !close(spz.opacities[i], ply.opacities[i], 1.0 / 255.0 + 1e-5) {
            failures.push(format!(
                "opacity {i}: {} vs {}",
                spz.opacities[i], ply.opacities[i]
            ));
        }
        let dot: f32 = (0..4)
            .map(|k| spz.rotations[i][k] * ply.rotations[i][k])
            .sum();
        if 1.0 - dot.abs() > 5e-5 {
            failures.push(format!(
                "rotation {i}: {:?} vs {:?} (1 - |dot| = {})",
                spz.rotations[i],
                ply.rotations[i],
                1.0 - dot.abs()
            ));
        }
    }
    let kinds = ["mean", "colour", "log-scale", "opacity", "rotation"].map(|kind| {
        (
            kind,
            failures.iter().filter(|f| f.starts_with(kind)).count(),
        )
    });
    assert!(
        failures.is_empty(),
        "{} disagreements ({kinds:?}), first: {:#?}",
        failures.len(),
        &failures[..failures.len().min(10)]
    );
    // Only the few Gaussians whose log-scale is below SPZ's floor of -10 are clamped.
    assert!(clamped_scales < 200, "{clamped_scales} clamped scales");
}

// ---------------------------------------------------------------------------------------------
// 4. Small files written by hand from the format's definition.

/// One Gaussian as SPZ stores it (in the file's RUB axes).
#[derive(Clone)]
struct Packed {
    position: [f32; 3],
    alpha: u8,
    colour: [u8; 3],
    scale: [u8; 3],
    /// (x, y, z, w), unit.
    rotation: [f32; 4],
    /// Coefficient-major, channel fastest, `3 · ((d+1)² − 1)` bytes.
    sh: Vec<u8>,
}

fn normalised(q: [f32; 4]) -> [f32; 4] {
    let n = q.iter().map(|c| c * c).sum::<f32>().sqrt();
    q.map(|c| c / n)
}

fn sample_points(sh_bytes: usize) -> Vec<Packed> {
    let rotations = [
        [0.1, -0.2, 0.3, 0.9],  // w largest
        [0.8, 0.1, -0.3, 0.2],  // x largest
        [-0.1, -0.9, 0.2, 0.3], // y largest (negative)
        [0.3, 0.2, 0.85, -0.1], // z largest
    ];
    rotations
        .iter()
        .enumerate()
        .map(|(i, &q)| Packed {
            position: [1.25 + i as f32, -2.5, 0.375 * i as f32 - 3.0],
            alpha: 40 + 60 * i as u8,
            colour: [10 + i as u8, 128, 250 - i as u8],
            scale: [0, 100 + i as u8, 255],
            rotation: normalised(q),
            sh: (0..sh_bytes).map(|k| (k * 37 + i * 11) as u8).collect(),
        })
        .collect()
}

fn fixed24(v: f32, fractional_bits: u8) -> [u8; 3] {
    let q = (v * (1u32 << fractional_bits) as f32).round() as i32;
    let b = q.to_le_bytes();
    [b[0], b[1], b[2]]
}

/// Version 3/4 "smallest three", packed as the format's writer does.
fn smallest_three(q: [f32; 4]) -> [u8; 4] {
    let largest = (0..4)
        .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()))
        .unwrap();
    let negate = q[largest] < 0.0;
    let mut word = largest as u32;
    for (k, &c) in q.iter().enumerate() {
        if k == largest {
            continue;
        }
        let c = if negate { -c } else { c };
        let magnitude = (c.abs() / FRAC_1_SQRT_2 * 511.0).round() as u32;
        word = (word << 10) | (u32::from(c < 0.0) << 9) | magnitude;
    }
    word.to_le_bytes()
}

/// Version 1/2 rotation: x, y, z with w made non-negative.
fn first_three(q: [f32; 4]) -> [u8; 3] {
    let s = if q[3] < 0.0 { -1.0 } else { 1.0 };
    [0, 1, 2].map(|k| ((s * q[k] + 1.0) * 127.5).round() as u8)
}

/// The six attribute arrays in file order. Version 1 positions must be exact in float16: they
/// are taken from `HALF_POSITIONS`.
fn arrays(points: &[Packed], version: u32, fractional_bits: u8) -> [Vec<u8>; 6] {
    let mut a: [Vec<u8>; 6] = Default::default();
    for p in points {
        if version == 1 {
            for (k, v) in p.position.iter().enumerate() {
                let half = HALF_POSITIONS
                    .iter()
                    .find(|(f, _)| f == v)
                    .unwrap_or_else(|| panic!("no half for {v} (axis {k})"))
                    .1;
                a[0].extend(half.to_le_bytes());
            }
        } else {
            for v in p.position {
                a[0].extend(fixed24(v, fractional_bits));
            }
        }
        a[1].push(p.alpha);
        a[2].extend(p.colour);
        a[3].extend(p.scale);
        if version >= 3 {
            a[4].extend(smallest_three(p.rotation));
        } else {
            a[4].extend(first_three(p.rotation));
        }
        a[5].extend(&p.sh);
    }
    a
}

/// Float16 bit patterns of the positions used in the version 1 test.
const HALF_POSITIONS: [(f32, u16); 7] = [
    (1.25, 0x3d00),
    (2.25, 0x4080),
    (-2.5, 0xc100),
    (-3.0, 0xc200),
    (-2.625, 0xc140),
    (0.0, 0x0000),
    (0.000_061_035_156, 0x0400),
];

fn legacy_content(
    version: u32,
    count: u32,
    sh_degree: u8,
    flags: u8,
    arrays: &[Vec<u8>],
) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend(b"NGSP");
    out.extend(version.to_le_bytes());
    out.extend(count.to_le_bytes());
    out.extend([sh_degree, 12, flags, 0]);
    for a in arrays {
        out.extend(a);
    }
    out
}

fn gzip(content: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(content).unwrap();
    enc.finish().unwrap()
}

fn v4_file(count: u32, sh_degree: u8, flags: u8, extensions: &[u8], arrays: &[Vec<u8>]) -> Vec<u8> {
    let streams: Vec<&Vec<u8>> = arrays.iter().filter(|a| !a.is_empty()).collect();
    let compressed: Vec<Vec<u8>> = streams
        .iter()
        .map(|s| {
            ruzstd::encoding::compress_to_vec(&s[..], ruzstd::encoding::CompressionLevel::Fastest)
        })
        .collect();
    let mut out = Vec::new();
    out.extend(b"NGSP");
    out.extend(4u32.to_le_bytes());
    out.extend(count.to_le_bytes());
    out.extend([sh_degree, 12, flags, streams.len() as u8]);
    out.extend((32 + extensions.len() as u32).to_le_bytes());
    out.extend([0u8; 12]);
    out.extend(extensions);
    for (s, c) in streams.iter().zip(&compressed) {
        out.extend((c.len() as u64).to_le_bytes());
        out.extend((s.len() as u64).to_le_bytes());
    }
    for c in &compressed {
        out.extend(c);
    }
    out
}

/// Signs of the degree 1-3 SH coefficients under RUB → RDF (y and z negated): −1 where the
/// basis function is odd in exactly one of y, z.
const SH_SIGNS_RUB_TO_RDF: [f32; 15] = [
    -1.0, -1.0, 1.0, // y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // xy, yz, 3z²−1, xz, x²−y²
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0, // degree 3
];

/// Checks a decoded scene against the packed points. `flip` is (1, −1, −1) for RUB files.
fn check_decoded(scene: &Scene, points: &[Packed], version: u32, flip: [f32; 3]) {
    assert_eq!(scene.len(), points.len());
    let coeffs = scene.sh_coeffs();
    for (i, p) in points.iter().enumerate() {
        for (k, f) in flip.iter().enumerate() {
            let mean = f * p.position[k];
            assert!(
                close(scene.means[i][k], mean, 2f32.powi(-12)),
                "mean {i}/{k}: {} vs {mean}",
                scene.means[i][k]
            );
            let scale = (p.scale[k] as f32 / 16.0 - 10.0).exp();
            assert!(
                close(scene.scales[i][k], scale, 1e-6 * scale),
                "scale {i}/{k}"
            );
            let f_dc = (p.colour[k] as f32 / 255.0 - 0.5) / 0.15;
            assert!(close(scene.sh_of(i)[k], f_dc, 1e-5), "f_dc {i}/{k}");
        }
        assert!(close(scene.opacities[i], p.alpha as f32 / 255.0, 1e-7));
        // Expected rotation: conjugated by the flip, as (w, x, y, z); compared up to sign.
        let det = flip[0] * flip[1] * flip[2];
        let [x, y, z, w] = p.rotation;
        let expected = [w, det * flip[0] * x, det * flip[1] * y, det * flip[2] * z];
        let dot: f32 = (0..4).map(|k| scene.rotations[i][k] * expected[k]).sum();
        // Versions 1-2 store 8 bits per component, versions 3-4 nine bits and a sign.
        let tol = if version >= 3 { 2e-5 } else { 1e-3 };
        assert!(
            1.0 - dot.abs() < tol,
            "rotation {i}: {:?} vs {expected:?}",
            scene.rotations[i]
        );
        for j in 1..coeffs {
            for ch in 0..3 {
                let byte = p.sh[3 * (j - 1) + ch];
                let sign = if flip == [1.0, -1.0, -1.0] {
                    SH_SIGNS_RUB_TO_RDF[j - 1]
                } else {
                    1.0
                };
                let expected = sign * (byte as f32 - 128.0) / 128.0;
                let got = scene.sh_of(i)[3 * j + ch];
                assert!(
                    close(got, expected, 1e-6),
                    "sh {i} coeff {j} channel {ch}: {got} vs {expected}"
                );
            }
        }
    }
}

const RUB: [f32; 3] = [1.0, -1.0, -1.0];
const SH_BYTES: [usize; 5] = [0, 9, 24, 45, 72];

#[test]
fn version_2_gzip_round_trip() {
    let points: Vec<Packed> = sample_points(SH_BYTES[1]).into_iter().take(3).collect();
    let content = legacy_content(2, 3, 1, 0, &arrays(&points, 2, 12));
    let scene = decode_spz(&gzip(&content), Path::new("v2.spz")).unwrap();
    assert_eq!(scene.sh_degree, 1);
    check_decoded(&scene, &points, 2, RUB);
    // The same content without the gzip wrapper reads the same.
    assert_eq!(
        decode_spz(&content, Path::new("v2-plain.spz")).unwrap(),
        scene
    );
}

#[test]
fn version_3_gzip_smallest_three_rotations() {
    for degree in [0u8, 2, 3] {
        let points = sample_points(SH_BYTES[degree as usize]);
        let content = legacy_content(3, 4, degree, 1, &arrays(&points, 3, 12));
        let scene = decode_spz(&gzip(&content), Path::new("v3.spz")).unwrap();
        assert_eq!(scene.sh_degree, degree);
        check_decoded(&scene, &points, 3, RUB);
    }
}

#[test]
fn version_3_sh_degree_4_keeps_degrees_0_to_3() {
    let points = sample_points(SH_BYTES[4]);
    let content = legacy_content(3, 4, 4, 0, &arrays(&points, 3, 12));
    let scene = decode_spz(&gzip(&content), Path::new("v3-deg4.spz")).unwrap();
    assert_eq!(scene.sh_degree, 3);
    assert_eq!(scene.sh.len(), 4 * 16 * 3);
    check_decoded(&scene, &points, 3, RUB);
}

#[test]
fn version_1_float16_positions() {
    let mut points: Vec<Packed> = sample_points(0).into_iter().take(2).collect();
    points[0].position = [1.25, -2.5, -3.0];
    points[1].position = [2.25, 0.000_061_035_156, -2.625];
    let content = legacy_content(1, 2, 0, 0, &arrays(&points, 1, 12));
    let scene = decode_spz(&gzip(&content), Path::new("v1.spz")).unwrap();
    check_decoded(&scene, &points, 1, RUB);
    assert_eq!(
        scene.means[1],
        [2.25, -0.000_061_035_156, 2.625],
        "float16 is exact"
    );
}

#[test]
fn version_4_hand_written_with_sh() {
    let points = sample_points(SH_BYTES[2]);
    let bytes = v4_file(4, 2, 0, &[], &arrays(&points, 4, 12));
    let scene = decode_spz(&bytes, Path::new("v4.spz")).unwrap();
    assert_eq!(scene.sh_degree, 2);
    check_decoded(&scene, &points, 4, RUB);
}

/// A version 4 file with an `SPZ_ADOBE_coordinate_system` record naming RDF needs no flip, and
/// one naming LUF flips x and y.
#[test]
fn version_4_coordinate_system_extension() {
    let points = sample_points(SH_BYTES[1]);
    let record = |code: u32| {
        let mut r = Vec::new();
        // An unrelated vendor record first: it must be skipped.
        r.extend(0x1234_0001u32.to_le_bytes());
        r.extend(3u32.to_le_bytes());
        r.extend([9, 9, 9]);
        r.extend(0xADBE_0003u32.to_le_bytes());
        r.extend(4u32.to_le_bytes());
        r.extend(code.to_le_bytes());
        r
    };
    let rdf = v4_file(4, 1, 0x2, &record(6), &arrays(&points, 4, 12));
    let scene = decode_spz(&rdf, Path::new("rdf.spz")).unwrap();
    check_decoded(&scene, &points, 4, [1.0, 1.0, 1.0]);

    let luf = v4_file(4, 1, 0x2, &record(7), &arrays(&points, 4, 12));
    let scene = decode_spz(&luf, Path::new("luf.spz")).unwrap();
    for (i, p) in points.iter().enumerate() {
        assert!(close(scene.means[i][0], -p.position[0], 1e-3));
        assert!(close(scene.means[i][1], -p.position[1], 1e-3));
        assert!(close(scene.means[i][2], p.position[2], 1e-3));
        // Degree 1 coefficients are (y, z, x): y and x flip, z does not.
        let expected = -(p.sh[0] as f32 - 128.0) / 128.0;
        assert!(close(scene.sh_of(i)[3], expected, 1e-6));
        let expected = (p.sh[3] as f32 - 128.0) / 128.0;
        assert!(close(scene.sh_of(i)[6], expected, 1e-6));
    }

    let rotated = v4_file(4, 1, 0x2, &record(12), &arrays(&points, 4, 12));
    let detail = expect_error(&rotated);
    assert!(detail.contains("RFU"), "{detail}");
}

/// Current writers append extension records after the arrays of a gzip file.
#[test]
fn version_3_trailing_extension_records() {
    let points = sample_points(0);
    let mut content = legacy_content(3, 4, 0, 0x2, &arrays(&points, 3, 12));
    content.extend(0xADBE_0003u32.to_le_bytes());
    content.extend(4u32.to_le_bytes());
    content.extend(6u32.to_le_bytes()); // RDF
    let scene = decode_spz(&gzip(&content), Path::new("v3-ext.spz")).unwrap();
    check_decoded(&scene, &points, 3, [1.0, 1.0, 1.0]);
}

#[test]
fn empty_scene_decodes_empty() {
    let content = legacy_content(3, 0, 0, 0, &arrays(&[], 3, 12));
    assert!(
        decode_spz(&gzip(&content), Path::new("empty.spz"))
            .unwrap()
            .is_empty()
    );
    let bytes = v4_file(0, 0, 0, &[], &arrays(&[], 4, 12));
    assert!(
        decode_spz(&bytes, Path::new("empty4.spz"))
            .unwrap()
            .is_empty()
    );
}

// ---------------------------------------------------------------------------------------------
// 5. Bad input: clear errors, no panic.

#[test]
fn truncated_files_are_errors() {
    let (_, bytes) = data_file("biker.spz");
    for len in [0, 3, 10, 31, 40, 200, bytes.len() / 2, bytes.len() - 1] {
        let detail = expect_error(&bytes[..len]);
        match len {
            0 => assert!(detail.contains("empty"), "{detail}"),
            3 => assert!(detail.contains("not an SPZ file"), "{detail}"),
            _ => assert!(detail.contains("truncated"), "len {len}: {detail}"),
        }
    }
    assert!(expect_error(&bytes[..bytes.len() - 1]).contains("rotations"));

    let points = sample_points(SH_BYTES[1]);
    let gz = gzip(&legacy_content(3, 4, 1, 0, &arrays(&points, 3, 12)));
    for len in [2, 10, 20, gz.len() / 2, gz.len() - 1] {
        let detail = expect_error(&gz[..len]);
        assert!(detail.contains("truncated"), "gzip len {len}: {detail}");
    }
    // A complete gzip stream whose content is short names the attribute that is cut.
    let mut content = legacy_content(3, 4, 1, 0, &arrays(&points, 3, 12));
    content.truncate(content.len() - 5);
    let detail = expect_error(&gzip(&content));
    assert!(
        detail.contains("truncated: SPZ spherical harmonics need 36 bytes, 31 remain"),
        "{detail}"
    );
}

#[test]
fn wrong_magic_is_an_error() {
    let (_, mut bytes) = data_file("biker.spz");
    bytes[3] = b'Q';
    let detail = expect_error(&bytes);
    assert!(
        detail.contains("not an SPZ file") && detail.contains("NGSQ"),
        "{detail}"
    );

    let mut content = legacy_content(3, 0, 0, 0, &arrays(&[], 3, 12));
    content[0] = b'X';
    let detail = expect_error(&gzip(&content));
    assert!(detail.contains("does not hold an SPZ file"), "{detail}");
}

#[test]
fn unsupported_versions_are_errors() {
    let (_, mut bytes) = data_file("biker.spz");
    bytes[4] = 7;
    assert_eq!(
        expect_error(&bytes),
        "SPZ version 7 is not supported (1-4 are)"
    );
    bytes[4] = 0;
    assert!(expect_error(&bytes).contains("SPZ version 0 is not supported"));

    let points = sample_points(0);
    for version in [0u32, 5, 9] {
        let content = legacy_content(version, 4, 0, 0, &arrays(&points, 3, 12));
        let detail = expect_error(&gzip(&content));
        assert_eq!(
            detail,
            format!("SPZ version {version} is not supported (1-4 are)")
        );
    }
    let content = legacy_content(4, 4, 0, 0, &arrays(&points, 3, 12));
    assert!(expect_error(&gzip(&content)).contains("version 4 inside a gzip stream"));
}

#[test]
fn impossible_headers_are_errors() {
    let (_, bytes) = data_file("biker.spz");
    let patched = |at: usize, value: &[u8]| {
        let mut b = bytes.clone();
        b[at..at + value.len()].copy_from_slice(value);
        b
    };
    let detail = expect_error(&patched(8, &u32::MAX.to_le_bytes()));
    assert!(detail.contains("claims 4294967295 Gaussians"), "{detail}");
    let detail = expect_error(&patched(8, &1_000_000u32.to_le_bytes()));
    assert!(
        detail.contains("stream 0 (positions)") && detail.contains("9000000"),
        "{detail}"
    );
    let detail = expect_error(&patched(12, &[5]));
    assert!(detail.contains("SH degree 5 is impossible"), "{detail}");
    let detail = expect_error(&patched(12, &[1]));
    assert!(
        detail.contains("declares 5 streams") && detail.contains("need 6"),
        "{detail}"
    );
    let detail = expect_error(&patched(13, &[40]));
    assert!(detail.contains("40 fractional bits"), "{detail}");
    let detail = expect_error(&patched(16, &8u32.to_le_bytes()));
    assert!(detail.contains("offset 8"), "{detail}");
    let detail = expect_error(&patched(16, &u32::MAX.to_le_bytes()));
    assert!(detail.contains("truncated"), "{detail}");
    // A TOC entry that claims more compressed bytes than the file has.
    let detail = expect_error(&patched(32, &u64::MAX.to_le_bytes()));
    assert!(
        detail.contains("truncated: SPZ stream 0 (positions)"),
        "{detail}"
    );
    // Garbage instead of zstd data.
    let mut garbage = bytes.clone();
    garbage[112..120].copy_from_slice(&[0xde, 0xad, 0xbe, 0xef, 0, 1, 2, 3]);
    let detail = expect_error(&garbage);
    assert!(detail.contains("stream 0 (positions)"), "{detail}");

    // A small gzip file claiming 50 million Gaussians is rejected before anything is allocated.
    let content = legacy_content(3, 50_000_000, 0, 0, &arrays(&sample_points(0), 3, 12));
    let detail = expect_error(&gzip(&content));
    assert!(detail.contains("claims 50000000 Gaussians"), "{detail}");

    // A valid zstd file of 200 000 copies of one Gaussian: every stream decodes to the size its
    // table of contents says, but the arrays are thousands of times the file, which no capture
    // compresses to; refused before decoding, naming the count and the file's size.
    let count = 200_000usize;
    let one = arrays(&sample_points(0)[..1], 4, 12);
    let repeated: Vec<Vec<u8>> = one.iter().map(|a| a.repeat(count)).collect();
    let file = v4_file(count as u32, 0, 0, &[], &repeated);
    let decoded: usize = repeated.iter().map(Vec::len).sum();
    assert!(decoded > 1032 * file.len(), "{decoded} vs {}", file.len());
    let detail = expect_error(&file);
    assert!(
        detail.contains("claims 200000 Gaussians")
            && detail.contains(&format!("{}-byte", file.len())),
        "{detail}"
    );
    // The same Gaussians with their positions spread out (as a capture's are) decode.
    let spread: Vec<Packed> = (0..2_000)
        .map(|i| {
            let mut p = sample_points(0)[i % 4].clone();
            p.position = [
                i as f32 * 0.013,
                (i % 37) as f32 * 0.07,
                (i % 11) as f32 * 0.3,
            ];
            p
        })
        .collect();
    let file = v4_file(spread.len() as u32, 0, 0, &[], &arrays(&spread, 4, 12));
    let path = Path::new("spread.spz");
    assert_eq!(
        decode_spz(&file, path)
            .expect("a plausible file decodes")
            .len(),
        2_000
    );
}

/// Deterministic byte mutations of small valid files of each kind: every result must be an
/// `Ok` or an `Err`, never a panic.
#[test]
fn mutated_files_never_panic() {
    let points = sample_points(SH_BYTES[1]);
    let v4 = v4_file(4, 1, 0, &[], &arrays(&points, 4, 12));
    let v3 = gzip(&legacy_content(3, 4, 1, 0, &arrays(&points, 3, 12)));
    let plain = legacy_content(2, 4, 1, 0, &arrays(&points, 2, 12));
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for original in [&v4, &v3, &plain] {
        for _ in 0..3000 {
            let mut bytes = original.clone();
            for _ in 0..1 + next() % 3 {
                let at = (next() % bytes.len() as u64) as usize;
                bytes[at] = next() as u8;
            }
            if next() % 4 == 0 {
                let keep = (next() % bytes.len() as u64) as usize;
                bytes.truncate(keep);
            }
            let _ = decode_spz(&bytes, Path::new("mutated.spz"));
        }
    }
}
