//! Experiments for splatraj: a config file made into runs, as a library.
//!
//! [`config`] is the TOML schema of `splatraj run` and `splatraj pose` (every knob, `extends`,
//! `--set` overrides, checks that name the key), at the bottom of the crate: it imports nothing
//! of it but the [`Extensions`] registries, and no module imports in a circle.
//! [`Experiment::prepare`] reads and checks the scene, world up, one target per query
//! ([`prepare::grounding`], shared with `splatraj query`), their windows and prior radii; then
//! [`TrajectoryOptimisation`] (the paper's method, restarts included; built from the
//! experiment, it gives a [`TrajectoryRun`]; [`Experiment::run_trajectory`] in one call),
//! [`Experiment::evaluate`] (per-window metrics, LDJ: [`outputs::evaluation`]),
//! [`Experiment::optimise_pose`] (the single-pose ablations, restarts as one batch) and
//! [`Experiment::sample_posterior`] (SGLD) do the work, telling an [`Observer`] of each step
//! (which may stop them, keeping the best so far). [`outputs::records`] and [`outputs`] turn
//! results into the run folder's files, each written whole or not at all. [`Extensions`]
//! carries what another crate adds (its own costs), and [`optimise::probe`],
//! [`prepare::views`], [`outputs::camera_file`], [`picking::views_page`] serve the smaller
//! commands (`render --grad`, `bench`, `query`, `scene views`).
//!
//! ```no_run
//! use std::path::Path;
//!
//! use splatraj_experiment::{Config, Experiment, optimise::observer};
//! # fn main() -> anyhow::Result<()> {
//! let config = Config::load(Path::new("configs/demo.toml"), &[])?;
//! let experiment = Experiment::prepare(&config)?;
//! let run = experiment.run_trajectory(&mut observer::quiet())?;
//! let trajectory = experiment.trajectory(&run.best().best)?;
//! let metrics = experiment.evaluate(&trajectory)?;
//! # let _ = metrics;
//! # Ok(())
//! # }
//! ```
//!
//! [`process`] runs the same into a run folder, every file written as `splatraj run` writes it.

#![warn(missing_docs)]

pub mod bench;
pub mod children;
pub mod config;
pub mod extensions;
pub mod frame_metrics;
pub mod json;
pub mod optimise;
pub mod outputs;
pub mod picking;
pub mod prepare;
pub mod process;
pub mod resources;
pub mod study;
pub mod write;

pub use config::Config;
pub use extensions::Extensions;
pub use optimise::observer::{Flow, Observer, Progress};
pub use optimise::pose_run::{PoseRun, Posterior};
pub use optimise::trajectory_run::{RunOptions, RunStop, TrajectoryOptimisation, TrajectoryRun};
pub use outputs::evaluation::Evaluation;
pub use outputs::run_files::RunOutputs;
pub use prepare::experiment::Experiment;
