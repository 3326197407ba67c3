//! A whole study: its plan made from the config file read once and checked whole, then its
//! runs measured one after another (each in a child process or here), then its folder
//! written, also when a stop cut it short. [`run_study`] is `splatraj study` in one call (the
//! command shows what it tells and the outcome); [`measure_one`] is a child's run.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::context::{measure_in_child, measure_runs};
use super::files::{StudyFile, study_folder, write_study};
use super::measure::{MemoryReading, measure_run};
use super::plan::{PlanOptions, PlannedStudy, Run, Shard};
use super::rows::StudyRow;
use super::summary::StudyContext;
use crate::config::ConfigFile;
use crate::extensions::Extensions;

/// Where each run of a study is measured.
#[derive(Debug, Clone, Copy)]
pub enum RunPlace<'a> {
    /// In a child process of `exe` (`splatraj study … --one RUN`): its peak memory is its own.
    Child {
        /// The splatraj binary.
        exe: &'a Path,
    },
    /// In this process (no peak memory figure).
    InProcess,
}

/// What a study was asked: the plan built from `config` with `options`, the runs of `shard`,
/// and where its folder goes (`out`, else a new one under `output.runs_dir`).
#[derive(Debug, Clone, Copy)]
pub struct StudyRequest<'a> {
    /// The base config file.
    pub config: &'a Path,
    /// The options the plan was built with (a child builds the same plan from them).
    pub options: &'a PlanOptions,
    /// The slice of the runs asked for.
    pub shard: Option<Shard>,
    /// The study folder, when given.
    pub out: Option<&'a Path>,
    /// Where the runs are measured.
    pub place: RunPlace<'a>,
}

/// What a study wrote.
#[derive(Debug)]
pub struct StudyOutcome {
    /// The study folder.
    pub dir: PathBuf,
    /// Its contents.
    pub study: StudyFile,
}

/// A study's folder, made.
#[derive(Debug)]
pub struct StudyFolder {
    /// The folder (a new one is named by the time it was made).
    pub dir: PathBuf,
}

/// Makes the study folder `request` writes into (default: under the base config's
/// `output.runs_dir`).
pub fn study_dir(study: &PlannedStudy, request: &StudyRequest<'_>) -> Result<StudyFolder> {
    let dir = study_folder(request.out, &study.base.output.runs_dir, &study.plan.name)?;
    Ok(StudyFolder { dir })
}

/// Measures `runs` of `plan` into `folder` (from [`study_dir`]) and writes the study there;
/// `progress` hears each run's position, label and outcome. `args` is the command line the
/// study's files record. A stop ends it between runs (and, in this process, within the run
/// under way): what was measured is written all the same, then the stop is the error
/// ([`splatraj_scene::stop::Stopped`], naming the folder).
pub fn conduct_study(
    study: PlannedStudy,
    runs: &[Run],
    folder: StudyFolder,
    request: &StudyRequest<'_>,
    extensions: &Extensions,
    args: impl IntoIterator<Item = String>,
    progress: impl FnMut(usize, &str, &Result<Vec<StudyRow>, String>),
) -> Result<StudyOutcome> {
    let since = splatraj_scene::stop::Since::now();
    let measure = |run: &Run| match request.place {
        RunPlace::InProcess => measure_run(&study, run, extensions, MemoryReading::Shared, since)
            .map_err(|e| format!("{e:#}")),
        RunPlace::Child { exe } => {
            measure_in_child(exe, request.config, request.options, run.index)
        }
    };
    let (rows, failures) = measure_runs(&study.plan, runs, measure, progress, since);
    let context = StudyContext::new(&study.plan, &study.base, args);
    let study = StudyFile::new(study.plan, request.shard, context, rows, failures);
    write_study(&folder.dir, &study)?;
    if since.stopped() {
        return Err(splatraj_scene::stop::Stopped {
            what: format!(
                "{} rows measured ({} runs planned), written to {}",
                study.rows.len(),
                study.plan.runs.len(),
                folder.dir.display()
            ),
        }
        .into());
    }
    Ok(StudyOutcome {
        dir: folder.dir,
        study,
    })
}

/// Measures run `index` of the plan `options` make of the config file `config`, in this
/// process, with its own peak memory (what a child of [`RunPlace::Child`] does: `splatraj
/// study … --one index`).
pub fn measure_one(
    config: &Path,
    options: &PlanOptions,
    index: usize,
    extensions: &Extensions,
) -> Result<Vec<StudyRow>> {
    let study = PlannedStudy::new(&ConfigFile::read(config)?, options, extensions)?;
    let study = &study;
    let plan = &study.plan;
    let run = plan
        .runs
        .get(index)
        .with_context(|| format!("--one {index}: the plan has {} runs", plan.runs.len()))?;
    let since = splatraj_scene::stop::Since::now();
    measure_run(study, run, extensions, MemoryReading::OwnProcess, since)
}

/// What a study tells as it goes, worded by the library ([`super::lines`]).
#[derive(Debug, Clone, Copy)]
pub enum StudyNews<'a> {
    /// The plan, a dry run's verdict or the study folder.
    Line(&'a str),
    /// A measured row's progress line.
    Row(&'a str),
    /// A run that failed, and why.
    Failed(&'a str),
}

/// How [`run_study`] ended.
#[derive(Debug)]
pub enum StudyEnd {
    /// A dry run: the plan was checked whole, nothing ran.
    Checked,
    /// The runs were measured and the study written.
    Conducted(Box<StudyOutcome>),
}

/// `splatraj study` whole: the plan made from the config file read once, checked whole before
/// its first run ([`PlannedStudy::check`]; a dry run stops there), its folder made, then its
/// runs measured and the study written ([`conduct_study`]). `tell` hears the plan's outline,
/// the check's verdict (dry run), the folder, and each run's rows or failure. `args` is the
/// command line the study's files record.
pub fn run_study(
    request: &StudyRequest<'_>,
    dry_run: bool,
    extensions: &Extensions,
    args: impl IntoIterator<Item = String>,
    tell: &mut dyn FnMut(StudyNews<'_>),
) -> Result<StudyEnd> {
    let study = PlannedStudy::new(
        &ConfigFile::read(request.config)?,
        request.options,
        extensions,
    )?;
    let runs = study.plan.runs_of(request.shard);
    // Everything that can be known before the first run is checked now, dry run or not; a
    // refusal is the only thing told.
    let check = study.check(&runs, request.out, extensions)?;
    for line in study.plan.outline(runs.len(), request.shard) {
        tell(StudyNews::Line(&line));
    }
    if dry_run {
        tell(StudyNews::Line(&check.summary()));
        return Ok(StudyEnd::Checked);
    }
    let folder = study_dir(&study, request)?;
    tell(StudyNews::Line(&format!(
        "study folder: {}",
        folder.dir.display()
    )));
    let total = runs.len();
    let outcome = conduct_study(
        study,
        &runs,
        folder,
        request,
        extensions,
        args,
        |i, label, measured| {
            let at = format!("[{}/{total}] {label}", i + 1);
            match measured {
                Ok(rows) => {
                    for r in rows {
                        tell(StudyNews::Row(&r.progress_line(&at)));
                    }
                }
                Err(error) => tell(StudyNews::Failed(&format!("{at}: failed: {error}"))),
            }
        },
    )?;
    Ok(StudyEnd::Conducted(Box::new(outcome)))
}
