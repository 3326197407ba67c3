//! The study folder: `study.json` (plan, rows, failures, summary), `study.csv`, `summary.md`
//! and `frontier.svg`, each written whole or not at all; reading it back, and merging the
//! folders of a study's shards into one study.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use super::plan::{Shard, StudyPlan};
use super::plot::frontier_svg;
use super::rows::{StudyRow, study_csv};
use super::summary::{StudyContext, StudySummary};
use super::text::command_line;
use crate::outputs::create_run_dir;
use crate::outputs::output_folder::OutputFolder;
use crate::write::{write_bytes, write_csv, write_json};

/// The format tag of `study.json`.
pub const STUDY_FORMAT: &str = "splatraj-study/1";

/// A run that did not finish.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// Run index.
    pub run: usize,
    /// Its variant's label.
    pub label: String,
    /// What went wrong.
    pub error: String,
}

/// `study.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StudyFile {
    /// [`STUDY_FORMAT`].
    pub format: String,
    /// The plan every run was made from.
    pub plan: StudyPlan,
    /// The slice of the runs this folder holds (none: all of them).
    pub shard: Option<Shard>,
    /// Where and how it ran.
    pub context: StudyContext,
    /// One per run and seed (or start), in run order.
    pub rows: Vec<StudyRow>,
    /// Runs that failed.
    pub failures: Vec<Failure>,
    /// The aggregate (recomputed from the rows when read back).
    #[serde(default, skip_deserializing)]
    pub summary: Option<StudySummary>,
}

impl StudyFile {
    /// A study of `rows` with its summary.
    pub fn new(
        plan: StudyPlan,
        shard: Option<Shard>,
        context: StudyContext,
        mut rows: Vec<StudyRow>,
        failures: Vec<Failure>,
    ) -> StudyFile {
        rows.sort_by_key(|r| (r.run, r.repeat));
        let summary = Some(StudySummary::new(&plan, &rows));
        StudyFile {
            format: STUDY_FORMAT.into(),
            plan,
            shard,
            context,
            rows,
            failures,
            summary,
        }
    }
}

/// The folder a study writes into: `out` (checked now: new, or holding only an earlier
/// study), else a fresh `<runs_dir>/<name>-study/<timestamp>/`.
pub fn study_folder(out: Option<&Path>, runs_dir: &Path, name: &str) -> Result<PathBuf> {
    match out {
        // Checked before the runs, written whole after them ([`write_study`]).
        Some(dir) => {
            OutputFolder::check(dir, &STUDY_NAMES)?;
            Ok(dir.to_path_buf())
        }
        None => create_run_dir(runs_dir, &format!("{name}-study")),
    }
}

/// What a study folder holds: the names [`write_study`] writes.
pub const STUDY_NAMES: [&str; 4] = ["study.csv", "frontier.svg", "summary.md", "study.json"];

/// Writes the study folder `target` whole ([`OutputFolder`]): new, or holding only an earlier
/// study ([`STUDY_NAMES`]), which it replaces; a second writer is refused, and a failure leaves
/// `target` as it was.
pub fn write_study(target: &Path, study: &StudyFile) -> Result<()> {
    let folder = OutputFolder::begin(target, &STUDY_NAMES)?;
    write_study_files(folder.path(), study)?;
    folder.commit()?;
    Ok(())
}

/// The files of [`write_study`] into the folder `dir`.
fn write_study_files(dir: &Path, study: &StudyFile) -> Result<()> {
    let summary = study
        .summary
        .clone()
        .unwrap_or_else(|| StudySummary::new(&study.plan, &study.rows));
    let (header, rows) = study_csv(&study.rows);
    write_csv(&dir.join("study.csv"), &header, &rows)?;
    let title = match study.shard {
        Some(s) => format!(
            "{}: error against time (shard {}/{})",
            study.plan.name, s.index, s.count
        ),
        None => format!("{}: error against time", study.plan.name),
    };
    write_bytes(
        &dir.join("frontier.svg"),
        frontier_svg(&summary, &title)?.as_bytes(),
    )?;
    let mut md = summary.markdown(&study.plan, &study.context);
    if let Some(s) = study.shard {
        md = format!(
            "> Shard {}/{} of the study: only its runs. `splatraj study merge` joins the shards.\n\n{md}",
            s.index, s.count
        );
    }
    if !study.failures.is_empty() {
        md += "\n## Failed runs\n\n";
        for f in &study.failures {
            md += &format!("- run {} (`{}`): {}\n", f.run, f.label, f.error);
        }
    }
    write_bytes(&dir.join("summary.md"), md.as_bytes())?;
    let with_summary = StudyFile {
        summary: Some(summary),
        ..study.clone()
    };
    write_json(&dir.join("study.json"), &with_summary)
}

