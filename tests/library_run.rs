//! The library runs the whole experiment: the process API (`splatraj::experiment::process`,
//! as `examples/library_run.rs` calls it) writes the same run folder as `splatraj run`, file
//! for file, with the same trajectory, metrics, frames and exports (times and paths aside).

mod common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use common::{TINY_CONFIG, s, splatraj, stderr, stdout};
use splatraj::experiment::optimise::observer;
use splatraj::experiment::process::RunFolder;
use splatraj::experiment::{Config, Experiment};

/// Every file under `dir`, relative to it.
fn files(dir: &Path) -> BTreeSet<PathBuf> {
    let mut out = BTreeSet::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.insert(path.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out
}

/// `metrics.json` without the wall times, which differ between any two runs, and the device
/// counters, which count the whole process (other tests of this binary run beside it).
fn metrics_without_times(dir: &Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    for key in [
        "optimisation_s",
        "per_iteration_ms",
        "metrics_s",
        "frames_s",
        "total_s",
        "peak_memory_mb",
        "counts",
    ] {
        v["run"].as_object_mut().unwrap().remove(key);
    }
    v
}

#[test]
fn the_library_writes_the_run_folder_the_cli_writes() {
    let dir = tempfile::tempdir().unwrap();
    let config_path = dir.path().join("tiny.toml");
    std::fs::write(&config_path, TINY_CONFIG).unwrap();
    let runs = |name: &str| format!("output.runs_dir=\"{}\"", dir.path().join(name).display());

    let out = splatraj(&["run", s(&config_path), "--quiet", "--set", &runs("cli")]);
    assert!(out.status.success(), "{}", stderr(&out));
    let cli = PathBuf::from(stdout(&out).lines().last().unwrap().trim());

    let config = Config::load(&config_path, &[runs("library")]).unwrap();
    let experiment = Experiment::prepare(&config).unwrap();
    experiment.check_trajectory_run(false).unwrap();
    let folder = RunFolder::create(&experiment).unwrap();
    let outcome = experiment
        .run_trajectory_in(&folder, &mut observer::quiet())
        .unwrap();
    let library = outcome.dir;

    assert_eq!(files(&cli), files(&library), "the same files");
    assert!(files(&cli).len() > 10, "{:?}", files(&cli));
    // history.csv holds each step's wall time (`elapsed_s`): compare the other columns.
    let history = |d: &Path| -> Vec<Vec<String>> {
        let text = std::fs::read_to_string(d.join("history.csv")).unwrap();
        let mut rows = text
            .lines()
            .map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>());
        let header = rows.next().unwrap();
        let elapsed = header.iter().position(|h| h == "elapsed_s").unwrap();
        std::iter::once(header.clone())
            .chain(rows)
            .map(|mut r| {
                r.remove(elapsed);
                r
            })
            .collect()
    };
    assert_eq!(history(&cli), history(&library));
    for same in ["trajectory.json", "frames/frame_0001.png", "video.mp4"] {
        assert_eq!(
            std::fs::read(cli.join(same)).unwrap(),
            std::fs::read(library.join(same)).unwrap(),
            "{same} differs"
        );
    }
    assert_eq!(metrics_without_times(&cli), metrics_without_times(&library));
    // The configs as run differ only in the runs folder each was told.
    let config_text = |d: &Path| {
        std::fs::read_to_string(d.join("config.toml"))
            .unwrap()
            .replace(&dir.path().join("cli").display().to_string(), "RUNS")
            .replace(&dir.path().join("library").display().to_string(), "RUNS")
    };
    assert_eq!(config_text(&cli), config_text(&library));
}
