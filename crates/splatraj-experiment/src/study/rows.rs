//! One measured row per run and seed (or per start of a pose run): `study.csv` and the rows
//! of `study.json`.

use serde::{Deserialize, Serialize};
use splatraj_traj::metrics::WindowMetrics;

use crate::outputs::Csv;

/// Where the optimisation's time went, seconds (summed over its steps).
///
/// Projection, binning and compositing are the renders' forward stages; backward is the
/// backward pass through renders and costs; costs is the cost evaluation on the rendered
/// images; optimiser is Adam's update and the bookkeeping around it.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct StageTimes {
    /// Gaussians to screen space (and SH, per-Gaussian channels).
    pub projection_s: f64,
    /// Culling, tile lists, depth order.
    pub binning_s: f64,
    /// Compositing the tiles.
    pub compositing_s: f64,
    /// Costs on the rendered images and poses.
    pub costs_s: f64,
    /// The backward pass.
    pub backward_s: f64,
    /// Adam's step and the rest of the loop.
    pub optimiser_s: f64,
    /// Of `projection_s`: the renderer's host decisions (cull, screen position, radius,
    /// depth), the rest being the differentiable projection.
    #[serde(default)]
    pub decide_s: f64,
    /// Of `backward_s`: the fused compositing's own backward, the rest being burn's autodiff
    /// through projection and costs (0 for the tensor rasterizer, whose backward is all
    /// autodiff).
    #[serde(default)]
    pub composite_backward_s: f64,
}

impl StageTimes {
    /// The stages' names and values, in order; a `decide_s` and `composite_backward_s` part
    /// follows the stage it is part of.
    pub fn entries(&self) -> [(&'static str, f64); 8] {
        [
            ("projection_s", self.projection_s),
            ("decide_s", self.decide_s),
            ("binning_s", self.binning_s),
            ("compositing_s", self.compositing_s),
            ("costs_s", self.costs_s),
            ("backward_s", self.backward_s),
            ("composite_backward_s", self.composite_backward_s),
            ("optimiser_s", self.optimiser_s),
        ]
    }
}

/// One measured run (one seed, or one start of a pose run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StudyRow {
    /// Run index in the plan.
    pub run: usize,
    /// Variant index in the plan.
    pub variant: usize,
    /// The variant's label.
    pub label: String,
    /// Repeat index: the seed offset (trajectory) or the start (pose).
    pub repeat: usize,
    /// The run's config seed.
    pub seed: u64,
    /// Wall time of the optimisation, seconds (a pose run's whole batch).
    pub optimisation_s: f64,
    /// Wall time of the variant's whole run (config, scene, targets, optimisation), seconds.
    pub run_s: f64,
    /// Peak resident memory of the run's process up to the end of the optimisation (MB;
    /// none when runs shared a process).
    pub peak_mb: Option<f64>,
    /// Optimisation steps run.
    pub iterations: usize,
    /// The best sampled loss of the optimisation (its own estimate, not the evaluation's).
    pub best_total: f64,
    /// Per-stage times, when measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stages: Option<StageTimes>,
    /// The judged error (see the plan's quality; lower is better).
    pub error: f64,
    /// Mean over windows of the evaluation's TCE (`None` when a window never shows its object).
    pub tce: Option<f64>,
    /// Mean over windows of the evaluation's TRE.
    pub tre: f64,
    /// Mean over windows of the evaluation's IoU.
    pub iou: f64,
    /// Mean over windows of the share of samples that show the object.
    pub visible: f64,
    /// LDJ of the camera centre (trajectory runs).
    pub ldj_positional: Option<f64>,
    /// LDJ of the rotation (trajectory runs).
    pub ldj_angular: Option<f64>,
    /// Smallest clearance of the camera from the scene's geometry over every window, scene
    /// units (when the base config has a clearance cost: a setting can trade it for framing,
    /// which TCE and TRE do not show).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_clearance: Option<f64>,
    /// Mean over windows of the share of time closer to the geometry than the margin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inside_margin: Option<f64>,
    /// The evaluation per window.
    pub windows: Vec<WindowScore>,
}

