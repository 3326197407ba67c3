//! `region` source against a direct filter of the Gaussian centres.

mod common;

use splatraj_semantic::{Region, RegionSource, SelectionOptions, SemanticError, find_target};

#[test]
fn box_selects_the_centres_inside_it() {
    let scene = common::fruit_drops();
    let (min, max) = ([0.6, 0.0, -2.2], [0.8, 0.2, -2.05]);
    let source = RegionSource::single("bowl", Region::Box { min, max });
    let t = find_target(&source, &scene, "Bowl", &SelectionOptions::default()).unwrap();
    let direct: Vec<f32> = scene
        .means
        .iter()
        .map(|m| {
            let inside = m[0] >= 0.6
                && m[0] <= 0.8
                && m[1] >= 0.0
                && m[1] <= 0.2
                && m[2] >= -2.2
                && m[2] <= -2.05;
            if inside { 1.0 } else { 0.0 }
        })
        .collect();
    assert_eq!(t.mask, direct);
    let count = direct.iter().filter(|v| **v > 0.5).count();
    assert!(count > 100 && count < scene.len(), "{count}");
    assert_eq!(t.count, count);
    for k in 0..3 {
        assert!(t.centre[k] >= min[k] && t.centre[k] <= max[k]);
    }
}

#[test]
fn sphere_selects_the_centres_within_its_radius() {
    let scene = common::fruit_drops();
    let c = scene.bounds().unwrap().center();
    let radius = 0.08;
    let source = RegionSource::single("middle", Region::Sphere { centre: c, radius });
    let t = find_target(&source, &scene, "middle", &SelectionOptions::default()).unwrap();
    let direct: Vec<f32> = scene
        .means
        .iter()
        .map(|m| {
            let d = ((m[0] - c[0]).powi(2) + (m[1] - c[1]).powi(2) + (m[2] - c[2]).powi(2)).sqrt();
            if d <= radius { 1.0 } else { 0.0 }
        })
        .collect();
    assert_eq!(t.mask, direct);
    assert!(t.count > 10 && t.count < scene.len(), "{}", t.count);
}

#[test]
fn empty_and_invalid_regions_are_errors() {
    let scene = common::fruit_drops();
    let far = RegionSource::single(
        "far",
        Region::Sphere {
            centre: [100.0, 0.0, 0.0],
            radius: 1.0,
        },
    );
    let err = find_target(&far, &scene, "far", &SelectionOptions::default()).unwrap_err();
    assert!(
        matches!(err, SemanticError::NothingSelected { .. }),
        "{err}"
    );
    assert!(err.to_string().contains("contains none"), "{err}");

    let bad = RegionSource::single(
        "bad",
        Region::Box {
            min: [1.0, 0.0, 0.0],
            max: [0.0, 1.0, 1.0],
        },
    );
    let err = find_target(&bad, &scene, "bad", &SelectionOptions::default()).unwrap_err();
    assert!(err.to_string().contains("min[0]"), "{err}");

    let err = find_target(&far, &scene, "fra", &SelectionOptions::default()).unwrap_err();
    assert!(err.to_string().contains("closest: \"far\""), "{err}");
}
