//! The `[targets]` config table: TOML examples of each source parse and build the source they
//! describe; unknown keys, bad values and unreadable files are errors that name the key.

mod common;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use serde::Deserialize;
use splatraj_semantic::selection::{
    ClusterOptions, DEFAULT_EPS_FACTOR, DEFAULT_EPS_QUANTILE, EpsRule, KeepClusters,
};
use splatraj_semantic::{
    RegionSpec, SelectionOptions, SourceKind, TargetSourceConfig, TargetsConfig, find_target,
};

/// A config file holding a `[targets]` table, as the `run` config embeds it.
#[derive(Debug, Deserialize)]
struct File {
    targets: TargetsConfig,
}

fn parse(text: &str) -> Result<TargetsConfig, String> {
    toml::from_str::<File>(text)
        .map(|f| f.targets)
        .map_err(|e| e.to_string())
}

/// The typed config of `c`'s source, its keys named as a config file names them.
fn typed(c: &TargetsConfig) -> TargetSourceConfig {
    c.source_config(&|k| format!("targets.{k}")).unwrap()
}

fn device() -> Device {
    Device::flex()
}

fn label_ids(scene: &splatraj_scene::Scene, id: i32) -> Vec<usize> {
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    (0..ids.len()).filter(|&i| ids[i] == id).collect()
}

#[test]
fn an_empty_table_is_the_labels_source_with_default_selection() {
    let c = parse("[targets]\n").unwrap();
    assert_eq!(c, TargetsConfig::default());
    assert_eq!(c.source, SourceKind::Labels);
    assert_eq!(c.selection().unwrap(), SelectionOptions::default());
}

#[test]
fn labels_example_selects_a_label_through_its_synonym_and_a_config_name() {
    let c = parse(
        r#"
[targets]
source = "labels"
label_names = { "3" = "apple" }
synonyms = { "apple" = ["pomme", "red fruit"] }
"#,
    )
    .unwrap();
    let TargetSourceConfig::Labels(labels) = typed(&c) else {
        panic!("labels config")
    };
    assert_eq!(labels.synonyms["apple"], vec!["pomme", "red fruit"]);
    let source = c.build(Path::new("/nowhere"), &device()).unwrap();
    assert_eq!(source.kind(), "labels");
    let scene = common::fruit_drops();
    let t = find_target(
        source.as_ref(),
        &scene,
        "Red  Fruit",
        &c.selection().unwrap(),
    )
    .unwrap();
    assert_eq!(t.name, "apple");
    assert_eq!(t.indices(), label_ids(&scene, 3));
}

#[test]
fn region_example_builds_named_boxes_and_spheres() {
    let c = parse(
        r#"
[targets]
source = "region"
regions = { shelf = { box = [0.5, 0.0, -2.3, 0.75, 0.15, -2.0] }, ball = { sphere = [0.6, 0.1, -2.1, 0.2] } }
"#,
    )
    .unwrap();
    let TargetSourceConfig::Region(region) = typed(&c) else {
        panic!("region config")
    };
    assert_eq!(
        region.regions["ball"],
        RegionSpec::Sphere([0.6, 0.1, -2.1, 0.2])
    );
    let source = c.build(Path::new(""), &device()).unwrap();
    let scene = common::fruit_drops();
    let options = c.selection().unwrap();
    // Brute-force references, written from the TOML numbers, not through Region.
    let in_box = |p: &[f32; 3]| {
        (0.5..=0.75).contains(&p[0])
            && (0.0..=0.15).contains(&p[1])
            && (-2.3..=-2.0).contains(&p[2])
    };
    let in_ball = |p: &[f32; 3]| {
        (p[0] - 0.6).powi(2) + (p[1] - 0.1).powi(2) + (p[2] + 2.1).powi(2) <= 0.2f32.powi(2)
    };
    for (query, inside) in [
        ("shelf", &in_box as &dyn Fn(&[f32; 3]) -> bool),
        ("BALL", &in_ball),
    ] {
        let expected: Vec<usize> = (0..scene.len())
            .filter(|&i| inside(&scene.means[i]))
            .collect();
        assert!(
            !expected.is_empty() && expected.len() < scene.len(),
            "{query}"
        );
        let t = find_target(source.as_ref(), &scene, query, &options).unwrap();
        assert_eq!(t.indices(), expected, "{query}");
    }
}

