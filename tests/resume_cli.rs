//! Crash-safe runs: a run killed with SIGKILL mid-optimisation leaves a parseable best
//! trajectory (`checkpoint.json`) that `splatraj run --resume RUN_DIR` finishes; Ctrl-C exits
//! 130 with every file written for the best trajectory so far; a time limit is recorded as
//! such.
#![cfg(unix)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{TINY_CONFIG, s, splatraj, stderr};
use splatraj::traj::trajectory::TrajectoryRecord;

/// Steps of the runs below: a few seconds in a debug build, long enough to be stopped.
const STEPS: usize = 600;

fn setup() -> (tempfile::TempDir, PathBuf) {
    setup_with(TINY_CONFIG)
}

/// [`setup`] of another config text (the tiny config edited).
fn setup_with(config_text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("tiny.toml");
    let runs = dir.path().join("runs");
    let text = config_text
        .replace(
            "iterations = 3\nsamples",
            &format!("iterations = {STEPS}\nsamples"),
        )
        .replace(
            "[output]\n",
            &format!("[output]\nruns_dir = \"{}\"\n", runs.display()),
        );
    assert!(text.contains(&format!("iterations = {STEPS}")) && text.contains("runs_dir"));
    std::fs::write(&config, text).unwrap();
    (dir, config)
}

fn spawn_run(config: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args(["run", s(config), "--quiet"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary runs")
}

/// The run folder of the config's runs once its checkpoint exists.
fn wait_for_checkpoint(runs: &Path, child: &mut Child) -> PathBuf {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before it was stopped");
        }
        let found = std::fs::read_dir(runs.join("tiny"))
            .ok()
            .and_then(|entries| {
                entries
                    .flatten()
                    .map(|e| e.path())
                    .find(|p| p.join("checkpoint.json").exists())
            });
        if let Some(dir) = found {
            return dir;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no checkpoint"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn no_partial_files(dir: &Path) {
    for folder in [dir.to_path_buf(), dir.join("frames")] {
        for entry in std::fs::read_dir(folder).into_iter().flatten().flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            assert!(
                !name.ends_with(".partial"),
                "left-over temporary file {name}"
            );
        }
    }
}

#[test]
fn a_killed_run_leaves_its_best_trajectory_and_resume_finishes_it() {
    let (dir, config) = setup();
    let mut child = spawn_run(&config);
    let run = wait_for_checkpoint(&dir.path().join("runs"), &mut child);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();

    // The checkpoint reads back as a trajectory, and says how far the run got.
    let checkpoint = std::fs::read_to_string(run.join("checkpoint.json")).unwrap();
    let record: TrajectoryRecord = serde_json::from_str(&checkpoint).unwrap();
    // The tiny config's windows cut (`output.transitions` auto): an RBF cut into shots.
    assert!(
        record.model.name().starts_with("rbf"),
        "{}",
        record.model.name()
    );
    assert!(record.weights.iter().flatten().all(|v| v.is_finite()));
    let state: serde_json::Value = serde_json::from_str(&checkpoint).unwrap();
    let done = state["steps_done"].as_u64().unwrap() as usize;
    assert!((1..STEPS).contains(&done), "steps done {done}");
    assert!(!run.join("metrics.json").exists());

    let out = splatraj(&["run", "--resume", s(&run), "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let metrics = json(&run.join("metrics.json"));
    assert_eq!(metrics["run"]["stop"], "finished");
    // The resumed run ran exactly the steps the checkpoint had left.
    assert_eq!(
        metrics["run"]["iterations_run"].as_u64().unwrap() as usize,
        STEPS - done
    );
    let finished: TrajectoryRecord =
        serde_json::from_str(&std::fs::read_to_string(run.join("trajectory.json")).unwrap())
            .unwrap();
    assert_eq!(finished.weights.len(), record.weights.len());
    assert!(
        !run.join("checkpoint.json").exists(),
        "a finished run keeps no checkpoint"
    );
    no_partial_files(&run);

    // A finished run is not resumed again.
    let again = splatraj(&["run", "--resume", s(&run), "--quiet"]);
    assert!(!again.status.success());
    assert!(
        stderr(&again).contains("already finished"),
        "{}",
        stderr(&again)
    );
}

#[test]
fn ctrl_c_writes_the_best_so_far_and_exits_130() {
    let (dir, config) = setup();
    let mut child = spawn_run(&config);
    let run = wait_for_checkpoint(&dir.path().join("runs"), &mut child);
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-INT", &pid])
            .status()
            .unwrap()
            .success()
    );
    let output = child.wait_with_output().unwrap();
    assert_eq!(output.status.code(), Some(130), "{}", stderr(&output));
    assert!(stderr(&output).contains("--resume"), "{}", stderr(&output));
    let metrics = json(&run.join("metrics.json"));
    assert_eq!(metrics["run"]["stop"], "interrupted");
    assert!(run.join("trajectory.json").exists());
    assert!(run.join("checkpoint.json").exists(), "kept for --resume");
    no_partial_files(&run);
}

#[test]
fn a_time_limit_is_recorded_as_such() {
    let (dir, config) = setup();
    let out = splatraj(&[
        "run",
        s(&config),
        "--quiet",
        "--set",
        "optimiser.time_limit_s=0.05",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let runs = dir.path().join("runs").join("tiny");
    let run = std::fs::read_dir(runs)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let metrics = json(&run.join("metrics.json"));
    assert_eq!(metrics["run"]["stop"], "time_limit");
    assert!((metrics["run"]["iterations_run"].as_u64().unwrap() as usize) < STEPS);
}

#[test]
fn a_resumed_zooming_run_goes_on_from_its_checkpointed_zoom() {
    let zooming = TINY_CONFIG.replace("[camera]\n", "[camera]\nlens = \"zoom\"\n");
    assert!(zooming.contains("lens = \"zoom\""));
    let (dir, config) = setup_with(&zooming);
    let mut child = spawn_run(&config);
    let run = wait_for_checkpoint(&dir.path().join("runs"), &mut child);
    child.kill().unwrap();
    child.wait().unwrap();

    // The checkpoint holds the best trajectory's zoom and the restart's own, one weight per
    // row of the trajectory (a checkpoint without them restarted the zoom at s = 1).
    let checkpoint = std::fs::read_to_string(run.join("checkpoint.json")).unwrap();
    let record: TrajectoryRecord = serde_json::from_str(&checkpoint).unwrap();
    let lens = record.lens.as_ref().expect("the checkpoint keeps the zoom");
    assert_eq!(lens.weights.len(), record.weights.len());
    assert!(lens.weights.iter().all(|w| w.is_finite()));
    let state: serde_json::Value = serde_json::from_str(&checkpoint).unwrap();
    assert_eq!(
        state["restart_best_lens"]["weights"]
            .as_array()
            .map(Vec::len),
        Some(record.weights.len()),
        "{state}"
    );

    let out = splatraj(&["run", "--resume", s(&run), "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let finished: TrajectoryRecord =
        serde_json::from_str(&std::fs::read_to_string(run.join("trajectory.json")).unwrap())
            .unwrap();
    let finished_lens = finished.lens.expect("the resumed run zooms");
    assert_eq!(finished_lens.range, lens.range);
}
