//! The CLIP text encoder against open_clip: token ids from open_clip's tokenizer and unit
//! embeddings from open_clip's `encode_text` on two small seeded towers (GELU in safetensors,
//! QuickGELU in a `torch.save`d state dict), made by `scripts/make_clip_text_fixture.py`; the
//! full ViT-B/16 and B/32 state-dict shapes open_clip builds; bad weight files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use safetensors::tensor::TensorView;
use splatraj_semantic::text_encoder::{
    Activation, ClipTokenizer, TextEncoder, TextEncoderOptions, TowerShape,
};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip")
}

struct Phrase {
    text: String,
    tokens: Vec<u32>,
    embeddings: BTreeMap<String, Vec<f64>>,
}

fn phrases() -> Vec<Phrase> {
    let text = std::fs::read_to_string(fixtures().join("phrases.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["phrases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| Phrase {
            text: p["text"].as_str().unwrap().to_string(),
            tokens: p["tokens"]
                .as_array()
                .unwrap()
                .iter()
                .map(|t| t.as_u64().unwrap() as u32)
                .collect(),
            embeddings: ["gelu", "quickgelu"]
                .iter()
                .map(|k| {
                    let v = p[*k]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|x| x.as_f64().unwrap())
                        .collect();
                    (k.to_string(), v)
                })
                .collect(),
        })
        .collect()
}

#[test]
fn tokenizer_matches_open_clip() {
    let tokenizer = ClipTokenizer::new();
    let phrases = phrases();
    assert!(phrases.len() >= 20);
    for p in &phrases {
        assert_eq!(tokenizer.padded_ids(&p.text), p.tokens, "{:?}", p.text);
    }
    // The long phrase is cut to the context with the end marker kept.
    let long = phrases.last().unwrap();
    assert_eq!(long.tokens[76], 49407);
}

fn check_tower(folder: &str, file: &str, activation: Activation, heads: usize) {
    let device = Device::flex();
    let path = fixtures().join(folder).join(file);
    let encoder = TextEncoder::from_file(&path, TextEncoderOptions::default(), &device).unwrap();
    assert_eq!(encoder.activation(), activation, "{}", encoder.describe());
    assert_eq!(encoder.heads(), heads);
    assert_eq!(encoder.shape().layers, 2);
    let phrases = phrases();
    let texts: Vec<&str> = phrases.iter().map(|p| p.text.as_str()).collect();
    let got = encoder.encode(&texts).unwrap();
    assert_eq!((got.rows, got.dim), (phrases.len(), 16));
    let mut worst = 0.0f64;
    for (i, p) in phrases.iter().enumerate() {
        let want = &p.embeddings[folder];
        for (g, w) in got.row(i).iter().zip(want) {
            worst = worst.max((f64::from(*g) - w).abs());
        }
    }
    eprintln!("{folder}: largest difference from open_clip {worst:e}");
    assert!(worst < 1e-5, "{folder}: largest difference {worst:e}");
    // One phrase alone gives the same row as in the batch (padding to the batch's longest
    // row must not change a shorter row).
    let alone = encoder.encode(&[texts[4]]).unwrap();
    for (a, b) in alone.row(0).iter().zip(got.row(4)) {
        assert!((a - b).abs() < 1e-6);
    }
}

#[test]
fn gelu_tower_in_safetensors_matches_open_clip() {
    check_tower("gelu", "open_clip_model.safetensors", Activation::Gelu, 4);
}

#[test]
fn quickgelu_tower_in_a_pytorch_state_dict_matches_open_clip() {
    check_tower(
        "quickgelu",
        "open_clip_pytorch_model.bin",
        Activation::QuickGelu,
        2,
    );
}

