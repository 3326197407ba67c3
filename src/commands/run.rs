//! `splatraj run CONFIG.toml`: optimise a trajectory that shows each query in turn, then write
//! the run folder (resolved config, trajectory, frames, metrics, history).
//!
//! Order of work: read and check everything (config, scene, targets) before any folder is
//! made; optimise from each start (a progress bar shows iteration, cost and time left; Ctrl-C
//! or `optimiser.time_limit_s` stops early and keeps the best so far); then evaluate the
//! per-window metrics on a fixed time grid at the output resolution, LDJ, and render frames.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use splatraj::config::{Config, MaskOverlay, StartKind};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_traj::metrics::{
    Smoothness, WindowMetrics, WindowObject, trajectory_ldj, window_metrics,
};
use splatraj_traj::optimise::sampling::{window_bounds, window_of};
use splatraj_traj::optimise::start::START_FIT_SAMPLES;
use splatraj_traj::optimise::{
    Flow, StopReason, TrajectoryResult, TrajectoryStep, WindowTarget, object_start_poses,
    optimise_trajectory, random_start_poses, window_start_trajectory,
};
use splatraj_traj::trajectory::{Trajectory, TrajectoryModel, TrajectoryRecord, uniform_times};

use super::outputs::{FrameSpec, create_run_dir, write_bytes, write_csv, write_frames, write_json};
use super::setup::{Prepared, prepare, resolve};

/// Arguments of `splatraj run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Experiment config (TOML).
    config: PathBuf,
    /// Override a config value, e.g. `--set optimiser.iterations=50` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Check the config, scene and queries, print what would run, and stop.
    #[arg(long)]
    check: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Set by Ctrl-C: the optimisation stops at the end of the current step.
pub fn interrupt_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = flag.clone();
    // A second registration (tests calling twice in one process) fails; the run still works,
    // only without the clean stop.
    // The first Ctrl-C asks for a clean stop; a second one quits at once (files already
    // written are whole, the others are not there).
    let on_signal = move || {
        if handler_flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    };
    if let Err(e) = ctrlc::set_handler(on_signal) {
        tracing::warn!("Ctrl-C will not stop the run cleanly: {e}");
    }
    flag
}

/// A progress bar on stderr (hidden when `quiet` or when stderr is not a terminal).
pub fn progress_bar(len: u64, quiet: bool) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if quiet {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise} < {eta_precise}] {bar:30} {pos}/{len} {msg}",
        )
        .expect("valid template"),
    );
    bar
}

/// One pose of the densely sampled trajectory in `trajectory.json`.
#[derive(Debug, Serialize)]
struct SampledPose {
    t: f64,
    window: usize,
    /// Φ = [ω, c].
    pose: [f64; 6],
    /// 4×4 world-to-camera matrix (OpenCV axes), row-major.
    world_to_camera: [[f64; 4]; 4],
}

/// One window in `trajectory.json`.
#[derive(Debug, Serialize)]
struct WindowInfo {
    index: usize,
    query: String,
    start: f64,
    end: f64,
    selected_gaussians: usize,
    object_centre: [f64; 3],
    prior_radius: f64,
    target_ratio: f64,
}

/// `trajectory.json`: reads back as a [`TrajectoryRecord`] (`model`, `weights`).
#[derive(Debug, Serialize)]
struct TrajectoryFile<'a> {
    model: &'a TrajectoryModel,
    weights: &'a [[f64; 6]],
    convention: &'static str,
    world_up: [f64; 3],
    intrinsics: Intrinsics,
    output_intrinsics: Intrinsics,
    windows: Vec<WindowInfo>,
    poses: Vec<SampledPose>,
}

/// `metrics.json`.
#[derive(Debug, Serialize)]
struct MetricsFile {
    windows: Vec<WindowMetrics>,
    ldj: Smoothness,
    ldj_samples: usize,
    run: RunReport,
}

/// How the optimisation went.
#[derive(Debug, Serialize)]
struct RunReport {
    scene: String,
    gaussians: usize,
    stop: StopReason,
    restarts_run: usize,
    best_restart: usize,
    best_step: usize,
    best_total: f64,
    iterations_run: usize,
    skipped_steps: usize,
    optimisation_s: f64,
    per_iteration_ms: f64,
    metrics_s: f64,
    frames_s: f64,
    total_s: f64,
    backend: String,
}

