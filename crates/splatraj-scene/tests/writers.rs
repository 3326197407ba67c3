//! The SPZ and compressed-PLY writers: against what the formats' reference tools write and
//! decode (`scripts/make_writer_fixtures.py`: Niantic's spz library, PlayCanvas's
//! splat-transform), round trips through our readers within the quantisation steps, the choice
//! of format by name, and targets that must not be replaced.

mod common;

use std::io::Read;
use std::path::Path;

use common::{SAME_BYTES, check_against, fixture, payload_offset, reference, shared_data};
use splatraj_scene::formats::compressed_ply_writer::{morton_order, write_compressed_ply_to};
use splatraj_scene::formats::spz_writer::{FRACTIONAL_BITS, encode_spz_content};
use splatraj_scene::{
    ReadOptions, Scene, SceneError, SceneFormat, read_scene, write_compressed_ply, write_scene,
    write_spz,
};

fn read(path: &Path) -> Scene {
    read_scene(path, &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .scene
}

/// The scene the fixtures were written from: every 8th Gaussian of fruit_drops_minimal.ply
/// (591, SH degree 3).
fn fruit_sh3() -> Scene {
    let full = read(&fixture("fruit_drops_minimal.ply"));
    let keep: Vec<bool> = (0..full.len()).map(|i| i % 8 == 0).collect();
    let scene = full.subset(&keep);
    assert_eq!((scene.len(), scene.sh_degree), (591, 3));
    scene
}

fn gunzip(path: &Path) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(std::fs::File::open(path).unwrap())
        .read_to_end(&mut out)
        .unwrap();
    out
}

// ---------------------------------------------------------------------------------------- SPZ

#[test]
fn spz_content_is_byte_identical_to_niantics_writer() {
    // Niantic's library wrote the same Gaussians as version 3 (PLY axes in, its defaults).
    let theirs = gunzip(&fixture("fruit_sh3_niantic_v3.spz"));
    let ours = encode_spz_content(&fruit_sh3(), Path::new("fruit_sh3.spz")).unwrap();
    assert_eq!(ours.len(), theirs.len());
    assert_eq!(ours[..16], theirs[..16], "header");
    let differing = ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} of {} bytes differ", ours.len());
}

#[test]
fn spz_fixture_is_what_the_writer_writes_now() {
    let stored = gunzip(&fixture("fruit_sh3.spz"));
    let now = encode_spz_content(&fruit_sh3(), Path::new("fruit_sh3.spz")).unwrap();
    assert!(
        stored == now,
        "regenerate with scripts/make_writer_fixtures.py"
    );
}

#[test]
fn spz_written_decodes_as_niantic_decodes_it() {
    let expected = reference("fruit_sh3_spz_reference.json");
    let scene = read(&fixture("fruit_sh3.spz"));
    assert_eq!(scene.len() as u64, expected["count"].as_u64().unwrap());
    assert_eq!(
        u64::from(scene.sh_degree),
        expected["sh_degree"].as_u64().unwrap()
    );
    let n = check_against(&scene, &expected["gaussians"], SAME_BYTES, "fruit_sh3.spz");
    assert!(n >= 40);
}

/// Largest |a − b| over matching values.
fn worst<const N: usize>(a: &[[f32; N]], b: &[[f32; N]], f: impl Fn(f32) -> f32) -> f32 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(&p, &q)| (f(p) - f(q)).abs()))
        .fold(0.0, f32::max)
}

