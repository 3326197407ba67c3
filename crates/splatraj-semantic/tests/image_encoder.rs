//! The CLIP image encoder against open_clip: global embeddings from open_clip's
//! `encode_image(normalize=True)` and ClearCLIP dense features from a PyTorch reference on
//! open_clip's own modules, on two small seeded towers (GELU in safetensors, QuickGELU in a
//! float16 `torch.save`d state dict), at the native input, larger and non-square inputs
//! (interpolated position embeddings), made by `scripts/make_clip_image_fixture.py`; the
//! full ViT-B/16 visual shapes; bad weight files; and the time of `dense` at ViT-B/16's
//! size (ignored: run with `--ignored --nocapture`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::Device;
use safetensors::SafeTensors;
use safetensors::tensor::TensorView;
use splatraj_semantic::image_encoder::{
    Activation, DENSE_SIZE, ImageEncoder, ImageEncoderOptions, RgbImage, VisionShape,
};

/// Largest difference from open_clip the tests allow.
const TOLERANCE: f64 = 1e-4;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/clip_image")
}

struct Case {
    name: String,
    tower: String,
    file: String,
    kind: String,
    images: Vec<String>,
    grid: [usize; 2],
}

fn cases() -> Vec<Case> {
    let text = std::fs::read_to_string(fixtures().join("cases.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| Case {
            name: c["name"].as_str().unwrap().into(),
            tower: c["tower"].as_str().unwrap().into(),
            file: c["file"].as_str().unwrap().into(),
            kind: c["kind"].as_str().unwrap().into(),
            images: c["images"]
                .as_array()
                .unwrap()
                .iter()
                .map(|i| i.as_str().unwrap().into())
                .collect(),
            grid: [
                c["grid"][0].as_u64().unwrap() as usize,
                c["grid"][1].as_u64().unwrap() as usize,
            ],
        })
        .collect()
}

fn image(name: &str) -> RgbImage {
    let bytes = std::fs::read(fixtures().join("images.safetensors")).unwrap();
    let tensors = SafeTensors::deserialize(&bytes).unwrap();
    let view = tensors.tensor(name).unwrap();
    let [height, width, 3] = view.shape()[..] else {
        panic!("{name}: {:?}", view.shape())
    };
    RgbImage {
        width,
        height,
        pixels: view.data().iter().map(|&b| f32::from(b) / 255.0).collect(),
    }
}