fn one_hot(k: usize, dim: usize) -> Vec<f32> {
    let mut v = vec![0.0; dim];
    v[k] = 1.0;
    v
}

/// One-hot features by label id (0..=8) and a table "apple" = label 3, negatives on axis 9.
fn write_feature_files(dir: &Path, scene: &splatraj_scene::Scene) {
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    let rows: Vec<Vec<f32>> = ids.iter().map(|&id| one_hot(id as usize, 10)).collect();
    common::write_npy(&dir.join("feat.npy"), &rows);
    let neg = one_hot(9, 10);
    let table = serde_json::json!({
        "apple": one_hot(3, 10), "banana": one_hot(5, 10),
        "object": neg, "things": neg, "stuff": neg, "texture": neg, "thing": neg,
    });
    std::fs::write(dir.join("table.json"), table.to_string()).unwrap();
}

#[test]
fn features_example_reads_files_relative_to_the_config_folder() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::fruit_drops();
    write_feature_files(dir.path(), &scene);
    let c = parse(
        r#"
[targets]
source = "features"
features = "feat.npy"
phrases = "table.json"
negatives = ["object", "thing"]
temperature = 10

[targets.selection]
top_fraction = 0.2
floor = 0.9
cluster = false
"#,
    )
    .unwrap();
    let TargetSourceConfig::Features(features) = typed(&c) else {
        panic!("features config")
    };
    assert_eq!(features.features.as_deref(), Some(Path::new("feat.npy")));
    assert_eq!(features.text.temperature, Some(10.0));
    let options = c.selection().unwrap();
    assert_eq!(options.cluster, None);
    let source = c.build(dir.path(), &device()).unwrap();
    assert_eq!(source.kind(), "features");
    let t = find_target(source.as_ref(), &scene, "apple", &options).unwrap();
    assert_eq!(t.indices(), label_ids(&scene, 3));

    // The same config from another folder: the error names the key and the file.
    let err = c
        .build(Path::new("/no/such/folder"), &device())
        .unwrap_err();
    let msg = err.to_string();
    assert!(msg.starts_with("targets.features: "), "{msg}");
    assert!(msg.contains("/no/such/folder/feat.npy"), "{msg}");
}

#[test]
fn langsplat_example_parses() {
    let c = parse(
        r#"
[targets]
source = "langsplat"
latents = "lang/latents.npy"
checkpoint = "lang/best_ckpt.pth"
phrases = "clip.safetensors"
negatives = ["object"]
temperature = 5.0

[targets.selection]
top_fraction = 0.05
"#,
    )
    .unwrap();
    assert_eq!(c.source, SourceKind::Langsplat);
    let TargetSourceConfig::Langsplat(langsplat) = typed(&c) else {
        panic!("langsplat config")
    };
    assert_eq!(langsplat.latents, Some(PathBuf::from("lang/latents.npy")));
    assert_eq!(
        langsplat.checkpoint,
        Some(PathBuf::from("lang/best_ckpt.pth"))
    );
    assert_eq!(langsplat.text.negatives, Some(vec!["object".to_string()]));
    assert_eq!(c.selection().unwrap().top_fraction, 0.05);
    // Only top_fraction was given: the rest keeps its defaults.
    assert_eq!(c.selection.cluster, Some(ClusterOptions::default()));
}

