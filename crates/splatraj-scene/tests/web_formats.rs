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
/// with ours; returns how many were compared.
fn check_against(scene: &Scene, gaussians: &Value, tol: Tolerance, what: &str) -> usize {
    let list = gaussians.as_array().expect("list of Gaussians");
    for g in list {
        let i = g["index"].as_u64().expect("index") as usize;
        let ctx = format!("{what}: Gaussian {i}");
        let mean = floats(&g["mean"]);
        for k in 0..3 {
            let d = (scene.means[i][k] - mean[k]).abs();
            assert!(
                d <= tol.mean * (1.0 + mean[k].abs()),
                "{ctx}: mean {:?} vs reference {mean:?}",
                scene.means[i]
            );
        }
        let scale = floats(&g["scale"]);
        for k in 0..3 {
            let d = (scene.scales[i][k] - scale[k]).abs();
            assert!(
                d <= tol.scale * scale[k],
                "{ctx}: scale {:?} vs reference {scale:?}",
                scene.scales[i]
            );
        }
        let q = floats(&g["rotation"]);
        let dot: f32 = (0..4).map(|k| scene.rotations[i][k] * q[k]).sum();
        assert!(
            1.0 - dot.abs() <= tol.rotation,
            "{ctx}: rotation {:?} vs reference {q:?}",
            scene.rotations[i]
        );
        let opacity = g["opacity"].as_f64().unwrap() as f32;
        assert!(
            (scene.opacities[i] - opacity).abs() <= tol.opacity,
            "{ctx}: opacity {} vs reference {opacity}",
            scene.opacities[i]
        );
        let sh = floats(&g["sh"]);
        assert_eq!(sh.len(), scene.sh_of(i).len(), "{ctx}: SH length");
        for (k, (ours, theirs)) in scene.sh_of(i).iter().zip(&sh).enumerate() {
            assert!(
                (ours - theirs).abs() <= tol.sh,
                "{ctx}: SH value {k} (coefficient {}, channel {}) is {ours}, reference {theirs}",
                k / 3,
                k % 3
            );
        }
    }
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