fn expected(name: &str) -> Vec<f64> {
    let bytes = std::fs::read(fixtures().join("expected.safetensors")).unwrap();
    let tensors = SafeTensors::deserialize(&bytes).unwrap();
    let view = tensors.tensor(name).unwrap();
    assert_eq!(view.dtype(), safetensors::Dtype::F64);
    view.data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

fn largest_difference(got: &[f32], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    got.iter()
        .zip(want)
        .map(|(g, w)| (f64::from(*g) - w).abs())
        .fold(0.0, f64::max)
}

fn check_tower(tower: &str, activation: Activation, heads: usize) {
    let device = Device::flex();
    let mut worst = BTreeMap::new();
    for case in cases().iter().filter(|c| c.tower == tower) {
        let path = fixtures().join(&case.tower).join(&case.file);
        let encoder = ImageEncoder::from_file(&path, ImageEncoderOptions::default(), &device)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(encoder.activation(), activation, "{}", encoder.describe());
        assert_eq!(encoder.heads(), heads, "{}", encoder.describe());
        assert_eq!(encoder.dim(), 16);
        let images: Vec<RgbImage> = case.images.iter().map(|n| image(n)).collect();
        let want = expected(&case.name);
        let diff = if case.kind == "global" {
            let got = encoder.encode(&images).unwrap();
            assert_eq!((got.rows, got.dim), (images.len(), 16));
            // One image alone gives the same row as in the batch.
            let alone = encoder.encode(&images[1..2]).unwrap();
            assert!(largest_difference(&alone.values, &want[16..]) < TOLERANCE);
            largest_difference(&got.values, &want)
        } else {
            let [rows, cols] = case.grid;
            let got = encoder.dense_grid(&images[0], rows, cols).unwrap();
            assert_eq!((got.rows, got.cols, got.dim), (rows, cols, 16));
            for r in 0..rows {
                for c in 0..cols {
                    let norm: f32 = got.at(r, c).iter().map(|v| v * v).sum::<f32>().sqrt();
                    assert!((norm - 1.0).abs() < 1e-5);
                }
            }
            largest_difference(&got.values, &want)
        };
        eprintln!("{}: largest difference from open_clip {diff:e}", case.name);
        assert!(
            diff < TOLERANCE,
            "{}: largest difference {diff:e}",
            case.name
        );
        worst.insert(case.name.clone(), diff);
    }
    assert_eq!(worst.len(), 4, "{worst:?}");
}

#[test]
fn gelu_tower_in_safetensors_matches_open_clip() {
    check_tower("gelu", Activation::Gelu, 4);
}

#[test]
fn quickgelu_tower_in_a_float16_pytorch_state_dict_matches_open_clip() {
    check_tower("quickgelu", Activation::QuickGelu, 2);
}

#[test]
fn dense_picks_the_grid_and_resizes_the_view() {
    let device = Device::flex();
    let path = fixtures().join("gelu/open_clip_model.safetensors");
    // Patch 8: a 64-pixel dense input is an 8×8 grid, as the fixture's interpolated case.
    let options = ImageEncoderOptions {
        dense_size: 64,
        ..Default::default()
    };
    let encoder = ImageEncoder::from_file(&path, options, &device).unwrap();
    assert!(
        encoder
            .describe()
            .contains("dense input 64×64 (8×8 patches"),
        "{}",
        encoder.describe()
    );
    assert_eq!(encoder.grid_for(64, 64), (8, 8));
    assert_eq!(encoder.grid_for(640, 480), (7, 9));
    assert_eq!(encoder.grid_for(480, 640), (9, 7));
    // A square image of the dense size gives the fixture's numbers through `dense`.
    let c64 = image("c64");
    let got = encoder.dense(&c64).unwrap();
    assert!(largest_difference(&got.values, &expected("gelu_dense_64")) < TOLERANCE);
    // Any other size is resized to the grid: a flat view at twice the size resizes exactly
    // to the flat view at the dense size, and gives its features.
    let flat = |side: usize| RgbImage {
        width: side,
        height: side,
        pixels: [0.2f32, 0.5, 0.7].repeat(side * side),
    };
    let (small, big) = (flat(64), flat(128));
    let want = encoder.dense(&small).unwrap();
    let again = encoder.dense(&big).unwrap();
    assert_eq!((again.rows, again.cols), (8, 8));
    assert!(
        largest_difference(
            &again.values,
            &want
                .values
                .iter()
                .map(|&v| f64::from(v))
                .collect::<Vec<_>>()
        ) < 1e-5
    );
    let wide = big.resized(100, 30);
    let features = encoder.dense(&wide).unwrap();
    assert_eq!((features.rows, features.cols), encoder.grid_for(100, 30));
    assert!(features.values.iter().all(|v| v.is_finite()));
    // Patch centres and the patch holding a pixel agree.
    let [x, y] = features.centre(1, 2, 100, 30);
    assert_eq!(features.patch_at(x, y, 100, 30), (1, 2));
    assert_eq!(
        features.centre(0, 0, 100, 30),
        [
            0.5 * 100.0 / features.cols as f32,
            0.5 * 30.0 / features.rows as f32
        ]
    );
    // Bad images are errors, not panics.
    let bad = RgbImage {
        width: 4,
        height: 4,
        pixels: vec![0.5; 10],
    };
    let err = encoder.dense(&bad).unwrap_err().to_string();
    assert!(err.contains("holds 10 values, expected 48"), "{err}");
    let nan = RgbImage {
        width: 1,
        height: 1,
        pixels: vec![0.5, f32::NAN, 0.5],
    };
    assert!(encoder.encode(&[nan]).is_err());
}

/// Tensor name → shape.
type Shapes = BTreeMap<String, Vec<usize>>;

/// A change that breaks a tower's tensors.
type Edit = Box<dyn Fn(&mut Shapes)>;

fn vit_b_16() -> Shapes {
    let text = std::fs::read_to_string(fixtures().join("vit_b_16_visual_shapes.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn full_vit_b_16_image_tower_is_recognised() {
    let shapes = vit_b_16();
    let tower = VisionShape::find(&shapes, Path::new("vit_b_16")).unwrap();
    assert_eq!(
        (
            tower.width,
            tower.layers,
            tower.patch,
            tower.grid,
            tower.mlp_width,
            tower.embed_dim
        ),
        (768, 12, 16, 14, 3072, 512)
    );
    assert_eq!(tower.input_size(), 224);
    // Every visual key open_clip has is one the reader expects, and no more.
    assert_eq!(tower.expected_shapes(), shapes);
}

/// Writes `tensors` (name → shape) as safetensors in `dir`, filled with small seeded values
/// (zeros would make every layer norm divide 0 by its epsilon).
fn write_safetensors(dir: &Path, name: &str, tensors: &Shapes) -> PathBuf {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let data: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .iter()
        .map(|(k, s)| {
            let n: usize = s.iter().product();
            let mut bytes = Vec::with_capacity(4 * n);
            for _ in 0..n {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                let v = ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.1;
                bytes.extend(v.to_le_bytes());
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
    let path = dir.join(name);
    safetensors::serialize_to_file(views, None, &path).unwrap();
    path
}

#[test]
fn bad_weights_name_the_file_and_the_tensor() {
    let dir = tempfile::tempdir().unwrap();
    let device = Device::flex();
    let good = VisionShape {
        width: 16,
        layers: 1,
        patch: 4,
        grid: 2,
        mlp_width: 64,
        embed_dim: 8,
    }
    .expected_shapes();
    // Width 16 is below one 64-wide head: the heads are given.
    let options = ImageEncoderOptions {
        heads: Some(2),
        dense_size: 16,
        ..Default::default()
    };
    let path = write_safetensors(dir.path(), "tower.safetensors", &good);
    let encoder = ImageEncoder::from_file(&path, options, &device).unwrap();
    let flat = RgbImage {
        width: 8,
        height: 8,
        pixels: vec![0.5; 8 * 8 * 3],
    };
    assert_eq!(encoder.encode(std::slice::from_ref(&flat)).unwrap().dim, 8);
    assert_eq!(encoder.dense(&flat).unwrap().rows, 4);
    let err = ImageEncoder::from_file(&path, ImageEncoderOptions::default(), &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("0 attention heads do not divide the image width 16"),
        "{err}"
    );
    let tiny = ImageEncoderOptions {
        dense_size: 2,
        ..options
    };
    let err = ImageEncoder::from_file(&path, tiny, &device)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("dense_size") && err.contains("less than one patch"),
        "{err}"
    );

    let cases: Vec<(Edit, &str)> = vec![
        (
            Box::new(|t| {
                t.remove("visual.transformer.resblocks.0.attn.out_proj.bias");
            }),
            "missing tensor \"visual.transformer.resblocks.0.attn.out_proj.bias\"",
        ),
        (
            Box::new(|t| {
                t.remove("visual.proj");
            }),
            "missing tensor \"visual.proj\"",
        ),
        (
            Box::new(|t| {
                t.insert("visual.ln_post.weight".into(), vec![9]);
            }),
            "tensor \"visual.ln_post.weight\" has shape [9], expected [16]",
        ),
        (
            Box::new(|t| {
                t.insert("visual.positional_embedding".into(), vec![6, 16]);
            }),
            "has 6 rows: expected a class token plus a square grid",
        ),
        (
            Box::new(|t| {
                t.insert("visual.conv1.weight".into(), vec![16, 3, 4, 2]);
            }),
            "patches must be square",
        ),
        (
            Box::new(|t| {
                t.insert("visual.transformer.resblocks.0.ls_1.gamma".into(), vec![16]);
            }),
            "\"visual.transformer.resblocks.0.ls_1.gamma\" belongs to an image-tower variant",
        ),
        (
            Box::new(|t| {
                t.insert("visual.attn_pool.query".into(), vec![4, 16]);
            }),
            "\"visual.attn_pool.query\" belongs to an image-tower variant",
        ),
        (
            Box::new(|t| {
                t.retain(|k, _| !k.contains("conv1"));
            }),
            "no tensor \"visual.conv1.weight\": not a CLIP ViT image tower",
        ),
    ];
    for (edit, message) in cases {
        let mut tensors = good.clone();
        edit(&mut tensors);
        let path = write_safetensors(dir.path(), "broken.safetensors", &tensors);
        let err = ImageEncoder::from_file(&path, options, &device)
            .unwrap_err()
            .to_string();
        assert!(err.contains(message), "{err}");
        assert!(err.contains("broken.safetensors"), "{err}");
    }
    // Not a checkpoint at all, and a missing file.
    let junk = dir.path().join("junk.bin");
    std::fs::write(&junk, b"not a checkpoint").unwrap();
    let err = ImageEncoder::from_file(&junk, options, &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("junk.bin"), "{err}");
    let err = ImageEncoder::from_file(&dir.path().join("nope.bin"), options, &device)
        .unwrap_err()
        .to_string();
    assert!(err.contains("nope.bin"), "{err}");
}

/// Time of `dense` for the full ViT-B/16 image tower (random weights) at the default input
/// on this machine; prints, asserts nothing about time. Run with
/// `cargo test -p splatraj-semantic --release --test image_encoder -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_dense_at_vit_b_16_size() {
    let dir = tempfile::tempdir().unwrap();
    let device = Device::flex();
    let path = write_safetensors(dir.path(), "vit_b_16.safetensors", &vit_b_16());
    let start = Instant::now();
    let encoder = ImageEncoder::from_file(&path, ImageEncoderOptions::default(), &device).unwrap();
    eprintln!("{} (read in {:.2?})", encoder.describe(), start.elapsed());
    let view = RgbImage {
        width: 640,
        height: 480,
        pixels: (0..640 * 480 * 3)
            .map(|i| (i % 251) as f32 / 250.0)
            .collect(),
    };
    let square = view.resized(DENSE_SIZE, DENSE_SIZE);
    for (what, image) in [("448×448", &square), ("640×480", &view)] {
        for run in 0..2 {
            let start = Instant::now();
            let features = encoder.dense(image).unwrap();
            eprintln!(
                "dense {what} (grid {}×{}), run {run}: {:.2?}",
                features.rows,
                features.cols,
                start.elapsed()
            );
        }
    }
    let start = Instant::now();
    encoder.encode(std::slice::from_ref(&view)).unwrap();
    eprintln!("encode 1 view at 224: {:.2?}", start.elapsed());
}
