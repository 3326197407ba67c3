//! `[output]`: what a run writes and where.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use splatraj_config::ConfigError;
use splatraj_report::video::{MAX_FPS, MIN_FPS, check_fps};
use splatraj_traj::transitions::TransitionMode;

/// Overlay of the target's mask on the output frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MaskOverlay {
    /// Plain RGB frames.
    #[default]
    None,
    /// The current window's object tinted.
    Tint,
}

/// What a run whose verdict fails on some window does after writing its folder
/// (`splatraj_traj::metrics::verdict`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VerdictPolicy {
    /// Warn and exit with status 3, so that scripts notice (the default).
    #[default]
    Fail,
    /// Warn, and exit 0 (a study's variants, smoke runs).
    Warn,
}

/// `[output]`: what is written and where.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Folder that holds `<name>/<timestamp>/` run folders (relative to the working
    /// directory, unlike input paths).
    pub runs_dir: PathBuf,
    /// Frames rendered along the whole trajectory (0: none), at evenly spaced times over
    /// [0, 1]; ignored when `seconds` is given. Default: `fps ×` the duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    /// Frame rate of `video.mp4` and of the exports (`exports/<format>/`), frames per second.
    pub fps: f64,
    /// Length of the video in seconds: when given, `fps × seconds` frames (rounded) are
    /// rendered instead of `frames`. Default: `frames / fps` when `frames` is given, else
    /// [`SECONDS_PER_QUERY`] per query.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Mask overlay on the frames.
    pub mask_overlay: MaskOverlay,
    /// What a failed verdict does: `fail` (exit status 3, the default) or `warn`.
    pub verdict: VerdictPolicy,
    /// Poses written to `trajectory.json` (evenly spaced over [0, 1]).
    pub trajectory_samples: usize,
    /// Samples per window for the metrics (default 30: 18 in the middle 60 % the verdict's
    /// `framed_share` judges, one every 0.1 s of a 3 s window).
    pub metric_samples: usize,
    /// Samples of the whole trajectory for LDJ.
    pub ldj_samples: usize,
    /// How consecutive windows are joined: `"pan"`, `"cut"` (each window its own shot) or
    /// `"auto"` (the default: cut where a pan would break the pacing limits, hide a part or
    /// need a long route; `splatraj_traj::transitions`).
    pub transitions: TransitionMode,
}

/// Seconds of video per query when neither `frames` nor `seconds` is given: long enough to
/// see an object and the move to the next, short enough that three parts make a 9 s clip.
pub const SECONDS_PER_QUERY: f64 = 3.0;

/// The smallest output side: one H.264 macroblock. A 1 × 1 output failed in OpenH264 only
/// after the whole optimisation (the adversarial trial); 16 × 16 encodes (checked by hand).
pub const MIN_VIDEO_SIDE: usize = 16;

impl Default for OutputConfig {
    /// 1280 × 720 at 30 fps, [`SECONDS_PER_QUERY`] per query, plain frames (the report's
    /// keyframes tint the object).
    fn default() -> Self {
        Self {
            runs_dir: PathBuf::from("runs"),
            frames: None,
            fps: 30.0,
            seconds: None,
            width: 1280,
            height: 720,
            mask_overlay: MaskOverlay::None,
            verdict: VerdictPolicy::Fail,
            trajectory_samples: 201,
            metric_samples: 30,
            ldj_samples: splatraj_traj::metrics::DEFAULT_LDJ_SAMPLES,
            transitions: TransitionMode::Auto,
        }
    }
}

impl OutputConfig {
    /// Frames to render for `queries` windows: `fps × seconds` (rounded, at least 1) when
    /// `seconds` is given, else `frames`, else `fps ×` [`SECONDS_PER_QUERY`] per query.
    pub fn frame_count(&self, queries: usize) -> usize {
        match (self.seconds, self.frames) {
            (Some(s), _) => ((self.fps * s).round() as usize).max(1),
            (None, Some(frames)) => frames,
            (None, None) => ((self.fps * self.duration(queries)).round() as usize).max(1),
        }
    }

    /// Duration of the whole path in seconds for `queries` windows: `seconds`, else
    /// `frames / fps` (when `frames` ≥ 1), else [`SECONDS_PER_QUERY`] per query.
    pub fn duration(&self, queries: usize) -> f64 {
        match (self.seconds, self.frames) {
            (Some(s), _) => s,
            (None, Some(frames)) if frames > 0 => frames as f64 / self.fps,
            _ => SECONDS_PER_QUERY * queries.max(1) as f64,
        }
    }

    /// Checks the counts and sizes; errors name the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad =
            |key: &str, reason: String| Err(ConfigError::new(format!("output.{key}"), reason));
        if self.width < MIN_VIDEO_SIDE || self.height < MIN_VIDEO_SIDE {
            return bad(
                "width",
                format!(
                    "and `output.height` ({} × {}) must be at least {MIN_VIDEO_SIDE} (the H.264 \
                     encoder's smallest frame)",
                    self.width, self.height
                ),
            );
        }
        if self.frames == Some(0) {
            return bad(
                "frames",
                "= 0 must be at least 1 (leave it out for `output.fps` × `output.seconds`)".into(),
            );
        }
        // The video's own check, so that `run --check` refuses what the video would.
        if check_fps(self.fps).is_err() {
            return bad(
                "fps",
                format!(
                    "= {:?} must be between {MIN_FPS} and {MAX_FPS} (the video's limits)",
                    self.fps
                ),
            );
        }
        if let Some(s) = self.seconds
            && !(s.is_finite() && s > 0.0)
        {
            return bad("seconds", format!("= {s} must be a positive number"));
        }
        if self.trajectory_samples < 2 {
            return bad("trajectory_samples", "must be ≥ 2".into());
        }
        if self.metric_samples == 0 {
            return bad("metric_samples", "must be ≥ 1".into());
        }
        if self.ldj_samples < splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES {
            return bad(
                "ldj_samples",
                format!("must be ≥ {}", splatraj_traj::metrics::ldj::MIN_LDJ_SAMPLES),
            );
        }
        Ok(())
    }
}
