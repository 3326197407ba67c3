//! A study's rows aggregated per variant (mean ± sd over its seeds), the Pareto frontier of
//! error against optimisation time, the cheapest variant within 5 % of the best, the optional
//! table grouped by one factor, and `summary.md`.

use serde::{Deserialize, Serialize};

use super::Quality;
use super::plan::StudyPlan;
use super::rows::{StageTimes, StudyRow, WindowScore};
use super::text::short_value;

/// The TCE a study judges a window by when it never showed its object (its TCE is undefined):
/// that of an object in a corner of the frame, √½, the worst a seen object can have.
pub const UNSEEN_TCE: f64 = std::f64::consts::FRAC_1_SQRT_2;

impl Quality {
    /// The error of one evaluation (a window never showing its object counts [`UNSEEN_TCE`]).
    pub fn error(self, windows: &[WindowScore]) -> f64 {
        let one = |w: &WindowScore| match self {
            Quality::Framing => w.tce.unwrap_or(UNSEEN_TCE) + w.tre,
            Quality::Tce => w.tce.unwrap_or(UNSEEN_TCE),
            Quality::Tre => w.tre,
            Quality::Iou => 1.0 - w.iou,
        };
        windows.iter().map(one).sum::<f64>() / windows.len().max(1) as f64
    }

    /// What the error is, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Quality::Framing => "TCE + TRE, mean over windows",
            Quality::Tce => "TCE, mean over windows",
            Quality::Tre => "TRE, mean over windows",
            Quality::Iou => "1 − IoU, mean over windows",
        }
    }
}

/// Mean and sample standard deviation of some values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (0 for one value).
    pub sd: f64,
    /// How many values.
    pub n: usize,
}

impl Spread {
    /// The spread of the finite values (None when there are none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Spread> {
        let v: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let sd = if n > 1 {
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        Some(Spread { mean, sd, n })
    }

    /// `mean ± sd` with `digits` decimals (the mean alone for one value).
    pub fn show(&self, digits: usize) -> String {
        if self.n > 1 {
            format!("{:.digits$} ± {:.digits$}", self.mean, self.sd)
        } else {
            format!("{:.digits$}", self.mean)
        }
    }
}

fn show(spread: Option<Spread>, digits: usize) -> String {
    spread.map_or("–".into(), |s| s.show(digits))
}

/// The figures of a set of rows.
#[derive(Debug, Clone, Serialize)]
pub struct Figures {
    /// Rows pooled.
    pub rows: usize,
    /// The judged error.
    pub error: Option<Spread>,
    /// Mean TCE.
    pub tce: Option<Spread>,
    /// Mean TRE.
    pub tre: Option<Spread>,
    /// Mean IoU.
    pub iou: Option<Spread>,
    /// Share of poses showing the object.
    pub visible: Option<Spread>,
    /// LDJ of the camera centre.
    pub ldj_positional: Option<Spread>,
    /// LDJ of the rotation.
    pub ldj_angular: Option<Spread>,
    /// Optimisation wall time, seconds.
    pub optimisation_s: Option<Spread>,
    /// Whole-run wall time, seconds.
    pub run_s: Option<Spread>,
    /// Peak memory, MB.
    pub peak_mb: Option<Spread>,
    /// Smallest clearance from the geometry over the windows, scene units.
    pub min_clearance: Option<Spread>,
    /// Share of time inside the clearance margin.
    pub inside_margin: Option<Spread>,
    /// Mean per-stage times, when measured.
    pub stages: Option<StageTimes>,
}