#[test]
fn options_override_the_config_and_change_the_result() {
    let device = Device::flex();
    let path = fixtures().join("gelu/open_clip_model.safetensors");
    let options = TextEncoderOptions {
        activation: Some(Activation::QuickGelu),
        heads: Some(2),
    };
    let encoder = TextEncoder::from_file(&path, options, &device).unwrap();
    assert_eq!(
        (encoder.heads(), encoder.activation()),
        (2, Activation::QuickGelu)
    );
    let phrases = phrases();
    let got = encoder.encode(&[phrases[4].text.as_str()]).unwrap();
    let want = &phrases[4].embeddings["gelu"];
    let diff: f64 = got
        .row(0)
        .iter()
        .zip(want)
        .map(|(g, w)| (f64::from(*g) - w).abs())
        .fold(0.0, f64::max);
    assert!(diff > 1e-3, "the options were ignored");
    let bad = TextEncoderOptions {
        heads: Some(5),
        ..Default::default()
    };
    let err = TextEncoder::from_file(&path, bad, &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("5 attention heads do not divide the width 32"),
        "{err}"
    );
}

/// Tensor name → shape.
type Shapes = BTreeMap<String, Vec<usize>>;

/// A change that breaks a tower's tensors.
type Edit = Box<dyn Fn(&mut Shapes)>;

fn shapes(file: &str) -> Shapes {
    let text = std::fs::read_to_string(fixtures().join(file)).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn full_vit_b_towers_are_recognised() {
    for file in ["vit_b_16_shapes.json", "vit_b_32_shapes.json"] {
        let shapes = shapes(file);
        let tower = TowerShape::find(&shapes, Path::new(file)).unwrap();
        assert_eq!(
            (
                tower.vocab,
                tower.context,
                tower.width,
                tower.layers,
                tower.mlp_width,
                tower.embed_dim
            ),
            (49408, 77, 512, 12, 2048, 512),
            "{file}"
        );
        assert_eq!(tower.prefix, "");
        // Every text key open_clip has is one the reader expects, and the rest is the vision
        // tower (and logit scale).
        let expected = tower.expected_shapes();
        for (k, v) in &shapes {
            match expected.get(k) {
                Some(want) => assert_eq!(want, v, "{k}"),
                None => assert!(k.starts_with("visual.") || k == "logit_scale", "{k}"),
            }
        }
    }
}

/// Writes `tensors` (name → shape, zeros) as safetensors in `dir`.
fn write_safetensors(dir: &Path, tensors: &BTreeMap<String, Vec<usize>>) -> PathBuf {
    write_safetensors_with(dir, tensors, None)
}

/// [`write_safetensors`] with the first value of tensor `first.0` set to `first.1`.
fn write_safetensors_with(
    dir: &Path,
    tensors: &BTreeMap<String, Vec<usize>>,
    first: Option<(&str, f32)>,
) -> PathBuf {
    let data: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .iter()
        .map(|(k, s)| {
            let mut bytes = vec![0u8; 4 * s.iter().product::<usize>()];
            if let Some((name, value)) = first
                && name == k
            {
                bytes[..4].copy_from_slice(&value.to_le_bytes());
            }
            (k.clone(), bytes, s.clone())
        })
        .collect();
    let views: Vec<(String, TensorView)> = data
        .iter()
        .map(|(k, bytes, s)| {
            (
                k.clone(),
                TensorView::new(safetensors::Dtype::F32, s.clone(), bytes).unwrap(),
            )
        })
        .collect();
    let path = dir.join("tower.safetensors");
    safetensors::serialize_to_file(views, None, &path).unwrap();
    path
}

#[test]
fn bad_weights_name_the_file_and_the_tensor() {
    let dir = tempfile::tempdir().unwrap();
    let device = Device::flex();
    // Width 8 is below one 64-wide head: the heads are given.
    let options = TextEncoderOptions {
        heads: Some(2),
        activation: None,
    };
    let good = TowerShape {
        prefix: "text.".into(),
        vocab: 49408,
        context: 8,
        width: 8,
        layers: 1,
        mlp_width: 32,
        embed_dim: 4,
    }
    .expected_shapes();
    // The tower under `text.` (CustomTextCLIP) loads.
    let path = write_safetensors(dir.path(), &good);
    let encoder = TextEncoder::from_file(&path, options, &device);
    assert!(encoder.is_ok(), "{:?}", encoder.err());
    let err = TextEncoder::from_file(&path, TextEncoderOptions::default(), &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("attention heads do not divide the width 8"),
        "{err}"
    );

    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|t| {
                t.remove("text.transformer.resblocks.0.attn.out_proj.bias");
            }),
            "missing tensor \"text.transformer.resblocks.0.attn.out_proj.bias\"",
        ),
        (
            Box::new(|t| {
                t.insert("text.ln_final.weight".into(), vec![9]);
            }),
            "tensor \"text.ln_final.weight\" has shape [9], expected [8]",
        ),
        (
            Box::new(|t| {
                t.insert("text.transformer.resblocks.0.ls_1.gamma".into(), vec![8]);
            }),
            "\"text.transformer.resblocks.0.ls_1.gamma\" belongs to a text-tower variant",
        ),
        (
            Box::new(|t| {
                t.insert("text.token_embedding.weight".into(), vec![1000, 8]);
            }),
            "has 1000 rows but CLIP's tokenizer has 49408 tokens",
        ),
        (
            Box::new(|t| {
                t.retain(|k, _| !k.contains("token_embedding"));
            }),
            "no tensor \"token_embedding.weight\": not a CLIP text tower",
        ),
    ];
    for (edit, message) in cases {
        let mut tensors = good.clone();
        edit(&mut tensors);
        let path = write_safetensors(dir.path(), &tensors);
        let err = TextEncoder::from_file(&path, options, &device)
            .unwrap_err()
            .to_string();
        assert!(err.contains(message), "{err}");
        assert!(err.contains("tower.safetensors"), "{err}");
    }
    // A weight of 3e38 is finite but no trained weight: named with its tensor, not later as a
    // non-finite pixel of a rendered view.
    let path = write_safetensors_with(dir.path(), &good, Some(("text.ln_final.weight", 3e38)));
    let err = TextEncoder::from_file(&path, options, &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("tower.safetensors")
            && err.contains("\"text.ln_final.weight\"")
            && err.contains("3e38"),
        "{err}"
    );

    // Not a checkpoint at all, and a missing file.
    let junk = dir.path().join("junk.bin");
    std::fs::write(&junk, b"not a checkpoint").unwrap();
    let err = TextEncoder::from_file(&junk, TextEncoderOptions::default(), &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("junk.bin") && err.contains("TorchScript"),
        "{err}"
    );
    let err = TextEncoder::from_file(
        &dir.path().join("nope.bin"),
        TextEncoderOptions::default(),
        &device,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("nope.bin"), "{err}");
}

