//! `splatraj run` and `splatraj pose` end to end on a tiny demo scene: the run folder holds
//! whole files that read back; bad configs fail cleanly before any folder is made.

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG as TINY, assert_clean_failure, s, splatraj, stderr, stdout};
use splatraj::traj::trajectory::TrajectoryRecord;

fn setup(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, text).unwrap();
    (dir, config)
}

fn runs_set(dir: &Path) -> String {
    format!("output.runs_dir=\"{}\"", dir.join("runs").display())
}

fn run_folder(output: &std::process::Output) -> PathBuf {
    assert!(output.status.success(), "{}", stderr(output));
    PathBuf::from(stdout(output).lines().last().unwrap().trim())
}

fn no_partial_files(dir: &Path) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.contains("partial"), "left-over temporary file {name}");
    }
}

#[test]
fn run_writes_a_complete_run_folder() {
    let (dir, config) = setup(TINY);
    let out = splatraj(&["run", s(&config), "--quiet", "--set", &runs_set(dir.path())]);
    let run = run_folder(&out);
    assert!(run.starts_with(dir.path().join("runs").join("tiny")));
    no_partial_files(&run);

    let text = std::fs::read_to_string(run.join("trajectory.json")).unwrap();
    let record: TrajectoryRecord = serde_json::from_str(&text).unwrap();
    // The tiny config's 0.05 s windows cut (`output.transitions` auto): an RBF per shot.
    assert_eq!(record.model.name(), "rbf with cuts");
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["cuts"], serde_json::json!([0.5]));
    assert_eq!(json["shots"].as_array().unwrap().len(), 2);
    let poses = json["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 5);
    assert_eq!(poses[0]["window"], 0);
    assert_eq!(poses[4]["window"], 1);
    assert_eq!(json["windows"].as_array().unwrap().len(), 2);

    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    let windows = metrics["windows"].as_array().unwrap();
    assert_eq!(windows.len(), 2);
    assert_eq!(windows[1]["name"], "blue box");
    for key in ["tce", "tre", "iou", "visible"] {
        assert!(!windows[0][key].is_null(), "metrics lack {key}");
    }
    assert!(metrics["ldj"].is_object());
    assert_eq!(metrics["run"]["iterations_run"], 3);
    // What each stage asked of the device (a process of its own: nothing else counts here).
    // The scene goes up once, for the optimisation (its autodiff copy); the metrics and frames
    // render the plain copy the start search uploaded, and the objects alone uploaded while
    // preparing. A step reads once, the last step's results once more.
    let counts = &metrics["run"]["counts"];
    // The preparation searched the start views (renders) on the plain copy and each object
    // alone, each uploaded once.
    assert!(
        counts["preparation"]["renders"].as_u64() > Some(0),
        "{counts}"
    );
    assert_eq!(counts["preparation"]["scene_uploads"], 1 + 2, "{counts}");
    assert_eq!(counts["optimisation"]["scene_uploads"], 1, "{counts}");
    assert_eq!(counts["metrics"]["scene_uploads"], 0, "{counts}");
    assert_eq!(counts["frames"]["scene_uploads"], 0, "{counts}");
    assert_eq!(counts["optimisation"]["reads"], 3 + 1, "{counts}");
    // Two metric samples a window fit one pass: each window's mask and its object alone,
    // read once together (the passes take their poses from the host: no read before them).
    assert_eq!(counts["metrics"]["renders"], 2 * 2, "{counts}");
    assert_eq!(counts["metrics"]["reads"], 2, "{counts}");
    // A frame: its framing figures, then its pixels.
    assert_eq!(counts["frames"]["renders"], 3, "{counts}");
    assert_eq!(counts["frames"]["reads"], 3 * 2, "{counts}");

    let history = std::fs::read_to_string(run.join("history.csv")).unwrap();
    let lines: Vec<&str> = history.lines().collect();
    assert_eq!(lines.len(), 4, "header and three steps");
    assert!(lines[0].contains("q1_tce") && lines[0].contains("q0_prior"));

    for i in 0..3 {
        let png = image::open(run.join(format!("frames/frame_{i:04}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), (40, 30));
    }
    let resolved = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(resolved.contains("iterations = 3"), "{resolved}");

    // The run's trajectory starts another run, re-fitted to another model.
    let again = splatraj(&[
        "run",
        s(&config),
        "--quiet",
        "--set",
        &runs_set(dir.path()),
        "--set",
        &format!(
            "start.trajectory=\"{}\"",
            run.join("trajectory.json").display()
        ),
        "--set",
        "trajectory.kind=polynomial",
    ]);
    let second = run_folder(&again);
    assert_ne!(second, run, "a fresh folder per run");
    let record: TrajectoryRecord =
        serde_json::from_str(&std::fs::read_to_string(second.join("trajectory.json")).unwrap())
            .unwrap();
    // The start's cut is kept (`output.transitions` auto), the shots refitted polynomials.
    assert_eq!(record.model.name(), "polynomial with cuts");
}

#[test]
fn bad_configs_fail_before_any_folder_exists() {
    for (extra, mention) in [
        ("\n[start]\nrestart = 2\n", "restart"),
        ("\n[camera]\nfov_x = 0.0\n", "camera.fov_x"),
    ] {
        let (dir, config) =
            setup(&format!("{TINY}{extra}").replace("[camera]\nwidth = 32\nheight = 24\n", ""));
        let out = splatraj(&["run", s(&config), "--quiet", "--set", &runs_set(dir.path())]);
        assert_clean_failure(&out, &[mention]);
        assert!(
            !dir.path().join("runs").exists(),
            "no run folder for a bad config"
        );
    }
    let (dir, config) = setup(&TINY.replace("text = \"blue box\"", "text = \"blue bx\""));
    let out = splatraj(&["run", s(&config), "--quiet", "--set", &runs_set(dir.path())]);
    assert_clean_failure(&out, &["blue box"]);
    assert!(!dir.path().join("runs").exists());
    let (dir, config) = setup(TINY);
    let missing = dir.path().join("nope.npy");
    let out = splatraj(&[
        "run",
        s(&config),
        "--set",
        &format!("queries.0.mask=\"{}\"", missing.display()),
        "--set",
        &runs_set(dir.path()),
    ]);
    assert_clean_failure(&out, &["nope.npy"]);
}

#[test]
fn pose_runs_ablations_restarts_and_sgld() {
    let (dir, config) = setup(TINY);
    let out = splatraj(&[
        "pose",
        s(&config),
        "--quiet",
        "--set",
        &runs_set(dir.path()),
        "--ablation",
        "prior-tce",
        "--restarts",
        "2",
        "--sgld",
        "2",
    ]);
    let run = run_folder(&out);
    no_partial_files(&run);
    let pose: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("pose.json")).unwrap()).unwrap();
    assert_eq!(pose["ablation"], "prior-tce");
    // The config names no costs: the first-try set, less TRE (the ablation's).
    assert_eq!(
        pose["costs"],
        serde_json::json!([
            "tce",
            "upright",
            "prior",
            "clearance",
            "motion",
            "visibility"
        ])
    );
    assert_eq!(pose["starts"].as_array().unwrap().len(), 2);
    let best = pose["total"].as_f64().unwrap();
    for start in pose["starts"].as_array().unwrap() {
        assert!(start["total"].as_f64().unwrap() >= best);
    }
    let samples = std::fs::read_to_string(run.join("sgld_samples.csv")).unwrap();
    assert_eq!(
        samples.lines().count(),
        1 + 2 * 3,
        "header, 2 chains × 3 kept steps"
    );
    assert!(run.join("frame.png").exists());
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["sgld"]["chains"], 2);
}

