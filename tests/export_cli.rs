//! `splatraj export` on a run folder made by a 2-step run of a tiny config: every format's files
//! appear whole and read back (through `splatraj-report`) as the poses `trajectory.json` holds.

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG as TINY, assert_clean_failure, s, splatraj, stderr, stdout};
use splatraj_camera_paths::{CameraPose, Format, read_camera_path};

fn tiny_run(dir: &Path) -> PathBuf {
    let config = dir.join("tiny.toml");
    std::fs::write(&config, TINY).unwrap();
    let runs = format!("output.runs_dir=\"{}\"", dir.join("runs").display());
    let out = splatraj(&["run", s(&config), "--quiet", "--set", &runs]);
    assert!(out.status.success(), "{}", stderr(&out));
    PathBuf::from(stdout(&out).lines().last().unwrap().trim())
}

#[test]
fn export_writes_every_format_and_it_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run(dir.path());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("trajectory.json")).unwrap())
            .unwrap();
    // trajectory.json samples 5 poses at t = i/4; 0.5 s at 10 fps exports 5 frames at the same
    // times, evaluated from the model and weights.
    let sampled: Vec<[[f64; 4]; 4]> = json["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| serde_json::from_value(p["world_to_camera"].clone()).unwrap())
        .collect();
    assert_eq!(sampled.len(), 5);

    for format in Format::ALL {
        let out_dir = dir.path().join("out").join(format.name());
        let out = splatraj(&[
            "export",
            s(&run),
            "--format",
            format.name(),
            "--fps",
            "10",
            "--seconds",
            "0.5",
            "--width",
            "80",
            "--out",
            s(&out_dir),
        ]);
        assert!(out.status.success(), "{format}: {}", stderr(&out));
        assert_eq!(stdout(&out).trim(), s(&out_dir));
        for name in format.file_names() {
            assert!(out_dir.join(name).is_file(), "{format}: {name} missing");
        }
        let names: Vec<String> = std::fs::read_dir(&out_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), format.file_names().len(), "{names:?}");

        let main = match format {
            Format::Colmap => "images.txt",
            _ => format.file_names()[0],
        };
        let (detected, path) = read_camera_path(&out_dir.join(main)).unwrap();
        assert_eq!(detected, format);
        assert_eq!(path.frames.len(), 5, "{format}");
        for (i, (frame, w2c)) in path.frames.iter().zip(&sampled).enumerate() {
            let expected = CameraPose::from_world_to_camera(w2c).unwrap();
            let (r, c) = frame.pose.max_difference(&expected);
            // SuperSplat keeps position and viewing direction, not roll.
            let forward = (frame.pose.forward() - expected.forward()).length();
            match format {
                Format::Supersplat => assert!(c < 1e-6 && forward < 1e-6, "{format} {i}"),
                _ => assert!(r < 1e-6 && c < 1e-6, "{format} {i}: {r:e} {c:e}"),
            }
            if format != Format::Supersplat {
                let camera = frame.camera.unwrap();
                assert_eq!((camera.width, camera.height), (80, 60), "{format}");
            }
        }
    }

    // Defaults: the run's 3 frames at 30 fps, into exports/<format>/ of the run folder.
    let out = splatraj(&["export", s(&run), "--format", "nerfstudio"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let default_file = run
        .join("exports")
        .join("nerfstudio")
        .join("camera_path.json");
    let text = std::fs::read_to_string(&default_file).unwrap();
    let camera_path: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(camera_path["camera_path"].as_array().unwrap().len(), 3);
    assert_eq!(camera_path["render_width"], 40);
    assert_eq!(camera_path["render_height"], 30);

    // A trajectory.json given directly works too.
    let out = splatraj(&[
        "export",
        s(&run.join("trajectory.json")),
        "--format",
        "inria",
        "--out",
        s(&dir.path().join("direct")),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("direct").join("cameras.json").is_file());
}

#[test]
fn export_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere");
    assert_clean_failure(
        &splatraj(&["export", s(&missing), "--format", "colmap"]),
        &["cannot read the trajectory", "nowhere"],
    );
    let not_trajectory = dir.path().join("trajectory.json");
    std::fs::write(&not_trajectory, "{\"model\": 3}").unwrap();
    assert_clean_failure(
        &splatraj(&["export", s(&not_trajectory), "--format", "inria"]),
        &["is not a trajectory.json"],
    );
    let out = splatraj(&["export", s(&not_trajectory), "--format", "blender"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("unknown format"), "{}", stderr(&out));
}

#[test]
fn exported_camera_files_start_a_run() {
    use splatraj::experiment::{Config, Experiment};
    use splatraj::traj::trajectory::{Basis, uniform_times};

    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run(dir.path());
    let text = std::fs::read_to_string(run.join("trajectory.json")).unwrap();
    let record: splatraj::traj::trajectory::TrajectoryRecord = serde_json::from_str(&text).unwrap();
    let times = uniform_times(9);
    let k = record.model.count();
    let original: Vec<[f64; 6]> = record
        .model
        .matrix(&times)
        .chunks_exact(k)
        .map(|row| {
            std::array::from_fn(|j| row.iter().zip(&record.weights).map(|(p, w)| p * w[j]).sum())
        })
        .collect();

    for (format, file) in [
        ("nerfstudio", "camera_path.json"),
        ("colmap", "images.txt"),
        ("inria", "cameras.json"),
    ] {
        let out_dir = dir.path().join("start").join(format);
        let out = splatraj(&[
            "export",
            s(&run),
            "--format",
            format,
            "--fps",
            "100",
            "--seconds",
            "4",
            "--out",
            s(&out_dir),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        let config = dir.path().join("tiny.toml");
        let sets = vec![format!(
            "start.trajectory=\"{}\"",
            out_dir.join(file).display()
        )];
        let config = Config::load(&config, &sets).unwrap();
        let experiment = Experiment::prepare(&config).unwrap();
        let starts = experiment.start_trajectories().unwrap();
        assert_eq!(starts.len(), 1);
        let start = &starts[0];
        let k = start.model.count();
        // 400 frames of the run's path, fitted again to the same RBF model: the same path
        // (rotations and centres within 1e-4; the ridge and resampling leave a few 1e-6).
        for (i, row) in start.model.matrix(&times).chunks_exact(k).enumerate() {
            let pose: Vec<f64> = (0..6)
                .map(|j| row.iter().zip(&start.weights).map(|(p, w)| p * w[j]).sum())
                .collect();
            let expected = CameraPose::from_phi(original[i]);
            let got = CameraPose::from_phi(pose.try_into().unwrap());
            let (r, c) = got.max_difference(&expected);
            assert!(
                r < 1e-4 && c < 1e-4,
                "{format}: t = {}: {r:e} {c:e}",
                times[i]
            );
        }
    }

    // A file that is neither ours nor a camera file says both.
    let odd = dir.path().join("odd.json");
    std::fs::write(&odd, "{\"frames\": []}").unwrap();
    let config = Config::load(
        &dir.path().join("tiny.toml"),
        &[format!("start.trajectory=\"{}\"", odd.display())],
    )
    .unwrap();
    let err = Experiment::prepare(&config)
        .and_then(|e| e.start_trajectories())
        .unwrap_err();
    let message = format!("{err:#}");
    assert!(
        message.contains("start.trajectory") && message.contains("nor a camera file"),
        "{message}"
    );
}

#[test]
fn a_trajectory_file_inconsistent_with_itself_is_refused_naming_the_key() {
    // Each edit of a real run's trajectory.json that the adversarial trial found accepted
    // (docs/adversarial-trial.md): export must refuse it, naming the key, and write nothing.
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run(dir.path());
    let original: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("trajectory.json")).unwrap())
            .unwrap();
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &[&str]); 7] = [
        (
            "fx 0",
            |t| t["intrinsics"]["fx"] = 0.0.into(),
            &["`intrinsics`"],
        ),
        (
            "width 0",
            |t| t["intrinsics"]["width"] = 0.into(),
            &["`intrinsics`"],
        ),
        (
            "output width 1e9",
            |t| t["output_intrinsics"]["width"] = 1_000_000_000u64.into(),
            &["`output_intrinsics`", "65536"],
        ),
        (
            "no windows in the model",
            |t| t["model"]["windows"] = 0.into(),
            &["`model`"],
        ),
        (
            "zero up",
            |t| t["world_up"] = serde_json::json!([0, 0, 0]),
            &["`world_up`"],
        ),
        (
            "a window less",
            |t| {
                t["windows"].as_array_mut().unwrap().pop();
            },
            &["`windows`", "`model.windows`"],
        ),
        (
            "a window ending before it starts",
            |t| t["windows"][0]["end"] = (-1.0).into(),
            &["`windows.0`"],
        ),
    ];
    for (what, edit, mentions) in cases {
        let mut edited = original.clone();
        edit(&mut edited);
        let file = dir.path().join("trajectory.json");
        std::fs::write(&file, serde_json::to_string(&edited).unwrap()).unwrap();
        let out_dir = dir.path().join("exported");
        let out = splatraj(&[
            "export",
            s(&file),
            "--format",
            "colmap",
            "--out",
            s(&out_dir),
        ]);
        assert_clean_failure(&out, mentions);
        assert!(!out_dir.exists(), "{what}: something was exported");
    }
}
