//! The web viewers' formats (SOG, antimatter15 `.splat`, GaussianSplats3D `.ksplat`) against
//! values their reference tools decoded from the same files (`scripts/make_sog_fixture.py`,
//! `scripts/make_splat_fixtures.py`), and bad input.

mod common;

use std::path::{Path, PathBuf};

use common::{SAME_BYTES, Tolerance, check_against, fixture, reference, shared_data};
use serde_json::Value;
use splatraj_scene::formats::{LoadedScene, ReadOptions, SceneFormat};
use splatraj_scene::{SceneError, read_scene};

fn read(path: &Path) -> LoadedScene {
    read_scene(path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

// ---------------------------------------------------------------------------------------- SOG

#[test]
fn narcissus_sog_matches_splat_transform() {
    let Some(path) = shared_data("narcissus.sog") else {
        return;
    };
    let loaded = read(&path);
    assert_eq!(loaded.format, SceneFormat::Sog);
    let expected = reference("narcissus_sog_reference.json");
    assert_eq!(loaded.scene.len(), 101_275);
    assert_eq!(
        loaded.scene.len() as u64,
        expected["count"].as_u64().unwrap()
    );
    assert_eq!(loaded.scene.sh_degree, 0);
    assert_eq!(loaded.dropped, 0);
    let n = check_against(
        &loaded.scene,
        &expected["gaussians"],
        SAME_BYTES,
        "narcissus.sog",
    );
    assert!(n >= 10);
}

#[test]
fn sog_palette_bundled_and_unbundled_match_splat_transform() {
    let expected = reference("fruit_sh3_sog_reference.json");
    let count = expected["count"].as_u64().unwrap() as usize;
    let bundle = read(&fixture("fruit_sh3.sog"));
    assert_eq!(bundle.format, SceneFormat::Sog);
    assert_eq!((bundle.scene.len(), bundle.scene.sh_degree), (count, 3));
    check_against(
        &bundle.scene,
        &expected["bundle"],
        SAME_BYTES,
        "fruit_sh3.sog",
    );

    // The folder form, named by its folder or by its meta.json.
    let folder = fixture("fruit_sh3_sog");
    for path in [folder.clone(), folder.join("meta.json")] {
        let loaded = read(&path);
        assert_eq!(loaded.format, SceneFormat::Sog);
        assert_eq!((loaded.scene.len(), loaded.scene.sh_degree), (count, 3));
        check_against(
            &loaded.scene,
            &expected["folder"],
            SAME_BYTES,
            "fruit_sh3_sog/",
        );
    }
}

/// A copy of the unbundled fixture in a temporary folder, to damage.
fn sog_folder_copy() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let src = fixture("fruit_sh3_sog");
    for entry in std::fs::read_dir(&src).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.path().join(entry.file_name())).unwrap();
    }
    let path = dir.path().to_path_buf();
    (dir, path)
}

fn error_of(path: &Path) -> String {
    match read_scene(path, &ReadOptions::default()) {
        Ok(_) => panic!("{} was read, but it is damaged", path.display()),
        Err(e) => e.to_string(),
    }
}

fn edit_meta(folder: &Path, edit: impl FnOnce(&mut Value)) {
    let meta = folder.join("meta.json");
    let mut value: Value = serde_json::from_slice(&std::fs::read(&meta).unwrap()).unwrap();
    edit(&mut value);
    std::fs::write(&meta, serde_json::to_vec(&value).unwrap()).unwrap();
}

#[test]
fn sog_bad_input_is_named() {
    // A missing image names the image.
    let (_keep, dir) = sog_folder_copy();
    std::fs::remove_file(dir.join("quats.webp")).unwrap();
    let e = error_of(&dir);
    assert!(
        e.contains("missing image") && e.contains("quats.webp"),
        "{e}"
    );

    // More Gaussians than the images hold.
    let (_keep, dir) = sog_folder_copy();
    edit_meta(&dir, |m| m["count"] = 1_000_000.into());
    let e = error_of(&dir);
    assert!(
        e.contains("means_l.webp") && e.contains("fewer than the 1000000"),
        "{e}"
    );

    // A codebook too short for the indices the image uses.
    let (_keep, dir) = sog_folder_copy();
    edit_meta(&dir, |m| m["scales"]["codebook"] = vec![0.0; 4].into());
    let e = error_of(&dir);
    assert!(
        e.contains("scales index") && e.contains("codebook of 4"),
        "{e}"
    );

    // A NaN cannot be written in JSON; a null where a number belongs is named.
    let (_keep, dir) = sog_folder_copy();
    edit_meta(&dir, |m| m["means"]["mins"][1] = Value::Null);
    let e = error_of(&dir);
    assert!(e.contains("meta.json"), "{e}");

    // An image far larger than the Gaussians need (a 12 KB file can claim 16383² texels):
    // refused from its header, before 1 GB is allocated for it. A lossless WebP header alone:
    // RIFF, VP8L, the signature byte, then 14 + 14 bits of width − 1 and height − 1.
    let (_keep, dir) = sog_folder_copy();
    let side: u32 = 16383;
    let bits = (side - 1) | ((side - 1) << 14);
    let mut vp8l = vec![0x2f];
    vp8l.extend(bits.to_le_bytes());
    vp8l.extend([0u8; 64]);
    let mut webp = b"RIFF".to_vec();
    webp.extend((4 + 8 + vp8l.len() as u32).to_le_bytes());
    webp.extend(b"WEBPVP8L");
    webp.extend((vp8l.len() as u32).to_le_bytes());
    webp.extend(vp8l);
    std::fs::write(dir.join("means_l.webp"), webp).unwrap();
    let e = error_of(&dir);
    assert!(
        e.contains("means_l.webp") && e.contains("16383×16383") && e.contains("far more"),
        "{e}"
    );

    // An image that is not WebP.
    let (_keep, dir) = sog_folder_copy();
    std::fs::write(dir.join("sh0.webp"), b"not a webp at all").unwrap();
    let e = error_of(&dir);
    assert!(
        e.contains("sh0.webp") && e.contains("not a readable WebP"),
        "{e}"
    );

    // Unknown version, and a folder without meta.json.
    let (_keep, dir) = sog_folder_copy();
    edit_meta(&dir, |m| m["version"] = 7.into());
    assert!(error_of(&dir).contains("version 7"));
    let empty = tempfile::tempdir().unwrap();
    let e = error_of(empty.path());
    assert!(e.contains("no meta.json"), "{e}");

    // A truncated bundle: the zip's directory is gone.
    let bytes = std::fs::read(fixture("fruit_sh3.sog")).unwrap();
    let file = empty.path().join("cut.sog");
    std::fs::write(&file, &bytes[..bytes.len() - 200]).unwrap();
    let e = error_of(&file);
    assert!(e.contains("cut.sog"), "{e}");
}

