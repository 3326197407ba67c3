//! `features` route: synthetic language features built from the ground-truth labels.

mod common;

use std::collections::HashMap;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use splatraj_scene::{Features, Scene};
use splatraj_semantic::embeddings::{EMBEDDINGS_TENSOR, PHRASES_METADATA_KEY};
use splatraj_semantic::{
    ClusterOptions, EpsRule, FeatureInput, FeaturesSource, Matrix, PhraseTable, SelectionOptions,
    find_target, read_feature_sidecar,
};

const DIM: usize = 16;
const SIGMA: f32 = 0.1;
const NEGATIVES: [&str; 4] = ["object", "things", "stuff", "texture"];

/// The tiny fixture's objects are 6-22% of its Gaussians, so the real-scene default of the top
/// 2% would cut every one of them; 30% is above the largest. Unrelated Gaussians score about
/// 0.5 against orthogonal phrases (no more like the query than like a negative), so the floor
/// is raised to 0.9 to leave them out.
fn options() -> SelectionOptions {
    SelectionOptions {
        top_fraction: 0.3,
        floor: 0.9,
        ..Default::default()
    }
}

struct Synthetic {
    scene: Scene,
    table: PhraseTable,
    label_vectors: Vec<Vec<f32>>,
    rng: ChaCha8Rng,
}

/// fruit_drops with features = (unit vector of its label) + N(0, σ²) noise, and a phrase table
/// with "Category 1".."Category 8", "unlabelled" and the four negatives.
fn synthetic() -> Synthetic {
    let mut scene = common::fruit_drops();
    let mut rng = common::rng(7);
    // 9 label vectors (0..=8) and 4 negatives, all orthonormal.
    let vecs = common::orthonormal(&mut rng, 13, DIM);
    let label_vectors = vecs[..9].to_vec();
    let ids = scene.extras.labels.as_ref().unwrap().ids.clone();
    let mut values = Vec::with_capacity(ids.len() * DIM);
    for &id in &ids {
        values.extend(common::noisy(&mut rng, &label_vectors[id as usize], SIGMA));
    }
    scene.extras.features = Some(Features {
        names: (0..DIM).map(|k| format!("semantic_{k}")).collect(),
        dim: DIM,
        values,
    });
    let mut phrases: Vec<String> = (1..=8).map(|i| format!("Category {i}")).collect();
    phrases.push("unlabelled".into());
    phrases.extend(NEGATIVES.iter().map(|s| s.to_string()));
    let mut rows: Vec<Vec<f32>> = label_vectors[1..].to_vec();
    rows.push(label_vectors[0].clone());
    rows.extend(vecs[9..].iter().cloned());
    let table = table_of(&phrases, &rows);
    Synthetic {
        scene,
        table,
        label_vectors,
        rng,
    }
}

fn table_of(phrases: &[String], rows: &[Vec<f32>]) -> PhraseTable {
    let dim = rows[0].len();
    PhraseTable::new(
        "test table",
        phrases.to_vec(),
        Matrix {
            source: "test table".into(),
            rows: rows.len(),
            dim,
            values: rows.concat(),
        },
    )
    .unwrap()
}

#[test]
fn features_recover_each_object_with_precision_and_recall_above_095() {
    let s = synthetic();
    let ids = s.scene.extras.labels.as_ref().unwrap().ids.clone();
    let source = FeaturesSource::new(FeatureInput::Scene, s.table.clone());
    // The rule before issue 16, for the record (`--nocapture` prints both).
    let old = SelectionOptions {
        cluster: Some(ClusterOptions {
            eps: EpsRule::candidate_k_distance(),
            ..Default::default()
        }),
        ..options()
    };
    for id in 1..=8 {
        let query = format!("category {id}");
        let t = find_target(&source, &s.scene, &query, &options()).unwrap();
        let truth: Vec<bool> = ids.iter().map(|&l| l == id).collect();
        let (p, r) = common::precision_recall(&t.mask, &truth);
        let before = find_target(&source, &s.scene, &query, &old).unwrap();
        let (p0, r0) = common::precision_recall(&before.mask, &truth);
        println!(
            "{query}: scene density: precision {p:.4}, recall {r:.4}, clusters {:?}; candidate \
             k-distance: precision {p0:.4}, recall {r0:.4}",
            t.cluster_sizes()
        );
        assert!(
            p >= 0.95 && r >= 0.95,
            "{query}: precision {p:.3}, recall {r:.3}"
        );
        assert!(t.relevancy_spread.min > 0.9 && t.relevancy_spread.max < 1.0);
        assert!(t.relevancy_spread.min <= t.relevancy_spread.median);
        assert_eq!(t.mask.iter().filter(|m| **m > 0.5).count(), t.count);
    }
}

