//! `report.html` of a run folder, built from the folder's files (and the scene, for the views of
//! the path): what `splatraj run` writes last and `splatraj report RUN_DIR` rebuilds.
//!
//! Read: `config.toml` (shown, and names the scene), `metrics.json` (summary and per-window
//! table: every number it holds, so new metrics show up without code here),
//! `trajectory.json` (windows, object centres, world up and the sampled path),
//! `history.csv` (each cost term summed over the windows), `frame_metrics.csv` (TCE, TRE,
//! coverage along t), `frames/` (keyframes) and `video.mp4`. `metrics.json` and
//! `trajectory.json` must be there (a run writes both before its report); any other missing
//! file leaves its section empty with a note. A file that is there must be what a run writes:
//! a CSV whose rows do not match its header, or a `history.csv` without its `total` column, is
//! refused naming the file and the line.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde_json::Value;
use splatraj_camera_paths::CameraPose;
use splatraj_report::report::{
    CostHistory, FrameMetrics, INLINE_VIDEO_BYTES, Keyframe, PathSample, RunReport, SceneView,
    Shot, Table, VideoSource, Window,
};
use splatraj_scene::demo::{DemoConfig, demo_scene};
use splatraj_scene::{InvalidPolicy, ReadOptions, Scene, read_scene};
use splatraj_traj::trajectory::uniform_times;

use crate::outputs::Csv;
use crate::outputs::path_render::{
    FRAME_METRICS_FILE, KEYFRAMES_DIR, VIDEO_FILE, frame_name, keyframe_indices,
};
use crate::write::write_bytes;

/// The report's file name in a run folder.
pub const REPORT_FILE: &str = "report.html";

/// Scene points drawn in each view (more makes the page heavy without showing more).
const VIEW_POINTS: usize = 6000;

/// Gaussians fainter than this are left out of the views (floaters and haze).
const VIEW_MIN_OPACITY: f32 = 0.3;

/// Writes `report.html` into the run folder `dir` (whole or not at all); `scene` draws the
/// points under the path views. Returns the file.
pub fn write_run_report(dir: &Path, scene: Option<&Scene>) -> Result<PathBuf> {
    let report = run_report(dir, scene)?;
    let html = report.to_html()?;
    let path = dir.join(REPORT_FILE);
    write_bytes(&path, html.as_bytes())?;
    Ok(path)
}

/// What [`rebuild_run_report`] wrote.
#[derive(Debug, Clone)]
pub struct RebuiltReport {
    /// `report.html`.
    pub path: PathBuf,
    /// Invalid Gaussians dropped from the scene file given (under `InvalidPolicy::Drop`).
    pub dropped: usize,
}

/// `splatraj report` whole: rebuilds `report.html` of the run folder `dir` from its files, with
/// the scene under the path views: the file `scene` names, read with its options (a scene
/// without Gaussians is refused, naming it), else the one the run's config names
/// ([`run_scene`]).
pub fn rebuild_run_report(
    dir: &Path,
    scene: Option<(&Path, &ReadOptions)>,
) -> Result<RebuiltReport> {
    if !dir.is_dir() {
        bail!("{} is not a run folder", dir.display());
    }
    let (scene, dropped) = match scene {
        Some((path, read)) => {
            let loaded = crate::prepare::scene_files::read_scene_to_render(path, read)?;
            (loaded.scene, loaded.dropped)
        }
        None => (run_scene(dir)?, 0),
    };
    let path = write_run_report(dir, Some(&scene))?;
    Ok(RebuiltReport { path, dropped })
}

