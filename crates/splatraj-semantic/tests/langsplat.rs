//! `langsplat` source: the decoder read from a checkpoint written by PyTorch reproduces
//! PyTorch's decoding, bad checkpoints and latents fail naming the file and the key, and a
//! query selects the Gaussians whose latents decode to the phrase.
//!
//! The fixture (tests/data/langsplat, made by scripts/make_langsplat_fixture.py, see its
//! README) holds a LangSplat-layout autoencoder checkpoint, latents, and PyTorch's decoding of
//! them.

mod common;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::Deserialize;
use splatraj_scene::Scene;
use splatraj_semantic::sources::langsplat::LANGSPLAT_WIDTHS;
use splatraj_semantic::{
    LangsplatDecoder, LangsplatSource, Matrix, PhraseTable, SelectionOptions, TargetSource,
    TargetsConfig, find_target,
};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/langsplat")
        .join(name)
}

fn device() -> Device {
    Device::flex()
}

fn latents() -> Matrix {
    Matrix::from_npy(&fixture("latents.npy")).unwrap()
}

/// PyTorch's decoding of `latents.npy`.
fn reference() -> Matrix {
    Matrix::from_npy(&fixture("decoded.npy")).unwrap()
}

#[test]
fn decoder_matches_pytorch_on_the_fixture() {
    let decoder = LangsplatDecoder::from_checkpoint(&fixture("best_ckpt.pth"), &device()).unwrap();
    assert_eq!(decoder.widths(), LANGSPLAT_WIDTHS);
    assert_eq!((decoder.latent_dim(), decoder.output_dim()), (3, 512));
    let decoded = decoder.decode(&latents()).unwrap();
    let reference = reference();
    assert_eq!((decoded.rows, decoded.dim), (32, 512));
    assert_eq!((reference.rows, reference.dim), (32, 512));
    let worst = decoded
        .values
        .iter()
        .zip(&reference.values)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst <= 1e-5, "largest difference from PyTorch: {worst}");
    // The reference is not degenerate: its rows point in clearly different directions, so a
    // decoder that got a layer wrong could not match it by accident.
    let cos01: f32 = reference
        .row(0)
        .iter()
        .zip(reference.row(1))
        .map(|(a, b)| a * b)
        .sum();
    assert!(cos01 < 0.95, "{cos01}");
    for i in 0..decoded.rows {
        let norm: f32 = decoded.row(i).iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5, "row {i}: norm {norm}");
    }
}

