//! `legaussians` source: a point_cloud.ply in LEGaussians' layout, its index decoder and its
//! codebook give the codes and relevancies LEGaussians' own maths gives (argmax and softmax),
//! free-text queries (the fixture CLIP tower) rank the planted blob first, and bad files fail
//! naming the file and the key.
//!
//! The fixture (tests/data/legaussians, made by scripts/make_legaussians_fixture.py, see its
//! README) holds the PLY, the decoder, the codebook and the references.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use splatraj_scene::{ReadOptions, Scene, read_scene};
use splatraj_semantic::{SourceRegistry, TargetSource, TargetsConfig};

const PLANTED: [&str; 3] = ["red mug", "green ball", "potted plant"];
const PER_BLOB: usize = 40;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/legaussians")
        .join(name)
}

fn tower() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/clip/gelu/open_clip_model.safetensors")
}

fn scene() -> Scene {
    read_scene(&fixture("point_cloud.ply"), &ReadOptions::default())
        .unwrap()
        .scene
}

fn npy<T: npyz::Deserialize>(name: &str) -> Vec<T> {
    npyz::NpyFile::new(&std::fs::read(fixture(name)).unwrap()[..])
        .unwrap()
        .into_vec::<T>()
        .unwrap()
}

fn table(entries: &[(&str, toml::Value)]) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("index_decoder".into(), "index_decoder_chkpnt.pth".into());
    t.insert("codebook".into(), "codebook.pt".into());
    t.insert("text_encoder".into(), tower().display().to_string().into());
    for (k, v) in entries {
        t.insert(k.to_string(), v.clone());
    }
    t
}

fn build(table: toml::Table) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
    let config = TargetsConfig::custom("legaussians", table);
    config.build_with(&fixture(""), &Device::flex(), &SourceRegistry::default())
}

#[test]
fn codes_match_legaussians_decoding() {
    use splatraj_semantic::sources::legaussians::{read_codebook, read_index_decoder};
    use splatraj_semantic::{FeatureInput, FeaturesSource, Matrix, PhraseTable};
    let device = Device::flex();
    let decoder = read_index_decoder(&fixture("index_decoder_chkpnt.pth"), &device).unwrap();
    assert_eq!(decoder.widths(), &[8, 128, 256, 16]);
    let codebook = read_codebook(&fixture("codebook.pt"), 16).unwrap();
    assert_eq!((codebook.rows, codebook.dim), (16, 16));
    // Codes need no text: an empty table.
    let empty = Matrix {
        source: "none".into(),
        rows: 0,
        dim: 16,
        values: Vec::new(),
    };
    let table = PhraseTable::new("none", Vec::new(), empty).unwrap();
    let scoring = FeaturesSource::new(FeatureInput::Scene, table);
    let source = splatraj_semantic::sources::LeGaussiansSource::new(
        decoder,
        codebook,
        Default::default(),
        scoring,
    );
    let expected: Vec<usize> = npy::<i64>("expected_index.npy")
        .into_iter()
        .map(|i| i as usize)
        .collect();
    assert_eq!(source.codes(&scene()).unwrap(), expected);
}

#[test]
fn relevancy_matches_legaussians_in_both_modes() {
    let scene = scene();
    let n = scene.len();
    for mode in ["argmax", "softmax"] {
        let source = build(table(&[("combine", mode.into())])).unwrap();
        let expected = npy::<f32>(&format!("expected_relevancy_{mode}.npy"));
        let mut worst = 0.0f32;
        for (k, phrase) in PLANTED.iter().enumerate() {
            let r = source.relevancy(&scene, phrase).unwrap();
            let reference = &expected[k * n..(k + 1) * n];
            worst = r
                .values
                .iter()
                .zip(reference)
                .map(|(a, b)| (a - b).abs())
                .fold(worst, f32::max);
            // The planted blob ranks first.
            let blob = k * PER_BLOB..(k + 1) * PER_BLOB;
            let low_inside = r.values[blob.clone()].iter().copied().fold(1.0, f32::min);
            let high_outside = (0..n)
                .filter(|i| !blob.contains(i))
                .map(|i| r.values[i])
                .fold(0.0, f32::max);
            assert!(
                low_inside > 0.9 && high_outside < 0.5,
                "{mode} {phrase}: {low_inside} {high_outside}"
            );
        }
        // Scale 100 multiplies cosine differences (f32, and LEGaussians' +1e-6 in the cosine's
        // denominator) by 100 before the softmax.
        println!("{mode}: largest difference from LEGaussians' maths {worst:e}");
        assert!(worst < 2e-5, "{mode}: {worst}");
    }
}

#[test]
fn bad_files_and_keys_are_named() {
    for (key, file, words) in [
        (
            "index_decoder",
            "bad_decoder_missing.pth",
            "missing key \"conv2.weight\"",
        ),
        (
            "codebook",
            "bad_codebook_key.pt",
            "missing key \"embedding.weight\"",
        ),
        (
            "codebook",
            "bad_codebook_narrow.pt",
            "narrower than the text embeddings (16)",
        ),
        ("codebook", "missing.pt", "missing.pt"),
    ] {
        let e = build(table(&[(key, file.into())])).unwrap_err().to_string();
        assert!(
            e.contains(file)
                && e.contains(words)
                && e.contains(&format!("targets.custom.legaussians.{key}:")),
            "{file}: {e}"
        );
        println!("{e}");
    }
    let e = build(table(&[("combine", "mean".into())]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("combine") || e.contains("mean"), "{e}");
    let e = build(table(&[("codebok", "x.pt".into())]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("codebok") && e.contains("codebook"), "{e}");
    let mut no_codebook = table(&[]);
    no_codebook.remove("codebook");
    let e = build(no_codebook).unwrap_err().to_string();
    assert!(e.contains("codebook") && e.contains("needs"), "{e}");

    // A scene without the semantic features.
    let source = build(table(&[])).unwrap();
    let mut plain = scene();
    plain
        .extras
        .properties
        .retain(|p| !p.name.starts_with("clip_f_indices_"));
    let e = source.relevancy(&plain, "red mug").unwrap_err().to_string();
    assert!(e.contains("no clip_f_indices_* properties"), "{e}");
}