impl Figures {
    /// The figures of `rows`.
    pub fn of(rows: &[&StudyRow]) -> Figures {
        let spread =
            |f: &dyn Fn(&StudyRow) -> Option<f64>| Spread::of(rows.iter().filter_map(|r| f(r)));
        let timed: Vec<StageTimes> = rows.iter().filter_map(|r| r.stages).collect();
        let stages = (!timed.is_empty()).then(|| {
            let n = timed.len() as f64;
            let mean = |f: fn(&StageTimes) -> f64| timed.iter().map(f).sum::<f64>() / n;
            StageTimes {
                projection_s: mean(|s| s.projection_s),
                binning_s: mean(|s| s.binning_s),
                compositing_s: mean(|s| s.compositing_s),
                costs_s: mean(|s| s.costs_s),
                backward_s: mean(|s| s.backward_s),
                optimiser_s: mean(|s| s.optimiser_s),
                decide_s: mean(|s| s.decide_s),
                composite_backward_s: mean(|s| s.composite_backward_s),
            }
        });
        Figures {
            rows: rows.len(),
            error: spread(&|r| Some(r.error)),
            tce: spread(&|r| r.tce),
            tre: spread(&|r| Some(r.tre)),
            iou: spread(&|r| Some(r.iou)),
            visible: spread(&|r| Some(r.visible)),
            ldj_positional: spread(&|r| r.ldj_positional),
            ldj_angular: spread(&|r| r.ldj_angular),
            optimisation_s: spread(&|r| Some(r.optimisation_s)),
            run_s: spread(&|r| Some(r.run_s)),
            peak_mb: spread(&|r| r.peak_mb),
            min_clearance: spread(&|r| r.min_clearance),
            inside_margin: spread(&|r| r.inside_margin),
            stages,
        }
    }

    /// (mean optimisation time, mean error): the variant's point on the frontier plot.
    pub fn point(&self) -> (f64, f64) {
        (
            self.optimisation_s.map_or(f64::NAN, |s| s.mean),
            self.error.map_or(f64::NAN, |s| s.mean),
        )
    }
}

/// One variant's aggregate.
#[derive(Debug, Clone, Serialize)]
pub struct VariantSummary {
    /// Variant index.
    pub variant: usize,
    /// Its label.
    pub label: String,
    /// Its figures over its rows.
    pub figures: Figures,
    /// Whether no other variant is at least as fast and as good, and better in one.
    pub on_frontier: bool,
}

/// Rows grouped by the value of one factor.
#[derive(Debug, Clone, Serialize)]
pub struct Grouping {
    /// The factor's key.
    pub key: String,
    /// `(value, figures)` in the order the values first appear.
    pub groups: Vec<(String, Figures)>,
}

/// Everything `summary.md` and `frontier.svg` show.
#[derive(Debug, Clone, Serialize)]
pub struct StudySummary {
    /// The error judged.
    pub quality: Quality,
    /// One per variant that has rows, in plan order.
    pub variants: Vec<VariantSummary>,
    /// Frontier variants (indices into `variants`), fastest first.
    pub frontier: Vec<usize>,
    /// The variant with the lowest mean error (index into `variants`).
    pub best: Option<usize>,
    /// The fastest variant whose mean error is within 5 % of the best's (index into
    /// `variants`).
    pub cheapest_within_5_percent: Option<usize>,
    /// The rows grouped by `table_by`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grouping: Option<Grouping>,
}

/// For each point (time, error), whether it is on the Pareto frontier: no other point has
/// time ≤ and error ≤ with one of them strictly smaller. Points with a non-finite coordinate
/// are never on it. Sorted by time, a point is on the frontier when its error is the lowest
/// of its time and below every faster point's.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    order.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut on = vec![false; points.len()];
    let mut best = f64::INFINITY;
    let mut i = 0;
    while i < order.len() {
        let time = points[order[i]].0;
        let same_time: Vec<usize> = order[i..]
            .iter()
            .copied()
            .take_while(|&j| points[j].0 == time)
            .collect();
        let lowest = points[same_time[0]].1;
        if lowest < best {
            for &j in same_time.iter().filter(|&&j| points[j].1 == lowest) {
                on[j] = true;
            }
            best = lowest;
        }
        i += same_time.len();
    }
    on
}

