//! `report.html` of a run: written by `splatraj run`, rebuilt byte for byte by `splatraj
//! report RUN_DIR` from the folder's files and the scene, well-formed, self-contained and
//! holding what the folder holds; a failed rebuild leaves the old page whole.

mod common;

use std::path::{Path, PathBuf};

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr, stdout};

fn tiny_run_in(dir: &Path) -> PathBuf {
    let config = dir.join("tiny.toml");
    std::fs::write(&config, TINY_CONFIG).unwrap();
    let runs = format!("output.runs_dir=\"{}\"", dir.join("runs").display());
    let out = splatraj(&["run", s(&config), "--quiet", "--set", &runs]);
    assert!(out.status.success(), "{}", stderr(&out));
    PathBuf::from(stdout(&out).lines().last().unwrap().trim())
}

#[test]
fn the_report_is_rebuilt_from_the_run_folder_and_shows_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run_in(dir.path());
    let report = run.join("report.html");
    let written = std::fs::read_to_string(&report).unwrap();

    std::fs::remove_file(&report).unwrap();
    let out = splatraj(&["report", s(&run)]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).trim(), s(&report));
    let rebuilt = std::fs::read_to_string(&report).unwrap();
    // Same files, same scene (the demo room made again from its seed): the same page.
    assert!(
        rebuilt == written,
        "the rebuilt report differs from the run's"
    );

    let doc = roxmltree::Document::parse_with_options(
        &rebuilt,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("report.html is not well-formed: {e}"));
    let values = |attribute: &str| -> Vec<String> {
        doc.descendants()
            .filter_map(|n| n.attribute(attribute).map(String::from))
            .collect()
    };
    for src in values("src") {
        assert!(
            src.starts_with("data:"),
            "fetches {}",
            &src[..src.len().min(60)]
        );
    }
    for href in values("href") {
        assert!(href.starts_with('#'), "links to {href}");
    }
    let count = |tag: &str| {
        doc.descendants()
            .filter(|n| n.tag_name().name() == tag)
            .count()
    };
    // Along t, cost history, top view, side view.
    assert_eq!(count("svg"), 4);
    // The tiny run has 3 frames: t = 0 in window 0, t = 0.5 and 1 in window 1; the shot list
    // shows each shot's first keyframe again (the tiny run's 0.1 s windows cut: 2 shots).
    let images_in = |id: &str| {
        doc.descendants()
            .find(|n| n.attribute("id") == Some(id))
            .map_or(0, |section| {
                section
                    .descendants()
                    .filter(|n| n.tag_name().name() == "img")
                    .count()
            })
    };
    assert_eq!(images_in("keyframes"), 3);
    assert_eq!(images_in("shots"), 2);
    assert_eq!(count("img"), 5);

    // The video is the run's video.mp4, whole.
    let video = values("src")
        .into_iter()
        .find(|v| v.starts_with("data:video/mp4;base64,"))
        .expect("the video is inlined");
    let bytes = BASE64
        .decode(&video["data:video/mp4;base64,".len()..])
        .unwrap();
    assert_eq!(bytes, std::fs::read(run.join("video.mp4")).unwrap());

    // The per-window table holds metrics.json's numbers (as the page rounds them).
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap()).unwrap();
    let cells: Vec<&str> = doc.descendants().filter_map(|n| n.text()).collect();
    for w in metrics["windows"].as_array().unwrap() {
        let tce = format!("{:.4}", w["tce"].as_f64().unwrap());
        assert!(cells.contains(&tce.as_str()), "TCE {tce} not in the table");
        assert!(cells.contains(&w["name"].as_str().unwrap()));
    }
    // The config is shown as written into the folder.
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(
        cells
            .iter()
            .any(|c| c.contains(config.lines().next().unwrap()))
    );
}

#[test]
fn a_failed_rebuild_leaves_the_old_report_whole() {
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run_in(dir.path());
    let report = run.join("report.html");
    let before = std::fs::read(&report).unwrap();
    std::fs::write(run.join("metrics.json"), "{ not json").unwrap();
    assert_clean_failure(&splatraj(&["report", s(&run)]), &["metrics.json"]);
    assert_eq!(std::fs::read(&report).unwrap(), before);
    for entry in std::fs::read_dir(&run).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.ends_with(".partial"), "{name}");
    }
}

#[test]
fn a_scene_that_cannot_be_found_asks_for_scene() {
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run_in(dir.path());
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    let moved = config.replace(
        "[scene.demo]\ngaussians = 3000\nseed = 7\n",
        "path = \"gone.ply\"\n",
    );
    assert_ne!(moved, config, "the test edits the scene table: {config}");
    std::fs::write(run.join("config.toml"), moved).unwrap();
    assert_clean_failure(&splatraj(&["report", s(&run)]), &["gone.ply", "--scene"]);
    // Given the scene, the report is made.
    let scene = dir.path().join("demo.ply");
    let out = splatraj(&[
        "scene",
        "demo",
        "--out",
        s(&scene),
        "--gaussians",
        "3000",
        "--seed",
        "7",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = splatraj(&["report", s(&run), "--scene", s(&scene)]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_clean_failure(
        &splatraj(&["report", s(&dir.path().join("nowhere"))]),
        &["nowhere", "not a run folder"],
    );
}

#[test]
fn a_metrics_file_with_a_word_for_a_figure_or_a_window_too_many_is_refused() {
    // Both were rebuilt into a report with exit 0 in the adversarial trial.
    let dir = tempfile::tempdir().unwrap();
    let run = tiny_run_in(dir.path());
    let file = run.join("metrics.json");
    let original: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let report = std::fs::read(run.join("report.html")).unwrap();
    let mut word = original.clone();
    word["windows"][0]["tce"] = "x".into();
    let mut extra = original.clone();
    let first = extra["windows"][0].clone();
    extra["windows"].as_array_mut().unwrap().push(first);
    for (metrics, mentions) in [
        (word, ["`windows.0.tce`", "must be a number"]),
        (extra, ["`windows` lists 3 windows", "trajectory.json 2"]),
    ] {
        std::fs::write(&file, serde_json::to_string(&metrics).unwrap()).unwrap();
        assert_clean_failure(&splatraj(&["report", s(&run)]), &mentions);
        assert_eq!(std::fs::read(run.join("report.html")).unwrap(), report);
    }
}