/// `--check` reads every input and grounds every query, then stops: here with the `region`
/// source and with a per-Gaussian mask file, both naming the demo's red mug.
#[test]
fn region_sources_and_mask_files_ground_queries() {
    let queries = "[[queries]]\ntext = \"red mug\"\n[[queries]]\ntext = \"blue box\"\n";
    assert!(TINY.contains(queries));
    let region = TINY.replace(
        queries,
        "[targets]\nsource = \"region\"\nregions = { mug = { sphere = [0.307, -0.22, 0.797, 0.1] } }\n[[queries]]\ntext = \"mug\"\n",
    );
    let (dir, config) = setup(&region);
    let out = splatraj(&["run", s(&config), "--check", "--set", &runs_set(dir.path())]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("query 0: \"mug\""),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("runs").exists(), "--check writes nothing");

    // The red mug's Gaussians as a 0/1 .npy, from the same demo scene.
    let scene = splatraj::scene::demo::demo_scene(&splatraj::scene::demo::DemoConfig {
        seed: 7,
        gaussians: 3000,
    })
    .unwrap();
    let labels = scene.extras.labels.as_ref().unwrap();
    let mug = splatraj::scene::demo::demo_layout()
        .into_iter()
        .find(|o| o.name == "red mug")
        .unwrap();
    let mask: Vec<f32> = labels
        .ids
        .iter()
        .map(|&id| f32::from(u8::from(id == mug.id)))
        .collect();
    let count = mask.iter().filter(|&&m| m > 0.0).count();
    let path = dir.path().join("mug.npy");
    {
        use npyz::WriterBuilder;
        let mut bytes = Vec::new();
        let mut writer = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[mask.len() as u64])
            .writer(&mut bytes)
            .begin_nd()
            .unwrap();
        writer.extend(mask.iter().copied()).unwrap();
        writer.finish().unwrap();
        std::fs::write(&path, bytes).unwrap();
    }
    let out = splatraj(&[
        "run",
        s(&config),
        "--check",
        "--set",
        "queries.0.mask=\"mug.npy\"",
        "--set",
        &runs_set(dir.path()),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!("→ {count} Gaussians")),
        "the mask's {count} Gaussians: {}",
        stderr(&out)
    );
}