/// One window's evaluation (the figures of [`WindowMetrics`] a study keeps).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowScore {
    /// The query.
    pub name: String,
    /// Mean TCE over the evaluation's poses (`None`: the object was never in view).
    pub tce: Option<f64>,
    /// Mean TRE.
    pub tre: f64,
    /// Mean bounding-box IoU.
    pub iou: f64,
    /// Share of poses that show the object.
    pub visible_fraction: f64,
    /// Mean share of the frame the object covers.
    pub coverage: f64,
    /// Worst TCE (`None`: the object was never in view).
    pub tce_max: Option<f64>,
    /// Worst TRE.
    pub tre_max: f64,
    /// Smallest clearance from the geometry (when the clearance cost is on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_clearance: Option<f64>,
    /// Share of the window's time inside the clearance margin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_inside_margin: Option<f64>,
}

impl From<&WindowMetrics> for WindowScore {
    fn from(m: &WindowMetrics) -> Self {
        let clearance = m.path.as_ref().and_then(|p| p.clearance.as_ref());
        WindowScore {
            name: m.name.clone(),
            tce: m.tce,
            tre: m.tre,
            iou: m.iou,
            visible_fraction: m.visible_fraction,
            coverage: m.coverage,
            tce_max: m.tce_max,
            tre_max: m.tre_max,
            min_clearance: clearance.map(|c| c.min_clearance),
            time_inside_margin: clearance.map(|c| c.time_inside_margin),
        }
    }
}

impl StudyRow {
    /// The row with everything that depends on time and memory left out (what two runs of
    /// the same plan must agree on).
    pub fn without_times(&self) -> StudyRow {
        StudyRow {
            optimisation_s: 0.0,
            run_s: 0.0,
            peak_mb: None,
            stages: None,
            ..self.clone()
        }
    }
}

/// `study.csv`: one line per row, every figure (per-window values as `w<i>_<metric>`).
pub fn study_csv(rows: &[StudyRow]) -> Csv {
    let windows = rows.iter().map(|r| r.windows.len()).max().unwrap_or(0);
    let mut header: Vec<String> = [
        "run",
        "variant",
        "label",
        "repeat",
        "seed",
        "optimisation_s",
        "run_s",
        "peak_mb",
        "iterations",
        "best_total",
        "error",
        "tce",
        "tre",
        "iou",
        "visible",
        "ldj_positional",
        "ldj_angular",
        "min_clearance",
        "inside_margin",
    ]
    .map(String::from)
    .to_vec();
    header.extend(StageTimes::default().entries().map(|(n, _)| n.to_string()));
    for w in 0..windows {
        for m in ["tce", "tre", "iou", "visible_fraction"] {
            header.push(format!("w{w}_{m}"));
        }
    }
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    let body = rows
        .iter()
        .map(|r| {
            let mut row = vec![
                r.run.to_string(),
                r.variant.to_string(),
                csv_field(&r.label),
                r.repeat.to_string(),
                r.seed.to_string(),
                r.optimisation_s.to_string(),
                r.run_s.to_string(),
                opt(r.peak_mb),
                r.iterations.to_string(),
                r.best_total.to_string(),
                r.error.to_string(),
                opt(r.tce),
                r.tre.to_string(),
                r.iou.to_string(),
                r.visible.to_string(),
                opt(r.ldj_positional),
                opt(r.ldj_angular),
                opt(r.min_clearance),
                opt(r.inside_margin),
            ];
            row.extend(
                StageTimes::default()
                    .entries()
                    .iter()
                    .enumerate()
                    .map(|(i, _)| opt(r.stages.map(|s| s.entries()[i].1))),
            );
            for w in 0..windows {
                match r.windows.get(w) {
                    Some(m) => {
                        row.push(opt(m.tce));
                        row.extend([m.tre, m.iou, m.visible_fraction].map(|v| v.to_string()))
                    }
                    None => row.extend(std::iter::repeat_n(String::new(), 4)),
                }
            }
            row
        })
        .collect();
    (header, body)
}

/// A CSV field, quoted when it holds a comma or a quote.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}