impl StudySummary {
    /// The summary of `rows` of `plan`.
    pub fn new(plan: &StudyPlan, rows: &[StudyRow]) -> StudySummary {
        let mut variants: Vec<VariantSummary> = plan
            .variants
            .iter()
            .filter_map(|v| {
                let mine: Vec<&StudyRow> = rows.iter().filter(|r| r.variant == v.index).collect();
                (!mine.is_empty()).then(|| VariantSummary {
                    variant: v.index,
                    label: v.label.clone(),
                    figures: Figures::of(&mine),
                    on_frontier: false,
                })
            })
            .collect();
        let points: Vec<(f64, f64)> = variants.iter().map(|v| v.figures.point()).collect();
        for (v, on) in variants.iter_mut().zip(pareto_front(&points)) {
            v.on_frontier = on;
        }
        let mut frontier: Vec<usize> = (0..variants.len())
            .filter(|&i| variants[i].on_frontier)
            .collect();
        frontier.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
        let finite =
            || (0..points.len()).filter(|&i| points[i].0.is_finite() && points[i].1.is_finite());
        let best = finite().min_by(|&a, &b| points[a].1.total_cmp(&points[b].1));
        let cheapest_within_5_percent = best.and_then(|b| {
            let bound = points[b].1 + 0.05 * points[b].1.abs();
            finite()
                .filter(|&i| points[i].1 <= bound)
                .min_by(|&a, &c| points[a].0.total_cmp(&points[c].0))
        });
        let grouping = plan.table_by.as_ref().map(|key| {
            let mut groups: Vec<(String, Vec<&StudyRow>)> = Vec::new();
            for r in rows {
                let value = plan.variants[r.variant]
                    .settings
                    .iter()
                    .find(|(k, _)| k == key)
                    .map_or_else(
                        || {
                            format!(
                                "{} (config)",
                                plan.baseline_value.as_deref().unwrap_or("as configured")
                            )
                        },
                        |(_, v)| short_value(v),
                    );
                match groups.iter_mut().find(|(g, _)| *g == value) {
                    Some((_, members)) => members.push(r),
                    None => groups.push((value, vec![r])),
                }
            }
            Grouping {
                key: key.clone(),
                groups: groups
                    .into_iter()
                    .map(|(v, members)| (v, Figures::of(&members)))
                    .collect(),
            }
        });
        StudySummary {
            quality: plan.quality,
            variants,
            frontier,
            best,
            cheapest_within_5_percent,
            grouping,
        }
    }