fn checkpoint_error(path: &Path) -> String {
    LangsplatDecoder::from_checkpoint(path, &device())
        .map(|_| ())
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_checkpoints_name_the_file_and_the_key() {
    for (name, words) in [
        (
            "bad_missing_bias.pth",
            &["missing key", "\"decoder.2.bias\""][..],
        ),
        (
            "bad_shape.pth",
            &["\"decoder.2.weight\"", "[5, 7]", "outputs 4"][..],
        ),
        ("bad_odd_key.pth", &["unexpected key", "\"decoder.1."][..]),
        (
            "encoder_only.pth",
            &["no key decoder.*", "encoder.0.weight"][..],
        ),
    ] {
        let err = checkpoint_error(&fixture(name));
        assert!(err.contains(name), "{name}: file not named in {err}");
        for w in words {
            assert!(err.contains(w), "{name}: {w:?} missing from {err}");
        }
    }

    // A checkpoint cut short, a file that is not a checkpoint, a file that is not there.
    let dir = tempfile::tempdir().unwrap();
    let whole = std::fs::read(fixture("best_ckpt.pth")).unwrap();
    let cut = dir.path().join("cut.pth");
    std::fs::write(&cut, &whole[..whole.len() / 2]).unwrap();
    let text = dir.path().join("text.pth");
    std::fs::write(&text, "not a checkpoint").unwrap();
    for path in [cut, text, dir.path().join("absent.pth")] {
        let err = checkpoint_error(&path);
        assert!(err.contains(&path.display().to_string()), "{err}");
    }
}

#[test]
fn latents_of_the_wrong_width_or_not_finite_name_their_file() {
    let decoder = LangsplatDecoder::from_checkpoint(&fixture("best_ckpt.pth"), &device()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let wide = dir.path().join("wide.npy");
    common::write_npy(&wide, &vec![vec![0.1f32; 4]; 5]);
    let err = decoder
        .decode(&Matrix::from_npy(&wide).unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("wide.npy") && err.contains("width 4"), "{err}");

    let nan = dir.path().join("nan.npy");
    common::write_npy(&nan, &[vec![0.1, 0.2, 0.3], vec![0.1, f32::NAN, 0.3]]);
    let err = decoder
        .decode(&Matrix::from_npy(&nan).unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("nan.npy") && err.contains("Gaussian 1"),
        "{err}"
    );
}

/// 100 Gaussians along a line, alternating between "the object" (even indices: fixture
/// latent 0) and the rest (odd indices: latents 1-4), so that space cannot tell them apart.
fn scene_and_latents(dir: &Path) -> (Scene, PathBuf, Vec<usize>) {
    let n = 100;
    let all = latents();
    let rows: Vec<Vec<f32>> = (0..n)
        .map(|i| {
            let k = if i % 2 == 0 { 0 } else { 1 + (i / 2) % 4 };
            all.row(k).to_vec()
        })
        .collect();
    let path = dir.join("latents.npy");
    common::write_npy(&path, &rows);
    let scene = Scene {
        means: (0..n).map(|i| [i as f32 * 0.01, 0.0, 0.0]).collect(),
        scales: vec![[0.01; 3]; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![1.0; n],
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        extras: Default::default(),
    };
    (scene, path, (0..n).step_by(2).collect())
}

/// The phrase table, built from PyTorch's decoded vectors: "red mug" is latent 0's, the four
/// canonical negatives are latents 1-4's. A Gaussian with latent 0 is then exactly the query
/// (cosine 1), and one with latent k ≥ 1 exactly one negative, so relevancy > 0.5 holds for
/// the object only.
fn write_table(dir: &Path) -> PathBuf {
    let r = reference();
    let table = serde_json::json!({
        "red mug": r.row(0), "object": r.row(1), "things": r.row(2),
        "stuff": r.row(3), "texture": r.row(4),
    });
    let path = dir.join("table.json");
    std::fs::write(&path, table.to_string()).unwrap();
    path
}

fn options() -> SelectionOptions {
    SelectionOptions {
        top_fraction: 0.6,
        floor: 0.5,
        cluster: None,
    }
}

#[test]
fn a_langsplat_query_selects_the_gaussians_whose_latents_decode_to_the_phrase() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, latents_path, object) = scene_and_latents(dir.path());
    let table = PhraseTable::read(&write_table(dir.path()), None).unwrap();
    let decoder = LangsplatDecoder::from_checkpoint(&fixture("best_ckpt.pth"), &device()).unwrap();
    let source =
        LangsplatSource::new(&Matrix::from_npy(&latents_path).unwrap(), &decoder, table).unwrap();
    assert_eq!(source.kind(), "langsplat");
    let target = find_target(&source, &scene, "Red Mug", &options()).unwrap();
    assert_eq!(target.indices(), object);
    assert!(target.relevancy_spread.min > 0.5);

    // A phrase the table lacks: the error lists the closest.
    let err = find_target(&source, &scene, "red mugs", &options())
        .unwrap_err()
        .to_string();
    assert!(err.contains("\"red mug\""), "{err}");
}

#[derive(Deserialize)]
struct File {
    targets: TargetsConfig,
}

#[test]
fn the_config_builds_the_langsplat_source_from_its_files() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, _, object) = scene_and_latents(dir.path());
    write_table(dir.path());
    let text = format!(
        r#"
[targets]
source = "langsplat"
latents = "latents.npy"
checkpoint = "{}"
phrases = "table.json"

[targets.selection]
top_fraction = 0.6
cluster = false
"#,
        fixture("best_ckpt.pth").display()
    );
    let config = toml::from_str::<File>(&text).unwrap().targets;
    let source = config.build(dir.path(), &device()).unwrap();
    assert_eq!(source.kind(), "langsplat");
    let target = find_target(
        source.as_ref(),
        &scene,
        "red mug",
        &config.selection().unwrap(),
    )
    .unwrap();
    assert_eq!(target.indices(), object);

    // Each file's key is named when it is missing or wrong.
    let build = |text: &str| {
        toml::from_str::<File>(text)
            .unwrap()
            .targets
            .build(dir.path(), &device())
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let err = build(
        "[targets]\nsource = \"langsplat\"\nlatents = \"latents.npy\"\nphrases = \"table.json\"\n",
    );
    assert!(err.contains("targets.checkpoint"), "{err}");
    let err = build(&format!(
        "[targets]\nsource = \"langsplat\"\ncheckpoint = \"{}\"\nphrases = \"table.json\"\n",
        fixture("best_ckpt.pth").display()
    ));
    assert!(err.contains("targets.latents"), "{err}");
    let err = build(&format!(
        "[targets]\nsource = \"langsplat\"\nlatents = \"latents.npy\"\ncheckpoint = \"{}\"\nphrases = \"table.json\"\n",
        fixture("bad_missing_bias.pth").display()
    ));
    assert!(
        err.starts_with("targets.checkpoint: ") && err.contains("decoder.2.bias"),
        "{err}"
    );
    common::write_npy(&dir.path().join("wide.npy"), &vec![vec![0.0f32; 5]; 100]);
    let err = build(&format!(
        "[targets]\nsource = \"langsplat\"\nlatents = \"wide.npy\"\ncheckpoint = \"{}\"\nphrases = \"table.json\"\n",
        fixture("best_ckpt.pth").display()
    ));
    assert!(
        err.starts_with("targets.latents: ") && err.contains("wide.npy"),
        "{err}"
    );
}
