//! `splatraj pose CONFIG.toml`: one camera pose that frames one query (the paper's Table I),
//! with its ablations, restarts and SGLD posterior samples.
//!
//! The same config as `splatraj run`; `[pose]` picks the query and the ablation, and
//! `[pose.optimiser]` holds Adam's settings. Restarts run as one batch (one batched render per
//! step). `--sgld CHAINS` then runs that many Langevin chains from the best pose and writes
//! the kept samples. Outputs go to a fresh `runs/<name>/<timestamp>/`: `config.toml`,
//! `pose.json` (best pose and every start's result), `history.csv`, `metrics.json` (TCE, TRE,
//! IoU of the best pose at the output resolution), `frame.png`, and with `--sgld`
//! `sgld_samples.csv`. Ctrl-C during the optimisation stops it and keeps each start's best.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use splatraj::config::{Ablation, Config, MaskOverlay};
use splatraj_render::camera::Pose;
use splatraj_traj::metrics::{WindowMetrics, WindowObject, window_metrics};
use splatraj_traj::optimise::{
    Flow, PoseUnits, SinglePoseResult, StopReason, optimise_poses_observed, sample_poses_sgld,
};

use super::outputs::{FrameSpec, create_run_dir, frame_png, write_bytes, write_csv, write_json};
use super::run::{interrupt_flag, progress_bar, start_poses};
use super::setup::prepare;

