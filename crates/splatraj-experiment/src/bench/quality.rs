//! The first-try quality benchmark's figures, read from a finished run folder
//! (`splatraj bench first-try`, docs/first-try.md): per window whether its verdict passes,
//! its framing in the middle half, its framed share of the middle 60 %, the visible and hidden
//! shares, the smallest clearance, the largest turn of the view and orbit about the part
//! between two frames and the framing's wobble; per run its wall time. The runs
//! themselves are `splatraj run` in child processes ([`run_first_try`]), as a user runs them.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, anyhow, bail};
use serde::Serialize;
use serde_json::Value;

/// One window's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowQuality {
    /// The query.
    pub name: String,
    /// Whether its verdict passes.
    pub pass: bool,
    /// Names of the failed checks.
    pub failed: Vec<String>,
    /// Share of the window's samples that show the object.
    pub in_view: f64,
    /// Mean TCE of the middle half's samples in view (None: never in view).
    pub tce_middle: Option<f64>,
    /// Share of the middle 60 %'s samples framed (None: an older run folder).
    pub framed_share: Option<f64>,
    /// 1 − mean occluded share.
    pub visible: f64,
    /// Share of samples more than half hidden.
    pub hidden: f64,
    /// Smallest clearance from the geometry (None: no clearance cost).
    pub min_clearance: Option<f64>,
    /// Largest turn of the view between two consecutive frames, degrees (None: the run
    /// folder gives no duration).
    pub turn_per_frame: Option<f64>,
    /// Largest orbit about the part's centre between two consecutive frames, degrees (None:
    /// no duration, or an older run folder).
    pub orbit_per_frame: Option<f64>,
    /// The framing's wobble over the frames (None: no frames).
    pub wobble: Option<f64>,
}

/// One run's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunQuality {
    /// The run's name (`config.toml`'s `name`).
    pub name: String,
    /// Gaussians in its scene.
    pub gaussians: u64,
    /// Wall time of the whole run, seconds.
    pub total_s: f64,
    /// Of it, optimising.
    pub optimisation_s: f64,
    /// Of it, the metrics.
    pub metrics_s: f64,
    /// Of it, the frames, video and exports.
    pub frames_s: f64,
    /// Each stage's device counters (`metrics.json`'s `run.counts`; None in an older folder).
    pub counts: Option<Value>,
    /// Per window.
    pub windows: Vec<WindowQuality>,
}

impl RunQuality {
    /// Whether every window passes.
    pub fn pass(&self) -> bool {
        self.windows.iter().all(|w| w.pass)
    }
}

