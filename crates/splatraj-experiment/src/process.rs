//! One process API: a whole experiment, trajectory (`splatraj run`) or pose (`splatraj pose`),
//! into a run folder the library owns.
//!
//! A library user gets exactly the folder the command line gets, because the commands call
//! these same functions and only draw progress and print. The order of work is the
//! commands': every check that can fail before the work ([`Experiment::check_trajectory_run`],
//! [`Experiment::check_pose_run`]) runs before any folder exists; [`RunFolder::create`] makes
//! `runs_dir/name/<timestamp>/` with the config as run, or [`RunFolder::resume`] reopens a
//! stopped run's folder; then [`Experiment::run_trajectory_in`] / [`Experiment::run_pose_in`]
//! optimise (checkpointing a trajectory run) and write every file. Progress of every kind
//! (steps, restarts, the switch to the outputs, frames, SGLD) reaches the [`Observer`].
//! [`run_trajectory_experiment`] and [`run_pose_experiment`] are that order whole, from the
//! config file: the one call of `splatraj run` and `splatraj pose`.
//!
//! ```no_run
//! use splatraj_experiment::{Config, Experiment, optimise::observer, process::RunFolder};
//! # fn main() -> anyhow::Result<()> {
//! let config = Config::load(std::path::Path::new("configs/demo.toml"), &[])?;
//! let experiment = Experiment::prepare(&config)?;
//! experiment.check_trajectory_run(false)?;
//! let folder = RunFolder::create(&experiment)?;
//! let outcome = experiment.run_trajectory_in(&folder, &mut observer::quiet())?;
//! println!("{} ({} windows failing)", outcome.dir.display(), outcome.failing);
//! # Ok(())
//! # }
//! ```

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use splatraj_render::backend::Hardware;
use splatraj_render::counters::Counts;
use splatraj_traj::metrics::WindowMetrics;
use splatraj_traj::optimise::StopReason;

use crate::config::{Ablation, Config, MaskOverlay, VerdictPolicy};
use crate::optimise::checkpoint::{CHECKPOINT_FILE, Checkpoint};
use crate::optimise::observer::{Observer, Phase, Progress};
use crate::outputs::records::{PoseFile, pose_history, sgld_samples, trajectory_history};
use crate::outputs::run_files::RunOutputs;
use crate::outputs::run_folder::{
    MetricsFile, RunReport, StageCounts, StageTimes, check_writable, remove_checkpoint,
    remove_partial_files, resumable,
};
use crate::outputs::{FrameSpec, create_run_dir, frame_png};
use crate::prepare::experiment::Experiment;
use crate::resources::{MAX_STEPS_PER_SECOND, MemoryPlan, RAISE_LIMIT, TimeBound};
use crate::write::{write_bytes, write_csv, write_json};
use crate::{Evaluation, Posterior, RunOptions, RunStop, TrajectoryOptimisation, TrajectoryRun};

/// The run's config as run: every `"auto"` replaced by what was derived from the scene.
pub const CONFIG_FILE: &str = "config.toml";

/// A run's folder: where every file of one run goes.
///
/// A run that fails leaves no half-made folder ([`RunFolder::after_failure`]): a new run's
/// folder (and the folders made for it) is removed whole, unless the optimisation had finished,
/// in which case it is cut back to what a killed run leaves (`config.toml` and
/// `checkpoint.json`), which `splatraj run --resume` continues.
#[derive(Debug)]
pub struct RunFolder {
    dir: PathBuf,
    checkpoint: Option<Checkpoint>,
    /// Folders made for this run that did not exist before, innermost first (none for a
    /// resumed run).
    made: Vec<PathBuf>,
}

