//! The `lifted` source end to end with a small random-weight CLIP (both towers of the text
//! encoder's open_clip fixture): views planned, rendered, encoded, lifted, cached; a second
//! source reads the cache instead of rebuilding; bad options are named. Random weights make
//! the relevancy meaningless, so only the mechanics are checked here (docs/lifted.md says what
//! was verified with real weights and what was not).

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use burn::tensor::Device;
use splatraj_lift::field::FieldOptions;
use splatraj_lift::{LiftStage, LiftedConfig, LiftedSource, ViewOptions};
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_semantic::sources::TargetSource;
use splatraj_semantic::{SourceRegistry, TargetsConfig};

fn weights() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../splatraj-semantic/tests/fixtures/clip/gelu/open_clip_model.safetensors")
}

fn config(cache: &std::path::Path) -> LiftedConfig {
    LiftedConfig {
        views: ViewOptions {
            count: 6,
            ..ViewOptions::default()
        },
        field: FieldOptions {
            render_size: 64,
            lift_size: 48,
            components: 8,
        },
        cache_dir: Some(cache.to_path_buf()),
        ..LiftedConfig::new(weights())
    }
}

/// A source that records the stages it reports.
fn recorded(config: LiftedConfig) -> (LiftedSource, Arc<Mutex<Vec<LiftStage>>>) {
    let stages = Arc::new(Mutex::new(Vec::new()));
    let seen = stages.clone();
    let source = LiftedSource::new(config, Device::default(), None)
        .expect("source builds")
        .with_progress(Arc::new(move |stage, _, _| {
            seen.lock().unwrap().push(stage)
        }));
    (source, stages)
}

#[test]
fn a_field_is_built_once_cached_and_read_back() {
    let scene = demo_scene(&DemoConfig {
        seed: 3,
        gaussians: 4_000,
    })
    .unwrap();
    let cache = tempfile::tempdir().unwrap();
    let (source, stages) = recorded(config(cache.path()));
    let first = source.relevancy(&scene, "red mug").expect("a query runs");
    assert_eq!(first.values.len(), scene.len());
    assert!(
        first
            .values
            .iter()
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    );
    assert!(
        first.values.iter().any(|&v| v > 0.0),
        "some Gaussians are scored"
    );
    for stage in [
        LiftStage::Plan,
        LiftStage::Render,
        LiftStage::Encode,
        LiftStage::Lift,
    ] {
        assert!(
            stages.lock().unwrap().contains(&stage),
            "{stage:?} reported"
        );
    }
    let files: Vec<_> = std::fs::read_dir(cache.path()).unwrap().collect();
    assert_eq!(files.len(), 1, "one cache file: {files:?}");

    // Another query on the same source reuses the field in memory; a new source reads the
    // cache file: no view is rendered again and the values are the same.
    stages.lock().unwrap().clear();
    source
        .relevancy(&scene, "green ball")
        .expect("a second query runs");
    let (again, again_stages) = recorded(config(cache.path()));
    let second = again.relevancy(&scene, "red mug").unwrap();
    assert_eq!(first.values, second.values);
    assert!(
        stages.lock().unwrap().is_empty(),
        "{:?}",
        stages.lock().unwrap()
    );
    assert!(
        again_stages.lock().unwrap().is_empty(),
        "{:?}",
        again_stages.lock().unwrap()
    );

    // Other options are another field (a new cache file).
    let mut other = config(cache.path());
    other.views.count = 5;
    let (third, third_stages) = recorded(other);
    third.relevancy(&scene, "red mug").unwrap();
    assert!(third_stages.lock().unwrap().contains(&LiftStage::Render));
    assert_eq!(std::fs::read_dir(cache.path()).unwrap().count(), 2);
}

#[test]
fn a_damaged_cache_is_rebuilt_not_trusted() {
    let scene = demo_scene(&DemoConfig {
        seed: 3,
        gaussians: 2_000,
    })
    .unwrap();
    let cache = tempfile::tempdir().unwrap();
    let (source, _) = recorded(config(cache.path()));
    let want = source.relevancy(&scene, "plant").unwrap();
    let file = std::fs::read_dir(cache.path())
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() / 2]).unwrap();
    let (again, stages) = recorded(config(cache.path()));
    let got = again.relevancy(&scene, "plant").unwrap();
    assert_eq!(want.values, got.values);
    assert!(
        stages.lock().unwrap().contains(&LiftStage::Render),
        "rebuilt"
    );
}

#[test]
fn targets_source_lifted_builds_through_a_registry_and_names_bad_keys() {
    let mut registry = SourceRegistry::default();
    registry.register::<LiftedConfig>(splatraj_lift::LIFTED);
    let device = Device::default();
    let base = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let parse = |text: &str| -> TargetsConfig { toml::from_str(text).unwrap() };
    let good = parse(&format!(
        "source = \"lifted\"\ntext_encoder = {:?}\n[lifted]\nviews = {{ count = 4 }}\n",
        weights().display().to_string()
    ));
    let source = good.build_with(&base, &device, &registry).expect("builds");
    assert_eq!(source.kind(), "lifted");

    let bad = parse(&format!(
        "source = \"lifted\"\ntext_encoder = {:?}\n[lifted]\nviews = {{ count = 0 }}\n",
        weights().display().to_string()
    ));
    let error = bad
        .build_with(&base, &device, &registry)
        .unwrap_err()
        .to_string();
    assert!(error.contains("views.count"), "{error}");

    let typo = parse(&format!(
        "source = \"lifted\"\ntext_encoder = {:?}\n[lifted]\nview = {{ count = 4 }}\n",
        weights().display().to_string()
    ));
    let error = typo
        .build_with(&base, &device, &registry)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("targets.lifted") && error.contains("view"),
        "{error}"
    );

    let without = parse("source = \"lifted\"\n");
    let error = without
        .build_with(&base, &device, &registry)
        .unwrap_err()
        .to_string();
    assert!(error.contains("targets.text_encoder"), "{error}");

    let unregistered = good.build_with(&base, &device, &SourceRegistry::default());
    assert!(
        unregistered
            .unwrap_err()
            .to_string()
            .contains("splatraj-lift")
    );
}