    /// `summary.md`: what was run, every variant, the frontier, the cheapest setting within
    /// 5 % of the best, the grouped table and the stage times.
    pub fn markdown(&self, plan: &StudyPlan, context: &StudyContext) -> String {
        let mut md = format!("# Study of `{}`\n\n", plan.name);
        md += &format!(
            "- config: `{}`{}\n- design: {}, {} seed(s) per variant, {} task\n- judged by: {} \
             (lower is better), from one fixed evaluation at {} poses per window ({})\n- machine: {}\n",
            plan.config.display(),
            if plan.base_overrides.is_empty() {
                String::new()
            } else {
                format!(" with `{}`", plan.base_overrides.join("`, `"))
            },
            match plan.design {
                super::Design::OneAtATime => "one factor at a time",
                super::Design::Grid => "full grid",
            },
            plan.seeds,
            match plan.task {
                super::StudyTask::Trajectory => "trajectory",
                super::StudyTask::Pose => "single-pose",
            },
            self.quality.describe(),
            plan.evaluation.samples,
            context.evaluation,
            context.machine,
        );
        if let Some(command) = &context.command {
            md += &format!("- regenerate: `{command}`\n");
        }
        md += "\n## Variants\n\nMean ± sd over seeds (starts for single-pose runs); times in \
               seconds of wall time; peak memory of the run's own process.\n\n";
        // Clearance columns only when the base config keeps a clearance (else they are empty).
        let clearance = self
            .variants
            .iter()
            .any(|v| v.figures.min_clearance.is_some());
        let (head, rule) = if clearance {
            (" min clearance | time inside margin |", "---|---|")
        } else {
            ("", "")
        };
        md += &format!(
            "| variant | error | TCE | TRE | IoU | visible | LDJ pos | LDJ ang |{head} \
             optimisation s | run s | peak MB | frontier |\n"
        );
        md += &format!("|---|---|---|---|---|---|---|---|{rule}---|---|---|---|\n");
        for v in &self.variants {
            let f = &v.figures;
            let clearance_cells = if clearance {
                format!(
                    " {} | {} |",
                    show(f.min_clearance, 3),
                    show(f.inside_margin, 3)
                )
            } else {
                String::new()
            };
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |{clearance_cells} {} | {} | {} | {} |\n",
                v.label,
                show(f.error, 4),
                show(f.tce, 4),
                show(f.tre, 4),
                show(f.iou, 3),
                show(f.visible, 2),
                show(f.ldj_positional, 2),
                show(f.ldj_angular, 2),
                show(f.optimisation_s, 2),
                show(f.run_s, 2),
                show(f.peak_mb, 0),
                if v.on_frontier { "yes" } else { "" }
            );
        }
        md += "\n## Frontier\n\nThe variants no other variant beats in both optimisation time \
               and error, fastest first.\n\n| variant | optimisation s | error |\n|---|---|---|\n";
        for &i in &self.frontier {
            let v = &self.variants[i];
            md += &format!(
                "| {} | {} | {} |\n",
                v.label,
                show(v.figures.optimisation_s, 2),
                show(v.figures.error, 4)
            );
        }
        match (self.best, self.cheapest_within_5_percent) {
            (Some(b), Some(c)) => {
                let (best, cheap) = (&self.variants[b], &self.variants[c]);
                md += &format!(
                    "\nCheapest setting within 5 % of the best error: **{}** (error {}, {} s) \
                     against the best, {} (error {}, {} s).\n",
                    cheap.label,
                    show(cheap.figures.error, 4),
                    show(cheap.figures.optimisation_s, 2),
                    best.label,
                    show(best.figures.error, 4),
                    show(best.figures.optimisation_s, 2),
                );
            }
            _ => md += "\nNo variant has a finite error and time.\n",
        }
        if let Some(g) = &self.grouping {
            md += &format!(
                "\n## By `{}`\n\nMean ± sd over every row with that value (seeds, starts and \
                 the other factors pooled).\n\n| {} | rows | TCE | TRE | IoU | LDJ ang | LDJ pos | optimisation s |\n|---|---|---|---|---|---|---|---|\n",
                g.key, g.key
            );
            for (value, f) in &g.groups {
                md += &format!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    value,
                    f.rows,
                    show(f.tce, 3),
                    show(f.tre, 3),
                    show(f.iou, 3),
                    show(f.ldj_angular, 2),
                    show(f.ldj_positional, 2),
                    show(f.optimisation_s, 2)
                );
            }
        }
        if self.variants.iter().any(|v| v.figures.stages.is_some()) {
            md += "\n## Where the optimisation time goes\n\nSeconds per run, summed over steps \
                   (forward stages as the renderer's clock measures them); a bracketed column is the part \
                   of the stage before it.\n\n| variant | projection | (decide) | binning | compositing | costs | backward | (composite backward) | optimiser |\n|---|---|---|---|---|---|---|---|---|\n";
            for v in &self.variants {
                if let Some(s) = v.figures.stages {
                    md += &format!("| {} |", v.label);
                    for (_, value) in s.entries() {
                        md += &format!(" {value:.2} |");
                    }
                    md += "\n";
                }
            }
        }
        md
    }
}

/// What `summary.md` says about where and how a study ran.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct StudyContext {
    /// The machine (cores, CPU).
    pub machine: String,
    /// The evaluation's size and renderer, in words.
    pub evaluation: String,
    /// The command that regenerates the study, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_is_the_sample_standard_deviation() {
        let s = Spread::of([1.0, 2.0, 3.0, f64::NAN]).unwrap();
        assert_eq!((s.mean, s.n), (2.0, 3));
        assert!((s.sd - 1.0).abs() < 1e-12);
        assert_eq!(Spread::of([5.0]).unwrap().sd, 0.0);
        assert!(Spread::of([f64::NAN]).is_none());
    }

    #[test]
    fn ties_and_slower_equals_on_the_frontier() {
        let points = [
            (1.0, 3.0),
            (1.0, 3.0),
            (2.0, 3.0),
            (2.0, 1.0),
            (0.5, 5.0),
            (3.0, f64::NAN),
        ];
        assert_eq!(
            pareto_front(&points),
            [true, true, false, true, true, false]
        );
    }
}