/// Runs `splatraj run`.
pub fn run(args: RunArgs) -> Result<()> {
    let started = Instant::now();
    let config = Config::load(&args.config, &args.set)?;
    let prepared = prepare(&config, &args.config)?;
    print_plan(&config, &prepared);
    if args.check {
        return Ok(());
    }
    let costs = config.costs.build().map_err(anyhow::Error::msg)?;
    let n = prepared.windows.len();
    let model = config.trajectory.clone().with_windows(n);
    let starts = start_trajectories(&config, &args.config, &prepared, &model)?;

    let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
    eprintln!("run folder: {}", dir.display());
    write_bytes(
        &dir.join("config.toml"),
        toml::to_string(&config)?.as_bytes(),
    )?;

    let interrupted = interrupt_flag();
    let scene = prepared.autodiff_scene();
    let iterations = config.optimiser.iterations;
    let bar = progress_bar((iterations * starts.len()) as u64, args.quiet);
    let mut results: Vec<TrajectoryResult> = Vec::new();
    let optimisation_started = Instant::now();
    for (r, start) in starts.iter().enumerate() {
        let mut observer = |s: &TrajectoryStep| {
            bar.set_position((r * iterations + s.step + 1) as u64);
            bar.set_message(format!(
                "start {}/{}  cost {:.4}  best {:.4}",
                r + 1,
                starts.len(),
                s.total,
                s.best_total
            ));
            if interrupted.load(Ordering::SeqCst) {
                Flow::Stop
            } else {
                Flow::Continue
            }
        };
        let result = optimise_trajectory(
            &scene,
            &prepared.windows,
            &costs,
            &prepared.intrinsics,
            start,
            &config.optimiser,
            config.seed.wrapping_add(r as u64),
            &mut observer,
        )?;
        let stop = result.stop;
        results.push(result);
        if stop == StopReason::Interrupted {
            break;
        }
    }
    bar.finish_and_clear();
    let optimisation_s = optimisation_started.elapsed().as_secs_f64();
    let (best_restart, best) = results
        .iter()
        .enumerate()
        .filter(|(_, r)| r.best_total.is_finite())
        .min_by(|a, b| a.1.best_total.total_cmp(&b.1.best_total))
        .or_else(|| results.iter().enumerate().next())
        .context("no optimisation ran")?;
    let stop = results.last().map_or(StopReason::Finished, |r| r.stop);
    if stop == StopReason::Interrupted {
        eprintln!("stopped early: writing the best trajectory so far");
    }
    drop(scene);

    write_history(&dir.join("history.csv"), &results, &costs.names(), n)?;
    let trajectory = Trajectory::from_record(&best.best, &prepared.device, prepared.dtype)?;
    let output_intrinsics = prepared
        .intrinsics
        .rescaled(config.output.width, config.output.height)?;
    write_trajectory(
        &dir.join("trajectory.json"),
        &trajectory,
        &prepared,
        &output_intrinsics,
        config.output.trajectory_samples,
    )?;

    let metrics_started = Instant::now();
    let plain = prepared.plain_scene();
    let mut windows = Vec::with_capacity(n);
    for (i, w) in prepared.windows.iter().enumerate() {
        let alone = prepared.object_alone(i);
        let object = WindowObject {
            name: &w.name,
            mask: &w.mask,
            alone: &alone,
            target_ratio: w.context.target_ratio,
        };
        let pose_at = |times: &[f64]| trajectory.poses_at(times);
        windows.push(window_metrics(
            &plain,
            &object,
            i,
            n,
            config.output.metric_samples,
            &output_intrinsics,
            &pose_at,
        )?);
    }
    let ldj = trajectory_ldj(&trajectory, config.output.ldj_samples);
    let metrics_s = metrics_started.elapsed().as_secs_f64();

    let frames_started = Instant::now();
    let frame_times = uniform_times(config.output.frames);
    let frame_poses = trajectory.poses_at(&frame_times);
    let specs: Vec<FrameSpec> = frame_times
        .iter()
        .zip(&frame_poses)
        .map(|(&t, pose)| FrameSpec {
            pose: *pose,
            tint: (config.output.mask_overlay == MaskOverlay::Tint)
                .then(|| prepared.windows[window_of(t, n)].mask.as_slice()),
        })
        .collect();
    let frame_bar = progress_bar(specs.len() as u64, args.quiet);
    frame_bar.set_message("frames");
    write_frames(
        &plain,
        &output_intrinsics,
        &specs,
        &dir.join("frames"),
        &mut |done| frame_bar.set_position(done as u64),
    )?;
    frame_bar.finish_and_clear();
    let frames_s = frames_started.elapsed().as_secs_f64();

    let iterations_run: usize = results.iter().map(|r| r.history.len()).sum();
    let report = RunReport {
        scene: prepared.scene_name.clone(),
        gaussians: prepared.scene.len(),
        stop,
        restarts_run: results.len(),
        best_restart,
        best_step: best.best_step,
        best_total: best.best_total,
        iterations_run,
        skipped_steps: results.iter().map(|r| r.skipped_steps).sum(),
        optimisation_s,
        per_iteration_ms: 1e3 * optimisation_s / iterations_run.max(1) as f64,
        metrics_s,
        frames_s,
        total_s: started.elapsed().as_secs_f64(),
        backend: format!("{:?} {:?}", config.backend, config.precision),
    };
    print_summary(&windows, &ldj, &report);
    write_json(
        &dir.join("metrics.json"),
        &MetricsFile {
            windows,
            ldj,
            ldj_samples: config.output.ldj_samples,
            run: report,
        },
    )?;
    println!("{}", dir.display());
    Ok(())
}