impl RunFolder {
    /// A new folder `output.runs_dir/name/<timestamp>/` holding the experiment's config as run.
    pub fn create(experiment: &Experiment) -> Result<RunFolder> {
        let config = &experiment.config;
        let parent = config.output.runs_dir.join(&config.name);
        let mut made: Vec<PathBuf> = parent
            .ancestors()
            .take_while(|p| !p.as_os_str().is_empty() && !p.exists())
            .map(Path::to_path_buf)
            .collect();
        let dir = create_run_dir(&config.output.runs_dir, &config.name)?;
        made.insert(0, dir.clone());
        let folder = RunFolder {
            dir,
            checkpoint: None,
            made,
        };
        let config_text = toml::to_string(config)?;
        if let Err(e) = write_bytes(&folder.dir.join(CONFIG_FILE), config_text.as_bytes()) {
            return Err(folder.after_failure(e, Stage::Preparing));
        }
        Ok(folder)
    }

    /// Tidies the folder after `error` at `stage` and returns the error, saying what was
    /// kept: see the type's docs. A resumed run's folder is never removed, only cut back.
    pub fn after_failure(&self, error: anyhow::Error, stage: Stage) -> anyhow::Error {
        let resumable = self.checkpoint.is_some()
            || (stage == Stage::Outputs && self.dir.join(CHECKPOINT_FILE).is_file());
        if resumable {
            return match keep_only_resumable(&self.dir) {
                Ok(()) => error.context(format!(
                    "the run folder {} keeps its config and checkpoint: `splatraj run --resume \
                     {}` continues it",
                    self.dir.display(),
                    self.dir.display()
                )),
                Err(e) => error.context(format!("also, tidying the run folder failed: {e:#}")),
            };
        }
        if let Err(e) = std::fs::remove_dir_all(&self.dir) {
            return error.context(format!(
                "also, the run folder {} could not be removed: {e}",
                self.dir.display()
            ));
        }
        // The folders made for the run go too, when nothing else was put in them since.
        for made in &self.made[1..] {
            if std::fs::remove_dir(made).is_err() {
                break;
            }
        }
        error
    }

    /// The folder of a stopped trajectory run, cleared of the temporaries a killed process
    /// left, to continue from `checkpoint` ([`crate::outputs::run_folder::resumable`] reads both).
    pub fn resume(dir: &Path, checkpoint: Checkpoint) -> Result<RunFolder> {
        remove_partial_files(dir)?;
        Ok(RunFolder {
            dir: dir.to_path_buf(),
            checkpoint: Some(checkpoint),
            made: Vec::new(),
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The checkpoint a resumed run continues from.
    pub fn checkpoint(&self) -> Option<&Checkpoint> {
        self.checkpoint.as_ref()
    }
}

/// Where a run was when it failed (what [`RunFolder::after_failure`] keeps depends on it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Before or during the optimisation: nothing worth keeping was made.
    Preparing,
    /// Writing the outputs of a finished optimisation: its checkpoint is worth keeping.
    Outputs,
}

/// Removes everything in the run folder `dir` but `config.toml` and `checkpoint.json`.
fn keep_only_resumable(dir: &Path) -> Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        if name == CONFIG_FILE || name == CHECKPOINT_FILE {
            continue;
        }
        let path = entry.path();
        if entry.file_type()?.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        }
        .with_context(|| format!("cannot remove {}", path.display()))?;
    }
    Ok(())
}

/// What a trajectory experiment did and found.
#[derive(Debug)]
pub struct TrajectoryOutcome {
    /// Its run folder.
    pub dir: PathBuf,
    /// Why the optimisation ended.
    pub stop: RunStop,
    /// The per-window metrics, verdicts and LDJ (as written to `metrics.json`).
    pub evaluation: Evaluation,
    /// How the optimisation went (`metrics.json`'s `run`).
    pub report: RunReport,
    /// One line per window that fails its verdict (what is wrong and the likely fix).
    pub problems: Vec<String>,
    /// Windows failing their verdict.
    pub failing: usize,
    /// What a failing verdict does (`output.verdict`).
    pub policy: VerdictPolicy,
}

