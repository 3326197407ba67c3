//! Open-vocabulary queries through the command line, with the fixture CLIP tower (made by
//! open_clip, crates/splatraj-semantic/tests/fixtures/clip): `query` explains a free-text
//! query (relevancy over all Gaussians, thresholds, most relevant groups) when it selects the
//! planted object and when it selects nothing, and `encode-text` writes tables (.json,
//! .safetensors) whose embeddings are open_clip's.

mod common;

use std::path::{Path, PathBuf};

use common::{s, splatraj, stderr, stdout};
use serde_json::Value;
use splatraj_scene::{Scene, write_inria_ply};
use splatraj_semantic::PhraseTable;

const NEGATIVES: [&str; 4] = ["object", "things", "stuff", "texture"];
const PLANTED: [&str; 3] = ["red mug", "green ball", "potted plant"];
const PER_OBJECT: usize = 40;
const BACKGROUND: usize = 120;

fn clip(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-semantic/tests/fixtures/clip")
        .join(name)
}

/// open_clip's embedding (GELU tower) of each fixture phrase, by its text.
fn open_clip_embeddings() -> Vec<(String, Vec<f64>)> {
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(clip("phrases.json")).unwrap()).unwrap();
    json["phrases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let v = p["gelu"].as_array().unwrap();
            (
                p["text"].as_str().unwrap().to_string(),
                v.iter().map(|x| x.as_f64().unwrap()).collect(),
            )
        })
        .collect()
}

fn embedding(text: &str) -> Vec<f64> {
    open_clip_embeddings()
        .into_iter()
        .find(|(t, _)| t == text)
        .unwrap_or_else(|| panic!("{text:?} is not a fixture phrase"))
        .1
}

fn unit(v: &[f64]) -> Vec<f64> {
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    v.iter().map(|x| x / n).collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// LERF relevancy (temperature 10, minimum over the canonical negatives), written out here
/// from its definition.
fn lerf(feature: &[f64], query: &[f64]) -> f64 {
    let f = unit(feature);
    let q = dot(&f, &unit(query));
    NEGATIVES
        .iter()
        .map(|n| {
            let c = dot(&f, &unit(&embedding(n)));
            (10.0 * q).exp() / ((10.0 * q).exp() + (10.0 * c).exp())
        })
        .fold(1.0, f64::min)
}

/// Deterministic noise in [-a, a].
fn noise(state: &mut u64, a: f64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0) * a
}

/// A scene of three planted objects (40 Gaussians each on a 2 cm grid, 1 m apart, features
/// open_clip's embedding of the object's phrase plus noise) and 120 background Gaussians
/// (a canonical negative's embedding plus noise), written as a PLY and a feature sidecar.
/// Returns the paths and the features.
fn planted_scene(dir: &Path) -> (PathBuf, PathBuf, Vec<Vec<f64>>) {
    let mut state = 7u64;
    let mut means = Vec::new();
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (k, name) in PLANTED.iter().enumerate() {
        let base = embedding(name);
        for i in 0..PER_OBJECT {
            means.push([k as f32, (i % 8) as f32 * 0.02, (i / 8) as f32 * 0.02]);
            rows.push(base.iter().map(|x| x + noise(&mut state, 0.02)).collect());
        }
    }
    for i in 0..BACKGROUND {
        let base = embedding(NEGATIVES[i % 4]);
        means.push([
            noise(&mut state, 3.0) as f32,
            noise(&mut state, 3.0) as f32 + 2.0,
            noise(&mut state, 3.0) as f32,
        ]);
        rows.push(base.iter().map(|x| x + noise(&mut state, 0.05)).collect());
    }
    let n = means.len();
    let scene = Scene {
        means,
        scales: vec![[0.01; 3]; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![0.9; n],
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        extras: Default::default(),
    };
    let ply = dir.join("planted.ply");
    write_inria_ply(&scene, &ply).unwrap();
    let features = dir.join("features.npy");
    let mut bytes = Vec::new();
    {
        use npyz::WriterBuilder;
        let dim = rows[0].len() as u64;
        let mut w = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[n as u64, dim])
            .writer(&mut bytes)
            .begin_nd()
            .unwrap();
        for r in &rows {
            w.extend(r.iter().map(|&x| x as f32)).unwrap();
        }
        w.finish().unwrap();
    }
    std::fs::write(&features, bytes).unwrap();
    (ply, features, rows)
}

