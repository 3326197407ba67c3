//! `splatraj bench scale`: one config (the demo's by default) run whole at several scene sizes,
//! each as `splatraj run` in a child process of its own (so each peak memory is that size's
//! alone), and the per-step time, the time of each stage and the peak memory tabulated with
//! the cost of a step and the memory per Gaussian against the smallest size.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use serde::Serialize;
use serde_json::Value;

use crate::bench::quality::run_child;

/// What `splatraj bench scale` runs.
#[derive(Debug, Clone)]
pub struct ScaleBench {
    /// The config; its `[scene]` must be the demo scene (its size is what varies).
    pub config: PathBuf,
    /// Demo scene sizes, Gaussians.
    pub sizes: Vec<usize>,
    /// Optimisation steps per run (None: the config's own).
    pub iterations: Option<usize>,
    /// Further `--set` overrides for every run.
    pub set: Vec<String>,
    /// The folder the run folders go to.
    pub runs_dir: PathBuf,
}

/// One size's figures, read from its run folder's `metrics.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScaleRow {
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Gaussians the optimisation rendered (`optimise_gaussians`; None: not recorded).
    pub optimised: Option<usize>,
    /// Steps run.
    pub iterations: usize,
    /// Wall time per optimisation step, ms.
    pub per_step_ms: f64,
    /// Building the scene, its targets and the start, s (the whole run less the stages below).
    pub setup_s: f64,
    /// Optimisation, s.
    pub optimisation_s: f64,
    /// Metrics, s.
    pub metrics_s: f64,
    /// Frames, video and exports, s.
    pub frames_s: f64,
    /// The whole run, s.
    pub total_s: f64,
    /// Peak resident memory of the run, MB (None: not reported).
    pub peak_mb: Option<f64>,
    /// The run folder.
    pub folder: PathBuf,
}

/// The figures of the finished run folder `dir`.
pub fn read_scale_row(dir: &Path) -> Result<ScaleRow> {
    let path = dir.join("metrics.json");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let metrics: Value = serde_json::from_str(&text)
        .with_context(|| format!("{} is not valid JSON", path.display()))?;
    let run = &metrics["run"];
    let number = |key: &str| {
        run[key]
            .as_f64()
            .ok_or_else(|| anyhow!("{}: `run.{key}` is missing", path.display()))
    };
    let (optimisation_s, metrics_s, frames_s, total_s) = (
        number("optimisation_s")?,
        number("metrics_s")?,
        number("frames_s")?,
        number("total_s")?,
    );
    Ok(ScaleRow {
        gaussians: number("gaussians")? as usize,
        optimised: run["optimised_gaussians"].as_u64().map(|n| n as usize),
        iterations: number("iterations_run")? as usize,
        per_step_ms: number("per_iteration_ms")?,
        setup_s: total_s - optimisation_s - metrics_s - frames_s,
        optimisation_s,
        metrics_s,
        frames_s,
        total_s,
        peak_mb: run["peak_memory_mb"].as_f64(),
        folder: dir.to_path_buf(),
    })
}

/// Runs `bench.config` at each size ([`run_child`]: `exe run CONFIG --quiet`, verdict only
/// warning) and reads each run folder; `starting` hears each
/// size before it runs. A size whose run fails is reported among the failures (second) and the
/// next size still runs.
pub fn run_scale(
    exe: &Path,
    bench: &ScaleBench,
    starting: &mut dyn FnMut(usize),
) -> Result<(Vec<ScaleRow>, Vec<String>)> {
    if bench.sizes.is_empty() {
        bail!("--sizes: nothing to run");
    }
    let (mut rows, mut failures) = (Vec::new(), Vec::new());
    for &size in &bench.sizes {
        starting(size);
        match run_size(exe, bench, size) {
            Ok(row) => rows.push(row),
            Err(e) => failures.push(format!("{size} Gaussians: {e:#}")),
        }
    }
    Ok((rows, failures))
}

/// One run of `bench.config` at `size` Gaussians, and its figures.
fn run_size(exe: &Path, bench: &ScaleBench, size: usize) -> Result<ScaleRow> {
    let mut set = vec![format!("scene.demo.gaussians={size}")];
    if let Some(iterations) = bench.iterations {
        set.push(format!("optimiser.iterations={iterations}"));
    }
    set.extend(bench.set.iter().cloned());
    let folder = run_child(exe, &bench.config, &bench.runs_dir, &set)?;
    read_scale_row(&folder)
}

/// The rows as a table: per size the Gaussians the optimisation rendered, the step time and its ratio to the first row's, the stages,
/// the peak memory and the peak's growth per Gaussian over the first row.
pub fn scale_table(rows: &[ScaleRow]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "| Gaussians | optimised | steps | ms/step | × first | setup s | optimise s | metrics s | frames s | total s | peak MB | bytes/Gaussian over first |"
    );
    let _ = writeln!(
        out,
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let first = rows.first();
    for row in rows {
        let ratio = first.map_or(f64::NAN, |f| row.per_step_ms / f.per_step_ms);
        let slope = match (first, row.peak_mb, first.and_then(|f| f.peak_mb)) {
            (Some(f), Some(peak), Some(first_peak)) if row.gaussians > f.gaussians => format!(
                "{:.0}",
                (peak - first_peak) * 1024.0 * 1024.0 / (row.gaussians - f.gaussians) as f64
            ),
            _ => "–".into(),
        };
        let peak = row.peak_mb.map_or("–".into(), |p| format!("{p:.0}"));
        let optimised = row.optimised.map_or("–".into(), |n| n.to_string());
        let _ = writeln!(
            out,
            "| {} | {optimised} | {} | {:.0} | {ratio:.2} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {peak} | {slope} |",
            row.gaussians,
            row.iterations,
            row.per_step_ms,
            row.setup_s,
            row.optimisation_s,
            row.metrics_s,
            row.frames_s,
            row.total_s,
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(gaussians: usize, per_step_ms: f64, peak_mb: Option<f64>) -> ScaleRow {
        ScaleRow {
            gaussians,
            optimised: Some(gaussians.min(1_000_000)),
            iterations: 10,
            per_step_ms,
            setup_s: 1.0,
            optimisation_s: per_step_ms / 100.0,
            metrics_s: 2.0,
            frames_s: 3.0,
            total_s: 6.0 + per_step_ms / 100.0,
            peak_mb,
            folder: PathBuf::from("runs/x"),
        }
    }

    #[test]
    fn table_gives_ratios_and_bytes_per_gaussian_against_the_first_row() {
        let table = scale_table(&[
            row(1_000_000, 700.0, Some(1000.0)),
            row(3_000_000, 1400.0, Some(2000.0)),
            row(6_000_000, 2100.0, None),
        ]);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 5);
        assert!(lines[2].contains("| 1.00 |") && lines[2].ends_with("| 1000 | – |"));
        // 1000 MB over 2 M Gaussians: 524 bytes each.
        assert!(lines[3].contains("| 2.00 |") && lines[3].ends_with("| 2000 | 524 |"));
        assert!(lines[4].contains("| 3.00 |") && lines[4].ends_with("| – | – |"));
    }

    #[test]
    fn a_run_folder_without_figures_is_an_error_naming_the_file() {
        let dir = std::env::temp_dir().join(format!("splatraj-scale-row-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("metrics.json"), r#"{"run": {"gaussians": 5}}"#).unwrap();
        let error = read_scale_row(&dir).unwrap_err().to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(error.contains("metrics.json") && error.contains("run.optimisation_s"));
    }
}