impl TrajectoryOutcome {
    /// Whether the run ends as failed: some window fails its verdict and `output.verdict`
    /// does not only warn.
    pub fn verdict_fails(&self) -> bool {
        !self.problems.is_empty() && self.policy != VerdictPolicy::Warn
    }

    /// The run's result, a line each: per window TCE, TRE, in view, visible, hidden, clearance
    /// and verdict, then LDJ and the optimisation's figures.
    pub fn summary_lines(&self) -> Vec<String> {
        let (evaluation, report) = (&self.evaluation, &self.report);
        let mut lines = vec![
            "window  query                  TCE     TRE   in view  visible  hidden  clearance  verdict"
                .to_string(),
        ];
        for w in &evaluation.windows {
            // An object never in view has no framing error: show a dash, not the empty mask's 0.
            let tce = w
                .framing
                .tce_in_view
                .map_or("      -".to_string(), |t| format!("{t:>7.4}"));
            let clearance = w
                .path
                .as_ref()
                .and_then(|p| p.clearance.as_ref())
                .map_or("-".to_string(), |c| format!("{:.3}", c.min_clearance));
            let verdict = match &w.verdict {
                Some(v) if v.pass => "ok".to_string(),
                Some(v) => format!("FAIL ({})", v.failed().join(", ")),
                None => "-".to_string(),
            };
            lines.push(format!(
                "{:>6}  {:<20} {} {:>7.4}  {:>6.0}%  {:>6.0}%  {:>5.0}%  {:>9}  {}",
                w.window,
                w.name,
                tce,
                w.tre,
                100.0 * w.visible_fraction,
                100.0 * (1.0 - w.occlusion.mean_occluded),
                100.0 * w.occlusion.hidden_fraction,
                clearance,
                verdict
            ));
        }
        let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        lines.push(format!(
        "LDJ positional {}, angular {}; {} iterations in {:.1} s ({:.0} ms each), total {:.1} s",
        show(evaluation.ldj.positional),
        show(evaluation.ldj.angular),
        report.iterations_run,
        report.optimisation_s,
        report.per_iteration_ms,
        report.total_s
    ));
        lines
    }
}

/// `metrics.json` of a pose run.
#[derive(Debug, Serialize)]
pub struct PoseMetrics {
    /// The best pose's metrics at the output resolution.
    pub metrics: WindowMetrics,
    /// The SGLD samples' spread, when chains ran.
    pub sgld: Option<SgldSummary>,
}

/// Spread of the SGLD samples.
#[derive(Debug, Serialize)]
pub struct SgldSummary {
    /// Chains run.
    pub chains: usize,
    /// Samples kept.
    pub samples: usize,
    /// Mean of each pose component over the samples.
    pub mean: [f64; 6],
    /// Standard deviation of each pose component over the samples.
    pub std: [f64; 6],
    /// Updates skipped for a non-finite gradient.
    pub skipped_updates: usize,
    /// Wall time.
    pub seconds: f64,
}

impl From<&Posterior> for SgldSummary {
    fn from(p: &Posterior) -> Self {
        SgldSummary {
            chains: p.chains,
            samples: p.samples.len(),
            mean: p.mean,
            std: p.std,
            skipped_updates: p.skipped_updates,
            seconds: p.elapsed.as_secs_f64(),
        }
    }
}

/// What a pose experiment did and found.
#[derive(Debug)]
pub struct PoseOutcome {
    /// Its run folder.
    pub dir: PathBuf,
    /// Whether Ctrl-C (the observer) stopped the optimisation.
    pub interrupted: bool,
    /// `pose.json`: the best pose and every start's result.
    pub pose: PoseFile,
    /// `metrics.json`.
    pub metrics: PoseMetrics,
}

/// What the checks before a run found.
#[derive(Debug)]
pub struct RunPlan {
    /// Estimated peak memory, stage by stage (checked against the limit).
    pub memory: MemoryPlan,
    /// Optimisation steps in all (restarts × iterations), for a progress bar.
    pub steps: usize,
}