#[test]
fn spz_round_trip_is_within_the_quantisation_steps() {
    let scene = fruit_sh3();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fruit.spz");
    write_spz(&scene, &path).unwrap();
    let back = read(&path);
    assert_eq!((back.len(), back.sh_degree), (scene.len(), 3));

    let step = 1.0 / f32::from(1u16 << FRACTIONAL_BITS);
    let d_mean = worst(&scene.means, &back.means, |v| v);
    assert!(d_mean <= 0.5 * step + 1e-6, "positions: {d_mean}");
    // Log-scales in 1/16 steps; below −10 (scale e⁻¹⁰) they saturate.
    let (mut d_scale, mut saturated) = (0.0f32, 0);
    for (a, b) in scene.scales.iter().zip(&back.scales) {
        for k in 0..3 {
            if a[k].ln() < -10.0 {
                saturated += 1;
                assert!(
                    (b[k].ln() + 10.0).abs() < 1e-5,
                    "saturates at -10: {}",
                    b[k].ln()
                );
            } else {
                d_scale = d_scale.max((a[k].ln() - b[k].ln()).abs());
            }
        }
    }
    assert!(d_scale <= 0.5 / 16.0 + 1e-5, "log-scales: {d_scale}");
    let d_opacity = scene
        .opacities
        .iter()
        .zip(&back.opacities)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(d_opacity <= 0.5 / 255.0 + 1e-6, "opacity: {d_opacity}");
    // Smallest three: each of three components within half a 9-bit step of (1/√2)/511.
    let d_rotation = scene
        .rotations
        .iter()
        .zip(&back.rotations)
        .map(|(a, b)| 1.0 - (0..4).map(|k| a[k] * b[k]).sum::<f32>().abs())
        .fold(0.0, f32::max);
    assert!(d_rotation < 1e-5, "rotations: 1 - |q.q'| = {d_rotation}");
    let (mut d_dc, mut d_sh1, mut d_rest) = (0.0f32, 0.0f32, 0.0f32);
    for i in 0..scene.len() {
        for (k, (a, b)) in scene.sh_of(i).iter().zip(back.sh_of(i)).enumerate() {
            let d = (a - b).abs();
            match k / 3 {
                0 if (-0.5 / 0.15..0.5 / 0.15).contains(a) => d_dc = d_dc.max(d),
                // SH saturates at ±1; inside, steps of 8/128 (degree 1) and 16/128.
                1..=3 if a.abs() < 0.9 => d_sh1 = d_sh1.max(d),
                4.. if a.abs() < 0.85 => d_rest = d_rest.max(d),
                _ => {}
            }
        }
    }
    assert!(d_dc <= 0.5 / (0.15 * 255.0) + 1e-5, "DC: {d_dc}");
    // Rounded twice, as the reference does: to 1/128, then to a multiple of the bucket.
    assert!(d_sh1 <= 4.5 / 128.0 + 1e-5, "degree-1 SH: {d_sh1}");
    assert!(d_rest <= 8.5 / 128.0 + 1e-5, "degree-2/3 SH: {d_rest}");
    eprintln!(
        "SPZ round trip: position {d_mean:.2e}, log-scale {d_scale:.2e} ({saturated} \
         saturated), opacity \
         {d_opacity:.2e}, rotation {d_rotation:.2e}, DC {d_dc:.2e}, SH1 {d_sh1:.2e}, SH2-3 \
         {d_rest:.2e}"
    );
}

#[test]
fn spz_far_positions_get_fewer_fractional_bits_not_a_wrap() {
    let mut scene = fruit_sh3();
    scene.means[0] = [5000.0, -3000.5, 12.25];
    let content = encode_spz_content(&scene, Path::new("far.spz")).unwrap();
    // 5000 needs 13 integer bits + sign: 23 − 13 = 10 fractional bits.
    assert_eq!(content[13], 10);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("far.spz");
    write_spz(&scene, &path).unwrap();
    let back = read(&path);
    for k in 0..3 {
        assert!((back.means[0][k] - scene.means[0][k]).abs() <= 0.5 / 1024.0);
    }

    scene.means[0][0] = 1.0e7;
    let err = encode_spz_content(&scene, Path::new("far.spz")).unwrap_err();
    assert!(err.to_string().contains("24-bit"), "{err}");
}

#[test]
fn spz_of_biker_keeps_every_gaussian() {
    let Some(path) = shared_data("biker.compressed.ply") else {
        return;
    };
    let scene = read(&path);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("biker.spz");
    write_spz(&scene, &out).unwrap();
    let back = read(&out);
    assert_eq!(back.len(), scene.len());
    let d = worst(&scene.means, &back.means, |v| v);
    assert!(d <= 0.5 / 4096.0 + 1e-6, "{d}");
}