fn query(
    dir: &Path,
    ply: &Path,
    features: &Path,
    phrase: &str,
    json: bool,
) -> std::process::Output {
    let out = dir.join("out");
    let tower = clip("gelu/open_clip_model.safetensors");
    let mut args = vec![
        "query",
        "--scene",
        s(ply),
        "--features",
        s(features),
        "--text-encoder",
        s(&tower),
        "--query",
        phrase,
        "--top-fraction",
        "0.1",
        "--out",
        s(&out),
        "--width",
        "64",
        "--height",
        "48",
    ];
    if json {
        args.push("--json");
    }
    splatraj(&args)
}

#[test]
fn free_text_query_is_explained_when_found() {
    let dir = tempfile::tempdir().unwrap();
    let (ply, features, rows) = planted_scene(dir.path());
    let out = query(dir.path(), &ply, &features, "Red Mug", true);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: Value = serde_json::from_str(&stdout(&out)).unwrap();
    let x = &report["explanation"];
    // The largest relevancy is the largest of the definition's over the planted features.
    let expected: Vec<f64> = rows
        .iter()
        .map(|f| lerf(f, &embedding("red mug")))
        .collect();
    let max = expected.iter().copied().fold(0.0, f64::max);
    let printed = x["quantiles"]["max"].as_f64().unwrap();
    assert!((printed - max).abs() < 1e-4, "max {printed} vs {max}");
    let above = expected.iter().filter(|&&r| r > 0.5).count();
    assert_eq!(x["above_floor"].as_u64().unwrap() as usize, above);
    // The most relevant group is the red mug: at x = 0, 40 Gaussians at most.
    let top = &x["top"][0];
    let count = top["count"].as_u64().unwrap() as usize;
    assert!((20..=PER_OBJECT).contains(&count), "{top}");
    assert!(top["centre"][0].as_f64().unwrap().abs() < 0.05, "{top}");
    assert!(report["count"].as_u64().unwrap() >= 20);

    // As text: the quantiles, the thresholds and the groups.
    let out = query(dir.path(), &ply, &features, "red mug", false);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    println!("{text}");
    for words in [
        "relevancy of \"red mug\" over all Gaussians: min",
        "p99",
        "thresholds: floor 0.5000",
        "top 10% percentile",
        "most relevant 100 Gaussians",
    ] {
        assert!(text.contains(words), "{words:?} not in\n{text}");
    }
}

#[test]
fn free_text_query_that_selects_nothing_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let (ply, features, rows) = planted_scene(dir.path());
    // Typed with other spaces than the fixture phrase "  glass   of\twater \n": the same text
    // to the tokenizer.
    let out = query(dir.path(), &ply, &features, "glass of water", false);
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.starts_with("error: ") && !err.contains("panicked"),
        "{err}"
    );
    assert!(
        err.contains("no Gaussian has relevancy above the floor 0.5"),
        "{err}"
    );
    assert!(!dir.path().join("out/query.png").exists());
    let text = stdout(&out);
    println!("{text}");
    let max = rows
        .iter()
        .map(|f| lerf(f, &embedding("  glass   of\twater \n")))
        .fold(0.0, f64::max);
    assert!(max < 0.5, "the phrase should match nothing: {max}");
    let line = text
        .lines()
        .find(|l| l.starts_with("relevancy of \"glass of water\""))
        .unwrap_or_else(|| panic!("no relevancy line in\n{text}"));
    let printed: f64 = line.rsplit("max ").next().unwrap().trim().parse().unwrap();
    assert!((printed - max).abs() < 2e-4, "{line} vs {max}");
    assert!(text.contains("(0 Gaussians above)"), "{text}");
    assert!(
        text.contains("no Gaussian is more like \"glass of water\""),
        "{text}"
    );
    assert!(text.contains("Gaussians, relevancy mean"), "{text}");
}

