//! `[study]`: the variants `splatraj study` runs and how it judges them (the study itself is
//! [`crate::study`]).

use serde::{Deserialize, Serialize};
use splatraj_config::ConfigError;

/// How factors combine into variants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Design {
    /// The config itself, then each factor's values with every other key as configured.
    #[default]
    OneAtATime,
    /// Every combination of the factors' values.
    Grid,
}

/// The error a study judges variants by (lower is better), averaged over the windows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Quality {
    /// TCE + TRE: how well each object is centred and sized (the paper's image costs).
    #[default]
    Framing,
    /// TCE alone.
    Tce,
    /// TRE alone.
    Tre,
    /// 1 − IoU: how much of each object is hidden.
    Iou,
}

/// What each run of a study does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StudyTask {
    /// `splatraj run`'s optimisation: a trajectory through every query window.
    #[default]
    Trajectory,
    /// `splatraj pose`'s optimisation: one pose for `pose.query` (the paper's Table I); the
    /// seeds are the batch's random starts, one row each.
    Pose,
}

/// `[study]`: the variants of a study and how they are judged.
///
/// ```toml
/// [study]
/// design = "one-at-a-time"   # or "grid": every combination of the factors' values
/// seeds = 3                  # repeats per variant (seed, seed + 1, …): mean ± sd
/// quality = "framing"        # framing (TCE + TRE) | tce | tre | iou (1 − IoU): the error judged
/// task = "trajectory"        # or "pose" (single pose, `[pose]`)
/// table_by = "pose.ablation" # also tabulate grouped by this factor (optional)
/// [[study.vary]]
/// key = "optimiser.iterations"
/// values = [50, 100, 200]
/// [[study.vary]]
/// key = "camera"             # a table value sets each of its keys (merged, as `extends` does)
/// values = [{ width = 64, height = 48 }, { width = 256, height = 192 }]
/// [study.evaluation]         # the fixed evaluation every variant is judged by
/// width = 320
/// height = 240
/// samples = 32
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StudyConfig {
    /// The factors, in order (none: the default sweep of every accuracy-for-time knob).
    pub vary: Vec<FactorConfig>,
    /// One factor at a time around the config, or the full grid.
    pub design: Design,
    /// Repeats of every variant with seeds `seed`, `seed + 1`, … (≥ 1).
    pub seeds: usize,
    /// The error a variant is judged by (lower is better).
    pub quality: Quality,
    /// Trajectory or single-pose optimisation.
    pub task: StudyTask,
    /// A factor key to also tabulate by (rows grouped by its value, other factors pooled).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table_by: Option<String>,
    /// The fixed evaluation.
    pub evaluation: EvaluationConfig,
}

impl Default for StudyConfig {
    fn default() -> Self {
        Self {
            vary: Vec::new(),
            design: Design::OneAtATime,
            seeds: 1,
            quality: Quality::Framing,
            task: StudyTask::Trajectory,
            table_by: None,
            evaluation: EvaluationConfig::default(),
        }
    }
}

/// `[[study.vary]]`: one factor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FactorConfig {
    /// A config key, dotted as `--set` writes it.
    pub key: String,
    /// Its values (a table sets each of its keys).
    pub values: Vec<toml::Value>,
}

/// `[study.evaluation]`: the one evaluation every variant is judged by, built from the base
/// config (never from a variant), with the exact renderer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvaluationConfig {
    /// Image width, pixels (default: `output.width`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width: Option<usize>,
    /// Image height, pixels (default: `output.height`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height: Option<usize>,
    /// Poses per query window on a fixed grid (≥ 1).
    pub samples: usize,
    /// Samples of the whole trajectory for LDJ.
    pub ldj_samples: usize,
}

impl Default for EvaluationConfig {
    /// 32 poses per window at the output size; LDJ from the output default.
    fn default() -> Self {
        Self {
            width: None,
            height: None,
            samples: 32,
            ldj_samples: splatraj_traj::metrics::DEFAULT_LDJ_SAMPLES,
        }
    }
}

impl StudyConfig {
    /// Whether nothing is set (the table is then left out of a written config).
    pub fn is_default(&self) -> bool {
        *self == StudyConfig::default()
    }

    /// Range checks; errors name the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |key: String, reason: String| Err(ConfigError::new(key, reason));
        if self.seeds == 0 {
            return bad("study.seeds".into(), "must be ≥ 1".into());
        }
        if self.evaluation.samples == 0 {
            return bad("study.evaluation.samples".into(), "must be ≥ 1".into());
        }
        if self.evaluation.width == Some(0) || self.evaluation.height == Some(0) {
            return bad(
                "study.evaluation.width".into(),
                "and `height` must be ≥ 1".into(),
            );
        }
        if self.evaluation.ldj_samples < splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES {
            return bad(
                "study.evaluation.ldj_samples".into(),
                format!("must be ≥ {}", splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES),
            );
        }
        for (i, f) in self.vary.iter().enumerate() {
            if f.key.trim().is_empty() {
                return bad(format!("study.vary.{i}.key"), "is empty".into());
            }
            if f.values.is_empty() {
                return bad(
                    format!("study.vary.{i}.values"),
                    format!("is empty ({})", f.key),
                );
            }
        }
        Ok(())
    }
}