impl Experiment {
    /// What a run will do, a line each: scene, backend, up (with a warning when unsure), the
    /// values derived from the scene, and per query its start view, Gaussians and prior.
    pub fn plan_lines(&self) -> Vec<String> {
        let experiment = self;
        let mut lines = Vec::new();
        let hardware = Hardware::of(&experiment.device);
        lines.push(format!(
            "scene: {} ({} Gaussians), backend {:?} on {hardware}, rasterizer {:?}",
            experiment.scene_name,
            experiment.scene.len(),
            experiment.config.backend,
            experiment.config.rasterizer
        ));
        if let Some(warning) = hardware.warning() {
            lines.push(format!("warning: {warning}"));
        }
        lines.push(experiment.up.describe());
        if experiment.up.doubtful() {
            lines.push(
                "warning: the up guess is unsure; `splatraj scene views SCENE --out views.html` \
                 shows the scene upright for the guess and its two next candidates, each \
                 with the `scene.up` line that sets it (y-down captures: [0, -1, 0]; z-up: \
                 [0, 0, 1]), or `scene.cameras` takes it from the capture's cameras"
                    .to_string(),
            );
        }
        for d in &experiment.derived {
            lines.push(format!(
                "derived from the scene: {} = {:.4} ({})",
                d.key, d.value, d.why
            ));
        }
        // Where the windows pan or cut (`output.transitions`); a failure here (the view
        // search) is the start check's to report.
        for line in experiment.transition_lines().unwrap_or_default() {
            lines.push(format!("transitions: {line}"));
        }
        // The search already ran for the start check (`start_trajectories`), which caches it.
        let views = experiment.start_views().ok().flatten();
        for (i, w) in experiment.windows.iter().enumerate() {
            if let Some(view) = views.as_ref().and_then(|v| v.get(i)) {
                lines.push(format!(
                "query {i}: starts from azimuth {:.0}°, elevation {:.0}°, distance {:.3}: {:.0} % \
                 of it visible there",
                view.azimuth_degrees,
                view.elevation_degrees,
                view.distance,
                100.0 * view.visible_share
            ));
            }
            let c = w.context.object_centre;
            lines.push(format!(
            "query {i}: {:?} → {} Gaussians, centre [{:.3}, {:.3}, {:.3}], prior radius {:.3}, target ratio {}",
            w.name,
            experiment.selected[i],
            c[0],
            c[1],
            c[2],
            w.context.prior_radius,
            w.context.target_ratio
        ));
            for note in experiment.notes.get(i).into_iter().flatten() {
                lines.push(format!("query {i}: {note}"));
            }
        }
        lines
    }

    /// Every check of a trajectory run that can fail before the work
    /// ([`Experiment::check_trajectory_work`]) and, for a new run (`resuming` false), that the
    /// runs folder can be written.
    pub fn check_trajectory_run(&self, resuming: bool) -> Result<RunPlan> {
        let plan = self.check_trajectory_work()?;
        if !resuming {
            check_writable(&self.config.output.runs_dir.join(&self.config.name))?;
        }
        Ok(plan)
    }

    /// The checks of a trajectory optimisation that can fail before the work, wherever its
    /// result goes (a run folder, a study's row): its costs, the memory and time against their
    /// limits (`start.restarts` among the sizes) and the first start (reading
    /// `start.trajectory`).
    pub fn check_trajectory_work(&self) -> Result<RunPlan> {
        self.costs()?;
        let memory = self.trajectory_memory()?;
        memory.check(self.memory_limit()?, RAISE_LIMIT)?;
        // Before the time plan, which would warn that the time limit stops the optimisation.
        self.check_restarts_begin()?;
        let (optimisation, rest) = self.trajectory_time();
        optimisation.check(TimeBound::Key {
            key: "`optimiser.time_limit_s`",
            seconds: self.config.optimiser.time_limit_s,
        })?;
        rest.check(TimeBound::Unbounded)?;
        // The first start is built (a bad `start.trajectory`, shot or route fails there);
        // all of them would take time in proportion to `start.restarts`, which the time plan
        // above has weighed.
        self.first_start_trajectories(1)?;
        let restarts = self.start_count();
        Ok(RunPlan {
            memory,
            steps: restarts * self.config.optimiser.iterations,
        })
    }

