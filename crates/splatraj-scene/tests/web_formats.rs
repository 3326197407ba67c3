//! The web viewers' formats (SOG, antimatter15 `.splat`, GaussianSplats3D `.ksplat`) against
//! values their reference tools decoded from the same files (`scripts/make_sog_fixture.py`,
//! `scripts/make_splat_fixtures.py`), and bad input.

mod common;

use std::path::{Path, PathBuf};

use common::{fixture, shared_data};
use serde_json::Value;
use splatraj_scene::formats::{LoadedScene, ReadOptions, SceneFormat};
use splatraj_scene::{Scene, SceneError, read_scene};

fn read(path: &Path) -> LoadedScene {
    read_scene(path, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn reference(name: &str) -> Value {
    let text = std::fs::read_to_string(fixture(name)).expect("reference fixture");
    serde_json::from_str(&text).expect("reference JSON")
}

fn floats(v: &Value) -> Vec<f32> {
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
struct Tolerance {
    /// Absolute on positions.
    mean: f32,
    /// Relative on scales.
    scale: f32,
    /// On 1 − |q·q'| of unit quaternions.
    rotation: f32,
    /// Absolute on opacities.
    opacity: f32,
    /// Absolute on SH coefficients.
    sh: f32,
}

/// The float-for-float decodings of the same bytes (both read the codebook or the float).
const SAME_BYTES: Tolerance = Tolerance {
    mean: 1e-5,
    scale: 1e-5,
    rotation: 1e-6,
    opacity: 1e-5,
    sh: 1e-5,
};

/// Compares the Gaussians a reference decoded (`[{index, mean, scale, rotation, opacity, sh}]`)
/// with ours; prints the largest differences, returns how many Gaussians were compared.
fn check_against(scene: &Scene, gaussians: &Value, tol: Tolerance, what: &str) -> usize {
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