/// The figures of the run folder `dir` (its `metrics.json` and `config.toml`).
pub fn read_run_quality(dir: &Path) -> Result<RunQuality> {
    let path = dir.join("metrics.json");
    let text = splatraj_scene::input::read_text(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let metrics: Value = serde_json::from_str(&text)
        .with_context(|| format!("{} is not valid JSON", path.display()))?;
    let config: toml::Table = splatraj_scene::input::read_text(&dir.join("config.toml"))
        .ok()
        .and_then(|t| toml::from_str(&t).ok())
        .unwrap_or_default();
    let fps = config
        .get("output")
        .and_then(|o| o.get("fps"))
        .and_then(toml::Value::as_float)
        .unwrap_or(30.0);
    let number = |v: &Value| v.as_f64();
    let windows = metrics["windows"]
        .as_array()
        .with_context(|| format!("{} holds no windows", path.display()))?
        .iter()
        .map(|w| {
            let checks = w["verdict"]["checks"]
                .as_array()
                .cloned()
                .unwrap_or_default();
            let motion = &w["path"]["motion"];
            // Degrees per second over frames per second; per unit time when no duration.
            let per_second = number(&motion["peak_angular_speed"]).unwrap_or(0.0);
            // Per second when the path has a duration (every run has one now; older run
            // folders may not).
            let turn_per_frame = number(&motion["seconds"]).map(|_| per_second / fps);
            let orbit_per_frame = number(&motion["seconds"])
                .and(number(&motion["peak_orbit_speed"]))
                .map(|o| o / fps);
            WindowQuality {
                name: w["name"].as_str().unwrap_or_default().to_string(),
                pass: w["verdict"]["pass"].as_bool().unwrap_or(false),
                failed: checks
                    .iter()
                    .filter(|c| c["pass"] == Value::Bool(false))
                    .filter_map(|c| c["check"].as_str().map(String::from))
                    .collect(),
                in_view: number(&w["visible_fraction"]).unwrap_or(f64::NAN),
                tce_middle: number(&w["framing"]["tce_middle"]),
                framed_share: number(&w["framing"]["framed_share"]),
                visible: 1.0 - number(&w["occlusion"]["mean_occluded"]).unwrap_or(f64::NAN),
                hidden: number(&w["occlusion"]["hidden_fraction"]).unwrap_or(f64::NAN),
                min_clearance: number(&w["path"]["clearance"]["min_clearance"]),
                turn_per_frame,
                orbit_per_frame,
                wobble: number(&w["framing"]["wobble"]),
            }
        })
        .collect();
    Ok(RunQuality {
        name: config
            .get("name")
            .and_then(toml::Value::as_str)
            .unwrap_or("run")
            .to_string(),
        gaussians: metrics["run"]["gaussians"].as_u64().unwrap_or(0),
        total_s: number(&metrics["run"]["total_s"]).unwrap_or(f64::NAN),
        optimisation_s: number(&metrics["run"]["optimisation_s"]).unwrap_or(f64::NAN),
        metrics_s: number(&metrics["run"]["metrics_s"]).unwrap_or(f64::NAN),
        frames_s: number(&metrics["run"]["frames_s"]).unwrap_or(f64::NAN),
        counts: metrics["run"].get("counts").cloned(),
        windows,
    })
}

/// The runs as a Markdown table, one row per window, and a last line counting the passes.
pub fn quality_table(runs: &[RunQuality]) -> String {
    let show = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
    let degrees = |v: Option<f64>| v.map_or("–".to_string(), |d| format!("{d:.2}°"));
    let mut out = String::from(
        "| scene | Gaussians | window | verdict | in view | TCE (middle) | framed (middle 60 %) \
         | visible | hidden | min clearance | turn/frame | orbit/frame | wobble | time \
         (optimisation) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for run in runs {
        for (i, w) in run.windows.iter().enumerate() {
            let verdict = if w.pass {
                "pass".to_string()
            } else {
                format!("FAIL: {}", w.failed.join(", "))
            };
            let time = if i == 0 {
                format!("{:.0} s ({:.0} s)", run.total_s, run.optimisation_s)
            } else {
                String::new()
            };
            out.push_str(&format!(
                "| {} | {} | {} | {verdict} | {:.0} % | {} | {} | {:.0} % | {:.0} % | {} | {} | {} | {} | {time} |\n",
                if i == 0 { run.name.as_str() } else { "" },
                if i == 0 { run.gaussians.to_string() } else { String::new() },
                w.name,
                100.0 * w.in_view,
                show(w.tce_middle),
                w.framed_share
                    .map_or("–".to_string(), |f| format!("{:.0} %", 100.0 * f)),
                100.0 * w.visible,
                100.0 * w.hidden,
                show(w.min_clearance),
                degrees(w.turn_per_frame),
                degrees(w.orbit_per_frame),
                show(w.wobble),
            ));
        }
    }
    let windows: usize = runs.iter().map(|r| r.windows.len()).sum();
    let passed: usize = runs
        .iter()
        .map(|r| r.windows.iter().filter(|w| w.pass).count())
        .sum();
    let scenes = runs.iter().filter(|r| r.pass()).count();
    out.push_str(&format!(
        "\n{passed} of {windows} windows pass their verdict; {scenes} of {} scenes pass whole.\n",
        runs.len()
    ));
    out
}

/// Where the first-try configs live, relative to the repository root.
pub const FIRST_TRY_CONFIGS: &str = "configs/first-try";

/// Every `.toml` in `dir`, sorted.
pub fn configs_in(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {} (give configs)", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    found.sort();
    Ok(found)
}

/// What [`run_first_try`] runs.
#[derive(Debug, Clone)]
pub struct FirstTryBench {
    /// The configs, each run once.
    pub configs: Vec<PathBuf>,
    /// `key=value` overrides given to every run.
    pub set: Vec<String>,
    /// The folder the run folders go to (`output.runs_dir`).
    pub runs_dir: PathBuf,
}

/// Runs each config of `bench` with `exe run CONFIG --quiet` in a child process, the verdict
/// only warning (so that a failing run's folder is read too), and reads each run folder's
/// figures; `starting` hears each config before it runs.
pub fn run_first_try(
    exe: &Path,
    bench: &FirstTryBench,
    starting: &mut dyn FnMut(&Path),
) -> Result<Vec<RunQuality>> {
    let mut runs = Vec::with_capacity(bench.configs.len());
    for config in &bench.configs {
        starting(config);
        let folder = run_child(exe, config, &bench.runs_dir, &bench.set)?;
        runs.push(read_run_quality(&folder)?);
    }
    Ok(runs)
}

/// Runs `exe run CONFIG --quiet` in a child process, its run folder in `runs_dir`, the
/// verdict only warning (so that a run that misses its goals still reports), with the `--set`
/// overrides `set`; returns the run folder (the last line the run prints).
pub fn run_child(exe: &Path, config: &Path, runs_dir: &Path, set: &[String]) -> Result<PathBuf> {
    let runs_dir = toml::Value::String(runs_dir.display().to_string());
    let mut command = Command::new(exe);
    command.arg("run").arg(config).arg("--quiet");
    command.args(["--set", "output.verdict=\"warn\""]);
    command.args(["--set".to_string(), format!("output.runs_dir={runs_dir}")]);
    for s in set {
        command.args(["--set", s]);
    }
    // Through `output_until_stopped`: a stop ends the child too, and the child dies with this
    // process (the trial found bench children left running after their parent was killed).
    let output = crate::children::output_until_stopped(
        &mut command,
        &format!("the run of {}", config.display()),
    )?;
    if !output.status.success() {
        bail!(
            "the run of {} failed: {}",
            config.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    stdout
        .lines()
        .last()
        .map(|l| PathBuf::from(l.trim()))
        .ok_or_else(|| anyhow!("the run of {} printed no folder", config.display()))
}
