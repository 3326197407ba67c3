//! Stop requests (Ctrl-C, SIGTERM: `splatraj_scene::stop`) in the phases after the
//! optimisation and in a study: a request made at the start of the metrics, or after the last
//! frame (before the exports), ends the run with `Stopped` naming where it stopped, and leaves
//! the run folder whole (its config and checkpoint, for `--resume`); a study run stops within
//! itself and the study between runs, the cut-short run not measured.
//!
//! Requests are raised from the observer or before the call, never by a timed signal. They
//! are process-wide, so this file's tests run one at a time (and in their own process).

use std::path::Path;
use std::sync::Mutex;

use splatraj_experiment::config::ConfigFile;
use splatraj_experiment::optimise::observer::{Flow, Phase, Progress};
use splatraj_experiment::process::RunFolder;
use splatraj_experiment::study::context::measure_runs;
use splatraj_experiment::study::measure::MemoryReading;
use splatraj_experiment::study::plan::PlanOptions;
use splatraj_experiment::study::{PlannedStudy, measure_run};
use splatraj_experiment::{Config, Experiment, Extensions};
use splatraj_scene::stop::{self, Since, Stopped};

/// One test at a time: a request is seen by every loop of the process.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

const TINY: &str = r#"
name = "tiny"
seed = 3
[scene]
demo = { gaussians = 3000, seed = 7 }
[[queries]]
text = "red mug"
[[queries]]
text = "blue box"
[camera]
width = 32
height = 24
[optimiser]
iterations = 3
samples_per_window = 2
[output]
verdict = "warn"
frames = 3
width = 40
height = 30
trajectory_samples = 5
metric_samples = 2
ldj_samples = 11
[study]
seeds = 1
[study.evaluation]
samples = 2
ldj_samples = 11
"#;

/// The tiny config in `dir`, its runs going to `dir/runs`.
fn config_file(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("tiny.toml");
    let text = TINY.replace(
        "[output]\n",
        &format!("[output]\nruns_dir = \"{}\"\n", dir.join("runs").display()),
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Runs the tiny experiment, raising a stop request when `at` says so; returns the error
/// and the run folder.
fn run_stopped_at(at: impl Fn(&Progress) -> bool) -> (anyhow::Error, Vec<String>) {
    let dir = tempfile::tempdir().unwrap();
    let config = Config::load(&config_file(dir.path()), &[]).unwrap();
    let experiment = Experiment::prepare(&config).unwrap();
    experiment.check_trajectory_run(false).unwrap();
    let folder = RunFolder::create(&experiment).unwrap();
    let mut observer = |p: &Progress| {
        if at(p) {
            stop::request();
        }
        Flow::Continue
    };
    let error = experiment
        .run_trajectory_in(&folder, &mut observer)
        .expect_err("a stop request must end the outputs");
    (error, names(folder.dir()))
}

#[test]
fn a_stop_at_the_start_of_the_metrics_ends_the_run_keeping_its_checkpoint() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (error, left) = run_stopped_at(|p| matches!(p, Progress::Phase(Phase::Outputs { .. })));
    let stopped = error
        .downcast_ref::<Stopped>()
        .unwrap_or_else(|| panic!("not a stop: {error:#}"));
    assert!(
        stopped.what.contains("metrics of 0 of 2 windows"),
        "{stopped}"
    );
    assert!(stopped.what.contains("--resume"), "{stopped}");
    // No half-made outputs: what a resume needs, nothing else.
    assert_eq!(left, ["checkpoint.json", "config.toml"]);
}

#[test]
fn a_stop_after_the_last_frame_ends_the_run_before_the_exports() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // The last frame is not cut short (there is nothing left to cut): the exports are.
    let (error, left) =
        run_stopped_at(|p| matches!(p, Progress::Frame { done, frames } if done == frames));
    let stopped = error
        .downcast_ref::<Stopped>()
        .unwrap_or_else(|| panic!("not a stop: {error:#}"));
    assert!(stopped.what.contains("0 of 4 export formats"), "{stopped}");
    assert_eq!(left, ["checkpoint.json", "config.toml"]);
}

#[test]
fn a_study_run_stops_within_itself_and_the_study_between_runs() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let extensions = Extensions::default();
    let study = PlannedStudy::new(
        &ConfigFile::read(&config_file(dir.path())).unwrap(),
        &PlanOptions::default(),
        &extensions,
    )
    .unwrap();
    let plan = &study.plan;
    assert!(plan.runs.len() >= 2, "the default plan has several runs");

    // A request after `since`: the run stops at its first step and is not measured.
    let since = Since::now();
    stop::request();
    let error = measure_run(
        &study,
        &plan.runs[0],
        &extensions,
        MemoryReading::Shared,
        since,
    )
    .expect_err("a stopped run is not measured");
    let stopped = error.downcast_ref::<Stopped>().expect("a stop");
    assert!(stopped.what.contains("run 0 was cut short"), "{stopped}");

    // The study loop: a request during the first run ends it there, with nothing recorded.
    let since = Since::now();
    let mut measured = Vec::new();
    let (rows, failures) = measure_runs(
        plan,
        &plan.runs,
        |run| {
            measured.push(run.index);
            stop::request();
            Err("stopped".to_string())
        },
        |_, _, _| {},
        since,
    );
    assert_eq!(measured, [0], "the second run never starts");
    assert!(
        rows.is_empty() && failures.is_empty(),
        "a cut-short run is no failure"
    );
}