/// A planted failure: the camera held at the mug's centre (start there, steps too small to
/// move; the default normalised RBF holds a pose exactly), inside the object. The run writes
/// its whole folder, warns naming the query and the fix, records the
/// verdict in metrics.json and report.html, and exits with status 3; `output.verdict =
/// "warn"` keeps the warnings and exits 0.
#[test]
fn a_failed_verdict_warns_names_the_query_and_exits_3() {
    let text = TINY.replace("verdict = \"warn\"\n", "");
    let (dir, config) = setup(&text);
    let prepared = splatraj::experiment::Experiment::prepare(
        &splatraj::experiment::Config::load(&config, &[]).unwrap(),
    )
    .unwrap();
    let [x, y, z] = prepared.windows[0].context.object_centre;
    let held = [
        "--set".to_string(),
        format!("start.pose=[0.0, 0.0, 0.0, {x}, {y}, {z}]"),
        "--set".to_string(),
        "optimiser.learning_rate=1e-12".to_string(),
    ];
    let mut args = vec!["run", s(&config), "--quiet", "--set"];
    let runs = runs_set(dir.path());
    args.push(&runs);
    args.extend(held.iter().map(String::as_str));
    let out = splatraj(&args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        !err.contains("panicked") && !err.contains("error:"),
        "{err}"
    );
    assert!(
        err.contains("warning: window 0 \"red mug\": the camera is inside the object's box"),
        "{err}"
    );
    assert!(err.contains("likely fix"), "{err}");
    assert!(err.contains("exit status 3"), "{err}");
    let run = PathBuf::from(stdout(&out).lines().last().unwrap().trim());
    no_partial_files(&run);
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    let verdict = &metrics["windows"][0]["verdict"];
    assert_eq!(verdict["pass"], false);
    let inside = verdict["checks"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["check"] == "inside_object")
        .unwrap();
    assert_eq!(
        (&inside["pass"], &inside["value"]),
        (&false.into(), &1.0.into())
    );
    // The blue box's window looks out of the mug and never sees the box: no framing error
    // (not the 0 an empty mask's TCE would give).
    assert!(metrics["windows"][1]["framing"]["tce_in_view"].is_null());
    let report = std::fs::read_to_string(run.join("report.html")).unwrap();
    assert!(report.contains("id=\"verdict\""));
    assert!(
        report.contains("window 0 &quot;red mug&quot;: the camera is inside the object&#39;s box")
    );

    args.extend(["--set", "output.verdict=\"warn\""]);
    let warned = splatraj(&args);
    assert!(warned.status.success(), "{}", stderr(&warned));
    assert!(stderr(&warned).contains("warning: window 0 \"red mug\""));
}

#[test]
fn a_frame_not_showing_its_object_has_an_empty_tce_cell_not_zero() {
    // Two steps of the demo config leave the green ball out of some frames (its window's
    // "in view" is below 100 %): those frames have no TCE, the others a number.
    let dir = tempfile::tempdir().unwrap();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/demo.toml");
    let out = splatraj(&[
        "run",
        s(&config),
        "--quiet",
        "--set",
        "optimiser.iterations=2",
        "--set",
        "output.frames=30",
        "--set",
        &runs_set(dir.path()),
    ]);
    // 3: a window failed its verdict, expected after two steps.
    assert!(matches!(out.status.code(), Some(0 | 3)), "{}", stderr(&out));
    let run = PathBuf::from(stdout(&out).lines().last().unwrap().trim());
    let csv = std::fs::read_to_string(run.join("frame_metrics.csv")).unwrap();
    let mut header = csv.lines().next().unwrap().split(',');
    assert_eq!(header.nth(3), Some("tce"));
    let (mut hidden, mut shown) = (0, 0);
    for line in csv.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let coverage: f64 = cells[5].parse().unwrap();
        if coverage == 0.0 {
            assert_eq!(cells[3], "", "no TCE without the object: {line}");
            hidden += 1;
        } else {
            assert!(cells[3].parse::<f64>().unwrap().is_finite(), "{line}");
            shown += 1;
        }
    }
    assert!(hidden > 0 && shown > 0, "{hidden} hidden, {shown} shown");
}