/// The starting trajectories: from a file, a fixed pose, or seeded random poses.
fn start_trajectories(
    config: &Config,
    config_path: &Path,
    prepared: &Prepared,
    model: &TrajectoryModel,
) -> Result<Vec<TrajectoryRecord>> {
    let (device, dtype) = (&prepared.device, prepared.dtype);
    if let Some(file) = &config.start.trajectory {
        let base = config_path.parent().unwrap_or(Path::new("."));
        let path = resolve(base, file);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("`start.trajectory`: cannot read {}", path.display()))?;
        let record: TrajectoryRecord = serde_json::from_str(&text).with_context(|| {
            format!(
                "`start.trajectory`: {} is not a trajectory.json (needs `model` and `weights`)",
                path.display()
            )
        })?;
        let loaded = Trajectory::from_record(&record, device, dtype)
            .with_context(|| format!("`start.trajectory`: {}", path.display()))?;
        let refitted = if &record.model == model {
            loaded
        } else {
            loaded.refit(model.clone(), START_FIT_SAMPLES)?
        };
        return Ok(vec![refitted.record()]);
    }
    let n = prepared.windows.len();
    let per_restart = match config.start.pose {
        Some(pose) => vec![vec![Pose(pose); n]],
        None => start_poses(config, prepared, &prepared.windows)?,
    };
    per_restart
        .iter()
        .map(|per_window| {
            Ok(window_start_trajectory(model.clone(), per_window, device, dtype)?.record())
        })
        .collect()
}

/// For each restart, one start pose per window in `windows` (object-facing or random; a
/// random start is the same pose for every window).
pub fn start_poses(
    config: &Config,
    prepared: &Prepared,
    windows: &[WindowTarget],
) -> Result<Vec<Vec<Pose>>> {
    let (centre, half) = prepared.bounds;
    let restarts = config.start.restarts;
    Ok(match config.start.kind {
        StartKind::Objects => {
            let objects: Vec<([f64; 3], f64)> = windows
                .iter()
                .map(|w| (w.context.object_centre, w.context.prior_radius))
                .collect();
            (0..restarts)
                .map(|r| {
                    object_start_poses(
                        &objects,
                        centre,
                        prepared.up,
                        config.start.object_view(),
                        r,
                        config.seed,
                    )
                })
                .collect::<Result<_, _>>()?
        }
        StartKind::Random => random_start_poses(
            centre,
            half,
            prepared.up,
            &config.start.distribution(),
            restarts,
            config.seed,
        )?
        .into_iter()
        .map(|p| vec![p; windows.len()])
        .collect(),
    })
}

