//! `labels` source on fruit_drops with its ground-truth labels.

mod common;

use std::collections::BTreeMap;

use splatraj_semantic::{LabelsSource, SelectionOptions, SemanticError, find_target};

#[test]
fn each_label_query_selects_exactly_that_labels_gaussians() {
    let scene = common::fruit_drops();
    assert_eq!(scene.len(), 4721);
    let ids = scene.extras.labels.as_ref().unwrap().ids.clone();
    let source = LabelsSource::default();
    let mut total = 0;
    for id in 1..=8 {
        let query = format!("Category {id}");
        let target = find_target(&source, &scene, &query, &SelectionOptions::default()).unwrap();
        let expected: Vec<f32> = ids
            .iter()
            .map(|&l| if l == id { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(target.mask, expected, "{query}");
        let count = ids.iter().filter(|&&l| l == id).count();
        assert_eq!(target.count, count, "{query}");
        assert!(count > 0);
        assert_eq!(target.name, query);
        assert_eq!(
            target.cluster_sizes(),
            vec![count],
            "no clustering on ground truth by default"
        );
        assert!(target.clustering.is_none() && target.rejected.is_empty());
        total += count;
        // The robust centre lies inside the label's own bounding box.
        let pts: Vec<[f32; 3]> = (0..ids.len())
            .filter(|&i| ids[i] == id)
            .map(|i| scene.means[i])
            .collect();
        for k in 0..3 {
            let lo = pts.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min);
            let hi = pts.iter().map(|p| p[k]).fold(f32::NEG_INFINITY, f32::max);
            assert!(lo <= target.centre[k] && target.centre[k] <= hi);
            assert!(target.extent[k] >= 0.0 && target.extent[k] <= hi - lo);
        }
    }
    // Labels 1..8 plus the unlabelled 0 cover the scene.
    assert_eq!(total + ids.iter().filter(|&&l| l == 0).count(), 4721);
}

#[test]
fn case_spacing_synonyms_and_ids_match() {
    let scene = common::fruit_drops();
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    let want3: Vec<f32> = ids
        .iter()
        .map(|&l| if l == 3 { 1.0 } else { 0.0 })
        .collect();
    let source = LabelsSource {
        synonyms: BTreeMap::from([(
            "Category 3".to_string(),
            vec!["apple".to_string(), "red fruit".to_string()],
        )]),
        ..Default::default()
    };
    let opts = SelectionOptions::default();
    for q in ["category 3", "  CATEGORY   3 ", "apple", "Red Fruit", "3"] {
        let t = find_target(&source, &scene, q, &opts).unwrap();
        assert_eq!(t.mask, want3, "query {q:?}");
        assert_eq!(t.name, "Category 3", "query {q:?}");
    }
}

#[test]
fn a_misspelt_label_lists_the_closest_names() {
    let scene = common::fruit_drops();
    let err = find_target(
        &LabelsSource::default(),
        &scene,
        "Categroy 3",
        &SelectionOptions::default(),
    )
    .unwrap_err();
    match &err {
        SemanticError::NoMatch { closest, .. } => {
            assert_eq!(closest[0], "Category 3", "{closest:?}")
        }
        other => panic!("expected NoMatch, got {other:?}"),
    }
    let msg = err.to_string();
    assert!(msg.contains("\"Categroy 3\""), "{msg}");
    assert!(msg.contains("closest: \"Category 3\""), "{msg}");
    assert!(msg.contains("fruit_drops_minimal.json"), "{msg}");
}

#[test]
fn unknown_ids_and_bad_synonyms_are_errors() {
    let scene = common::fruit_drops();
    let opts = SelectionOptions::default();
    let err = find_target(&LabelsSource::default(), &scene, "42", &opts).unwrap_err();
    assert!(matches!(err, SemanticError::NoMatch { .. }), "{err}");

    let source = LabelsSource {
        synonyms: BTreeMap::from([("Categry 9".to_string(), vec!["pear".to_string()])]),
        ..Default::default()
    };
    let err = find_target(&source, &scene, "Category 1", &opts).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("synonyms") && msg.contains("Categry 9"),
        "{msg}"
    );

    let mut bare = scene.clone();
    bare.extras.labels = None;
    let err = find_target(&LabelsSource::default(), &bare, "Category 1", &opts).unwrap_err();
    assert!(err.to_string().contains("no per-Gaussian labels"), "{err}");
}

#[test]
fn dbscan_on_labels_is_an_option() {
    let scene = common::fruit_drops();
    let ids = &scene.extras.labels.as_ref().unwrap().ids;
    let source = LabelsSource {
        cluster: true,
        ..Default::default()
    };
    let t = find_target(&source, &scene, "Category 6", &SelectionOptions::default()).unwrap();
    assert!(t.clustering.is_some());
    // Clustering only removes Gaussians, and only the label's own.
    for (m, &l) in t.mask.iter().zip(ids) {
        if *m > 0.5 {
            assert_eq!(l, 6);
        }
    }
    let all = ids.iter().filter(|&&l| l == 6).count();
    assert!(
        t.count <= all && t.count as f64 >= 0.9 * all as f64,
        "{} of {all}",
        t.count
    );
    assert_eq!(t.candidates, all);
    assert_eq!(t.cluster_sizes().iter().sum::<usize>() + t.noise, all);
    assert_eq!(t.count + t.rejected.len(), all);
}