    /// Errors when `optimiser.time_limit_s` ends the run before every restart could take its
    /// first step: every start is built before the first step, so restarts that never begin
    /// would cost time the limit does not bound.
    fn check_restarts_begin(&self) -> Result<()> {
        let Some(limit) = self.config.optimiser.time_limit_s else {
            return Ok(());
        };
        let can_begin = (limit * MAX_STEPS_PER_SECOND).max(1.0);
        let restarts = self.start_count();
        if restarts as f64 > can_begin {
            bail!(
                "`start.restarts` = {restarts} restarts cannot all begin within \
                 `optimiser.time_limit_s` = {limit} s (at most {can_begin:.0} steps run in it, \
                 at {MAX_STEPS_PER_SECOND} a second), yet every start is built before the \
                 first step: make `start.restarts` at most {can_begin:.0}, or raise the limit"
            );
        }
        Ok(())
    }

    /// Runs the trajectory experiment into `folder` and writes every file: the optimisation
    /// (checkpointed to `checkpoint.json`; a resumed folder continues its checkpoint),
    /// `history.csv`, `trajectory.json`, then the metrics, frames, `video.mp4`, exports,
    /// `metrics.json` and `report.html`. A finished run drops its checkpoint; a stopped one
    /// keeps it for a resume. The observer hears every step (and may stop the optimisation,
    /// keeping the best so far), then [`Phase::Outputs`] and every frame.
    pub fn run_trajectory_in(
        &self,
        folder: &RunFolder,
        observer: &mut dyn Observer,
    ) -> Result<TrajectoryOutcome> {
        let dir = folder.dir();
        let options = RunOptions {
            checkpoint_dir: Some(dir),
            resume: folder.checkpoint(),
        };
        let counted = splatraj_render::counters::snapshot();
        let preparation = counted.since(&self.prepared_counts);
        let run = TrajectoryOptimisation::new(self)
            .and_then(|optimisation| optimisation.run(options, observer))
            .map_err(|e| folder.after_failure(e, Stage::Preparing))?;
        let optimisation = splatraj_render::counters::snapshot().since(&counted);
        self.write_trajectory_outputs(folder, &run, [preparation, optimisation], observer)
            .map_err(|e| folder.after_failure(e, Stage::Outputs))
    }

