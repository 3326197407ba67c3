//! What a study says to the person running it, line by line: the plan before the first run, the
//! check's verdict of a dry run, each measured row, the cheapest good variant and a merge. The
//! command prints these; the words live here so every front end says the same.

use crate::resources::show_bytes;
use crate::study::{Shard, StudyCheck, StudyFile, StudyPlan, StudyRow};

impl StudyPlan {
    /// The plan before its first run: a line for the study (and the shard's share of
    /// `runs` runs), then one per variant with its overrides.
    pub fn outline(&self, runs: usize, shard: Option<Shard>) -> Vec<String> {
        let share = shard
            .map(|s| format!(", shard {}/{}: {runs} run(s)", s.index, s.count))
            .unwrap_or_default();
        let head = format!(
            "study of {}: {} variant(s), {} run(s){share}",
            self.name,
            self.variants.len(),
            self.runs.len()
        );
        std::iter::once(head)
            .chain(self.variants.iter().map(|v| {
                format!(
                    "  variant {}: {}  [{}]",
                    v.index,
                    v.label,
                    v.overrides.join(" ")
                )
            }))
            .collect()
    }
}

impl StudyCheck {
    /// A dry run's verdict: the variants prepared and the largest memory stage.
    pub fn summary(&self) -> String {
        let peak = self
            .peak
            .as_ref()
            .map(|p| format!("; peak memory about {} ({})", show_bytes(p.bytes), p.what))
            .unwrap_or_default();
        format!("check passed: {} variant(s) prepared{peak}", self.variants)
    }
}

impl StudyRow {
    /// The progress line of this row, after `at` (the run's place and label).
    pub fn progress_line(&self, at: &str) -> String {
        format!(
            "{at} (repeat {}): error {:.4}, optimisation {:.2} s, peak {}",
            self.repeat,
            self.error,
            self.optimisation_s,
            self.peak_mb.map_or("–".into(), |m| format!("{m:.0} MB"))
        )
    }
}

impl StudyFile {
    /// The variant within 5 % of the best error at the least cost, when the summary has one.
    pub fn cheapest_line(&self) -> Option<String> {
        let summary = self.summary.as_ref()?;
        let cheapest = summary.cheapest_within_5_percent?;
        Some(format!(
            "cheapest within 5 % of the best error: {}",
            summary.variants[cheapest].label
        ))
    }

    /// What `study merge` of `folders` folders made.
    pub fn merged_line(&self, folders: usize) -> String {
        format!(
            "merged {folders} folder(s): {} rows of {} runs, {} failed",
            self.rows.len(),
            self.plan.runs.len(),
            self.failures.len()
        )
    }
}