/// Reads `dir/study.json`.
pub fn read_study(dir: &Path) -> Result<StudyFile> {
    let path = dir.join("study.json");
    let text = splatraj_scene::input::read_text(&path).with_context(|| {
        format!(
            "cannot read {} (is {} a study folder?)",
            path.display(),
            dir.display()
        )
    })?;
    let study: StudyFile = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a splatraj study.json", path.display()))?;
    if study.format != STUDY_FORMAT {
        bail!(
            "{}: format `{}`, expected `{STUDY_FORMAT}`",
            path.display(),
            study.format
        );
    }
    Ok(study)
}

/// `splatraj study merge` whole: the shards' folders `dirs` merged ([`merge_studies`]) and
/// written into `out` ([`write_study`]); returns the merged study.
pub fn merge_into(dirs: &[&Path], out: &Path) -> Result<StudyFile> {
    let study = merge_studies(dirs)?;
    write_study(out, &study)?;
    Ok(study)
}

/// Joins the study folders `dirs` (shards of one study) into one study: same plan, every
/// shard once, no run twice. Missing shards are an error naming them.
pub fn merge_studies(dirs: &[&Path]) -> Result<StudyFile> {
    let Some((first_dir, rest)) = dirs.split_first() else {
        bail!("study merge: give at least one study folder");
    };
    let first = read_study(first_dir)?;
    let mut rows = first.rows.clone();
    let mut failures = first.failures.clone();
    let mut shards: Vec<Shard> = first.shard.into_iter().collect();
    for dir in rest {
        let other = read_study(dir)?;
        if other.plan != first.plan {
            bail!(
                "{} holds another study than {} (its plan differs: config, overrides, factors, \
                 seeds or evaluation)",
                dir.display(),
                first_dir.display()
            );
        }
        if let Some(s) = other.shard {
            if shards.iter().any(|t| t.count != s.count) {
                bail!(
                    "{} is shard {}/{}, the others are of {} shards",
                    dir.display(),
                    s.index,
                    s.count,
                    shards[0].count
                );
            }
            if shards.contains(&s) {
                bail!(
                    "{}: shard {}/{} is given twice",
                    dir.display(),
                    s.index,
                    s.count
                );
            }
            shards.push(s);
        }
        rows.extend(other.rows);
        failures.extend(other.failures);
    }
    if let Some(count) = shards.first().map(|s| s.count) {
        let missing: Vec<String> = (1..=count)
            .filter(|k| !shards.iter().any(|s| s.index == *k))
            .map(|k| format!("{k}/{count}"))
            .collect();
        if !missing.is_empty() {
            bail!("study merge: shard(s) {} missing", missing.join(", "));
        }
    }
    let mut seen = std::collections::HashSet::new();
    for r in &rows {
        if !seen.insert((r.run, r.repeat)) {
            bail!(
                "study merge: run {} (`{}`, repeat {}) appears twice",
                r.run,
                r.label,
                r.repeat
            );
        }
    }
    let context = StudyContext {
        command: Some(merge_command(dirs, std::env::args())),
        ..first.context.clone()
    };
    Ok(StudyFile::new(first.plan, None, context, rows, failures))
}

/// The command that regenerates a merged study, for its `summary.md`: the process's own command
/// line when it is a `study merge` (only that one names `--out`, which this function is not
/// told), else a merge of `dirs` into a folder left for the reader to fill in.
fn merge_command(dirs: &[&Path], process: impl IntoIterator<Item = String>) -> String {
    let args: Vec<String> = process.into_iter().collect();
    if args.windows(2).any(|w| w[0] == "study" && w[1] == "merge") {
        return command_line(args);
    }
    let named = ["splatraj", "study", "merge"]
        .into_iter()
        .map(String::from)
        .chain(dirs.iter().map(|d| d.display().to_string()));
    format!("{} --out <folder>", command_line(named))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(args: &[&str]) -> Vec<String> {
        args.iter().map(|a| a.to_string()).collect()
    }

    #[test]
    fn a_merge_names_the_command_that_regenerates_it() {
        let dirs = [
            Path::new("studies/demo/shard-1"),
            Path::new("studies/demo/shard 2"),
        ];
        let typed = strings(&[
            "/usr/local/bin/splatraj",
            "study",
            "merge",
            "studies/demo/shard-1",
            "studies/demo/shard 2",
            "--out",
            "studies/demo/all",
        ]);
        assert_eq!(
            merge_command(&dirs, typed),
            "splatraj study merge studies/demo/shard-1 'studies/demo/shard 2' --out studies/demo/all"
        );
        // Called from elsewhere (a test binary, a library user): the folders, --out to fill in.
        assert_eq!(
            merge_command(&dirs, strings(&["tests-1234", "--nocapture"])),
            "splatraj study merge studies/demo/shard-1 'studies/demo/shard 2' --out <folder>"
        );
    }
}