    /// The files of the optimised `run` in `folder` (see [`Experiment::run_trajectory_in`]).
    fn write_trajectory_outputs(
        &self,
        folder: &RunFolder,
        run: &TrajectoryRun,
        [preparation, optimisation]: [Counts; 2],
        observer: &mut dyn Observer,
    ) -> Result<TrajectoryOutcome> {
        let dir = folder.dir();
        // Only a stop requested from now on cuts the outputs short: a run stopped while it
        // optimised still writes the outputs of its best trajectory.
        let since = splatraj_scene::stop::Since::now();
        let (header, rows) = trajectory_history(run, self.windows.len());
        write_csv(&dir.join("history.csv"), &header, &rows)?;
        let outputs = RunOutputs::of_run(self, run)?;
        write_json(
            &dir.join("trajectory.json"),
            &self.trajectory_file(outputs.trajectory())?,
        )?;

        let frames = self.config.output.frame_count(self.windows.len());
        observer.progress(&Progress::Phase(Phase::Outputs {
            frames,
            stop: run.stop,
        }));
        let written = outputs
            .write(
                dir,
                &mut |done| {
                    observer.progress(&Progress::Frame { done, frames });
                },
                since,
            )
            // A stop requested while the metrics, frames or exports are made (not one that
            // ended the optimisation) ends them at a whole window, frame or format; the
            // checkpoint stays for a resume.
            .map_err(|e| match e.downcast::<splatraj_scene::stop::Stopped>() {
                Ok(stopped) => splatraj_scene::stop::Stopped {
                    what: format!(
                        "{}; {} is cut back to its config and checkpoint (what was written \
                         is removed): `splatraj run --resume {}` writes the outputs again",
                        stopped.what,
                        dir.display(),
                        dir.display()
                    ),
                }
                .into(),
                Err(e) => e,
            })?;
        let times = StageTimes {
            metrics: written.metrics,
            frames: written.frames,
            total: self.prepared_at.elapsed(),
            counts: StageCounts {
                preparation,
                optimisation,
                metrics: written.metrics_counts,
                frames: written.frames_counts,
            },
        };
        let report = RunReport::new(self, run, times);
        let evaluation = written.evaluation;
        let (problems, failing) = (evaluation.problems(), evaluation.failing());
        write_json(
            &dir.join("metrics.json"),
            &MetricsFile::new(
                evaluation.clone(),
                self.config.output.ldj_samples,
                report.clone(),
            ),
        )?;
        outputs.write_report(dir)?;
        if run.stop == RunStop::Finished {
            remove_checkpoint(dir)?;
        }
        Ok(TrajectoryOutcome {
            dir: dir.to_path_buf(),
            stop: run.stop,
            evaluation,
            report,
            problems,
            failing,
            policy: self.config.output.verdict,
        })
    }

    /// Every check of a pose run that can fail before the work: the SGLD chain count, the
    /// memory against the limit, the costs and the starts.
    pub fn check_pose_run(&self, sgld: Option<usize>) -> Result<RunPlan> {
        if sgld == Some(0) {
            bail!("SGLD needs at least one chain (--sgld)");
        }
        let memory = self.pose_memory(sgld.unwrap_or(0));
        memory.check(self.memory_limit()?, RAISE_LIMIT)?;
        self.pose_time(sgld.unwrap_or(0))
            .check(TimeBound::Unbounded)?;
        self.pose_costs()?;
        self.pose_starts()?;
        Ok(RunPlan {
            memory,
            steps: self.config.pose.optimiser.iterations,
        })
    }

    /// Runs the pose experiment (`[pose]`) into `folder`: the batched optimisation
    /// (`history.csv`), `sgld` chains from the best pose when asked (`sgld_samples.csv`),
    /// `pose.json`, `frame.png` and `metrics.json`. The observer hears every step (and may stop
    /// the optimisation, keeping each start's best), then [`Phase::Sgld`].
    pub fn run_pose_in(
        &self,
        folder: &RunFolder,
        sgld: Option<usize>,
        observer: &mut dyn Observer,
    ) -> Result<PoseOutcome> {
        self.write_pose_run(folder, sgld, observer)
            .map_err(|e| folder.after_failure(e, Stage::Preparing))
    }

    /// The pose run of [`Experiment::run_pose_in`], failing as it comes.
    fn write_pose_run(
        &self,
        folder: &RunFolder,
        sgld: Option<usize>,
        observer: &mut dyn Observer,
    ) -> Result<PoseOutcome> {
        let dir = folder.dir();
        let run = self.optimise_pose(observer)?;
        let interrupted = run.stop() == StopReason::Interrupted;
        let (header, rows) = pose_history(&run.results);
        write_csv(&dir.join("history.csv"), &header, &rows)?;
        let best = run.best();
        let sgld = match sgld {
            Some(chains) => {
                observer.progress(&Progress::Phase(Phase::Sgld { chains }));
                let posterior = self.sample_posterior(best.pose, chains)?;
                let (header, rows) = sgld_samples(&posterior);
                write_csv(&dir.join("sgld_samples.csv"), &header, &rows)?;
                Some(SgldSummary::from(&posterior))
            }
            None => None,
        };
        let pose = PoseFile::new(self, &run);
        write_json(&dir.join("pose.json"), &pose)?;
        let metrics = self.evaluate_pose(best.pose)?;
        let window = &self.windows[self.config.pose.query];
        let tint = (self.config.output.mask_overlay == MaskOverlay::Tint)
            .then_some(window.mask.as_slice());
        let png = frame_png(
            &self.plain_scene(),
            (&self.output_intrinsics()?, self.config.rasterizer),
            &FrameSpec {
                pose: best.pose.0,
                tint,
            },
        )?;
        write_bytes(&dir.join("frame.png"), &png)?;
        let metrics = PoseMetrics { metrics, sgld };
        write_json(&dir.join("metrics.json"), &metrics)?;
        Ok(PoseOutcome {
            dir: dir.to_path_buf(),
            interrupted,
            pose,
            metrics,
        })
    }
}

