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
use splatraj_traj::trajectory::{Pose, TrajectoryModel, TrajectoryRecord};

use crate::outputs::write_json;

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
}

impl Checkpoint {
    /// The best trajectory so far as a record.
    pub fn best_record(&self) -> TrajectoryRecord {
        TrajectoryRecord {
            model: self.model.clone(),
            weights: self.weights.clone(),
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
        let deserializer = &mut serde_json::Deserializer::from_str(&text);
        serde_path_to_error::deserialize(deserializer).map_err(|e| {
            anyhow::anyhow!(
                "{}: `{}`: {}",
                path.display(),
                e.path(),
                e.inner().to_string().trim_end()
            )
        })
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
