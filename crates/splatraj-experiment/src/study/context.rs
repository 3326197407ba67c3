//! Where and how a study ran, for its files: the machine, the fixed evaluation in words, the
//! command that regenerates it; and the rows a child process reports.

use std::path::Path;
use std::process::{Command, Output};

use super::StudyRow;
use super::files::Failure;
use super::plan::{PlanOptions, Preset, Run, StudyPlan};
use super::summary::StudyContext;
use super::text::command_line;
use crate::children::output_until_stopped;
use crate::config::Config;

impl StudyContext {
    /// The context of `plan` over `base` run on this machine with the command line `args`.
    pub fn new(plan: &StudyPlan, base: &Config, args: impl IntoIterator<Item = String>) -> Self {
        StudyContext {
            machine: machine(),
            evaluation: format!(
                "{}×{}, {:?} {:?} {:?}, exact rendering",
                plan.evaluation.width.unwrap_or(base.output.width),
                plan.evaluation.height.unwrap_or(base.output.height),
                base.rasterizer,
                base.precision,
                base.backend
            ),
            command: Some(command_line(args)),
        }
    }
}

/// The machine in words: CPU model and cores.
pub fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, m)| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{model}, {cores} cores available")
}

/// The rows a child process (`splatraj study ... --one RUN`) printed as its last line, or its
/// error message.
pub fn rows_from_child(output: &Output) -> Result<Vec<StudyRow>, String> {
    let stdout = String::from_utf8_lossy(&output.stdout);
    let parsed = stdout
        .lines()
        .last()
        .and_then(|line| serde_json::from_str::<Vec<StudyRow>>(line).ok());
    match (output.status.success(), parsed) {
        (true, Some(rows)) => Ok(rows),
        _ => {
            let err = String::from_utf8_lossy(&output.stderr);
            let err = err.trim().strip_prefix("error: ").unwrap_or(err.trim());
            Err(if err.is_empty() {
                format!("the study process ended with {}", output.status)
            } else {
                err.to_string()
            })
        }
    }
}

impl Preset {
    /// The name `--preset` takes.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Table1 => "table1",
            Preset::Table2 => "table2",
        }
    }
}

impl PlanOptions {
    /// The `splatraj study` arguments that rebuild this plan from `config` in another process.
    pub fn study_args(&self, config: &Path) -> Vec<String> {
        let mut args = vec!["study".to_string(), config.display().to_string()];
        for s in &self.set {
            args.extend(["--set".into(), s.clone()]);
        }
        for factor in &self.vary {
            // Values are TOML text; commas inside brackets or quotes do not split on re-parsing.
            args.extend([
                "--vary".into(),
                format!("{}={}", factor.key, factor.values.join(",")),
            ]);
        }
        if self.grid {
            args.push("--grid".into());
        }
        if let Some(seeds) = self.seeds {
            args.extend(["--seeds".into(), seeds.to_string()]);
        }
        if let Some(preset) = self.preset {
            args.extend(["--preset".into(), preset.name().into()]);
        }
        args
    }
}

/// Runs run `index` of the plan `options` builds from `config` in a child process of `exe`
/// (`splatraj study … --one index`), so that its peak memory is its own.
pub fn measure_in_child(
    exe: &Path,
    config: &Path,
    options: &PlanOptions,
    index: usize,
) -> Result<Vec<StudyRow>, String> {
    let output = output_until_stopped(
        Command::new(exe)
            .args(options.study_args(config))
            .args(["--one", &index.to_string()]),
        &format!("the study process of run {index}"),
    )
    .map_err(|e| format!("{e:#}"))?;
    rows_from_child(&output)
}

/// Measures `runs` of `plan` one after another with `measure`, keeping going past failures;
/// `progress` hears each run's position, label and outcome. A stop requested `since`
/// ([`splatraj_scene::stop`]) ends it between runs. Returns the rows and the failures.
pub fn measure_runs(
    plan: &StudyPlan,
    runs: &[Run],
    mut measure: impl FnMut(&Run) -> Result<Vec<StudyRow>, String>,
    mut progress: impl FnMut(usize, &str, &Result<Vec<StudyRow>, String>),
    since: splatraj_scene::stop::Since,
) -> (Vec<StudyRow>, Vec<Failure>) {
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    splatraj_scene::stop::honour();
    for (i, run) in runs.iter().enumerate() {
        // A stop (Ctrl-C, SIGTERM) ends the study between runs; a run it cut short is not
        // a failure, only not measured.
        if since.stopped() {
            break;
        }
        let label = &plan.variants[run.variant].label;
        let measured = measure(run);
        if since.stopped() {
            break;
        }
        progress(i, label, &measured);
        match measured {
            Ok(new) => rows.extend(new),
            Err(error) => failures.push(Failure {
                run: run.index,
                label: label.clone(),
                error,
            }),
        }
    }
    (rows, failures)
}
