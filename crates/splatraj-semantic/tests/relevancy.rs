//! LERF relevancy against values worked out by hand.

mod common;

use common::scene_with_2d_features;
use splatraj_semantic::sources::TargetSource;
use splatraj_semantic::vectors::{cosine, pair_softmax};
use splatraj_semantic::{FeatureInput, FeaturesSource, Matrix, PhraseTable};

fn table(rows: &[(&str, [f32; 2])]) -> PhraseTable {
    PhraseTable::new(
        "hand table",
        rows.iter().map(|(p, _)| p.to_string()).collect(),
        Matrix {
            source: "hand table".into(),
            rows: rows.len(),
            dim: 2,
            values: rows.iter().flat_map(|(_, v)| *v).collect(),
        },
    )
    .unwrap()
}

#[test]
fn one_negative_matches_the_softmax_worked_by_hand() {
    // Gaussian 0: f = (3, 4), |f| = 5. Query q = (1, 0): cos = 3/5 = 0.6.
    // Negative n = (0, 2): cos = 4/5 = 0.8. τ = 10:
    //   r = e^(10·0.6) / (e^(10·0.6) + e^(10·0.8)) = e^6 / (e^6 + e^8) = 1 / (1 + e^2).
    // Gaussian 1: f = (1, 1): cos_q = cos_n = 1/√2, so r = 1/2.
    // Gaussian 2: f = (2, -1), |f| = √5: cos_q = 2/√5, cos_n = -1/√5:
    //   r = 1 / (1 + e^(10·(-1/√5 - 2/√5))) = 1 / (1 + e^(-30/√5)).
    let scene = scene_with_2d_features(&[[3.0, 4.0], [1.0, 1.0], [2.0, -1.0]], 0.0);
    let mut source = FeaturesSource::new(
        FeatureInput::Scene,
        table(&[("red apple", [1.0, 0.0]), ("object", [0.0, 2.0])]),
    );
    source.negatives = vec!["object".into()];
    let r = source.relevancy(&scene, "Red Apple").unwrap();
    let e = std::f64::consts::E;
    let expected = [
        e.powi(6) / (e.powi(6) + e.powi(8)),
        0.5,
        1.0 / (1.0 + (-30.0 / 5f64.sqrt()).exp()),
    ];
    assert!((expected[0] - 0.119_202_922).abs() < 1e-8);
    for (got, want) in r.values.iter().zip(expected) {
        assert!((f64::from(*got) - want).abs() < 1e-6, "{got} vs {want}");
    }
}

#[test]
fn the_minimum_over_negatives_and_the_temperature_are_used() {
    // f = (1, 0); q = (1, 1)/√2·|·|: cos_q = 1/√2. Negatives: (1, 0) cos 1, (0, 1) cos 0.
    // τ = 2: against (1, 0): 1/(1 + e^(2(1 - 1/√2))); against (0, 1): 1/(1 + e^(2(0 - 1/√2))).
    // The minimum is the first.
    let scene = scene_with_2d_features(&[[1.0, 0.0]], 0.0);
    let mut source = FeaturesSource::new(
        FeatureInput::Scene,
        table(&[("q", [1.0, 1.0]), ("a", [5.0, 0.0]), ("b", [0.0, 0.5])]),
    );
    source.negatives = vec!["b".into(), "a".into()];
    source.temperature = 2.0;
    let r = source.relevancy(&scene, "q").unwrap();
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let want = 1.0 / (1.0 + (2.0 * (1.0 - s)).exp());
    let other = 1.0 / (1.0 + (2.0 * (0.0 - s)).exp());
    assert!(want < other);
    assert!(
        (f64::from(r.values[0]) - want).abs() < 1e-6,
        "{} vs {want}",
        r.values[0]
    );
}

#[test]
fn pair_softmax_is_stable_for_large_temperatures() {
    assert_eq!(pair_softmax(1.0, -1.0, 1e6), 1.0);
    assert_eq!(pair_softmax(-1.0, 1.0, 1e6), 0.0);
    assert!((pair_softmax(0.3, 0.3, 10.0) - 0.5).abs() < 1e-7);
    assert!((cosine(&[3.0, 4.0], &[1.0, 0.0]).unwrap() - 0.6).abs() < 1e-7);
    let err = cosine(&[0.0, 0.0], &[1.0, 0.0]).unwrap_err().to_string();
    assert!(err.contains("zero length"), "{err}");
}