#[test]
fn dbscan_removes_outliers_planted_far_from_the_object() {
    let mut s = synthetic();
    let ids = s.scene.extras.labels.as_ref().unwrap().ids.clone();
    let object = 2;
    // 20 unlabelled Gaussians get object 2's feature (plus noise) and move 10 m away, each in
    // its own direction: look-alikes that only their position gives away.
    let planted: Vec<usize> = (0..ids.len()).filter(|&i| ids[i] == 0).take(20).collect();
    assert_eq!(planted.len(), 20);
    let features = s.scene.extras.features.as_mut().unwrap();
    for &i in &planted {
        let v = common::noisy(&mut s.rng, &s.label_vectors[object], SIGMA);
        features.values[i * DIM..(i + 1) * DIM].copy_from_slice(&v);
        let dir: [f32; 3] = std::array::from_fn(|_| s.rng.random_range(-1.0f32..1.0));
        let n = dir.iter().map(|x| x * x).sum::<f32>().sqrt();
        for (m, d) in s.scene.means[i].iter_mut().zip(dir) {
            *m += 10.0 * d / n;
        }
    }
    let source = FeaturesSource::new(FeatureInput::Scene, s.table.clone());
    let truth: Vec<bool> = ids.iter().map(|&l| l == object as i32).collect();

    // Without DBSCAN the planted Gaussians pass the thresholds: the test can fail.
    let raw = find_target(
        &source,
        &s.scene,
        "Category 2",
        &SelectionOptions {
            cluster: None,
            ..options()
        },
    )
    .unwrap();
    let kept_raw = planted.iter().filter(|&&i| raw.mask[i] > 0.5).count();
    assert_eq!(
        kept_raw, 20,
        "the outliers look like the object by their features"
    );

    let t = find_target(&source, &s.scene, "Category 2", &options()).unwrap();
    let kept = planted.iter().filter(|&&i| t.mask[i] > 0.5).count();
    assert_eq!(kept, 0, "DBSCAN keeps {kept} of the 20 outliers");
    assert!(t.noise + t.cluster_sizes()[1..].iter().sum::<usize>() >= 20);
    assert!(planted.iter().all(|i| t.rejected.contains(i)));
    let (p, r) = common::precision_recall(&t.mask, &truth);
    assert!(p >= 0.95 && r >= 0.95, "precision {p:.3}, recall {r:.3}");
    // The robust centre stays on the object, not pulled toward the outliers.
    let raw_mean: f32 = raw
        .centre
        .iter()
        .zip(&t.centre)
        .map(|(a, b)| (a - b).abs())
        .sum();
    assert!(raw_mean < 0.05, "median centre moved by {raw_mean}");
    for k in 0..3 {
        assert!(t.extent[k] < 0.5, "extent {:?}", t.extent);
    }
}

#[test]
fn keep_all_clusters_above_a_fraction() {
    let mut s = synthetic();
    let ids = s.scene.extras.labels.as_ref().unwrap().ids.clone();
    // A second copy of object 5, 10 m away: two clusters of equal weight.
    let copies: Vec<usize> = (0..ids.len()).filter(|&i| ids[i] == 5).collect();
    let n0 = s.scene.len();
    for &i in &copies {
        let m = s.scene.means[i];
        s.scene.means.push([m[0] + 10.0, m[1], m[2]]);
        let f = s.scene.extras.features.as_ref().unwrap().row(i).to_vec();
        s.scene.extras.features.as_mut().unwrap().values.extend(f);
    }
    let source = FeaturesSource::new(FeatureInput::Scene, s.table.clone());
    let opts = SelectionOptions {
        top_fraction: 0.5,
        ..options()
    };
    let largest = find_target(&source, &s.scene, "Category 5", &opts).unwrap();
    let both = find_target(
        &source,
        &s.scene,
        "Category 5",
        &SelectionOptions {
            cluster: Some(ClusterOptions {
                keep: splatraj_semantic::KeepClusters::AboveFraction(0.3),
                ..Default::default()
            }),
            ..opts
        },
    )
    .unwrap();
    assert!(largest.clusters.len() >= 2, "{:?}", largest.cluster_sizes());
    let far =
        |t: &splatraj_semantic::Target| (n0..s.scene.len()).filter(|&i| t.mask[i] > 0.5).count();
    let near = |t: &splatraj_semantic::Target| copies.iter().filter(|&&i| t.mask[i] > 0.5).count();
    // Largest: one copy only. Above 30%: both.
    assert!((far(&largest) == 0) != (near(&largest) == 0));
    assert!(far(&both) as f64 >= 0.95 * copies.len() as f64);
    assert!(near(&both) as f64 >= 0.95 * copies.len() as f64);
}

