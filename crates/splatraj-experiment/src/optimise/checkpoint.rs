//! The run folder's `checkpoint.json`: the best trajectory found so far, written while the
//! optimisation runs, so that a crash, a power cut or a second Ctrl-C loses seconds of work,
//! and `splatraj run --resume RUN_DIR` can continue.
//!
//! Its top-level `model` and `weights` are the best trajectory over every restart so far, so
//! the file reads back as a trajectory record (`[start] trajectory = "checkpoint.json"` works).
//! The other keys say where the run was: the restart in progress, its steps and its own best
//! (what a resumed run continues from). Writes are atomic (temporary file, then rename) and at
//! most one per [`CHECKPOINT_INTERVAL`], so the cost inside the loop stays a few microseconds
//! per step.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use splatraj_traj::trajectory::lens::LensPath;
use splatraj_traj::trajectory::{Pose, TrajectoryModel, TrajectoryRecord};

use crate::write::write_json;

/// File name of the checkpoint in a run folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.json";

/// Shortest time between two checkpoint writes (the first improvement is written at once).
pub const CHECKPOINT_INTERVAL: Duration = Duration::from_secs(2);

/// What `checkpoint.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Model of the best trajectory so far.
    pub model: TrajectoryModel,
    /// Its weights `[K][6]`, scene units.
    pub weights: Vec<Pose>,
    /// Its sampled loss.
    pub best_total: f64,
    /// The restart (0-based) that found it.
    pub best_restart: usize,
    /// The step of that restart.
    pub best_step: usize,
    /// The restart in progress (0-based).
    pub restart: usize,
    /// Steps it has run.
    pub steps_done: usize,
    /// Its own best so far (weights and sampled loss): where a resumed run continues it.
    pub restart_best: Option<(Vec<Pose>, f64)>,
    /// Restarts in all.
    pub restarts: usize,
    /// Steps per restart.
    pub steps: usize,
    /// Optimisation seconds so far (over every resumption).
    pub elapsed_s: f64,
    /// Folder the run's relative input paths resolve against (its config's folder).
    pub base_dir: PathBuf,
    /// The best trajectory's zoom when the lens zooms (absent: a fixed lens, or a checkpoint
    /// from before the zoom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<LensPath>,
    /// The restart in progress' own best zoom, beside `restart_best` (where a resumed run
    /// continues it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restart_best_lens: Option<LensPath>,
}

impl Checkpoint {
    /// What resuming the run folder `dir` from this checkpoint continues, in one line.
    pub fn resuming_line(&self, dir: &Path) -> String {
        format!(
            "resuming {}: restart {}/{} at step {}/{}, best sampled loss so far {:.4}",
            dir.display(),
            self.restart + 1,
            self.restarts,
            self.steps_done,
            self.steps,
            self.best_total
        )
    }

    /// The best trajectory so far as a record.
    pub fn best_record(&self) -> TrajectoryRecord {
        TrajectoryRecord {
            model: self.model.clone(),
            weights: self.weights.clone(),
            lens: self.lens.clone(),
        }
    }

    /// Reads `RUN_DIR/checkpoint.json`; errors name the file.
    pub fn read(run_dir: &Path) -> Result<Checkpoint> {
        let path = run_dir.join(CHECKPOINT_FILE);
        let text = splatraj_scene::input::read_text(&path).with_context(|| {
            format!(
                "cannot read {} (a run that stopped before its first step has none: start it \
                 again)",
                path.display()
            )
        })?;
        let checkpoint: Checkpoint = crate::json::strict_json(&text).map_err(|(key, e)| {
            anyhow::anyhow!("{}: `{key}`: {}", path.display(), e.to_string().trim_end())
        })?;
        checkpoint
            .check()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        Ok(checkpoint)
    }