#[test]
fn encode_text_tables_hold_open_clips_embeddings() {
    let dir = tempfile::tempdir().unwrap();
    let phrases = ["red mug", "A photo of a CAT.", "日本の猫", "café crème"];
    let tower = clip("gelu/open_clip_model.safetensors");
    for name in ["table.json", "table.safetensors"] {
        let path = dir.path().join(name);
        let mut args = vec![
            "encode-text",
            "--text-encoder",
            s(&tower),
            "--out",
            s(&path),
        ];
        args.extend(phrases);
        let out = splatraj(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        // Read back as queries read tables; the negatives were added.
        let table = PhraseTable::read(&path, None).unwrap();
        assert_eq!(
            table.phrases.len(),
            phrases.len() + NEGATIVES.len(),
            "{name}"
        );
        let mut worst = 0.0f64;
        for phrase in phrases.iter().chain(&NEGATIVES) {
            let ours = table.get(phrase, "phrase").unwrap();
            let theirs = embedding(phrase);
            assert_eq!(ours.len(), theirs.len());
            for (a, b) in ours.iter().zip(&theirs) {
                worst = worst.max((f64::from(*a) - b).abs());
            }
        }
        println!("{name}: largest difference from open_clip {worst:e}");
        assert!(worst < 1e-5, "{name}: {worst}");
    }
    // The JSON is the documented plain form: phrase → list of floats.
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("table.json")).unwrap())
            .unwrap();
    assert_eq!(json["red mug"].as_array().unwrap().len(), 16);
}

/// A plain scene (no labels, no features) with CLIP weights: `query` lifts a language field
/// from the scene's own renders (the `lifted` source, chosen without being named), caches it
/// beside the scene, and the next query reads the cache. The fixture towers have random
/// weights, so `--floor 0` lets the mechanics run to a selection.
#[test]
fn a_plain_scene_is_queried_through_a_lifted_field_and_the_field_is_cached() {
    let dir = tempfile::tempdir().unwrap();
    let scene = splatraj_scene::demo::demo_scene(&splatraj_scene::demo::DemoConfig {
        seed: 5,
        gaussians: 3_000,
    })
    .unwrap();
    let plain = Scene {
        extras: Default::default(),
        ..scene
    };
    let path = dir.path().join("room.ply");
    write_inria_ply(&plain, &path).unwrap();
    let weights = clip("gelu/open_clip_model.safetensors");
    let query = |extra: &[&str]| {
        let mut args = vec![
            "query",
            "--scene",
            s(&path),
            "--text-encoder",
            s(&weights),
            "--query",
            "red mug",
            "--floor",
            "0",
            "--out",
            s(dir.path()),
        ];
        args.extend_from_slice(extra);
        splatraj(&args)
    };
    let first = query(&[]);
    assert!(first.status.success(), "{}", stderr(&first));
    let cache = dir.path().join("room.ply.splatraj-lifted");
    let files: Vec<_> = std::fs::read_dir(&cache)
        .expect("the field is cached beside the scene")
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let written = std::fs::metadata(&files[0]).unwrap().modified().unwrap();

    let second = query(&["--source", "lifted"]);
    assert!(second.status.success(), "{}", stderr(&second));
    assert_eq!(
        stdout(&first),
        stdout(&second),
        "the cached field gives the same answer"
    );
    assert_eq!(std::fs::read_dir(&cache).unwrap().count(), 1);
    assert_eq!(
        std::fs::metadata(&files[0]).unwrap().modified().unwrap(),
        written,
        "the cache was read, not written again"
    );

    let without = splatraj(&[
        "query",
        "--scene",
        s(&path),
        "--source",
        "lifted",
        "--query",
        "red mug",
    ]);
    assert!(!without.status.success());
    assert!(
        stderr(&without).contains("--text-encoder"),
        "{}",
        stderr(&without)
    );
}

/// A run config with `source = "lifted"`: its field's memory is estimated before any view is
/// rendered, and a limit below the estimate is refused naming the stage and the key.
#[test]
fn a_lifted_field_over_the_memory_limit_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("lifted.toml");
    std::fs::write(
        &config,
        format!(
            "name = \"lifted\"\nmax_memory_gb = 0.001\n[scene]\ndemo = {{ gaussians = 2000 }}\n\
             [targets]\nsource = \"lifted\"\ntext_encoder = {:?}\n[[queries]]\ntext = \"red mug\"\n",
            s(&clip("gelu/open_clip_model.safetensors"))
        ),
    )
    .unwrap();
    let out = splatraj(&["run", s(&config), "--check"]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("lifted field") && err.contains("max_memory_gb"),
        "{err}"
    );
}
