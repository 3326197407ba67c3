//! One run of a study in this process: the variant's optimisation, timed, then the fixed
//! evaluation.
//!
//! The variant's time is what a user of that setting waits for: `run_s` from reading the
//! config to the end of the optimisation, `optimisation_s` the optimisation alone. Peak memory
//! (VmHWM) is read before the evaluation so that the evaluation's renders, the same for every
//! variant, do not hide the variant's own peak. The evaluation is built from the base config
//! ([`PlannedStudy::evaluation_config`]): its resolution, sample grid, precision, rasterizer and
//! exact rendering rules are the same whatever the variant changed.

use std::time::Instant;

use anyhow::Result;
use splatraj_render::camera::Pose;
use splatraj_render::stages::{self, Stage};

use super::StudyTask;
use super::plan::{PlannedStudy, Run};
use super::rows::{StageTimes, StudyRow, WindowScore};
use crate::extensions::Extensions;
use crate::optimise::observer;
use crate::optimise::trajectory_run::RunStop;
use crate::prepare::experiment::Experiment;
use crate::resources::peak_mb;
use splatraj_scene::stop::{Since, Stopped};
use splatraj_traj::optimise::StopReason;

/// The error of a run a stop request cut short.
fn cut_short(run: &Run) -> Stopped {
    Stopped {
        what: format!("run {} was cut short and is not measured", run.index),
    }
}

/// Which peak memory a row reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MemoryReading {
    /// This process runs one run only: its high-water mark is the run's.
    OwnProcess,
    /// Runs share this process: no per-run figure.
    Shared,
}

/// Runs `run` of `plan` here and evaluates it: one row (trajectory) or one per start (pose).
/// A stop requested `since` ([`splatraj_scene::stop`]) ends it at the next step or window
/// with [`Stopped`]: a run cut short is not measured.
pub fn measure_run(
    study: &PlannedStudy,
    run: &Run,
    extensions: &Extensions,
    memory: MemoryReading,
    since: Since,
) -> Result<Vec<StudyRow>> {
    if matches!(memory, MemoryReading::OwnProcess) {
        // A child of `study`: it must not outlive its parent.
        crate::children::exit_with_parent();
    }
    let started = Instant::now();
    let plan = &study.plan;
    let config = study.run_config(run, extensions)?;
    let experiment = Experiment::prepare_with(&config, extensions)?;
    let variant = &plan.variants[run.variant];
    let peak = || match memory {
        MemoryReading::OwnProcess => peak_mb(),
        MemoryReading::Shared => None,
    };
    let evaluation = Experiment::prepare_with(&study.evaluation_config(extensions)?, extensions)?;
    let row = |repeat: usize, seed: u64, windows: Vec<WindowScore>| {
        let mean = |f: fn(&WindowScore) -> f64| {
            windows.iter().map(f).sum::<f64>() / windows.len().max(1) as f64
        };
        StudyRow {
            run: run.index,
            variant: variant.index,
            label: variant.label.clone(),
            repeat,
            seed,
            optimisation_s: 0.0,
            run_s: 0.0,
            peak_mb: None,
            iterations: 0,
            best_total: f64::NAN,
            stages: None,
            error: plan.quality.error(&windows),
            tce: windows
                .iter()
                .map(|w| w.tce)
                .sum::<Option<f64>>()
                .map(|s| s / windows.len().max(1) as f64),
            tre: mean(|w| w.tre),
            iou: mean(|w| w.iou),
            visible: mean(|w| w.visible_fraction),
            ldj_positional: None,
            ldj_angular: None,
            min_clearance: windows
                .iter()
                .filter_map(|w| w.min_clearance)
                .reduce(f64::min),
            inside_margin: windows
                .iter()
                .map(|w| w.time_inside_margin)
                .sum::<Option<f64>>()
                .map(|s| s / windows.len().max(1) as f64),
            windows,
        }
    };
    match plan.task {
        StudyTask::Trajectory => {
            stages::reset();
            let result = experiment.run_trajectory(&mut observer::until_stopped(since))?;
            if result.stop == RunStop::Interrupted {
                return Err(cut_short(run).into());
            }
            let run_s = started.elapsed().as_secs_f64();
            let peak_mb = peak();
            // Before the evaluation renders (the renderer's clock is process-wide).
            let split = stage_times(&result);
            let trajectory = evaluation.trajectory(&result.best().best)?;
            let judged = evaluation.evaluate_since(&trajectory, since)?;
            let windows = judged.windows.iter().map(WindowScore::from).collect();
            Ok(vec![StudyRow {
                optimisation_s: result.elapsed.as_secs_f64(),
                run_s,
                peak_mb,
                iterations: result.iterations_run(),
                best_total: result.best().best_total,
                stages: Some(split),
                ldj_positional: judged.ldj.positional,
                ldj_angular: judged.ldj.angular,
                ..row(run.repeat, config.seed, windows)
            }])
        }
        StudyTask::Pose => {
            let result = experiment.optimise_pose(&mut observer::until_stopped(since))?;
            if result.stop() == StopReason::Interrupted {
                return Err(cut_short(run).into());
            }
            let run_s = started.elapsed().as_secs_f64();
            let peak_mb = peak();
            let query = config.pose.query;
            let plain = evaluation.plain_scene();
            let intrinsics = evaluation.output_intrinsics()?;
            result
                .results
                .iter()
                .enumerate()
                .map(|(start, r)| {
                    let pose: Pose = r.pose;
                    let metrics = evaluation.window_metrics(
                        &plain,
                        query,
                        (0, 1),
                        1,
                        &intrinsics,
                        (&|t: &[f64]| vec![pose.0; t.len()], None),
                    )?;
                    Ok(StudyRow {
                        optimisation_s: result.elapsed.as_secs_f64(),
                        run_s,
                        peak_mb,
                        iterations: result.iterations_run(),
                        best_total: r.total,
                        ..row(start, config.seed, vec![WindowScore::from(&metrics)])
                    })
                })
                .collect()
        }
    }
}

/// Where a trajectory run's optimisation time went: the renderer's forward stages from its
/// process-wide clock (reset before the optimisation), the loop's own phase times, and the
/// costs as what the loop's evaluation took beyond the renders.
fn stage_times(run: &crate::TrajectoryRun) -> StageTimes {
    let render: Vec<f64> = stages::totals()
        .iter()
        .map(|(_, d)| d.as_secs_f64())
        .collect();
    let of = |stage: Stage| render[Stage::ALL.iter().position(|s| *s == stage).unwrap_or(0)];
    let steps = run.results.iter().flat_map(|r| &r.history);
    let (mut evaluate, mut backward, mut update) = (0.0, 0.0, 0.0);
    for s in steps {
        evaluate += s.timing.evaluate.as_secs_f64();
        backward += s.timing.backward.as_secs_f64();
        update += s.timing.update.as_secs_f64();
    }
    let forward = of(Stage::Decide) + of(Stage::Project) + of(Stage::Bin) + of(Stage::Composite);
    StageTimes {
        projection_s: of(Stage::Decide) + of(Stage::Project),
        binning_s: of(Stage::Bin),
        compositing_s: of(Stage::Composite),
        costs_s: (evaluate - forward).max(0.0),
        backward_s: backward,
        optimiser_s: update,
        decide_s: of(Stage::Decide),
        composite_backward_s: of(Stage::CompositeBackward),
    }
}