#[test]
fn sidecars_and_tables_read_from_every_format() {
    let s = synthetic();
    let dir = tempfile::tempdir().unwrap();
    let f = s.scene.extras.features.as_ref().unwrap();
    let n = s.scene.len();

    // Features as .npy [N, D] float32.
    let npy = dir.path().join("features.npy");
    write_npy(&npy, &f.values, n, DIM);
    let m = read_feature_sidecar(&npy).unwrap();
    assert_eq!((m.rows, m.dim), (n, DIM));
    assert_eq!(m.values, f.values);

    // Features as .safetensors, tensor "features".
    let st = dir.path().join("features.safetensors");
    write_safetensors(&st, "features", &f.values, n, DIM, None);
    let m2 = read_feature_sidecar(&st).unwrap();
    assert_eq!(m2.values, f.values);

    // The sidecar route selects the same as the scene route.
    let from_scene = FeaturesSource::new(FeatureInput::Scene, s.table.clone());
    let from_file = FeaturesSource::new(FeatureInput::Sidecar(m), s.table.clone());
    let a = find_target(&from_scene, &s.scene, "Category 4", &options()).unwrap();
    let b = find_target(&from_file, &s.scene, "Category 4", &options()).unwrap();
    assert_eq!(a.mask, b.mask);

    // Phrase table as JSON, .npy + phrases, .safetensors with metadata phrases.
    let t = &s.table;
    let json: HashMap<&str, &[f32]> = t
        .phrases
        .iter()
        .enumerate()
        .map(|(i, p)| (p.as_str(), t.vectors.row(i)))
        .collect();
    let jp = dir.path().join("table.json");
    std::fs::write(&jp, serde_json::to_string(&json).unwrap()).unwrap();
    let tp = dir.path().join("table.npy");
    write_npy(&tp, &t.vectors.values, t.phrases.len(), DIM);
    let pp = dir.path().join("phrases.txt");
    std::fs::write(&pp, t.phrases.join("\n") + "\n").unwrap();
    let sp = dir.path().join("table.safetensors");
    let meta = serde_json::to_string(&t.phrases).unwrap();
    write_safetensors(
        &sp,
        EMBEDDINGS_TENSOR,
        &t.vectors.values,
        t.phrases.len(),
        DIM,
        Some(meta),
    );
    for table in [
        PhraseTable::read(&jp, None).unwrap(),
        PhraseTable::read(&tp, Some(&pp)).unwrap(),
        PhraseTable::read(&sp, None).unwrap(),
    ] {
        for p in &t.phrases {
            assert_eq!(
                table.get(p, "phrase").unwrap(),
                t.get(p, "phrase").unwrap(),
                "{}",
                table.source
            );
        }
    }
    // Without phrases an .npy table cannot be read.
    let err = PhraseTable::read(&tp, None).unwrap_err().to_string();
    assert!(err.contains("phrases file"), "{err}");
    assert!(PHRASES_METADATA_KEY == "phrases");
}

fn write_npy(path: &std::path::Path, values: &[f32], rows: usize, dim: usize) {
    use npyz::WriterBuilder;
    let file = std::fs::File::create(path).unwrap();
    let mut w = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[rows as u64, dim as u64])
        .writer(std::io::BufWriter::new(file))
        .begin_nd()
        .unwrap();
    w.extend(values.iter().copied()).unwrap();
    w.finish().unwrap();
}

fn write_safetensors(
    path: &std::path::Path,
    name: &str,
    values: &[f32],
    rows: usize,
    dim: usize,
    phrases: Option<String>,
) {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let view =
        safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![rows, dim], &bytes)
            .unwrap();
    let meta = phrases.map(|p| HashMap::from([(PHRASES_METADATA_KEY.to_string(), p)]));
    let out = safetensors::serialize([(name, view)], meta).unwrap();
    std::fs::write(path, out).unwrap();
}
