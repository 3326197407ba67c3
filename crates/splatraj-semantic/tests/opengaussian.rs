//! `opengaussian` source: `cluster_lang.npz` as OpenGaussian writes it (np.savez, stored and
//! deflated) is read, each Gaussian scores as its leaf, unmatched leaves score 0, and bad
//! files fail naming the file and the array.
//!
//! The fixture (tests/data/opengaussian, made by scripts/make_opengaussian_fixture.py) holds 9
//! orthonormal 16-d leaves for fruit_drops' 4721 Gaussians, leaf_ind[i] = 7i mod 9, leaf 8
//! never matched (zero feature), and a phrase table "leaf 0".."leaf 7" near the leaves.

mod common;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use splatraj_semantic::sources::opengaussian::ClusterLang;
use splatraj_semantic::{SourceRegistry, TargetSource, TargetsConfig};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/opengaussian")
        .join(name)
}

fn build(
    npz: &str,
    extra: &[(&str, toml::Value)],
) -> splatraj_semantic::Result<Box<dyn TargetSource>> {
    let mut table = toml::Table::new();
    table.insert("cluster_lang".into(), npz.into());
    table.insert("phrases".into(), "phrases.json".into());
    for (k, v) in extra {
        table.insert(k.to_string(), v.clone());
    }
    TargetsConfig::custom("opengaussian", table).build_with(
        &fixture(""),
        &Device::flex(),
        &SourceRegistry::default(),
    )
}

#[test]
fn stored_and_deflated_files_read_the_same() {
    let stored = ClusterLang::read(&fixture("cluster_lang.npz")).unwrap();
    let deflated = ClusterLang::read(&fixture("cluster_lang_compressed.npz")).unwrap();
    assert_eq!(stored.leaf_ind, deflated.leaf_ind);
    assert_eq!(stored.leaf_feat.values, deflated.leaf_feat.values);
    assert_eq!((stored.leaf_feat.rows, stored.leaf_feat.dim), (9, 16));
    assert_eq!(stored.leaf_ind.len(), 4721);
    assert!(
        stored
            .leaf_ind
            .iter()
            .enumerate()
            .all(|(i, &k)| k == (7 * i) % 9)
    );
    assert_eq!(
        stored.occu_count,
        [3.0, 5.0, 2.0, 7.0, 4.0, 1.0, 6.0, 3.0, 0.0]
    );
}

#[test]
fn each_gaussian_scores_as_its_leaf() {
    let scene = common::fruit_drops();
    let source = build("cluster_lang.npz", &[]).unwrap();
    assert_eq!(source.kind(), "opengaussian");
    for k in 0..8usize {
        let r = source.relevancy(&scene, &format!("leaf {k}")).unwrap();
        for (i, &v) in r.values.iter().enumerate() {
            let leaf = (7 * i) % 9;
            match leaf {
                _ if leaf == k => assert!(v > 0.99, "leaf {k}, Gaussian {i}: {v}"),
                // The never-matched leaf has no feature: nothing to match.
                8 => assert_eq!(v, 0.0, "Gaussian {i} of the unmatched leaf"),
                // An orthogonal leaf is no more like the query than like a negative (the phrases carry
                // N(0, 0.01²) noise, so cosines of a few hundredths remain).
                _ => assert!(
                    (v - 0.5).abs() < 0.15,
                    "leaf {k}, Gaussian {i} (leaf {leaf}): {v}"
                ),
            }
        }
    }
    // min_views = 4 drops leaves 0, 2, 5 and 7 (matched in 3, 2, 1, 3 views).
    let strict = build("cluster_lang.npz", &[("min_views", 4.into())]).unwrap();
    let r = strict.relevancy(&scene, "leaf 2").unwrap();
    assert!(r.values.iter().all(|&v| v == 0.0 || (v - 0.5).abs() < 0.15));
    let r = strict.relevancy(&scene, "leaf 3").unwrap();
    assert!(r.values[3] > 0.99, "{}", r.values[3]); // Gaussian 3 is in leaf 21 mod 9 = 3
}

#[test]
fn bad_files_name_the_file_and_the_array() {
    for (file, what) in [
        ("bad_no_leaf_ind.npz", "leaf_ind"),
        ("bad_leaf_range.npz", "Gaussian 100 has leaf 9"),
        ("bad_feat_1d.npz", "leaf_feat"),
        ("phrases.json", "not a readable .npz"),
    ] {
        let e = build(file, &[]).unwrap_err().to_string();
        println!("{e}");
        assert!(
            e.contains(file) && e.contains(what) && e.contains("cluster_lang"),
            "{file}: {e}"
        );
    }
    let e = build("cluster_lang.npz", &[("leaf_ind", 1.into())])
        .unwrap_err()
        .to_string();
    assert!(e.contains("leaf_ind") && e.contains("min_views"), "{e}");
}

#[test]
fn a_scene_of_another_size_is_refused() {
    let mut scene = common::fruit_drops();
    let keep: Vec<bool> = (0..scene.len()).map(|i| i < 100).collect();
    scene.retain(&keep);
    let source = build("cluster_lang.npz", &[]).unwrap();
    let e = source.relevancy(&scene, "leaf 1").unwrap_err().to_string();
    assert!(e.contains("4721") && e.contains("100"), "{e}");
}