// ------------------------------------------------------------------------------ compressed PLY

/// The bytes after the header.
fn payload(bytes: &[u8]) -> &[u8] {
    &bytes[payload_offset(bytes)..]
}

#[test]
fn compressed_ply_matches_splat_transforms_writer() {
    let scene = fruit_sh3();
    let mut ours = Vec::new();
    write_compressed_ply_to(&scene, &mut ours).unwrap();
    let theirs = std::fs::read(fixture("fruit_sh3_splat_transform.compressed.ply")).unwrap();
    let (ours, theirs) = (payload(&ours), payload(&theirs));
    assert_eq!(ours.len(), theirs.len());
    let chunks = scene.len().div_ceil(256);
    let ranges = chunks * 18 * 4;
    // Chunk ranges: the reference takes them from the file's log-scales, we from ln of the
    // activated scales, so they may be an ulp or so apart.
    for (a, b) in ours[..ranges].chunks(4).zip(theirs[..ranges].chunks(4)) {
        let (a, b) = (
            f32::from_le_bytes(a.try_into().unwrap()),
            f32::from_le_bytes(b.try_into().unwrap()),
        );
        assert!(
            (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
            "chunk range {a} vs {b}"
        );
    }
    // Order (Morton), packed words and SH bytes: identical.
    let differing = ours[ranges..]
        .iter()
        .zip(&theirs[ranges..])
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differing, 0, "{differing} packed bytes differ");
}

#[test]
fn compressed_ply_written_decodes_as_splat_transform_decodes_it() {
    let expected = reference("fruit_sh3_compressed_ply_reference.json");
    let scene = read(&fixture("fruit_sh3.compressed.ply"));
    assert_eq!(scene.len() as u64, expected["count"].as_u64().unwrap());
    let n = check_against(
        &scene,
        &expected["gaussians"],
        SAME_BYTES,
        "fruit_sh3.compressed.ply",
    );
    assert!(n >= 40);
}

#[test]
fn compressed_ply_round_trip_is_within_the_quantisation_steps() {
    let scene = fruit_sh3();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fruit.compressed.ply");
    write_compressed_ply(&scene, &path).unwrap();
    let back = read(&path);
    assert_eq!((back.len(), back.sh_degree), (scene.len(), 3));
    // The file holds the Gaussians in Morton order; chunk c holds order[256c..256(c+1)].
    let order = morton_order(&scene.means);
    for (c, members) in order.chunks(256).enumerate() {
        let range = |f: &dyn Fn(usize) -> f32| {
            let values = members.iter().map(|&i| f(i as usize));
            values.clone().fold(f32::MIN, f32::max) - values.fold(f32::MAX, f32::min)
        };
        for (j, &i) in members.iter().enumerate() {
            let (i, at) = (i as usize, c * 256 + j);
            for k in 0..3 {
                let bits = if k == 1 { 10 } else { 11 };
                let steps = ((1u32 << bits) - 1) as f32;
                let pos_tol = 0.5 * range(&|g| scene.means[g][k]) / steps + 1e-6;
                let d = (back.means[at][k] - scene.means[i][k]).abs();
                assert!(d <= pos_tol, "Gaussian {i} axis {k}: {d} > {pos_tol}");
                let scale_tol = 0.5 * range(&|g| scene.scales[g][k].ln()) / steps + 1e-5;
                let d = (back.scales[at][k].ln() - scene.scales[i][k].ln()).abs();
                assert!(
                    d <= scale_tol,
                    "Gaussian {i} log-scale {k}: {d} > {scale_tol}"
                );
            }
            assert!((back.opacities[at] - scene.opacities[i]).abs() <= 0.5 / 255.0 + 1e-6);
            let q = scene.rotations[i];
            let dot: f32 = (0..4).map(|k| back.rotations[at][k] * q[k]).sum();
            // Three components within half a step of √2/1023 each.
            assert!(1.0 - dot.abs() < 1e-5, "Gaussian {i}: rotation {dot}");
            for (k, (a, b)) in scene.sh_of(i).iter().zip(back.sh_of(at)).enumerate() {
                let tol = if k < 3 {
                    // Colour in 8 bits of the chunk's colour range.
                    0.5 * range(&|g| scene.sh_of(g)[k]) / 255.0 + 1e-5
                } else if a.abs() < 3.9 {
                    // [-4, 4] in 256 steps of 1/32, decoded at the step's middle.
                    0.5 / 32.0 + 1e-5
                } else {
                    continue;
                };
                assert!((a - b).abs() <= tol, "Gaussian {i} SH {k}: {a} vs {b}");
            }
        }
    }
}

