//! The lens over time end to end (`[camera] lens = "zoom"`, docs/conventions.md "The lens"): a
//! zooming run's `trajectory.json` carries the lens, `metrics.json` the field of view per
//! sample, and every export, read back by our own readers, the zoomed camera per frame; a bad
//! `zoom_range` fails naming its key; a fixed lens writes no lens.

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG as TINY, assert_clean_failure, s, splatraj, stderr, stdout};
use splatraj::render::camera::Intrinsics;
use splatraj::traj::trajectory::{TrajectoryRecord, uniform_times};

fn setup() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, TINY).unwrap();
    (dir, config)
}

fn runs_set(dir: &Path) -> String {
    format!("output.runs_dir=\"{}\"", dir.join("runs").display())
}

fn run(config: &Path, dir: &Path, sets: &[&str]) -> PathBuf {
    let runs = runs_set(dir);
    let mut args = vec!["run", s(config), "--quiet", "--set", &runs];
    for set in sets {
        args.extend(["--set", set]);
    }
    let out = splatraj(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    PathBuf::from(stdout(&out).lines().last().unwrap().trim())
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_zooming_run_records_and_exports_its_lens() {
    let (dir, config) = setup();
    // Thirty steps at 0.05: the zoom moves to about 0.76 in the first window, 1.18 in the
    // second (measured).
    let folder = run(
        &config,
        dir.path(),
        &[
            "camera.lens=\"zoom\"",
            "optimiser.iterations=30",
            "optimiser.learning_rate=0.05",
            "output.frames=6",
        ],
    );
    let text = std::fs::read_to_string(folder.join("trajectory.json")).unwrap();
    let record: TrajectoryRecord = serde_json::from_str(&text).unwrap();
    let lens = record
        .lens
        .clone()
        .expect("trajectory.json carries the lens");
    assert_eq!((lens.range.min, lens.range.max), (0.5, 2.0));
    assert_eq!(lens.weights.len(), record.weights.len());

    // The frame camera: [output] 40 × 30 at the default 60° horizontal.
    let output = Intrinsics::from_fov_x(60.0, 40, 30).unwrap();
    let file = json(&folder.join("trajectory.json"));
    for pose in file["poses"].as_array().unwrap() {
        let t = pose["t"].as_f64().unwrap();
        let s = record.zooms_at(&[t])[0];
        assert!((pose["zoom"].as_f64().unwrap() - s).abs() < 1e-12);
        let fov = output.zoomed(s).unwrap().horizontal_fov_degrees();
        assert!((pose["fov_x_degrees"].as_f64().unwrap() - fov).abs() < 1e-9);
    }

    // metrics.json: per sample, t, zoom and both fields of view.
    let metrics = json(&folder.join("metrics.json"));
    for w in metrics["windows"].as_array().unwrap() {
        let l = &w["lens"];
        let ts = l["t"].as_array().unwrap();
        assert_eq!(ts.len(), 2, "metric_samples = 2");
        for (k, t) in ts.iter().enumerate() {
            let s = record.zooms_at(&[t.as_f64().unwrap()])[0];
            assert!((l["zoom"][k].as_f64().unwrap() - s).abs() < 1e-12);
            let camera = output.zoomed(s).unwrap();
            let fov_x = l["fov_x_degrees"][k].as_f64().unwrap();
            let fov_y = l["fov_y_degrees"][k].as_f64().unwrap();
            // Closed form: 2·atan(w / (2·fx·s)) with the principal point at the centre.
            let want_x = 2.0 * (20.0 / (output.fx * s)).atan().to_degrees();
            assert!((fov_x - want_x).abs() < 1e-9, "{fov_x} vs {want_x}");
            assert!((fov_y - camera.vertical_fov_degrees()).abs() < 1e-9);
        }
    }

    // Every frame's zoom, and it moved.
    let times = uniform_times(6);
    let zooms = record.zooms_at(&times);
    assert!(
        zooms.iter().any(|s| (s - 1.0).abs() > 0.05),
        "the zoom moved: {zooms:?}"
    );
    let fovs: Vec<f64> = zooms
        .iter()
        .map(|&s| output.zoomed(s).unwrap().vertical_fov_degrees())
        .collect();
    // Read back by our own readers: nerfstudio's `fov`, COLMAP's camera per image and
    // INRIA's focal lengths give each frame's field of view.
    for file in [
        "nerfstudio/camera_path.json",
        "colmap/images.txt",
        "inria/cameras.json",
    ] {
        let (_, path) =
            splatraj_camera_paths::read_camera_path(&folder.join("exports").join(file)).unwrap();
        assert_eq!(path.frames.len(), 6, "{file}");
        for (k, (frame, want)) in path.frames.iter().zip(&fovs).enumerate() {
            let got = frame
                .camera
                .expect("a camera per frame")
                .vertical_fov_degrees();
            assert!(
                (got - want).abs() < 1e-6,
                "{file} frame {k}: {got} vs {want}"
            );
        }
    }
    // SuperSplat: the fov of each key, every key one of the frames'.
    let (_, path) =
        splatraj_camera_paths::read_camera_path(&folder.join("exports/supersplat/settings.json"))
            .unwrap();
    assert!(!path.frames.is_empty());
    let settings = json(&folder.join("exports/supersplat/settings.json"));
    let keyed = settings["animTracks"][0]["keyframes"]["values"]["fov"]
        .as_array()
        .unwrap();
    for fov in keyed {
        let fov = fov.as_f64().unwrap();
        assert!(
            fovs.iter().any(|f| (f - fov).abs() < 1e-6),
            "SuperSplat key fov {fov} is a frame's ({fovs:?})"
        );
    }
    for frame in &path.frames {
        let got = frame.camera.unwrap().vertical_fov_degrees();
        let (lo, hi) = fovs
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &f| (a.min(f), b.max(f)));
        assert!(
            got > lo - 1e-6 && got < hi + 1e-6,
            "{got} within [{lo}, {hi}]"
        );
    }
}

#[test]
fn a_fixed_lens_writes_no_lens() {
    let (dir, config) = setup();
    let folder = run(&config, dir.path(), &[]);
    let file = json(&folder.join("trajectory.json"));
    assert!(file.get("lens").is_none());
    assert!(file["poses"][0].get("zoom").is_none());
    let metrics = json(&folder.join("metrics.json"));
    assert!(metrics["windows"][0].get("lens").is_none());
}

#[test]
fn a_bad_zoom_range_names_its_key() {
    let (dir, config) = setup();
    for range in ["[1.5, 3.0]", "[0.0, 2.0]", "[0.5, 0.8]"] {
        let set = format!("camera.zoom_range={range}");
        let runs = runs_set(dir.path());
        let out = splatraj(&[
            "run",
            s(&config),
            "--check",
            "--set",
            &runs,
            "--set",
            "camera.lens=\"zoom\"",
            "--set",
            &set,
        ]);
        assert_clean_failure(&out, &["camera.zoom_range", "0 < min < 1 < max"]);
    }
    let out = splatraj(&[
        "run",
        s(&config),
        "--check",
        "--set",
        "camera.lens=\"wide\"",
    ]);
    assert_clean_failure(&out, &["camera.lens"]);
}

/// A dolly-zoom window's zoom is locked to its camera's distance, s = d/r_w (r_w the window's
/// working radius, `prior_radius` in trajectory.json), up to the basis fit.
#[test]
fn a_dolly_zoom_window_zooms_with_its_distance() {
    let (dir, config) = setup();
    let folder = run(
        &config,
        dir.path(),
        &[
            "camera.lens=\"zoom\"",
            "queries.1.shot={kind=\"dolly-zoom\"}",
            "output.transitions=\"cut\"",
            "output.trajectory_samples=41",
            "output.frames=41",
        ],
    );
    let file = json(&folder.join("trajectory.json"));
    let window = &file["windows"][1];
    let centre: Vec<f64> = window["object_centre"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let working = window["prior_radius"].as_f64().unwrap();
    let mut checked = 0;
    let mut zooms = Vec::new();
    for pose in file["poses"].as_array().unwrap() {
        let t = pose["t"].as_f64().unwrap();
        // The window's inner 80 %: the fit of a jump at the cut rounds its very ends.
        if !(0.55..=0.95).contains(&t) {
            continue;
        }
        let c: Vec<f64> = (3..6).map(|k| pose["pose"][k].as_f64().unwrap()).collect();
        let d = (0..3)
            .map(|k| (c[k] - centre[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let zoom = pose["zoom"].as_f64().unwrap();
        assert!(
            (zoom / (d / working) - 1.0).abs() < 0.02,
            "t = {t}: zoom {zoom} vs d/r_w {}",
            d / working
        );
        zooms.push(zoom);
        checked += 1;
    }
    assert!(checked >= 10);
    let (lo, hi) = zooms
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), &z| (a.min(z), b.max(z)));
    assert!(
        hi / lo > 1.5,
        "the camera dollies and the lens zooms: {zooms:?}"
    );

    // metrics.json's `shot.zoom`, computed again from frame_metrics.csv and the lens: frames
    // t = k/40, window 1 from k = 20, its middle 60 % k = 24 … 36; linear size √coverage
    // over its mean there; the horizontal field of view 2·atan(W/(2·fx·s)) at the 40-pixel
    // frame's 60°.
    let record: TrajectoryRecord =
        serde_json::from_str(&std::fs::read_to_string(folder.join("trajectory.json")).unwrap())
            .unwrap();
    let fx = 20.0 / 30f64.to_radians().tan();
    let fov = |t: f64| 2.0 * (20.0 / (fx * record.zooms_at(&[t])[0])).atan().to_degrees();
    let csv = std::fs::read_to_string(folder.join("frame_metrics.csv")).unwrap();
    let rows: Vec<(usize, f64, f64)> = csv
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            (
                f[0].parse().unwrap(),
                f[1].parse().unwrap(),
                f[5].parse().unwrap(),
            )
        })
        .collect();
    let ratio = |keep: &dyn Fn(usize) -> bool| {
        let fovs: Vec<f64> = rows
            .iter()
            .filter(|r| keep(r.0))
            .map(|r| fov(r.1))
            .collect();
        fovs.iter().copied().fold(0.0, f64::max) / fovs.iter().copied().fold(f64::MAX, f64::min)
    };
    let sizes: Vec<f64> = rows
        .iter()
        .filter(|r| (24..=36).contains(&r.0))
        .map(|r| r.2.sqrt())
        .collect();
    let mean = sizes.iter().sum::<f64>() / sizes.len() as f64;
    assert!(
        mean > 0.0,
        "the object shows in the window's middle: {sizes:?}"
    );
    let hold = &json(&folder.join("metrics.json"))["windows"][1]["shot"]["zoom"];
    let close = |key: &str, want: f64| {
        let got = hold[key].as_f64().unwrap();
        assert!((got - want).abs() < 1e-6, "{key}: {got} vs {want}");
    };
    assert_eq!(hold["frames"], 13);
    close(
        "size_min",
        sizes.iter().copied().fold(f64::MAX, f64::min) / mean,
    );
    close("size_max", sizes.iter().copied().fold(0.0, f64::max) / mean);
    close("fov_ratio", ratio(&|k| k >= 20));
    close("fov_ratio_middle", ratio(&|k| (24..=36).contains(&k)));
    // And the verdict judges it.
    let metrics = json(&folder.join("metrics.json"));
    let checks = metrics["windows"][1]["verdict"]["checks"]
        .as_array()
        .unwrap();
    assert!(
        checks.iter().any(|c| c["check"] == "held_size"),
        "{checks:?}"
    );
    assert!(metrics["windows"][0]["shot"].is_null());
}

#[test]
fn a_dolly_zoom_with_a_fixed_lens_names_the_key() {
    let (dir, config) = setup();
    let runs = runs_set(dir.path());
    // Refused by `--check` already, before any folder is made.
    let out = splatraj(&[
        "run",
        s(&config),
        "--check",
        "--set",
        &runs,
        "--set",
        "queries.1.shot={kind=\"dolly-zoom\"}",
    ]);
    assert_clean_failure(&out, &["camera.lens", "queries.1.shot"]);
    assert!(!dir.path().join("runs").exists());
}

/// A dolly zoom whose zoom leaves `camera.zoom_range` is refused while the run is prepared:
/// by `--check`, and by a run before its folder is made. The default dolly zoom goes from 0.6
/// to 1.8 times the working radius, so it needs the zoom 0.6 → 1.8 whatever the scene.
#[test]
fn a_dolly_zoom_outside_the_zoom_range_is_refused_before_the_run_folder() {
    let (dir, config) = setup();
    let runs = runs_set(dir.path());
    for check in [Some("--check"), None] {
        let mut args = vec!["run", s(&config), "--quiet", "--set", &runs];
        args.extend(check);
        args.extend([
            "--set",
            "camera.lens=\"zoom\"",
            "--set",
            "camera.zoom_range=[0.8, 1.5]",
            "--set",
            "queries.1.shot={kind=\"dolly-zoom\"}",
        ]);
        let out = splatraj(&args);
        assert_clean_failure(
            &out,
            &[
                s(&config),
                "`queries.1.shot` (dolly-zoom)",
                "from 0.600 to 1.800",
                "`camera.zoom_range` = [0.8, 1.5]",
            ],
        );
        assert!(
            !dir.path().join("runs").exists(),
            "{check:?}: no run folder is left behind"
        );
    }
}
