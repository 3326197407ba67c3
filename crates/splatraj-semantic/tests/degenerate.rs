//! Empty and degenerate inputs give clear errors, never NaN or a panic.

mod common;

/// Gaussians 1 cm apart with these 2-D features.
fn small_scene(features: Vec<[f32; 2]>) -> splatraj_scene::Scene {
    common::scene_with_2d_features(&features, 0.01)
}

use splatraj_semantic::{
    FeatureInput, FeaturesSource, Matrix, PhraseTable, Relevancy, Scoring, SelectionOptions,
    SemanticError, find_target, select,
};

fn source() -> FeaturesSource {
    let phrases = ["apple", "object", "things", "stuff", "texture"];
    let rows: [[f32; 2]; 5] = [[1.0, 0.0], [0.0, 1.0], [0.0, 1.0], [-1.0, 1.0], [0.0, 1.0]];
    FeaturesSource::new(
        FeatureInput::Scene,
        PhraseTable::new(
            "t",
            phrases.iter().map(|s| s.to_string()).collect(),
            Matrix {
                source: "t".into(),
                rows: 5,
                dim: 2,
                values: rows.iter().flatten().copied().collect(),
            },
        )
        .unwrap(),
    )
}

fn opts() -> SelectionOptions {
    SelectionOptions {
        top_fraction: 1.0,
        cluster: None,
        ..Default::default()
    }
}

#[test]
fn a_zero_norm_feature_vector_is_named() {
    let mut f = vec![[1.0, 0.1]; 10];
    f[7] = [0.0, 0.0];
    let err = find_target(&source(), &small_scene(f), "apple", &opts()).unwrap_err();
    assert!(matches!(err, SemanticError::ZeroVector { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(
        msg.contains("Gaussian 7") && msg.contains("zero length"),
        "{msg}"
    );
}

#[test]
fn a_zero_norm_phrase_and_nan_features_are_errors() {
    let mut s = source();
    s.table = PhraseTable::new(
        "t0",
        vec!["apple".into(), "object".into()],
        Matrix {
            source: "t0".into(),
            rows: 2,
            dim: 2,
            values: vec![0.0, 0.0, 0.0, 1.0],
        },
    )
    .unwrap();
    s.negatives = vec!["object".into()];
    let err = find_target(&s, &small_scene(vec![[1.0, 0.0]; 4]), "apple", &opts()).unwrap_err();
    assert!(err.to_string().contains("phrase \"apple\""), "{err}");

    let mut f = vec![[1.0, 0.1]; 4];
    f[2] = [f32::NAN, 0.0];
    let err = find_target(&source(), &small_scene(f), "apple", &opts()).unwrap_err();
    assert!(
        err.to_string().contains("Gaussian 2") && err.to_string().contains("NaN"),
        "{err}"
    );
}

#[test]
fn unknown_phrases_and_missing_negatives_list_the_closest() {
    let scene = small_scene(vec![[1.0, 0.0]; 4]);
    let err = find_target(&source(), &scene, "aple", &opts()).unwrap_err();
    match &err {
        SemanticError::NoMatch { closest, what, .. } => {
            assert_eq!(closest[0], "apple");
            assert!(what.starts_with("phrase"));
        }
        other => panic!("expected NoMatch, got {other:?}"),
    }
    let mut s = source();
    s.negatives.push("backgrounds".into());
    let err = find_target(&s, &scene, "apple", &opts())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("canonical negative phrase") && err.contains("\"backgrounds\""),
        "{err}"
    );
}

#[test]
fn all_below_the_floor_is_an_error_with_the_best_value() {
    // Features point at "object": every relevancy is well below 0.5.
    let f: Vec<[f32; 2]> = (0..10).map(|i| [0.01 * i as f32, 1.0]).collect();
    let err = find_target(&source(), &small_scene(f), "apple", &opts()).unwrap_err();
    assert!(
        matches!(err, SemanticError::NothingSelected { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("above the floor 0.5") && msg.contains("highest"),
        "{msg}"
    );
}

#[test]
fn equal_relevancies_empty_scenes_and_bad_options_are_errors() {
    let err = find_target(
        &source(),
        &small_scene(vec![[1.0, 0.0]; 6]),
        "apple",
        &opts(),
    )
    .unwrap_err();
    assert!(matches!(err, SemanticError::Degenerate { .. }), "{err:?}");
    assert!(err.to_string().contains("same relevancy"), "{err}");

    let err = find_target(&source(), &small_scene(vec![]), "apple", &opts()).unwrap_err();
    assert!(matches!(err, SemanticError::EmptyScene), "{err:?}");

    let scene = small_scene(vec![[1.0, 0.0]; 3]);
    let rel = Relevancy {
        name: "x".into(),
        values: vec![0.9, 0.1, 0.6],
        scoring: Scoring::Graded,
        notes: Vec::new(),
    };
    let err = select(
        &scene,
        "x",
        &rel,
        &SelectionOptions {
            top_fraction: 0.0,
            ..opts()
        },
    )
    .unwrap_err();
    assert!(err.to_string().contains("top_fraction"), "{err}");
    // Too few candidates for DBSCAN's min_points: a clear error, not an empty target.
    let err = select(&scene, "x", &rel, &SelectionOptions::default()).unwrap_err();
    assert!(err.to_string().contains("min_points"), "{err}");
    // Wrong feature count for the scene.
    let mut s = source();
    s.features = FeatureInput::Sidecar(Matrix {
        source: "side.npy".into(),
        rows: 2,
        dim: 2,
        values: vec![1.0; 4],
    });
    let err = find_target(&s, &scene, "apple", &opts())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("side.npy") && err.contains("2 feature vectors"),
        "{err}"
    );
}

#[test]
fn a_soft_mask_without_members_says_why() {
    // Renders take mask values as weights, but membership needs a value above 0.5.
    let scene = small_scene(vec![[1.0, 0.0]; 4]);
    let rel = Relevancy {
        name: "half.npy".into(),
        values: vec![0.5; 4],
        scoring: Scoring::Mask { cluster: false },
        notes: Vec::new(),
    };
    let err = select(&scene, "half.npy", &rel, &opts()).unwrap_err();
    assert!(
        matches!(err, SemanticError::NothingSelected { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("above 0.5") && msg.contains("largest value is 0.5"),
        "{msg}"
    );
}
