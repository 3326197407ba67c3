//! `[output] transitions` from a config: `"cut"` makes each window its own shot (the run's
//! model cut, the start holding each view up to its cut, the frames continuous within a shot
//! and switching only at the cuts, no rate taken across a cut), `trajectory.json` lists the
//! shots and reads back (render-path's reader) with the same cuts, every export carries them
//! through our own readers, `"pan"` keeps one shot, and a bad value names the key.

use std::path::Path;

use glam::DVec3;
use splatraj_camera_paths::Format;
use splatraj_experiment::outputs::camera_paths::{RunTrajectory, export_files};
use splatraj_experiment::outputs::run_files::RunOutputs;
use splatraj_experiment::{Config, Experiment, Extensions, optimise::observer};
use splatraj_traj::trajectory::TrajectoryModel;

const ROOM: &str = r#"
name = "transitions"
seed = 3
[scene]
demo = { gaussians = 20000, seed = 7 }
[[queries]]
text = "red mug"
[[queries]]
text = "green ball"
[[queries]]
text = "plant"
[camera]
width = 32
height = 24
[costs.tce]
[costs.tre]
[costs.prior]
[costs.motion]
max_angular_speed = 36.0
[optimiser]
iterations = 2
samples_per_window = 2
[output]
width = 40
height = 30
seconds = 3.0
fps = 10.0
metric_samples = 4
ldj_samples = 301
"#;

fn config(transitions: &str) -> anyhow::Result<Config> {
    let text = ROOM.replace(
        "[output]\n",
        &format!("[output]\ntransitions = {transitions}\n"),
    );
    Config::from_toml(&text, Path::new("."), &Extensions::default())
}

fn centre(p: &[f64; 6]) -> DVec3 {
    DVec3::new(p[3], p[4], p[5])
}

#[test]
fn cut_makes_shots_that_jump_only_at_the_cuts_and_every_file_carries_them() {
    let experiment = Experiment::prepare(&config("\"cut\"").unwrap()).unwrap();
    let model = experiment.run_model().unwrap();
    let TrajectoryModel::Cuts(cut) = &model else {
        panic!("expected a cut model, got {model:?}");
    };
    assert_eq!(cut.spans().cuts, vec![1, 2]);
    let run = experiment.run_trajectory(&mut observer::quiet()).unwrap();
    let outputs = RunOutputs::of_run(&experiment, &run).unwrap();
    let trajectory = outputs.trajectory();
    assert_eq!(trajectory.model(), &model);

    // 30 frames at 10 fps: shots of frames 0–9, 10–19, 20–29.
    let frames = outputs.frames().unwrap();
    assert_eq!(frames.cuts, vec![10, 20]);
    let steps: Vec<f64> = frames
        .poses
        .windows(2)
        .map(|w| centre(&w[0]).distance(centre(&w[1])))
        .collect();
    let within = (0..steps.len())
        .filter(|&k| !frames.cuts.contains(&(k + 1)))
        .map(|k| steps[k])
        .fold(0.0, f64::max);
    let across = frames
        .cuts
        .iter()
        .map(|&c| steps[c - 1])
        .fold(f64::INFINITY, f64::min);
    assert!(
        across > 10.0 * within,
        "a cut jumps ({across}), a shot moves on gently ({within})"
    );

    // No rate across a cut: each window's peak speed is its own shot's.
    let evaluation = experiment.evaluate(trajectory).unwrap();
    let seconds = 3.0;
    for w in &evaluation.windows {
        let motion = &w.path.as_ref().unwrap().motion;
        assert!(
            motion.peak_speed < 0.5 * across * 30.0 / seconds,
            "window {}: peak speed {} counts a cut",
            w.window,
            motion.peak_speed
        );
    }

    // trajectory.json lists the shots and reads back with the same cuts.
    let dir = tempfile::tempdir().unwrap();
    let file = experiment.trajectory_file(trajectory).unwrap();
    assert_eq!(file.shots.len(), 3);
    assert_eq!(file.cuts, vec![1.0 / 3.0, 2.0 / 3.0]);
    assert!(file.poses.iter().all(|p| p.shot == p.window));
    assert_eq!(file.shots[1].queries, vec!["green ball".to_string()]);
    assert!(file.shots[1].cut_reason.as_deref().unwrap().contains("cut"));
    let path = dir.path().join("trajectory.json");
    std::fs::write(&path, serde_json::to_string(&file).unwrap()).unwrap();
    let back = RunTrajectory::read(&path).unwrap();
    let request = splatraj_experiment::outputs::camera_paths::FrameRequest {
        fps: Some(20.0),
        seconds: Some(3.0),
        ..Default::default()
    };
    assert_eq!(back.frames(&request).unwrap().cuts, vec![20, 40]);

    // Every export reads back with the cuts.
    let centres: Vec<[f64; 3]> = experiment
        .windows
        .iter()
        .map(|w| w.context.object_centre)
        .collect();
    for format in Format::ALL {
        let files = export_files(&frames, &centres, format).unwrap();
        for (name, text) in &files {
            std::fs::write(dir.path().join(name), text).unwrap();
        }
        let main = dir
            .path()
            .join(format.file_names()[if format == Format::Colmap { 1 } else { 0 }]);
        let (_, read) = splatraj_camera_paths::read_camera_path(&main).unwrap();
        assert_eq!(read.cuts, vec![10, 20], "{format}");
    }
}

#[test]
fn pan_keeps_one_shot_and_a_bad_value_names_the_key() {
    let experiment = Experiment::prepare(&config("\"pan\"").unwrap()).unwrap();
    assert!(!matches!(
        experiment.run_model().unwrap(),
        TrajectoryModel::Cuts(_)
    ));
    assert!(experiment.joins().unwrap().iter().all(|j| !j.is_cut()));
    let error = format!("{:#}", config("\"wipe\"").unwrap_err());
    assert!(error.contains("output.transitions"), "{error}");
    assert!(error.contains("pan") && error.contains("auto"), "{error}");
}