/// Where `splatraj run`'s config comes from.
#[derive(Debug, Clone, Copy)]
pub enum RunSource<'a> {
    /// A config file and its `KEY=VALUE` overrides: a new run.
    Config {
        /// The config file.
        path: &'a Path,
        /// `--set` overrides.
        set: &'a [String],
    },
    /// A stopped run's folder (its `config.toml` with the overrides, and `checkpoint.json`).
    Resume {
        /// The run folder.
        dir: &'a Path,
        /// `--set` overrides.
        set: &'a [String],
    },
}

/// Everything `splatraj run` is asked.
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryRequest<'a> {
    /// The config, or the run to resume.
    pub source: RunSource<'a>,
    /// `max_memory_gb` over the file's and the overrides' (already checked).
    pub max_memory_gb: Option<f64>,
    /// Only check (`--check`): every check before the work, and stop.
    pub check_only: bool,
}

/// How `splatraj run` ended.
#[derive(Debug)]
pub enum TrajectoryEnd {
    /// `--check`: every check passed; what the run would take.
    Checked(RunPlan),
    /// The run ran and wrote its folder.
    Ran(Box<TrajectoryOutcome>),
}

/// `splatraj run` whole: the config read (or the stopped run's, resumed), the experiment
/// prepared and checked ([`Experiment::check_trajectory_run`]), then, unless only checking,
/// the run folder made ([`RunFolder::create`] or [`RunFolder::resume`]) and the run into it
/// ([`Experiment::run_trajectory_in`]). The observer hears the plan, the folder and a resume
/// as [`Observer::line`]s, [`Phase::Optimisation`] before the first step, then every step,
/// phase and frame.
pub fn run_trajectory_experiment(
    request: &TrajectoryRequest<'_>,
    observer: &mut dyn Observer,
) -> Result<TrajectoryEnd> {
    let (mut config, resume) = match request.source {
        RunSource::Resume { dir, set } => {
            let (config, checkpoint) = resumable(dir, set)?;
            observer.line(&checkpoint.resuming_line(dir));
            (config, Some((dir, checkpoint)))
        }
        RunSource::Config { path, set } => (Config::load(path, set)?, None),
    };
    // Over the file and the overrides; checked as the option was read.
    if request.max_memory_gb.is_some() {
        config.max_memory_gb = request.max_memory_gb;
    }
    let experiment = Experiment::prepare(&config)?;
    let plan = experiment.check_trajectory_run(resume.is_some())?;
    for line in experiment.plan_lines() {
        observer.line(&line);
    }
    if request.check_only {
        return Ok(TrajectoryEnd::Checked(plan));
    }
    // Stop requests are honoured (acted on at the loops' next whole step) before the run
    // folder exists: a signal between the two would otherwise end the process at once and
    // leave a folder without a checkpoint, which a resume cannot continue.
    splatraj_scene::stop::honour();
    let folder = match resume {
        Some((dir, checkpoint)) => RunFolder::resume(dir, checkpoint)?,
        None => RunFolder::create(&experiment)?,
    };
    observer.line(&format!("run folder: {}", folder.dir().display()));
    observer.progress(&Progress::Phase(Phase::Optimisation { steps: plan.steps }));
    experiment
        .run_trajectory_in(&folder, observer)
        .map(|outcome| TrajectoryEnd::Ran(Box::new(outcome)))
}

