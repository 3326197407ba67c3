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
    let source = LiftedSource::new(config, Device::default())
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

    // A weights file that cannot be read is named by the key the user set, not by the lifted
    // table it went into.
    let missing = parse("source = \"lifted\"\ntext_encoder = \"no-such-weights.safetensors\"\n");
    let error = missing
        .build_with(&base, &device, &registry)
        .unwrap_err()
        .to_string();
    assert!(
        error.starts_with("targets.text_encoder")
            && error.contains("no-such-weights.safetensors")
            && !error.contains("targets.lifted"),
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

/// The capture's cameras (an INRIA `cameras.json`) and its photos (here: renders saved as PNG
/// under the cameras' image names) replace the planned views; a missing photo or photos
/// without cameras are named errors.
#[test]
fn the_captures_cameras_and_photos_replace_planned_views() {
    use splatraj_lift::cameras::{camera_path, read_views};
    use splatraj_lift::field::render_rgb;
    use splatraj_render::render::DeviceScene;

    let scene = demo_scene(&DemoConfig {
        seed: 3,
        gaussians: 2_000,
    })
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let intrinsics = splatraj_render::camera::Intrinsics::from_fov_x(60.0, 80, 60).unwrap();
    let views: Vec<splatraj_lift::View> = [[-0.3, -1.8, 1.2], [1.5, -1.0, 1.4], [-1.2, 0.5, 1.6]]
        .into_iter()
        .map(|eye| splatraj_lift::View {
            pose: splatraj_render::camera::Pose::look_at(
                eye.into(),
                glam::DVec3::new(0.0, 0.3, 0.8),
                glam::DVec3::Z,
            )
            .unwrap(),
            intrinsics,
        })
        .collect();
    let files = splatraj_camera_paths::export(
        &camera_path(&views),
        splatraj_camera_paths::Format::Inria,
        &splatraj_camera_paths::ExportOptions::default(),
    )
    .unwrap();
    let cameras = dir.path().join(files[0].0);
    std::fs::write(&cameras, &files[0].1).unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let device_scene = DeviceScene::new(&scene, &Device::default(), burn::tensor::DType::F32);
    for named in read_views(&cameras).unwrap() {
        let rgb = render_rgb(&device_scene, &named.view, 80).unwrap();
        let bytes: Vec<u8> = rgb
            .pixels
            .iter()
            .map(|v| (v * 255.0).round() as u8)
            .collect();
        image::RgbImage::from_raw(rgb.width as u32, rgb.height as u32, bytes)
            .unwrap()
            .save(photos.join(format!("{}.png", named.stem())))
            .unwrap();
    }

    let with = |cameras: Option<&std::path::Path>, photos: Option<&std::path::Path>| {
        let mut c = config(dir.path());
        c.cache_dir = None;
        c.cameras = cameras.map(std::path::Path::to_path_buf);
        c.photos = photos.map(std::path::Path::to_path_buf);
        c
    };
    let (source, stages) = recorded(with(Some(&cameras), Some(&photos)));
    let relevancy = source
        .relevancy(&scene, "red mug")
        .expect("runs on the capture's views");
    assert_eq!(relevancy.values.len(), scene.len());
    let stages = stages.lock().unwrap();
    assert!(
        !stages.contains(&LiftStage::Plan),
        "no views planned: {stages:?}"
    );
    assert!(stages.contains(&LiftStage::Lift));

    // Photos are matched to cameras by name: one missing is named.
    let first = std::fs::read_dir(&photos)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    std::fs::remove_file(&first).unwrap();
    let error = LiftedSource::new(with(Some(&cameras), Some(&photos)), Device::default())
        .unwrap_err()
        .to_string();
    assert!(error.contains("no photo for 1 of 3 cameras"), "{error}");
    let error = LiftedSource::new(with(None, Some(&photos)), Device::default())
        .unwrap_err()
        .to_string();
    assert!(error.contains("targets.lifted.photos"), "{error}");

    // A photo that is not its camera's image (another aspect ratio) is named, not stretched.
    image::RgbImage::new(60, 60).save(&first).unwrap();
    let (source, _) = recorded(with(Some(&cameras), Some(&photos)));
    let error = source.relevancy(&scene, "red mug").unwrap_err().to_string();
    assert!(
        error.contains(&first.display().to_string()) && error.contains("aspect ratio"),
        "{error}"
    );
}

/// Keys that the field depends on but that are not options: `open_clip_config.json` beside
/// the weights (heads, activation) changes the cache key; shared keys set inside
/// `[targets.lifted]` are refused rather than silently overridden.
#[test]
fn the_cache_key_follows_the_towers_config_and_shared_keys_stay_in_targets() {
    let dir = tempfile::tempdir().unwrap();
    let weights_copy = dir.path().join("open_clip_model.safetensors");
    std::fs::copy(weights(), &weights_copy).unwrap();
    let scene = demo_scene(&DemoConfig {
        seed: 3,
        gaussians: 1_000,
    })
    .unwrap();
    let key = || {
        LiftedSource::new(LiftedConfig::new(weights_copy.clone()), Device::default())
            .unwrap()
            .key(&scene)
            .unwrap()
    };
    let config = dir.path().join("open_clip_config.json");
    std::fs::copy(weights().with_file_name("open_clip_config.json"), &config).unwrap();
    let before = key();
    // The same towers' config, edited (another size and time): another key.
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, format!("{text}\n")).unwrap();
    assert_ne!(
        before,
        key(),
        "editing open_clip_config.json changes the key"
    );

    let mut registry = SourceRegistry::default();
    registry.register::<LiftedConfig>(splatraj_lift::LIFTED);
    let both: TargetsConfig = toml::from_str(&format!(
        "source = \"lifted\"\ntext_encoder = {:?}\ntemperature = 5\n[lifted]\ntemperature = 7\n",
        weights().display().to_string()
    ))
    .unwrap();
    let error = both
        .build_with(dir.path(), &Device::default(), &registry)
        .unwrap_err()
        .to_string();
    assert!(error.contains("targets.lifted.temperature"), "{error}");
}

/// An up that is no direction (zero, or not finite) is refused naming the key, before any
/// weights are read.
#[test]
fn an_up_that_is_no_direction_is_refused_naming_the_key() {
    for up in [
        [0.0, 0.0, 0.0],
        [0.0, f64::NAN, 1.0],
        [f64::INFINITY, 0.0, 0.0],
    ] {
        let mut config = LiftedConfig::new("no-such-weights.safetensors".into());
        config.up = Some(up);
        let Err(error) = LiftedSource::new(config, Device::default()) else {
            panic!("up = {up:?} was accepted");
        };
        let error = error.to_string();
        assert!(
            error.contains("targets.lifted.up") && error.contains("not a direction"),
            "{error}"
        );
    }
}