#[test]
fn selection_table_spells_every_dbscan_option() {
    let c = parse(
        r#"
[targets.selection]
floor = 0.6
cluster = { min_points = 8, eps = { fixed = 0.05 }, keep = { above_fraction = 0.1 } }
"#,
    )
    .unwrap();
    let s = c.selection().unwrap();
    assert_eq!(s.floor, 0.6);
    assert_eq!(
        s.cluster,
        Some(ClusterOptions {
            min_points: 8,
            eps: EpsRule::Fixed(0.05),
            keep: KeepClusters::AboveFraction(0.1),
        })
    );
    let c = parse(
        "[targets.selection.cluster]\neps = { auto = { neighbour = 1 } }\nkeep = \"largest\"\n",
    )
    .unwrap();
    assert_eq!(
        c.selection().unwrap().cluster.unwrap().eps,
        EpsRule::Auto {
            neighbour: Some(1),
            quantile: DEFAULT_EPS_QUANTILE,
            factor: DEFAULT_EPS_FACTOR,
        }
    );
    let c = parse("[targets.selection]\ncluster = true\n").unwrap();
    assert_eq!(
        c.selection().unwrap().cluster,
        Some(ClusterOptions::default())
    );
}

#[test]
fn configs_survive_a_toml_round_trip() {
    let mut c = parse(
        r#"
[targets]
source = "region"
regions = { shelf = { box = [0, 0, 0, 1, 1, 1] } }
[targets.selection]
cluster = { eps = { fixed = 0.5 }, keep = { above_fraction = 0.2 } }
"#,
    )
    .unwrap();
    for cluster in [c.selection.cluster, None] {
        c.selection.cluster = cluster;
        #[derive(serde::Serialize)]
        struct Out<'a> {
            targets: &'a TargetsConfig,
        }
        let text = toml::to_string(&Out { targets: &c }).unwrap();
        assert_eq!(parse(&text).unwrap(), c, "{text}");
    }
}

#[test]
fn unknown_keys_and_bad_values_name_the_key() {
    for (text, words) in [
        (
            "[targets]\nphrase = \"t.json\"\n",
            &["phrase", "unknown field"][..],
        ),
        (
            "[targets]\nlatent = \"l.npy\"\n",
            &["targets.latent", "unknown field", "latents, checkpoint"][..],
        ),
        (
            "[targets]\ntext_heads = -2\n",
            &["targets.text_heads", "-2"][..],
        ),
        (
            "[targets]\ncustom = { near = 3 }\n",
            &["targets.custom.near", "expected a map"][..],
        ),
        (
            "[targets]\nsource = \"clip\"\n",
            &["source", "clip", "langsplat"][..],
        ),
        (
            "[targets]\ntemperature = \"hot\"\n",
            &["temperature", "hot"][..],
        ),
        (
            "[targets.selection]\ntopfraction = 0.1\n",
            &["topfraction", "top_fraction"][..],
        ),
        (
            "[targets.selection]\ncluster = { min-pts = 3 }\n",
            &["min-pts", "min_points"][..],
        ),
        (
            "[targets.selection]\ncluster = 3\n",
            &["cluster", "true, false"][..],
        ),
        (
            "[targets.selection]\ncluster = { eps = { auto = { quantil = 0.5 } } }\n",
            &["quantil", "quantile"][..],
        ),
        (
            "[targets]\nregions = { a = { cube = [0, 0, 0, 1, 1, 1] } }\n",
            &["cube", "box", "sphere"][..],
        ),
        (
            "[targets]\nregions = { a = { sphere = [0, 0, 1] } }\n",
            &["sphere", "4"][..],
        ),
    ] {
        let err = parse(text).unwrap_err();
        for w in words {
            assert!(err.contains(w), "{text:?}: {w:?} missing from {err}");
        }
    }
}