// ------------------------------------------------------------------------- .splat and .ksplat

#[test]
fn antimatter15_splat_matches_splat_transform() {
    let expected = &reference("tiny_splat_reference.json")["files"]["tiny.splat"];
    let loaded = read(&fixture("tiny.splat"));
    assert_eq!(loaded.format, SceneFormat::Splat);
    assert_eq!(
        loaded.scene.len() as u64,
        expected["count"].as_u64().unwrap()
    );
    assert_eq!(loaded.scene.sh_degree, 0);
    // Rotations: we decode bytes as main.js does, (b − 128)/128; splat-transform uses
    // b/255·2 − 1. Both normalise, which leaves a difference well under a degree.
    let tol = Tolerance {
        rotation: 2e-4,
        ..SAME_BYTES
    };
    check_against(&loaded.scene, &expected["gaussians"], tol, "tiny.splat");
}

#[test]
fn ksplat_levels_match_splat_transform() {
    let files = &reference("tiny_splat_reference.json")["files"];
    for level in 0..3 {
        let name = format!("tiny_l{level}.ksplat");
        let expected = &files[&name];
        let loaded = read(&fixture(&name));
        assert_eq!(loaded.format, SceneFormat::Ksplat, "{name}");
        assert_eq!(
            loaded.scene.len() as u64,
            expected["count"].as_u64().unwrap()
        );
        assert_eq!(loaded.scene.sh_degree, 2, "{name}");
        check_against(&loaded.scene, &expected["gaussians"], SAME_BYTES, &name);
    }
}

#[test]
fn ksplat_is_detected_from_its_header_not_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let renamed = dir.path().join("scene.bin");
    std::fs::copy(fixture("tiny_l1.ksplat"), &renamed).unwrap();
    assert_eq!(read(&renamed).format, SceneFormat::Ksplat);
    // A .splat is recognised only by its name: the same bytes under another name are refused.
    let renamed = dir.path().join("scene.bin2");
    std::fs::copy(fixture("tiny.splat"), &renamed).unwrap();
    assert!(matches!(
        read_scene(&renamed, &ReadOptions::default()),
        Err(SceneError::UnknownFormat { .. })
    ));
}

#[test]
fn splat_and_ksplat_bad_input_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let splat = std::fs::read(fixture("tiny.splat")).unwrap();

    // A .splat cut inside a record is not a whole number of records.
    let e = error_of(&write("cut.splat", &splat[..splat.len() - 5]));
    assert!(
        e.contains("cut.splat") && e.contains("32-byte records"),
        "{e}"
    );

    // A NaN position names the Gaussian and the property.
    let mut nan = splat.clone();
    nan[32 * 7 + 4..32 * 7 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = error_of(&write("nan.splat", &nan));
    assert!(e.contains("Gaussian 7") && e.contains("x/y/z"), "{e}");

    // A .ksplat cut short, by name and renamed (then it is no longer recognised).
    let ksplat = std::fs::read(fixture("tiny_l2.ksplat")).unwrap();
    let e = error_of(&write("cut.ksplat", &ksplat[..ksplat.len() - 100]));
    assert!(e.contains("cut.ksplat") && e.contains("truncated"), "{e}");
    let e = error_of(&write("short.ksplat", &ksplat[..1000]));
    assert!(e.contains("truncated") && e.contains("4096"), "{e}");

    // A compression level GaussianSplats3D does not define.
    let mut level = ksplat.clone();
    level[20] = 7;
    let e = error_of(&write("level.ksplat", &level));
    assert!(e.contains("compression level 7"), "{e}");

    // A header whose splat count disagrees with its sections.
    let mut count = ksplat.clone();
    count[16..20].copy_from_slice(&1000u32.to_le_bytes());
    let e = error_of(&write("count.ksplat", &count));
    assert!(e.contains("1000 splats") && e.contains("196"), "{e}");
}