/// Everything `splatraj pose` is asked: the config with its overrides, then the options that
/// set typed fields over both, and the SGLD chains.
#[derive(Debug, Clone, Copy)]
pub struct PoseRequest<'a> {
    /// The config file.
    pub config: &'a Path,
    /// `--set` overrides.
    pub set: &'a [String],
    /// `pose.ablation`, when given.
    pub ablation: Option<Ablation>,
    /// `start.restarts`, when given.
    pub restarts: Option<usize>,
    /// `max_memory_gb`, when given (already checked).
    pub max_memory_gb: Option<f64>,
    /// SGLD chains to run from the best pose, when asked.
    pub sgld: Option<usize>,
}

/// `splatraj pose` whole: the config read (low to high: the file, the overrides, the
/// options), the experiment prepared and checked ([`Experiment::check_pose_run`]), the run
/// folder made and the pose run into it ([`Experiment::run_pose_in`]). The observer hears the
/// query's plan and the folder as [`Observer::line`]s, [`Phase::Optimisation`], then every
/// step and [`Phase::Sgld`].
pub fn run_pose_experiment(
    request: &PoseRequest<'_>,
    observer: &mut dyn Observer,
) -> Result<PoseOutcome> {
    let config = Config::load_edited(request.config, request.set, |config| {
        if let Some(a) = request.ablation {
            config.pose.ablation = a;
        }
        if let Some(r) = request.restarts {
            config.start.restarts = r;
        }
        if request.max_memory_gb.is_some() {
            config.max_memory_gb = request.max_memory_gb;
        }
    })?;
    let experiment = Experiment::prepare(&config)?;
    let plan = experiment.check_pose_run(request.sgld)?;
    let index = config.pose.query;
    if let Some(warning) = Hardware::of(&experiment.device).warning() {
        observer.line(&format!("warning: {warning}"));
    }
    observer.line(&format!(
        "query {:?}: {} Gaussians, {} start(s), costs {:?}",
        experiment.windows[index].name,
        experiment.selected[index],
        experiment.pose_starts()?.len(),
        experiment.pose_costs()?.names()
    ));
    // Honoured before the run folder exists, as a trajectory run does: a signal in between
    // would end the process at once and leave an empty folder.
    splatraj_scene::stop::honour();
    let folder = RunFolder::create(&experiment)?;
    observer.line(&format!("run folder: {}", folder.dir().display()));
    observer.progress(&Progress::Phase(Phase::Optimisation { steps: plan.steps }));
    experiment.run_pose_in(&folder, request.sgld, observer)
}

impl PoseOutcome {
    /// The best pose and its metrics, in two lines.
    pub fn summary(&self) -> String {
        let (metrics, pose) = (&self.metrics.metrics, &self.pose);
        format!(
            "best pose {:?}\nTCE {}  TRE {:.4}  IoU {:.3}  visible {}  ({:.1} s, {:.0} ms/iteration for {} start(s))",
            pose.pose,
            metrics
                .tce
                .map_or("undefined (never in view)".to_string(), |t| format!(
                    "{t:.4}"
                )),
            metrics.tre,
            metrics.iou,
            metrics.visible,
            pose.optimisation_s,
            pose.per_iteration_ms,
            pose.starts.len()
        )
    }
}

impl RunPlan {
    /// What `--check` says when every check passed: the estimated peak memory and its stage.
    pub fn check_line(&self) -> Option<String> {
        self.memory.peak().map(|peak| {
            format!(
                "check passed; peak memory about {} ({})",
                crate::resources::show_bytes(peak.bytes),
                peak.what
            )
        })
    }
}