/// What `report.html` shows of the run folder `dir`.
pub fn run_report(dir: &Path, scene: Option<&Scene>) -> Result<RunReport> {
    if !dir.is_dir() {
        bail!("{} is not a run folder", dir.display());
    }
    let config = splatraj_scene::input::read_text(&dir.join("config.toml")).unwrap_or_default();
    let metrics_file = dir.join("metrics.json");
    let metrics = read_json(&metrics_file)?;
    check_metrics(&metrics, &metrics_file, scene)?;
    let trajectory = read_json(&dir.join("trajectory.json"))?;
    if !trajectory.is_object() {
        bail!(
            "{}: not a run's trajectory.json (a JSON object)",
            dir.join("trajectory.json").display()
        );
    }
    let title = toml::from_str::<toml::Value>(&config)
        .ok()
        .and_then(|c| c.get("name")?.as_str().map(String::from))
        .unwrap_or_else(|| "run".into());
    let windows = windows_of(&trajectory);
    let shots = shots_of(&trajectory);
    let measured = metrics
        .get("windows")
        .and_then(Value::as_array)
        .map_or(0, Vec::len);
    if !windows.is_empty() && measured > 0 && measured != windows.len() {
        bail!(
            "{}: key `windows` lists {measured} windows, the run's trajectory.json {}",
            metrics_file.display(),
            windows.len()
        );
    }
    let along = read_frame_metrics(&dir.join(FRAME_METRICS_FILE))?;
    let video = video_of(dir)?;
    Ok(RunReport {
        title,
        folder: dir.display().to_string(),
        summary: summary_of(&metrics),
        verdict: verdict_of(&metrics),
        metrics: window_table(&metrics),
        keyframes: keyframes(dir, &along, windows.len())?,
        history: read_history(&dir.join("history.csv"))?,
        view: scene.map(|s| scene_view(s, &trajectory)),
        along,
        windows,
        shots,
        video,
        config,
    })
}

/// The per-window numbers of `metrics.json` the report tabulates and plots.
const WINDOW_FIGURES: [&str; 8] = [
    "samples",
    "tce",
    "tre",
    "iou",
    "coverage",
    "visible_fraction",
    "tce_max",
    "tre_max",
];

