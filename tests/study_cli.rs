//! `splatraj study` end to end: each run in its own process (rows with their own peak memory),
//! the four files, shards that merge into the rows of an unsharded study (times aside), and
//! clean failures.

mod common;

use std::path::{Path, PathBuf};

use common::{TINY_CONFIG, assert_clean_failure, s, splatraj, stderr, stdout};

fn setup() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    std::fs::write(&config, TINY_CONFIG).unwrap();
    (dir, config)
}

/// A two-knob study of the tiny config into `out`, optionally one shard of it.
fn study(config: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "study",
        s(config),
        "--vary",
        "optimiser.iterations=2,4",
        "--vary",
        "camera={width=16,height=12},{width=48,height=36}",
        "--set",
        "study.evaluation.samples=2",
        "--set",
        "study.evaluation.ldj_samples=11",
        "--quiet",
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    splatraj(&args)
}

fn rows(dir: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("study.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let mut r = r.clone();
            for timed in ["optimisation_s", "run_s", "peak_mb", "stages"] {
                r.as_object_mut().unwrap().remove(timed);
            }
            r
        })
        .collect()
}

#[test]
fn shards_merge_into_the_unsharded_study() {
    let (dir, config) = setup();
    let whole = dir.path().join("whole");
    let out = study(&config, &whole, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).trim(), s(&whole));
    for file in ["study.csv", "study.json", "frontier.svg", "summary.md"] {
        assert!(whole.join(file).is_file(), "{file}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("study.json")).unwrap()).unwrap();
    // Baseline, two iteration counts, two resolutions; one seed each, each in its own process.
    assert_eq!(json["plan"]["variants"].as_array().unwrap().len(), 5);
    let all = json["rows"].as_array().unwrap();
    assert_eq!(all.len(), 5);
    assert!(
        all.iter()
            .all(|r| r["peak_mb"].as_f64().is_some_and(|m| m > 0.0))
    );

    let shards: Vec<PathBuf> = (1..=2)
        .map(|k| dir.path().join(format!("shard{k}")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        let out = study(&config, shard, &["--shard", &format!("{}/2", k + 1)]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert_eq!(rows(&shards[0]).len(), 3);
    assert_eq!(rows(&shards[1]).len(), 2);
    let merged = dir.path().join("merged");
    let out = splatraj(&[
        "study",
        "merge",
        s(&shards[1]),
        s(&shards[0]),
        "--out",
        s(&merged),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(rows(&merged), rows(&whole));

    // One shard alone is not the study.
    let out = splatraj(&["study", "merge", s(&shards[0]), "--out", s(&merged)]);
    assert_clean_failure(&out, &["2/2", "missing"]);
}

#[test]
fn bad_studies_fail_cleanly_before_running() {
    let (dir, config) = setup();
    let out_dir = dir.path().join("out");
    let out = study(
        &config,
        &out_dir,
        &["--vary", "optimiser.samples_per_window=0"],
    );
    assert_clean_failure(&out, &["samples_per_window"]);
    assert!(!out_dir.exists(), "no folder for a study that cannot run");
    let out = study(&config, &out_dir, &["--shard", "3/2"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("--shard"), "{}", stderr(&out));
    let out = splatraj(&["study", "merge", s(dir.path()), "--out", s(&out_dir)]);
    assert_clean_failure(&out, &["study.json"]);
}
