//! `splatraj study` end to end: each run in its own process (rows with their own peak memory),
//! the four files, shards that merge into the rows of an unsharded study (times aside), and
//! clean failures; `--dry-run` refuses, before any run, what the runs would fail on.

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

/// `splatraj study CONFIG --dry-run` for the tiny config edited by `edit` (given the scratch
/// folder), with `extra` arguments; runs go to `<scratch>/runs`.
fn dry_run(
    edit: impl Fn(&Path, &str) -> String,
    extra: &[&str],
) -> (tempfile::TempDir, std::process::Output) {
    let dir = tempfile::tempdir().unwrap();
    let runs = dir.path().join("runs");
    let text = TINY_CONFIG.replace(
        "[output]\n",
        &format!("[output]\nruns_dir = {:?}\n", s(&runs)),
    );
    let config = dir.path().join("study.toml");
    std::fs::write(&config, edit(dir.path(), &text)).unwrap();
    let mut args = vec![
        "study",
        s(&config),
        "--dry-run",
        "--vary",
        "optimiser.iterations=1,2",
    ];
    args.extend_from_slice(extra);
    let out = splatraj(&args);
    (dir, out)
}

/// The config as it is.
fn unchanged(_: &Path, text: &str) -> String {
    text.to_string()
}

#[test]
fn dry_run_of_a_sound_study_passes_and_leaves_nothing_behind() {
    let (dir, out) = dry_run(unchanged, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    // The baseline and the two iteration counts, each prepared.
    assert!(
        stderr(&out).contains("check passed: 3 variant(s) prepared"),
        "{}",
        stderr(&out)
    );
    assert!(
        !dir.path().join("runs").exists(),
        "a dry run makes no folder"
    );
}

#[test]
fn dry_run_refuses_an_evaluation_width_beyond_the_memory_limit() {
    // 10⁶ × 30 pixels (the output height) at 32 poses per window, rendered twice, is tens of
    // gigabytes: more than the 8 GB given.
    let (_dir, out) = dry_run(
        unchanged,
        &[
            "--set",
            "study.evaluation.width=1000000",
            "--set",
            "max_memory_gb=8",
        ],
    );
    assert_clean_failure(
        &out,
        &[
            "`study.evaluation.width`",
            "1000000 × 30",
            "more than the limit of 8.0 GB",
        ],
    );
}

#[test]
fn dry_run_refuses_evaluation_samples_beyond_any_machine() {
    // 10¹⁰ poses per window held at once: petabytes.
    let (_dir, out) = dry_run(
        unchanged,
        &["--set", "study.evaluation.samples=10000000000"],
    );
    assert_clean_failure(
        &out,
        &[
            "`study.evaluation.samples` = 10000000000",
            "PB of memory",
            "more than the limit",
        ],
    );
}

#[test]
fn dry_run_refuses_an_empty_query_text() {
    let (_dir, out) = dry_run(|_, t| t.replace("\"red mug\"", "\"\""), &[]);
    assert_clean_failure(&out, &["queries.0.text"]);
}

#[test]
fn dry_run_refuses_a_query_no_label_matches() {
    let (_dir, out) = dry_run(|_, t| t.replace("\"red mug\"", "\"unicorn\""), &[]);
    assert_clean_failure(&out, &["`queries.0.text`", "unicorn"]);
}

#[test]
fn dry_run_refuses_a_missing_scene_file() {
    let (_dir, out) = dry_run(
        |d, t| {
            t.replace(
                "demo = { gaussians = 3000, seed = 7 }",
                &format!("path = {:?}", s(&d.join("missing.ply"))),
            )
        },
        &[],
    );
    assert_clean_failure(&out, &["missing.ply"]);
}

#[test]
fn dry_run_refuses_a_runs_dir_that_is_a_file() {
    let (dir, out) = dry_run(
        |d, t| {
            std::fs::write(d.join("afile"), "unrelated\n").unwrap();
            t.replace(s(&d.join("runs")), s(&d.join("afile")))
        },
        &[],
    );
    assert_clean_failure(&out, &["output.runs_dir", "afile", "not a folder"]);
    assert_eq!(
        std::fs::read_to_string(dir.path().join("afile")).unwrap(),
        "unrelated\n",
        "the file is left as it was"
    );
}

#[test]
fn dry_run_checks_every_variant_not_only_the_base() {
    // The base config grounds both queries; one variant asks for a label the scene lacks.
    let (_dir, out) = dry_run(unchanged, &["--vary", "queries.1.text=\"unicorn\""]);
    assert_clean_failure(&out, &["study variant `text=unicorn`", "unicorn"]);
}