/// Refuses a `metrics.json` that is not what a run writes (an object with a `windows` list
/// of objects whose figures are numbers, and a `run` object), and a scene whose Gaussian
/// count is not the run's `run.gaussians` (another scene's views would be drawn under this
/// run's path).
fn check_metrics(metrics: &Value, file: &Path, scene: Option<&Scene>) -> Result<()> {
    let windows_ok = metrics
        .get("windows")
        .and_then(Value::as_array)
        .is_some_and(|w| w.iter().all(Value::is_object));
    if !windows_ok {
        bail!(
            "{}: key `windows` must be a list of objects (one per query window)",
            file.display()
        );
    }
    // The figures the window table reads are numbers, or null where undefined.
    for (i, w) in metrics["windows"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
    {
        for key in WINDOW_FIGURES {
            if let Some(v) = w.get(key)
                && !(v.is_number() || v.is_null())
            {
                bail!(
                    "{}: key `windows.{i}.{key}` = {v} must be a number (or null)",
                    file.display()
                );
            }
        }
    }
    let Some(run) = metrics.get("run").and_then(Value::as_object) else {
        bail!("{}: key `run` must be an object", file.display());
    };
    if let (Some(scene), Some(gaussians)) = (scene, run.get("gaussians")) {
        let Some(gaussians) = gaussians.as_u64() else {
            bail!("{}: key `run.gaussians` must be a count", file.display());
        };
        if gaussians != scene.len() as u64 {
            bail!(
                "the scene has {} Gaussians but this run's had {gaussians} ({} key \
                 `run.gaussians`): give the run's own scene (`--scene`)",
                scene.len(),
                file.display()
            );
        }
    }
    Ok(())
}

/// A JSON file of the run folder that a run always writes (so a missing one is an error).
fn read_json(path: &Path) -> Result<Value> {
    match splatraj_scene::input::read_text(path) {
        Ok(text) => serde_json::from_str(&text)
            .with_context(|| format!("{} is not valid JSON", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{} is missing: a run writes it before its report (is this a trajectory run's \
             folder?)",
            path.display()
        ),
        Err(e) => Err(e).with_context(|| format!("cannot read {}", path.display())),
    }
}

/// A JSON scalar as table text (numbers to 4 significant places).
fn cell(value: &Value) -> Option<String> {
    match value {
        Value::Number(n) => n.as_f64().map(|v| {
            if v.fract() == 0.0 && v.abs() < 1e9 {
                format!("{v}")
            } else {
                format!("{v:.4}")
            }
        }),
        Value::Bool(b) => Some(b.to_string()),
        Value::String(s) => Some(s.clone()),
        Value::Null => Some("–".into()),
        _ => None,
    }
}

fn summary_of(metrics: &Value) -> Vec<(String, String)> {
    let mut rows = Vec::new();
    if let Some(run) = metrics.get("run").and_then(Value::as_object) {
        rows.extend(
            run.iter()
                .filter_map(|(k, v)| Some((k.replace('_', " "), cell(v)?))),
        );
    }
    if let Some(ldj) = metrics.get("ldj").and_then(Value::as_object) {
        rows.extend(
            ldj.iter()
                .filter_map(|(k, v)| Some((format!("LDJ {k}"), cell(v)?))),
        );
    }
    rows
}

/// Every scalar of every window of `metrics.json`, one column per key (in first-seen order).
fn window_table(metrics: &Value) -> Table {
    let windows: Vec<&serde_json::Map<String, Value>> = metrics
        .get("windows")
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(Value::as_object).collect())
        .unwrap_or_default();
    // The usual columns first, in reading order; any others after them.
    let mut header: Vec<String> = [
        "window",
        "name",
        "samples",
        "tce",
        "tre",
        "iou",
        "coverage",
        "visible_fraction",
        "visible",
        "tce_max",
        "tre_max",
    ]
    .into_iter()
    .filter(|k| windows.iter().any(|w| w.contains_key(*k)))
    .map(String::from)
    .collect();
    for w in &windows {
        for (k, v) in w.iter() {
            if cell(v).is_some() && !header.contains(k) {
                header.push(k.clone());
            }
        }
    }
    let rows = windows
        .iter()
        .map(|w| {
            header
                .iter()
                .map(|k| w.get(k).and_then(cell).unwrap_or_default())
                .collect()
        })
        .collect();
    Table { header, rows }
}

/// Every window's failed checks, as `metrics.json` words them (None: no window has a verdict).
fn verdict_of(metrics: &Value) -> Option<Vec<String>> {
    let windows = metrics.get("windows").and_then(Value::as_array)?;
    let verdicts: Vec<&Value> = windows.iter().filter_map(|w| w.get("verdict")).collect();
    if verdicts.is_empty() {
        return None;
    }
    Some(
        verdicts
            .iter()
            .filter_map(|v| v.get("problems").and_then(Value::as_array))
            .flatten()
            .filter_map(|p| p.as_str().map(String::from))
            .collect(),
    )
}

fn windows_of(trajectory: &Value) -> Vec<Window> {
    let list = trajectory.get("windows").and_then(Value::as_array);
    list.map(|a| {
        a.iter()
            .map(|w| Window {
                query: w["query"].as_str().unwrap_or_default().to_string(),
                start: w["start"].as_f64().unwrap_or(0.0),
                end: w["end"].as_f64().unwrap_or(1.0),
                target_ratio: w["target_ratio"].as_f64().unwrap_or(f64::NAN),
            })
            .collect()
    })
    .unwrap_or_default()
}

/// The shots of `trajectory.json` (none in a file written before they were recorded).
fn shots_of(trajectory: &Value) -> Vec<Shot> {
    let list = trajectory.get("shots").and_then(Value::as_array);
    let strings = |v: &Value| -> Vec<String> {
        v.as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|s| s.as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    };
    list.map(|a| {
        a.iter()
            .map(|s| Shot {
                windows: s["windows"]
                    .as_array()
                    .map(|w| {
                        w.iter()
                            .filter_map(|i| i.as_u64().map(|i| i as usize))
                            .collect()
                    })
                    .unwrap_or_default(),
                queries: strings(&s["queries"]),
                start: s["start"].as_f64().unwrap_or(0.0),
                end: s["end"].as_f64().unwrap_or(1.0),
                cut_reason: s["cut_reason"].as_str().map(String::from),
            })
            .collect()
    })
    .unwrap_or_default()
}

fn read_csv(path: &Path) -> Result<Option<Csv>> {
    let text = match splatraj_scene::input::read_text(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
    };
    // Numbered from 1, as an editor shows them.
    let mut lines = text
        .lines()
        .zip(1..)
        .map(|(line, number)| (number, line))
        .filter(|(_, l)| !l.trim().is_empty());
    let header: Vec<String> = match lines.next() {
        Some((_, h)) => h.split(',').map(|s| s.trim().to_string()).collect(),
        None => return Ok(None),
    };
    let mut rows = Vec::new();
    for (number, line) in lines {
        let row: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
        if row.len() != header.len() {
            bail!(
                "{}: line {number}: {} fields, but the header has {}",
                path.display(),
                row.len(),
                header.len()
            );
        }
        rows.push(row);
    }
    Ok(Some((header, rows)))
}

fn number(path: &Path, line: usize, column: &str, text: Option<&String>) -> Result<f64> {
    let text = text.with_context(|| format!("{}: line {line}: no `{column}`", path.display()))?;
    text.parse().with_context(|| {
        format!(
            "{}: line {line}: `{column}` = {text:?} is not a number",
            path.display()
        )
    })
}

fn read_frame_metrics(path: &Path) -> Result<Vec<FrameMetrics>> {
    let Some((header, rows)) = read_csv(path)? else {
        return Ok(Vec::new());
    };
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{}: no `{name}` column", path.display()))
    };
    let [t, window, tce, tre, coverage] = [
        column("t")?,
        column("window")?,
        column("tce")?,
        column("tre")?,
        column("coverage")?,
    ];
    rows.iter()
        .enumerate()
        .map(|(i, row)| {
            let get = |c: usize, name: &str| number(path, i + 2, name, row.get(c));
            Ok(FrameMetrics {
                t: get(t, "t")?,
                window: get(window, "window")? as usize,
                // An empty cell: the frame does not show its object (undefined TCE).
                tce: match row.get(tce) {
                    Some(cell) if cell.is_empty() => None,
                    cell => Some(number(path, i + 2, "tce", cell)?),
                },
                tre: get(tre, "tre")?,
                coverage: get(coverage, "coverage")?,
            })
        })
        .collect()
}

/// `history.csv` as one series per cost term (its `q<i>_<term>` columns summed) and the total.
fn read_history(path: &Path) -> Result<Option<CostHistory>> {
    let Some((header, rows)) = read_csv(path)? else {
        return Ok(None);
    };
    let mut terms: Vec<(String, Vec<usize>)> = Vec::new();
    for (c, name) in header.iter().enumerate() {
        let Some(term) = name
            .strip_prefix('q')
            .and_then(|rest| rest.split_once('_'))
            .filter(|(i, _)| i.parse::<usize>().is_ok())
            .map(|(_, term)| term.to_string())
        else {
            continue;
        };
        match terms.iter_mut().find(|(t, _)| *t == term) {
            Some((_, columns)) => columns.push(c),
            None => terms.push((term, vec![c])),
        }
    }
    // Every run's history has the total: without it, this is not a run's history.
    let Some(total) = header.iter().position(|h| h == "total") else {
        bail!(
            "{}: line 1: no `total` column, so not a run's history.csv (its header is {:?})",
            path.display(),
            header.join(",")
        );
    };
    terms.push(("total".into(), vec![total]));
    let mut series: Vec<(String, Vec<f64>)> =
        terms.iter().map(|(t, _)| (t.clone(), Vec::new())).collect();
    for (i, row) in rows.iter().enumerate() {
        for ((term, columns), (_, values)) in terms.iter().zip(&mut series) {
            let mut sum = 0.0;
            for &c in columns {
                sum += number(path, i + 2, term, row.get(c))?;
            }
            values.push(sum);
        }
    }
    Ok(Some(CostHistory {
        steps: (0..rows.len()).map(|s| s as f64).collect(),
        terms: series,
    }))
}

/// Up to [`crate::outputs::path_render::KEYFRAMES_PER_WINDOW`] frames of each window, evenly spread over its frames
/// ([`keyframe_indices`]): the tinted copies in `keyframes/` when the run wrote them, else the
/// frames themselves.
fn keyframes(dir: &Path, along: &[FrameMetrics], windows: usize) -> Result<Vec<Vec<Keyframe>>> {
    let frames_dir = dir.join("frames");
    let count = (0..)
        .take_while(|&i| frames_dir.join(frame_name(i)).is_file())
        .count();
    // Frame times: from the per-frame metrics, else evenly spaced as the run renders them.
    let times: Vec<f64> = if along.len() == count {
        along.iter().map(|f| f.t).collect()
    } else {
        uniform_times(count)
    };
    keyframe_indices(&times, windows)
        .into_iter()
        .map(|indices| {
            indices
                .into_iter()
                .map(|i| {
                    let name = frame_name(i);
                    let tinted = dir.join(KEYFRAMES_DIR).join(&name);
                    let path = if tinted.is_file() {
                        tinted
                    } else {
                        frames_dir.join(&name)
                    };
                    Ok(Keyframe {
                        t: times[i],
                        png: splatraj_scene::input::read_bytes(&path)
                            .with_context(|| format!("cannot read {}", path.display()))?,
                        name,
                    })
                })
                .collect()
        })
        .collect()
}

fn video_of(dir: &Path) -> Result<Option<VideoSource>> {
    let path = dir.join(VIDEO_FILE);
    let Ok(meta) = std::fs::metadata(&path) else {
        return Ok(None);
    };
    Ok(Some(if meta.len() as usize <= INLINE_VIDEO_BYTES {
        VideoSource::Inline(
            splatraj_scene::input::read_bytes(&path)
                .with_context(|| format!("cannot read {}", path.display()))?,
        )
    } else {
        VideoSource::Link(VIDEO_FILE.into())
    }))
}

/// The scene's opaque Gaussians (an even sample), the sampled path and the objects.
fn scene_view(scene: &Scene, trajectory: &Value) -> SceneView {
    let opaque: Vec<usize> = (0..scene.len())
        .filter(|&i| scene.opacities[i] >= VIEW_MIN_OPACITY)
        .collect();
    let stride = opaque.len().div_ceil(VIEW_POINTS).max(1);
    let points = opaque
        .iter()
        .step_by(stride)
        .map(|&i| {
            let colour = scene
                .base_color(i)
                .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
            (scene.means[i], colour)
        })
        .collect();
    let path = trajectory
        .get("poses")
        .and_then(Value::as_array)
        .map(|poses| {
            poses
                .iter()
                .filter_map(|p| {
                    let phi: [f64; 6] = serde_json::from_value(p.get("pose")?.clone()).ok()?;
                    let camera = CameraPose::from_phi(phi);
                    Some(PathSample {
                        centre: camera.centre.to_array(),
                        forward: camera.forward().to_array(),
                        window: p.get("window")?.as_u64()? as usize,
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    let objects = trajectory
        .get("windows")
        .and_then(Value::as_array)
        .map(|windows| {
            windows
                .iter()
                .filter_map(|w| {
                    let centre: [f64; 3] =
                        serde_json::from_value(w.get("object_centre")?.clone()).ok()?;
                    Some((w["query"].as_str().unwrap_or_default().to_string(), centre))
                })
                .collect()
        })
        .unwrap_or_default();
    let up = trajectory
        .get("world_up")
        .and_then(|u| serde_json::from_value(u.clone()).ok())
        .unwrap_or([0.0, 0.0, 1.0]);
    SceneView {
        up,
        points,
        path,
        objects,
    }
}

/// The scene a run folder's `config.toml` names: the demo room is made again; a file is looked
/// for where the run found it (`metrics.json`'s `run.scene`), then as the config names it from
/// the working directory and from the run folder.
pub fn run_scene(dir: &Path) -> Result<Scene> {
    let text = splatraj_scene::input::read_text(&dir.join("config.toml"))
        .with_context(|| format!("cannot read {}", dir.join("config.toml").display()))?;
    let config: toml::Value = toml::from_str(&text)
        .with_context(|| format!("{}: not valid TOML", dir.join("config.toml").display()))?;
    let scene = config.get("scene").context("config.toml has no [scene]")?;
    if let Some(demo) = scene.get("demo") {
        let defaults = DemoConfig::default();
        let number = |key: &str, default: u64| {
            demo.get(key)
                .and_then(toml::Value::as_integer)
                .map_or(default, |v| v as u64)
        };
        return Ok(demo_scene(&DemoConfig {
            seed: number("seed", defaults.seed),
            gaussians: number("gaussians", defaults.gaussians as u64) as usize,
        })?);
    }
    let named = scene
        .get("path")
        .and_then(toml::Value::as_str)
        .context("config.toml: [scene] names neither `path` nor `demo`")?;
    let run_saw = read_json(&dir.join("metrics.json"))?["run"]["scene"]
        .as_str()
        .map(PathBuf::from);
    let candidates: Vec<PathBuf> = run_saw
        .into_iter()
        .chain([PathBuf::from(named), dir.join(named)])
        .collect();
    let Some(found) = candidates.iter().find(|p| p.is_file()) else {
        bail!(
            "cannot find the run's scene {named:?} (looked at {}): give it with --scene",
            candidates
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    let options = ReadOptions {
        invalid: if scene.get("drop_invalid").and_then(toml::Value::as_bool) == Some(true) {
            InvalidPolicy::Drop
        } else {
            InvalidPolicy::Reject
        },
        labels: None,
    };
    Ok(read_scene(found, &options)?.scene)
}