#[test]
fn compressed_ply_of_biker_matches_the_file_it_came_from() {
    // biker.compressed.ply was written by SuperSplat; rewriting what we read from it gives
    // back the same packed words (the Morton order of decoded centres is the file's own).
    let Some(path) = shared_data("biker.compressed.ply") else {
        return;
    };
    let scene = read(&path);
    let mut ours = Vec::new();
    write_compressed_ply_to(&scene, &mut ours).unwrap();
    let back = splatraj_scene::formats::decode(
        &ours,
        SceneFormat::CompressedPly,
        Path::new("biker.compressed.ply"),
    )
    .unwrap();
    assert_eq!(back.len(), scene.len());
    let order = morton_order(&scene.means);
    let d = order
        .iter()
        .enumerate()
        .flat_map(|(at, &i)| (0..3).map(move |k| (at, i as usize, k)))
        .map(|(at, i, k)| (back.means[at][k] - scene.means[i][k]).abs())
        .fold(0.0, f32::max);
    assert!(d < 1e-3, "positions move by {d}");
}

// ------------------------------------------------------------------------ format and targets

#[test]
fn output_format_follows_the_name() {
    let format = |name: &str| SceneFormat::for_output(Path::new(name));
    assert_eq!(format("a/b.ply").unwrap(), SceneFormat::InriaPly);
    assert_eq!(format("b.PLY").unwrap(), SceneFormat::InriaPly);
    assert_eq!(
        format("b.compressed.ply").unwrap(),
        SceneFormat::CompressedPly
    );
    assert_eq!(format("b.spz").unwrap(), SceneFormat::Spz);
    for (name, says) in [
        ("b.foo", "'.foo'"),
        ("noext", "without an extension"),
        ("b.sog", "reads sog"),
        ("b.splat", "reads splat"),
        ("b.ksplat", "reads ksplat"),
    ] {
        let err = format(name).unwrap_err();
        assert!(matches!(err, SceneError::Unwritable { .. }), "{err:?}");
        let shown = err.to_string();
        assert!(shown.contains(name) && shown.contains(says), "{shown}");
        assert!(
            shown.contains(".spz") && shown.contains(".compressed.ply"),
            "{shown}"
        );
    }
}

#[test]
fn write_scene_does_not_replace_a_folder_or_a_link() {
    let scene = fruit_sh3();
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("out.spz");
    std::fs::create_dir(&folder).unwrap();
    let err = write_scene(&scene, &folder, SceneFormat::Spz).unwrap_err();
    assert!(err.to_string().contains("a folder"), "{err}");
    assert!(folder.is_dir());

    let target = dir.path().join("target.ply");
    std::fs::write(&target, b"keep").unwrap();
    let link = dir.path().join("link.compressed.ply");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let err = write_scene(&scene, &link, SceneFormat::CompressedPly).unwrap_err();
    assert!(err.to_string().contains("symbolic link"), "{err}");
    assert_eq!(std::fs::read(&target).unwrap(), b"keep");

    // A regular file is replaced, whole.
    let file = dir.path().join("out2.spz");
    std::fs::write(&file, b"old").unwrap();
    write_scene(&scene, &file, SceneFormat::Spz).unwrap();
    assert_eq!(read(&file).len(), scene.len());
    let err = write_scene(&scene, &file, SceneFormat::Sog).unwrap_err();
    assert!(err.to_string().contains("does not write"), "{err}");
}