mod common;

/// Free text end to end: a scene whose Gaussians carry open_clip's embeddings (from the
/// fixture, not from our encoder) of three phrases, plus noise; the `features` source with
/// the fixture's text encoder and no phrase table selects each planted object by its phrase.
#[test]
fn free_text_query_selects_the_planted_object() {
    use splatraj_scene::Scene;
    use splatraj_semantic::{SelectionOptions, SourceKind, TargetsConfig, find_target};

    let phrases = phrases();
    let planted = ["red mug", "green ball", "potted plant"];
    let per_object = 40;
    let mut rng = common::rng(13);
    let mut means = Vec::new();
    let mut rows = Vec::new();
    let mut truth = Vec::new();
    for (k, name) in planted.iter().enumerate() {
        let base: Vec<f32> = phrases.iter().find(|p| p.text == *name).unwrap().embeddings["gelu"]
            .iter()
            .map(|&x| x as f32)
            .collect();
        for i in 0..per_object {
            means.push([
                k as f32 * 10.0,
                (i % 8) as f32 * 0.02,
                (i / 8) as f32 * 0.02,
            ]);
            rows.push(common::noisy(&mut rng, &base, 0.02));
            truth.push(k);
        }
    }
    let n = means.len();
    let scene = Scene {
        means,
        scales: vec![[0.01; 3]; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![1.0; n],
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        extras: Default::default(),
    };
    let dir = tempfile::tempdir().unwrap();
    common::write_npy(&dir.path().join("features.npy"), &rows);
    let encoder = fixtures().join("gelu/open_clip_model.safetensors");
    let config = TargetsConfig {
        selection: SelectionOptions {
            // Below one object's share (1/3): the percentile keeps only the most relevant.
            top_fraction: 0.3,
            floor: 0.5,
            cluster: None,
        },
        ..TargetsConfig::new(
            SourceKind::Features,
            keys(&[
                ("features", "features.npy"),
                ("text_encoder", path(&encoder)),
            ]),
        )
    };
    let device = Device::flex();
    let source = config.build(dir.path(), &device).unwrap();
    for (k, name) in planted.iter().enumerate() {
        // Typed differently from the fixture's phrase: the tokenizer's clean-up makes it the
        // same text.
        let query = name.to_uppercase();
        let target = find_target(source.as_ref(), &scene, &query, &config.selection).unwrap();
        let selected: Vec<usize> = target.indices();
        assert!(selected.len() >= 30, "{query}: {selected:?}");
        assert!(
            selected.iter().all(|&i| truth[i] == k),
            "{query}: {selected:?}"
        );
    }
    // Without an encoder the same phrase is not known.
    let mut no_encoder = config.clone();
    no_encoder.keys.remove("text_encoder");
    let err = no_encoder
        .build(dir.path(), &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("needs text embeddings"), "{err}");
}

/// `[targets] text_heads` reaches the encoder: the fixture's config says 4 heads, and 5 (which
/// does not divide its width 32) is refused by the encoder; 0, or heads without an encoder or
/// for another source, are refused naming the key.
#[test]
fn targets_text_heads_reaches_the_text_encoder() {
    use splatraj_semantic::{SourceKind, TargetsConfig};
    let dir = tempfile::tempdir().unwrap();
    common::write_npy(&dir.path().join("features.npy"), &[vec![1.0f32; 16]]);
    let encoder = fixtures().join("gelu/open_clip_model.safetensors");
    let config = TargetsConfig::new(
        SourceKind::Features,
        keys(&[
            ("features", "features.npy"),
            ("text_encoder", path(&encoder)),
        ]),
    );
    let device = Device::flex();
    let error = |config: TargetsConfig| match config.build(dir.path(), &device) {
        Ok(_) => String::new(),
        Err(e) => e.to_string(),
    };
    assert_eq!(error(config.clone()), "", "the config's 4 heads build");
    let with = |heads: i64| {
        let mut with = config.clone();
        with.keys.insert("text_heads".into(), heads.into());
        with
    };
    assert_eq!(error(with(2)), "", "2 heads divide the width 32");
    let err = error(with(5));
    assert!(
        err.contains("targets.text_encoder") && err.contains("5 attention heads"),
        "{err}"
    );
    let err = error(with(0));
    assert!(
        err.contains("targets.text_heads") && err.contains("≥ 1"),
        "{err}"
    );
    let mut phrases_only = with(2);
    phrases_only.keys.remove("text_encoder");
    let table = fixtures().join("phrases.json");
    phrases_only
        .keys
        .insert("phrases".into(), path(&table).into());
    let err = error(phrases_only);
    assert!(err.contains("targets.text_heads"), "{err}");
    let err = error(TargetsConfig::new(
        SourceKind::Labels,
        toml::Table::from_iter([("text_heads".to_string(), 2.into())]),
    ));
    assert!(
        err.contains("targets.text_heads") && err.contains("not to the labels source"),
        "{err}"
    );
}

/// A `[targets]` table of string values.
fn keys(pairs: &[(&str, &str)]) -> toml::Table {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), toml::Value::from(*v)))
        .collect()
}

/// A path as a config writes it.
fn path(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}
