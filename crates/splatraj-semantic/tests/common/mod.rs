//! Shared test helpers: the fruit_drops fixture with its ground-truth labels, synthetic
//! features.
#![allow(dead_code)]

use std::path::PathBuf;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use splatraj_scene::{Extras, Features, ReadOptions, Scene, read_scene};

/// The scene crate's fixture folder.
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../splatraj-scene/tests/data")
}

/// fruit_drops_minimal with its ground-truth label sidecar (4721 Gaussians, ids 0..=8).
pub fn fruit_drops() -> Scene {
    let dir = data_dir();
    let loaded = read_scene(
        &dir.join("fruit_drops_minimal.ply"),
        &ReadOptions {
            labels: Some(dir.join("fruit_drops_minimal.json")),
            ..Default::default()
        },
    )
    .expect("fixture reads");
    loaded.scene
}

/// `count` mutually orthonormal random vectors of length `dim` (Gram-Schmidt on Gaussian
/// draws), so that distinct labels and negatives have cosine 0 with each other, as a
/// well-trained language field would keep distinct concepts apart.
pub fn orthonormal(rng: &mut ChaCha8Rng, count: usize, dim: usize) -> Vec<Vec<f32>> {
    assert!(count <= dim);
    let mut out: Vec<Vec<f64>> = Vec::new();
    while out.len() < count {
        let mut v: Vec<f64> = (0..dim).map(|_| rng.sample(StandardNormal)).collect();
        for u in &out {
            let d: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
            for (x, y) in v.iter_mut().zip(u) {
                *x -= d * y;
            }
        }
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n > 1e-6 {
            out.push(v.iter().map(|x| x / n).collect());
        }
    }
    out.into_iter()
        .map(|v| v.into_iter().map(|x| x as f32).collect())
        .collect()
}

/// `base + σ·noise` with independent normal noise per component.
pub fn noisy(rng: &mut ChaCha8Rng, base: &[f32], sigma: f32) -> Vec<f32> {
    base.iter()
        .map(|&b| b + sigma * rng.sample::<f32, _>(StandardNormal))
        .collect()
}

/// A deterministic generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Precision and recall of `mask` against the Gaussians with `truth[i]` true.
pub fn precision_recall(mask: &[f32], truth: &[bool]) -> (f64, f64) {
    let tp = mask
        .iter()
        .zip(truth)
        .filter(|(m, t)| **m > 0.5 && **t)
        .count() as f64;
    let selected = mask.iter().filter(|m| **m > 0.5).count() as f64;
    let positives = truth.iter().filter(|t| **t).count() as f64;
    (tp / selected.max(1.0), tp / positives.max(1.0))
}

/// A scene with one Gaussian per 2-D feature vector, placed `spacing` apart along x.
pub fn scene_with_2d_features(features: &[[f32; 2]], spacing: f32) -> Scene {
    let n = features.len();
    Scene {
        means: (0..n).map(|i| [i as f32 * spacing, 0.0, 0.0]).collect(),
        scales: vec![[0.01; 3]; n],
        rotations: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacities: vec![1.0; n],
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        extras: Extras {
            features: Some(Features {
                names: vec!["f0".into(), "f1".into()],
                dim: 2,
                values: features.iter().flatten().copied().collect(),
            }),
            ..Default::default()
        },
    }
}

/// Writes `[N, dim]` float32 rows as `.npy`.
pub fn write_npy(path: &std::path::Path, rows: &[Vec<f32>]) {
    use npyz::WriterBuilder;
    let dim = rows[0].len();
    let mut bytes = Vec::new();
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[rows.len() as u64, dim as u64])
        .writer(&mut bytes)
        .begin_nd()
        .unwrap();
    for r in rows {
        w.extend(r.iter().copied()).unwrap();
    }
    w.finish().unwrap();
    std::fs::write(path, bytes).unwrap();
}