fn write_trajectory(
    path: &Path,
    trajectory: &Trajectory,
    prepared: &Prepared,
    output_intrinsics: &Intrinsics,
    samples: usize,
) -> Result<()> {
    let n = prepared.windows.len();
    let times = uniform_times(samples);
    let poses = trajectory
        .poses_at(&times)
        .into_iter()
        .zip(&times)
        .map(|(pose, &t)| {
            let m = Pose(pose).world_to_camera();
            SampledPose {
                t,
                window: window_of(t, n),
                pose,
                world_to_camera: std::array::from_fn(|r| std::array::from_fn(|c| m.col(c)[r])),
            }
        })
        .collect();
    let record = trajectory.record();
    let windows = prepared
        .windows
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let (start, end) = window_bounds(i, n);
            WindowInfo {
                index: i,
                query: w.name.clone(),
                start,
                end,
                selected_gaussians: prepared.selected[i],
                object_centre: w.context.object_centre,
                prior_radius: w.context.prior_radius,
                target_ratio: w.context.target_ratio,
            }
        })
        .collect();
    write_json(
        path,
        &TrajectoryFile {
            model: &record.model,
            weights: &record.weights,
            convention: "pose = [ω (rotation vector of camera-to-world), camera centre]; OpenCV camera axes (x right, y down, z forward); t in [0, 1]",
            world_up: prepared.up,
            intrinsics: prepared.intrinsics,
            output_intrinsics: *output_intrinsics,
            windows,
            poses,
        },
    )
}

fn write_history(
    path: &Path,
    results: &[TrajectoryResult],
    names: &[&'static str],
    windows: usize,
) -> Result<()> {
    let mut header: Vec<String> = [
        "restart",
        "step",
        "elapsed_s",
        "total",
        "best_total",
        "updated",
    ]
    .map(String::from)
    .to_vec();
    for i in 0..windows {
        for name in names {
            header.push(format!("q{i}_{name}"));
        }
    }
    let rows = results
        .iter()
        .enumerate()
        .flat_map(|(r, result)| {
            result.history.iter().map(move |s| {
                let mut row = vec![
                    r.to_string(),
                    s.step.to_string(),
                    format!("{:.4}", s.elapsed.as_secs_f64()),
                    s.total.to_string(),
                    s.best_total.to_string(),
                    u8::from(s.updated).to_string(),
                ];
                for w in &s.windows {
                    row.extend(w.iter().map(|(_, _, v)| v.to_string()));
                }
                row
            })
        })
        .collect::<Vec<_>>();
    write_csv(path, &header, &rows)
}

fn print_plan(config: &Config, prepared: &Prepared) {
    eprintln!(
        "scene: {} ({} Gaussians), up {:?} ({}), backend {:?}",
        prepared.scene_name,
        prepared.scene.len(),
        prepared.up,
        prepared.up_from,
        config.backend
    );
    for (i, w) in prepared.windows.iter().enumerate() {
        let c = w.context.object_centre;
        eprintln!(
            "query {i}: {:?} → {} Gaussians, centre [{:.3}, {:.3}, {:.3}], prior radius {:.3}, target ratio {}",
            w.name,
            prepared.selected[i],
            c[0],
            c[1],
            c[2],
            w.context.prior_radius,
            w.context.target_ratio
        );
    }
}

fn print_summary(windows: &[WindowMetrics], ldj: &Smoothness, report: &RunReport) {
    eprintln!("window  query                  TCE     TRE     IoU   visible");
    for w in windows {
        eprintln!(
            "{:>6}  {:<20} {:>7.4} {:>7.4} {:>7.3}   {:.0}%",
            w.window,
            w.name,
            w.tce,
            w.tre,
            w.iou,
            100.0 * w.visible_fraction
        );
    }
    let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    eprintln!(
        "LDJ positional {}, angular {}; {} iterations in {:.1} s ({:.0} ms each), total {:.1} s",
        show(ldj.positional),
        show(ldj.angular),
        report.iterations_run,
        report.optimisation_s,
        report.per_iteration_ms,
        report.total_s
    );
}
