//! `gaussian_grouping` source: a point_cloud.ply in Gaussian Grouping's layout and a
//! classifier.pth saved as its train.py saves it are classified as PyTorch classifies them,
//! queries select instances by id or by a configured name, `min_probability` leaves unsure
//! Gaussians out, and bad inputs fail naming the file and the key or property.
//!
//! The fixture (tests/data/gaussian_grouping, made by
//! scripts/make_gaussian_grouping_fixture.py, see its README) holds the PLY, the classifier,
//! and PyTorch's argmax class and softmax probability of every Gaussian.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use splatraj_scene::{ReadOptions, Scene, read_scene};
use splatraj_semantic::sources::gaussian_grouping::{
    classify, identity_encodings, read_classifier,
};
use splatraj_semantic::{SourceRegistry, TargetSource, TargetsConfig};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/gaussian_grouping")
        .join(name)
}

fn scene() -> Scene {
    read_scene(&fixture("point_cloud.ply"), &ReadOptions::default())
        .unwrap()
        .scene
}

/// PyTorch's classes and probabilities.
fn expected() -> (Vec<usize>, Vec<f32>) {
    let ids = npyz::NpyFile::new(&std::fs::read(fixture("expected_ids.npy")).unwrap()[..])
        .unwrap()
        .into_vec::<i64>()
        .unwrap();
    let prob = npyz::NpyFile::new(&std::fs::read(fixture("expected_prob.npy")).unwrap()[..])
        .unwrap()
        .into_vec::<f32>()
        .unwrap();
    (ids.into_iter().map(|i| i as usize).collect(), prob)
}

fn build(table: toml::Table) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
    let config = TargetsConfig::custom("gaussian_grouping", table);
    config.build_with(&fixture(""), &Device::flex(), &SourceRegistry::default())
}

fn table(entries: &[(&str, toml::Value)]) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("classifier".into(), "classifier.pth".into());
    for (k, v) in entries {
        t.insert(k.to_string(), v.clone());
    }
    t
}

#[test]
fn classification_matches_pytorch() {
    let scene = scene();
    let encodings = identity_encodings(&scene).unwrap();
    assert_eq!((encodings.rows, encodings.dim), (220, 16));
    let classifier = read_classifier(&fixture("classifier.pth"), &Device::flex()).unwrap();
    assert_eq!((classifier.latent_dim(), classifier.output_dim()), (16, 32));
    let found = classify(&classifier, &encodings).unwrap();
    let (ids, prob) = expected();
    assert_eq!(found.ids, ids);
    let worst = found
        .probability
        .iter()
        .zip(&prob)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!("largest probability difference from PyTorch: {worst:e}");
    assert!(worst < 1e-5, "{worst}");
}

/// The Gaussians PyTorch puts in class `id` with probability at least `min`.
fn members(id: usize, min: f32) -> Vec<f32> {
    let (ids, prob) = expected();
    ids.iter()
        .zip(&prob)
        .map(|(&i, &p)| f32::from(u8::from(i == id && p >= min)))
        .collect()
}