/// Arguments of `splatraj pose`.
#[derive(Debug, Args)]
pub struct PoseArgs {
    /// Experiment config (TOML).
    config: PathBuf,
    /// Override a config value, e.g. `--set pose.query=1` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Which costs join the prior (overrides `pose.ablation`).
    #[arg(long, value_enum)]
    ablation: Option<Ablation>,
    /// Independent random starts, optimised together; the best is kept (overrides
    /// `start.restarts`).
    #[arg(long)]
    restarts: Option<usize>,
    /// After optimising, run this many SGLD chains from the best pose and write the samples.
    #[arg(long, value_name = "CHAINS")]
    sgld: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// One start's outcome in `pose.json`.
#[derive(Debug, Serialize)]
struct StartReport {
    start: [f64; 6],
    pose: [f64; 6],
    total: f64,
    best_step: usize,
    terms: Vec<(&'static str, f64, f64)>,
}

/// `pose.json`.
#[derive(Debug, Serialize)]
struct PoseFile {
    query: String,
    ablation: Ablation,
    costs: Vec<&'static str>,
    /// Best pose Φ = [ω, c] (OpenCV camera axes).
    pose: [f64; 6],
    /// Its 4×4 world-to-camera matrix, row-major.
    world_to_camera: [[f64; 4]; 4],
    total: f64,
    /// `finished`, or `interrupted` by Ctrl-C.
    stop: StopReason,
    starts: Vec<StartReport>,
    skipped_steps: usize,
    optimisation_s: f64,
    per_iteration_ms: f64,
}

/// `metrics.json` of a pose run.
#[derive(Debug, Serialize)]
struct PoseMetrics {
    metrics: WindowMetrics,
    sgld: Option<SgldSummary>,
}

/// Spread of the SGLD samples.
#[derive(Debug, Serialize)]
struct SgldSummary {
    chains: usize,
    samples: usize,
    /// Mean and standard deviation of each pose component over the samples.
    mean: [f64; 6],
    std: [f64; 6],
    skipped_updates: usize,
    seconds: f64,
}

/// Runs `splatraj pose`.
pub fn run(args: PoseArgs) -> Result<()> {
    let mut overrides = args.set.clone();
    if let Some(a) = args.ablation {
        overrides.push(format!(
            "pose.ablation={}",
            toml::Value::try_from(a).context("ablation")?
        ));
    }
    if let Some(r) = args.restarts {
        overrides.push(format!("start.restarts={r}"));
    }
    let config = Config::load(&args.config, &overrides)?;
    if args.sgld == Some(0) {
        anyhow::bail!("--sgld needs at least one chain");
    }
    let prepared = prepare(&config, &args.config)?;
    let index = config.pose.query;
    let window = &prepared.windows[index];
    let costs = config
        .pose
        .ablation
        .apply(&config.costs)
        .build()
        .map_err(anyhow::Error::msg)?;
    let starts: Vec<Pose> = match config.start.pose {
        Some(p) => vec![Pose(p)],
        None => start_poses(&config, &prepared, std::slice::from_ref(window))?
            .into_iter()
            .map(|per_window| per_window[0])
            .collect(),
    };
    eprintln!(
        "query {:?}: {} Gaussians, {} start(s), costs {:?}",
        window.name,
        prepared.selected[index],
        starts.len(),
        costs.names()
    );

    let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
    eprintln!("run folder: {}", dir.display());
    write_bytes(
        &dir.join("config.toml"),
        toml::to_string(&config)?.as_bytes(),
    )?;

    let scene = prepared.autodiff_scene();
    let started = Instant::now();
    let interrupted = interrupt_flag();
    let bar = progress_bar(config.pose.optimiser.iterations as u64, args.quiet);
    let results = optimise_poses_observed(
        &scene,
        &window.mask,
        &window.context,
        &costs,
        &prepared.intrinsics,
        &starts,
        &config.pose.optimiser,
        &mut |step, lowest| {
            bar.set_position(step as u64 + 1);
            bar.set_message(format!("best {lowest:.4}"));
            if interrupted.load(Ordering::SeqCst) {
                Flow::Stop
            } else {
                Flow::Continue
            }
        },
    )?;
    bar.finish_and_clear();
    if results[0].stop == StopReason::Interrupted {
        eprintln!("stopped early: writing the best pose so far");
    }
    let optimisation_s = started.elapsed().as_secs_f64();
    let best: &SinglePoseResult = results
        .iter()
        .filter(|r| r.total.is_finite())
        .min_by(|a, b| a.total.total_cmp(&b.total))
        .unwrap_or(&results[0]);
    write_pose_history(&dir.join("history.csv"), &results)?;

    let sgld = match args.sgld {
        Some(chains) => {
            let bar = progress_bar(1, args.quiet);
            bar.set_message(format!("SGLD, {chains} chains"));
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            let sampled = sample_poses_sgld(
                &scene,
                &window.mask,
                &window.context,
                &costs,
                &prepared.intrinsics,
                &vec![best.pose; chains],
                PoseUnits::with_position(window.context.prior_radius),
                &config.sgld,
                config.seed,
            )?;
            bar.finish_and_clear();
            let header: Vec<String> =
                ["chain", "step", "total", "wx", "wy", "wz", "cx", "cy", "cz"]
                    .map(String::from)
                    .to_vec();
            let rows: Vec<Vec<String>> = sampled
                .samples
                .iter()
                .map(|s| {
                    let mut row =
                        vec![s.chain.to_string(), s.step.to_string(), s.total.to_string()];
                    row.extend(s.pose.0.iter().map(|v| v.to_string()));
                    row
                })
                .collect();
            write_csv(&dir.join("sgld_samples.csv"), &header, &rows)?;
            let count = sampled.samples.len().max(1) as f64;
            let mean: [f64; 6] = std::array::from_fn(|i| {
                sampled.samples.iter().map(|s| s.pose.0[i]).sum::<f64>() / count
            });
            let std: [f64; 6] = std::array::from_fn(|i| {
                (sampled
                    .samples
                    .iter()
                    .map(|s| (s.pose.0[i] - mean[i]).powi(2))
                    .sum::<f64>()
                    / count)
                    .sqrt()
            });
            Some(SgldSummary {
                chains,
                samples: sampled.samples.len(),
                mean,
                std,
                skipped_updates: sampled.skipped_updates,
                seconds: sampled.elapsed.as_secs_f64(),
            })
        }
        None => None,
    };
    drop(scene);

    let m = best.pose.world_to_camera();
    // Steps actually run (fewer than configured after Ctrl-C); a finished run's last row is the
    // evaluation after the last update, not a step.
    let finished = usize::from(best.stop == StopReason::Finished);
    let iterations = best.history.len().saturating_sub(finished).max(1);
    write_json(
        &dir.join("pose.json"),
        &PoseFile {
            query: window.name.clone(),
            ablation: config.pose.ablation,
            costs: costs.names(),
            pose: best.pose.0,
            world_to_camera: std::array::from_fn(|r| std::array::from_fn(|c| m.col(c)[r])),
            total: best.total,
            stop: best.stop,
            starts: results
                .iter()
                .zip(&starts)
                .map(|(r, s)| StartReport {
                    start: s.0,
                    pose: r.pose.0,
                    total: r.total,
                    best_step: r.best_step,
                    terms: r.terms.clone(),
                })
                .collect(),
            skipped_steps: best.skipped_steps,
            optimisation_s,
            per_iteration_ms: 1e3 * optimisation_s / iterations as f64,
        },
    )?;

    let output_intrinsics = prepared
        .intrinsics
        .rescaled(config.output.width, config.output.height)?;
    let plain = prepared.plain_scene();
    let alone = prepared.object_alone(index);
    let object = WindowObject {
        name: &window.name,
        mask: &window.mask,
        alone: &alone,
        target_ratio: window.context.target_ratio,
    };
    let pose = best.pose.0;
    let metrics = window_metrics(
        &plain,
        &object,
        0,
        1,
        1,
        &output_intrinsics,
        &|t: &[f64]| vec![pose; t.len()],
    )?;
    eprintln!(
        "best pose {:?}\nTCE {:.4}  TRE {:.4}  IoU {:.3}  visible {}  ({:.1} s, {:.0} ms/iteration for {} start(s))",
        pose,
        metrics.tce,
        metrics.tre,
        metrics.iou,
        metrics.visible,
        optimisation_s,
        1e3 * optimisation_s / iterations as f64,
        starts.len()
    );
    let tint = (config.output.mask_overlay == MaskOverlay::Tint).then_some(window.mask.as_slice());
    let png = frame_png(&plain, &output_intrinsics, &FrameSpec { pose, tint })?;
    write_bytes(&dir.join("frame.png"), &png)?;
    write_json(&dir.join("metrics.json"), &PoseMetrics { metrics, sgld })?;
    println!("{}", dir.display());
    Ok(())
}

fn write_pose_history(path: &Path, results: &[SinglePoseResult]) -> Result<()> {
    let names: Vec<&str> = results[0].history[0].terms.iter().map(|t| t.0).collect();
    let mut header: Vec<String> = [
        "start", "step", "total", "updated", "wx", "wy", "wz", "cx", "cy", "cz",
    ]
    .map(String::from)
    .to_vec();
    header.extend(names.iter().map(|n| n.to_string()));
    let rows = results
        .iter()
        .enumerate()
        .flat_map(|(s, r)| {
            r.history.iter().map(move |h| {
                let mut row = vec![
                    s.to_string(),
                    h.step.to_string(),
                    h.total.to_string(),
                    u8::from(h.updated).to_string(),
                ];
                row.extend(h.pose.0.iter().map(|v| v.to_string()));
                row.extend(h.terms.iter().map(|t| t.2.to_string()));
                row
            })
        })
        .collect::<Vec<_>>();
    write_csv(path, &header, &rows)
}
