//! `feature3dgs` source: Feature 3DGS's 1×1-convolution decoder read from a checkpoint written
//! by PyTorch reproduces PyTorch's convolution, bad checkpoints fail naming the file and the
//! key, and a query selects the Gaussians whose `semantic_*` features decode to the phrase.
//!
//! The fixture (tests/data/feature3dgs, made by scripts/make_feature3dgs_fixture.py, see its
//! README) holds a `CNN_decoder` state dict, inputs, and PyTorch's convolution of them.

mod common;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use splatraj_scene::{Features, Scene};
use splatraj_semantic::sources::feature3dgs::read_decoder;
use splatraj_semantic::{Matrix, SourceRegistry, TargetSource, TargetsConfig};

const IN: usize = 8;
const NEGATIVES: [&str; 4] = ["object", "things", "stuff", "texture"];

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/feature3dgs")
        .join(name)
}

/// PyTorch's convolution of the fixture inputs, rows L2-normalised (the decoder's output is
/// compared by direction: cosines ignore length).
fn reference_directions() -> Matrix {
    let mut m = Matrix::from_npy(&fixture("decoded.npy")).unwrap();
    for row in m.values.chunks_mut(m.dim) {
        let n = row.iter().map(|x| x * x).sum::<f32>().sqrt();
        row.iter_mut().for_each(|x| *x /= n);
    }
    m
}

#[test]
fn decoder_matches_pytorch_convolution() {
    let decoder = read_decoder(&fixture("decoder_chkpnt.pth"), &Device::flex()).unwrap();
    assert_eq!((decoder.latent_dim(), decoder.output_dim()), (IN, 32));
    let decoded = decoder
        .decode(&Matrix::from_npy(&fixture("features.npy")).unwrap())
        .unwrap();
    let reference = reference_directions();
    assert_eq!((decoded.rows, decoded.dim), (12, 32));
    let worst = decoded
        .values
        .iter()
        .zip(&reference.values)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "largest difference from PyTorch: {worst}");
}

/// A phrase table file (JSON) with "category k" = PyTorch's decoding of basis vector k-1 and
/// four random negatives, written to `dir`.
fn write_table(dir: &Path) -> PathBuf {
    let reference = Matrix::from_npy(&fixture("decoded.npy")).unwrap();
    let mut rng = common::rng(11);
    let mut table = serde_json::Map::new();
    for k in 1..=IN {
        table.insert(format!("category {k}"), reference.row(k - 1).into());
    }
    let zero = vec![0.0f32; reference.dim];
    for n in NEGATIVES {
        table.insert(n.into(), common::noisy(&mut rng, &zero, 1.0).into());
    }
    let path = dir.join("table.json");
    std::fs::write(&path, serde_json::to_string(&table).unwrap()).unwrap();
    path
}

/// fruit_drops with `semantic_0..7` = basis vector (label − 1) + N(0, 0.02²) noise for the
/// labelled Gaussians, a random vector for the unlabelled ones.
fn scene() -> Scene {
    let mut scene = common::fruit_drops();
    let mut rng = common::rng(5);
    let ids = scene.extras.labels.as_ref().unwrap().ids.clone();
    let mut values = Vec::with_capacity(ids.len() * IN);
    for &id in &ids {
        let mut base = vec![0.0f32; IN];
        match id {
            1..=8 => base[id as usize - 1] = 1.0,
            _ => base = common::noisy(&mut rng, &base, 1.0),
        }
        values.extend(common::noisy(&mut rng, &base, 0.02));
    }
    scene.extras.features = Some(Features {
        names: (0..IN).map(|k| format!("semantic_{k}")).collect(),
        dim: IN,
        values,
    });
    scene
}

fn config(table: toml::Table) -> TargetsConfig {
    TargetsConfig::custom("feature3dgs", table)
}

fn keys(dir: &Path, decoder: Option<&str>) -> toml::Table {
    let mut table = toml::Table::new();
    table.insert(
        "phrases".into(),
        write_table(dir).display().to_string().into(),
    );
    if let Some(d) = decoder {
        table.insert("decoder".into(), fixture(d).display().to_string().into());
    }
    table
}

fn build(table: toml::Table, dir: &Path) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
    config(table).build_with(dir, &Device::flex(), &SourceRegistry::default())
}

#[test]
fn query_ranks_the_planted_category_first() {
    let dir = tempfile::tempdir().unwrap();
    let source = build(keys(dir.path(), Some("decoder_chkpnt.pth")), dir.path()).unwrap();
    assert_eq!(source.kind(), "feature3dgs");
    let scene = scene();
    let ids = scene.extras.labels.as_ref().unwrap().ids.clone();
    for k in 1..=IN as i32 {
        let r = source.relevancy(&scene, &format!("category {k}")).unwrap();
        let inside = (0..ids.len()).filter(|&i| ids[i] == k).map(|i| r.values[i]);
        let outside = (0..ids.len()).filter(|&i| ids[i] != k).map(|i| r.values[i]);
        let low_inside = inside.fold(f32::INFINITY, f32::min);
        let high_outside = outside.fold(f32::NEG_INFINITY, f32::max);
        println!("category {k}: lowest inside {low_inside:.4}, highest outside {high_outside:.4}");
        assert!(
            low_inside > 0.9 && low_inside > high_outside,
            "category {k}: lowest inside {low_inside}, highest outside {high_outside}"
        );
    }
}

#[test]
fn without_the_decoder_a_width_mismatch_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let source = build(keys(dir.path(), None), dir.path()).unwrap();
    let e = source
        .relevancy(&scene(), "category 1")
        .unwrap_err()
        .to_string();
    assert!(e.contains("length 8") && e.contains("32"), "{e}");
}

#[test]
fn bad_checkpoints_name_the_file_and_the_key() {
    let dir = tempfile::tempdir().unwrap();
    for (file, key) in [
        ("bad_kernel.pth", "conv.weight"),
        ("bad_missing_bias.pth", "conv.bias"),
        ("bad_not_decoder.pth", "conv.weight"),
    ] {
        let e = build(keys(dir.path(), Some(file)), dir.path())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(file) && e.contains(key) && e.contains("targets.custom.feature3dgs"),
            "{file}: {e}"
        );
        println!("{e}");
    }
}

#[test]
fn unknown_keys_and_a_missing_decoder_file_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut table = keys(dir.path(), None);
    table.insert("decodr".into(), "x.pth".into());
    let e = build(table, dir.path()).unwrap_err().to_string();
    assert!(e.contains("decodr") && e.contains("decoder"), "{e}");
    println!("{e}");
    let e = build(keys(dir.path(), Some("missing.pth")), dir.path())
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.pth"), "{e}");
}