#[test]
fn queries_select_instances_by_id_and_name() {
    let scene = scene();
    let names: toml::Table = toml::from_str(r#""7" = "teapot""#).unwrap();
    let synonyms: toml::Table = toml::from_str(r#"teapot = ["kettle"]"#).unwrap();
    let source = build(table(&[
        ("label_names", names.into()),
        ("synonyms", synonyms.into()),
    ]))
    .unwrap();
    assert_eq!(source.kind(), "gaussian_grouping");
    for (query, id) in [("3", 3), ("12", 12), ("teapot", 7), ("Kettle", 7), ("7", 7)] {
        let r = source.relevancy(&scene, query).unwrap();
        let expected = members(id, 0.3);
        // The fixture's blobs hold 50 Gaussians each; a few of class 7's are unsure.
        let count = expected.iter().filter(|&&v| v > 0.5).count();
        assert!((40..=50).contains(&count), "{query}: {count}");
        assert_eq!(r.values, expected, "{query}");
    }
    // An id no Gaussian carries: the error lists the ids there are.
    let e = source.relevancy(&scene, "5").unwrap_err().to_string();
    assert!(
        e.contains("\"5\"") && e.contains("teapot") && e.contains("12 (50 Gaussians)"),
        "{e}"
    );
    println!("{e}");
}

#[test]
fn min_probability_leaves_unsure_gaussians_out() {
    let scene = scene();
    let (_, prob) = expected();
    for min in [0.0f32, 0.5, 0.8] {
        let source = build(table(&[("min_probability", f64::from(min).into())])).unwrap();
        let r = source.relevancy(&scene, "7").unwrap();
        assert_eq!(r.values, members(7, min), "min_probability {min}");
    }
    // Above every probability of class 7: the instance exists but is not selected, and the
    // error says so with its highest probability (PyTorch's).
    let highest = prob
        .iter()
        .zip(expected().0)
        .filter(|(_, id)| *id == 7)
        .map(|(&p, _)| p)
        .fold(0.0f32, f32::max);
    let source = build(table(&[("min_probability", 0.9.into())])).unwrap();
    let e = source.relevancy(&scene, "7").unwrap_err().to_string();
    assert!(
        e.contains("min_probability = 0.9") && e.contains(&format!("{highest:.3}")),
        "{e}"
    );
    println!("{e}");
    // The scattered Gaussians (the last 20) are near-uniform over 32 classes: below the
    // default 0.3 they join no instance, and "-1" names them.
    let source = build(table(&[])).unwrap();
    let r = source.relevancy(&scene, "-1").unwrap();
    let unsure: Vec<f32> = prob.iter().map(|&p| f32::from(u8::from(p < 0.3))).collect();
    assert_eq!(r.values, unsure);
    assert!(r.values[200..].iter().all(|&v| v == 1.0));
}

#[test]
fn bad_inputs_name_the_file_and_the_key() {
    let scene = scene();
    for (file, key) in [
        ("bad_kernel.pth", "\"weight\" has shape [32, 16, 3, 3]"),
        ("bad_no_bias.pth", "missing key \"bias\""),
        ("missing.pth", "missing.pth"),
    ] {
        let e = build(table(&[("classifier", file.into())]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(file) && e.contains(key) && e.contains("targets.custom.gaussian_grouping"),
            "{file}: {e}"
        );
        println!("{e}");
    }
    // Width mismatch: found at the first query, naming the classifier and the properties.
    let source = build(table(&[("classifier", "bad_width.pth".into())])).unwrap();
    let e = source.relevancy(&scene, "3").unwrap_err().to_string();
    assert!(
        e.contains("bad_width.pth") && e.contains("width 8") && e.contains("16 obj_dc_"),
        "{e}"
    );
    println!("{e}");

    // A scene without identity encodings, and one with a gap in their numbering.
    let source = build(table(&[])).unwrap();
    let mut plain = scene.clone();
    plain
        .extras
        .properties
        .retain(|p| !p.name.starts_with("obj_dc_"));
    let e = source.relevancy(&plain, "3").unwrap_err().to_string();
    assert!(e.contains("no obj_dc_* properties"), "{e}");
    let mut gap = scene.clone();
    gap.extras.properties.retain(|p| p.name != "obj_dc_4");
    let e = source.relevancy(&gap, "3").unwrap_err().to_string();
    assert!(e.contains("no obj_dc_4"), "{e}");
    println!("{e}");

    // Unknown keys and out-of-range values name the key.
    let e = build(table(&[("min_prob", 0.5.into())]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("min_prob") && e.contains("min_probability"),
        "{e}"
    );
    let e = build(table(&[("min_probability", 1.5.into())]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("min_probability") && e.contains("[0, 1]"), "{e}");
    let names: toml::Table = toml::from_str(r#"bear = "teddy""#).unwrap();
    let e = build(table(&[("label_names", names.into())]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bear") && e.contains("integer"), "{e}");
    let e = build(toml::Table::new()).unwrap_err().to_string();
    assert!(e.contains("classifier"), "{e}");
}