    /// Refuses bookkeeping no run writes (a resumed run would go on from it without a word):
    /// the restart in progress, or the best's, beyond the restarts; more steps done than a
    /// restart has; a time or a loss that is not a finite number of the right sign.
    pub fn check(&self) -> std::result::Result<(), String> {
        let bad = |key: &str, why: String| Err(format!("`{key}` {why}"));
        if self.restarts == 0 {
            return bad("restarts", "= 0: a run has at least one restart".into());
        }
        if self.restart >= self.restarts {
            return bad(
                "restart",
                format!(
                    "= {} is beyond the run's restarts (`restarts` = {}, counted from 0)",
                    self.restart, self.restarts
                ),
            );
        }
        if self.best_restart > self.restart {
            return bad(
                "best_restart",
                format!(
                    "= {} is a restart that has not run yet (`restart` = {})",
                    self.best_restart, self.restart
                ),
            );
        }
        if self.steps_done > self.steps {
            return bad(
                "steps_done",
                format!(
                    "= {} is more than a restart's `steps` = {}",
                    self.steps_done, self.steps
                ),
            );
        }
        if self.best_step >= self.steps.max(1) {
            return bad(
                "best_step",
                format!(
                    "= {} is beyond a restart's `steps` = {}",
                    self.best_step, self.steps
                ),
            );
        }
        if !(self.elapsed_s.is_finite() && self.elapsed_s >= 0.0) {
            return bad(
                "elapsed_s",
                format!(
                    "= {:?} is not a time in seconds (finite, ≥ 0)",
                    self.elapsed_s
                ),
            );
        }
        let losses = std::iter::once(("best_total", self.best_total))
            .chain(self.restart_best.iter().map(|(_, l)| ("restart_best", *l)));
        for (key, loss) in losses {
            if !loss.is_finite() {
                return bad(key, format!("holds the loss {loss:?}, which is not finite"));
            }
        }
        // A zoom has one weight per basis function, as its trajectory has a row of six.
        let zooms = [
            ("lens", self.lens.as_ref(), self.weights.len()),
            (
                "restart_best_lens",
                self.restart_best_lens.as_ref(),
                self.restart_best.as_ref().map_or(0, |(w, _)| w.len()),
            ),
        ];
        for (key, lens, rows) in zooms {
            if let Some(lens) = lens
                && let Err(e) = lens.validate(rows)
            {
                return bad(key, format!("does not fit its trajectory: {e}"));
            }
        }
        Ok(())
    }
}

/// Writes a checkpoint to a run folder at a bounded rate.
#[derive(Debug)]
pub struct Checkpointer {
    path: PathBuf,
    last_write: Option<Instant>,
    pending: Option<Checkpoint>,
}

impl Checkpointer {
    /// A checkpointer writing `run_dir/checkpoint.json`.
    pub fn new(run_dir: &Path) -> Self {
        Self {
            path: run_dir.join(CHECKPOINT_FILE),
            last_write: None,
            pending: None,
        }
    }

    /// Offers a newer state: written now if the last write is [`CHECKPOINT_INTERVAL`] old (or
    /// there was none), else kept for the next offer or [`Checkpointer::flush`].
    pub fn offer(&mut self, checkpoint: Checkpoint) -> Result<()> {
        self.pending = Some(checkpoint);
        if self
            .last_write
            .is_none_or(|t| t.elapsed() >= CHECKPOINT_INTERVAL)
        {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes the newest state offered, if not yet written.
    pub fn flush(&mut self) -> Result<()> {
        if let Some(checkpoint) = self.pending.take() {
            write_json(&self.path, &checkpoint)?;
            self.last_write = Some(Instant::now());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use splatraj_traj::trajectory::Rbf;

    fn checkpoint() -> Checkpoint {
        Checkpoint {
            model: TrajectoryModel::Rbf(Rbf::default()),
            weights: vec![[0.0; 6]; 8],
            best_total: 0.5,
            best_restart: 1,
            best_step: 40,
            restart: 2,
            steps_done: 10,
            restart_best: Some((vec![[0.0; 6]; 8], 0.7)),
            restarts: 4,
            steps: 200,
            elapsed_s: 12.5,
            base_dir: PathBuf::from("."),
            lens: None,
            restart_best_lens: None,
        }
    }

    /// What a run writes passes; each field out of what a run can write is named.
    #[test]
    fn bookkeeping_no_run_writes_is_refused_by_its_key() {
        assert_eq!(checkpoint().check(), Ok(()));
        type Edit = fn(&mut Checkpoint);
        let cases: [(Edit, &str); 9] = [
            (|c| c.steps_done = 1_000_000_000_000_000_000, "`steps_done`"),
            (|c| c.restart = 4, "`restart` = 4 is beyond"),
            (|c| c.best_restart = 3, "`best_restart` = 3"),
            (|c| c.elapsed_s = -1.0, "`elapsed_s` = -1.0"),
            (|c| c.elapsed_s = f64::NAN, "`elapsed_s` = NaN"),
            (|c| c.restarts = 0, "`restarts`"),
            (|c| c.best_step = 200, "`best_step` = 200"),
            (
                |c| c.restart_best = Some((vec![], f64::INFINITY)),
                "`restart_best`",
            ),
            // Seven zoom weights for a trajectory of eight rows.
            (
                |c| {
                    c.lens = Some(LensPath {
                        range: splatraj_traj::trajectory::ZoomRange { min: 0.5, max: 2.0 },
                        weights: vec![0.0; 7],
                    })
                },
                "`lens` does not fit",
            ),
        ];
        for (edit, mentions) in cases {
            let mut c = checkpoint();
            edit(&mut c);
            let e = c.check().unwrap_err();
            assert!(e.contains(mentions), "{e}");
        }
    }
}