#[test]
fn out_of_range_selection_values_name_their_key() {
    for (text, key) in [
        ("top_fraction = 3", "targets.selection.top_fraction"),
        ("floor = 1.0", "targets.selection.floor"),
        (
            "cluster = { min_points = 0 }",
            "targets.selection.cluster.min_points",
        ),
        (
            "cluster = { eps = { auto = { factor = -1 } } }",
            "targets.selection.cluster.eps.auto.factor",
        ),
        (
            "cluster = { eps = { auto = { quantile = 2 } } }",
            "targets.selection.cluster.eps.auto.quantile",
        ),
        (
            "cluster = { eps = { fixed = 0 } }",
            "targets.selection.cluster.eps.fixed",
        ),
        (
            "cluster = { keep = { above_fraction = 1.5 } }",
            "targets.selection.cluster.keep.above_fraction",
        ),
    ] {
        let c = parse(&format!("[targets.selection]\n{text}\n")).unwrap();
        let err = c.selection().unwrap_err().to_string();
        assert!(err.contains(&format!("`{key}`")), "{text}: {err}");
    }
}

#[test]
fn build_errors_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    write_feature_files(dir.path(), &common::fruit_drops());
    let build = |text: &str| {
        parse(text)
            .unwrap()
            .build(dir.path(), &device())
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    for (text, words) in [
        // A key of another source.
        (
            "[targets]\nsource = \"labels\"\nphrases = \"table.json\"\n",
            &["targets.phrases", "features and langsplat", "labels"][..],
        ),
        (
            "[targets]\nsource = \"features\"\nphrases = \"table.json\"\nsynonyms = { a = [\"b\"] }\n",
            &["targets.synonyms", "labels source only"][..],
        ),
        (
            "[targets]\nsource = \"features\"\nphrases = \"table.json\"\nlatents = \"l.npy\"\n",
            &[
                "targets.latents",
                "langsplat source only",
                "not to the features",
            ][..],
        ),
        // A text key the lifted source does not take (it scores with its own field).
        (
            "[targets]\nsource = \"lifted\"\ntext_encoder = \"w.safetensors\"\nphrases = \"t.json\"\n",
            &[
                "targets.phrases",
                "features and langsplat source only",
                "lifted",
            ][..],
        ),
        (
            "[targets]\nsource = \"labels\"\n[targets.custom.near]\nradius = 1\n",
            &["targets.custom.near", "custom.near only", "labels"][..],
        ),
        // A needed key missing.
        (
            "[targets]\nsource = \"features\"\n",
            &["targets.phrases", "phrase table"][..],
        ),
        (
            "[targets]\nsource = \"region\"\n",
            &["targets.regions", "at least one"][..],
        ),
        // A file that is not there, or not a table.
        (
            "[targets]\nsource = \"features\"\nphrases = \"missing.json\"\n",
            &["targets.phrases: ", "missing.json"][..],
        ),
        (
            "[targets]\nsource = \"features\"\nphrases = \"feat.npy\"\n",
            &["targets.phrases: ", "feat.npy", "phrases file"][..],
        ),
        // Values the source cannot use.
        (
            "[targets]\nsource = \"features\"\nphrases = \"table.json\"\nnegatives = [\"stuf\"]\n",
            &["targets.negatives: ", "stuf", "\"stuff\""][..],
        ),
        (
            "[targets]\nsource = \"features\"\nphrases = \"table.json\"\nnegatives = []\n",
            &["targets.negatives", "at least one"][..],
        ),
        (
            "[targets]\nsource = \"features\"\nphrases = \"table.json\"\ntemperature = 0\n",
            &["targets.temperature", "> 0"][..],
        ),
        (
            "[targets]\nsource = \"region\"\nregions = { shelf = { box = [1, 0, 0, 0, 1, 1] } }\n",
            &["targets.regions.shelf", "min[0]"][..],
        ),
        (
            "[targets]\nsource = \"region\"\nregions = { ball = { sphere = [0, 0, 0, -1] } }\n",
            &["targets.regions.ball", "radius"][..],
        ),
        (
            "[targets]\nlabel_names = { three = \"apple\" }\n",
            &["targets.label_names", "three", "integer"][..],
        ),
    ] {
        let err = build(text);
        for w in words {
            assert!(err.contains(w), "{text:?}: {w:?} missing from {err:?}");
        }
    }
}
