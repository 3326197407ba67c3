//! A small study in this process (tiny demo scene, two knobs × two values): a row for every
//! run, a frontier of exactly the non-dominated variants (brute force), files that read back,
//! and an evaluation that does not depend on the variant.

use std::path::{Path, PathBuf};

use splatraj_experiment::Extensions;
use splatraj_experiment::config::ConfigFile;
use splatraj_experiment::study::measure::MemoryReading;
use splatraj_experiment::study::plan::PlanOptions;
use splatraj_experiment::study::rows::StudyRow;
use splatraj_experiment::study::summary::StudyContext;
use splatraj_experiment::study::{
    Design, Factor, PlannedStudy, StudyFile, StudySummary, measure_run, read_study, write_study,
};

const TINY: &str = r#"
name = "tiny"
seed = 3
[scene]
demo = { gaussians = 3000, seed = 7 }
[[queries]]
text = "red mug"
[[queries]]
text = "blue box"
[camera]
width = 32
height = 24
[optimiser]
iterations = 3
samples_per_window = 2
# The paper's four costs: no clearance, so the study has no clearance to report.
[costs.tce]
[costs.tre]
[costs.upright]
[costs.prior]
[output]
width = 40
height = 30
[study]
seeds = 2
[study.evaluation]
samples = 2
ldj_samples = 11
"#;

/// Every run of `study`, measured in this process.
fn measure_all(study: &PlannedStudy, extensions: &Extensions) -> Vec<StudyRow> {
    let mut rows = Vec::new();
    for run in &study.plan.runs {
        rows.extend(
            measure_run(
                study,
                run,
                extensions,
                MemoryReading::Shared,
                splatraj_scene::stop::Since::now(),
            )
            .unwrap(),
        );
    }
    rows
}

/// The study of the config file `path` with `options`.
fn planned(path: &Path, options: &PlanOptions, extensions: &Extensions) -> PlannedStudy {
    PlannedStudy::new(&ConfigFile::read(path).unwrap(), options, extensions).unwrap()
}

fn config(dir: &Path) -> PathBuf {
    let path = dir.join("tiny.toml");
    std::fs::write(&path, TINY).unwrap();
    path
}

fn options(grid: bool) -> PlanOptions {
    PlanOptions {
        vary: vec![
            Factor::parse("optimiser.iterations=2,4").unwrap(),
            Factor::parse("camera={width=16,height=12},{width=48,height=36}").unwrap(),
        ],
        grid,
        ..PlanOptions::default()
    }
}

#[test]
fn one_at_a_time_is_the_baseline_and_each_value_alone() {
    let dir = tempfile::tempdir().unwrap();
    let study = planned(&config(dir.path()), &options(false), &Extensions::default());
    let plan = &study.plan;
    assert_eq!(plan.design, Design::OneAtATime);
    let labels: Vec<&str> = plan.variants.iter().map(|v| v.label.as_str()).collect();
    assert_eq!(
        labels,
        [
            "baseline",
            "iterations=2",
            "iterations=4",
            "camera={width=16,height=12}",
            "camera={width=48,height=36}"
        ]
    );
    // The table value sets each key, keeping the rest of [camera] (fov_x, target_ratio).
    assert_eq!(
        plan.variants[3].overrides,
        ["camera.height=12", "camera.width=16"]
    );
    assert_eq!(plan.runs.len(), 5 * 2);
    // A value equal to the config's is the baseline itself, not a second variant.
    let same = PlanOptions {
        vary: vec![Factor::parse("optimiser.iterations=3,4").unwrap()],
        ..PlanOptions::default()
    };
    let study = planned(&config(dir.path()), &same, &Extensions::default());
    assert_eq!(study.plan.variants.len(), 2);
    // A bad value fails before anything runs, naming the variant and the key.
    let bad = PlanOptions {
        vary: vec![Factor::parse("optimiser.samples_per_window=0").unwrap()],
        ..PlanOptions::default()
    };
    let file = ConfigFile::read(&config(dir.path())).unwrap();
    let err = PlannedStudy::new(&file, &bad, &Extensions::default()).unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("samples_per_window=0"), "{text}");
}

#[test]
fn a_grid_study_has_a_row_per_run_and_a_non_dominated_frontier() {
    let dir = tempfile::tempdir().unwrap();
    let extensions = Extensions::default();
    let study = planned(&config(dir.path()), &options(true), &extensions);
    let plan = &study.plan;
    assert_eq!(plan.variants.len(), 4);
    assert_eq!(plan.runs.len(), 8);
    let rows = measure_all(&study, &extensions);
    for v in &plan.variants {
        let seeds: Vec<u64> = rows
            .iter()
            .filter(|r| r.variant == v.index)
            .map(|r| r.seed)
            .collect();
        assert_eq!(seeds, [3, 4], "variant {}", v.label);
    }
    for r in &rows {
        assert!(r.error.is_finite() && r.optimisation_s > 0.0, "{r:?}");
        // Renders ran, and decide is part of projection (the renderer's clock is
        // process-wide and other tests render at the same time, so only same-clock relations
        // and positivity are checked).
        let stages = r.stages.unwrap();
        assert!(stages.decide_s > 0.0 && stages.decide_s <= stages.projection_s);
        assert!(stages.composite_backward_s > 0.0, "{stages:?}");
        // No clearance cost in the config: nothing to report.
        assert!(r.min_clearance.is_none() && r.windows[0].min_clearance.is_none());
        assert_eq!(r.windows.len(), 2);
        assert!(r.peak_mb.is_none());
        // The evaluation is the base config's, whatever the variant: 2 poses per window.
        let expected = (r.windows[0].tce.unwrap()
            + r.windows[0].tre
            + r.windows[1].tce.unwrap()
            + r.windows[1].tre)
            / 2.0;
        assert!((r.error - expected).abs() < 1e-12);
    }

    let summary = StudySummary::new(plan, &rows);
    assert_eq!(summary.variants.len(), 4);
    // Brute force: a variant is on the frontier iff no other is at least as fast and as good
    // and strictly better in one.
    let points: Vec<(f64, f64)> = summary.variants.iter().map(|v| v.figures.point()).collect();
    for (i, v) in summary.variants.iter().enumerate() {
        let dominated = points.iter().enumerate().any(|(j, q)| {
            j != i
                && q.0 <= points[i].0
                && q.1 <= points[i].1
                && (q.0 < points[i].0 || q.1 < points[i].1)
        });
        assert_eq!(
            v.on_frontier, !dominated,
            "{}: {:?} of {points:?}",
            v.label, points[i]
        );
        assert_eq!(summary.frontier.contains(&i), !dominated);
    }
    // Mean over the two seeds.
    let first: Vec<f64> = rows
        .iter()
        .filter(|r| r.variant == 0)
        .map(|r| r.error)
        .collect();
    let mean = summary.variants[0].figures.error.unwrap().mean;
    assert!((mean - (first[0] + first[1]) / 2.0).abs() < 1e-12);
    let best = summary.best.unwrap();
    let cheap = summary.cheapest_within_5_percent.unwrap();
    assert!(points[cheap].1 <= points[best].1 * 1.05 + 1e-15);
    assert!(
        points
            .iter()
            .all(|p| p.1 > points[best].1 * 1.05 || p.0 >= points[cheap].0)
    );

    let out = dir.path().join("study");
    let study = StudyFile::new(
        plan.clone(),
        None,
        StudyContext::default(),
        rows.clone(),
        Vec::new(),
    );
    write_study(&out, &study).unwrap();
    for file in ["study.csv", "study.json", "frontier.svg", "summary.md"] {
        assert!(out.join(file).is_file(), "{file}");
    }
    let back = read_study(&out).unwrap();
    assert_eq!(back.plan, *plan);
    // serde_json reads floats back to within an ulp.
    assert_eq!(back.rows.len(), study.rows.len());
    for (a, b) in back.rows.iter().zip(&study.rows) {
        assert_eq!((a.run, a.repeat, &a.label), (b.run, b.repeat, &b.label));
        assert!((a.error - b.error).abs() < 1e-12 && (a.iou - b.iou).abs() < 1e-12);
    }
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 8);
    let svg = std::fs::read_to_string(out.join("frontier.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("iterations=4"));
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.contains("Cheapest setting within 5 %"), "{md}");

    // The folder is written whole: a second study replaces the first (its rows, not a mix),
    // and a folder holding the user's files is refused, untouched.
    let fewer = StudyFile::new(
        plan.clone(),
        None,
        StudyContext::default(),
        rows[..2].to_vec(),
        Vec::new(),
    );
    write_study(&out, &fewer).unwrap();
    assert_eq!(read_study(&out).unwrap().rows.len(), 2);
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2);
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), "mine").unwrap();
    let err = format!("{:#}", write_study(&mine, &study).unwrap_err());
    assert!(err.contains("notes.txt"), "{err}");
    assert_eq!(std::fs::read_dir(&mine).unwrap().count(), 1);
}

/// With a clearance cost in the base config, every row carries the evaluation's clearance: the
/// smallest over its windows and the mean share of time inside the margin, and `summary.md`
/// shows them.
#[test]
fn a_clearance_config_reports_the_paths_clearance() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny-clear.toml");
    let config = TINY.replace(
        "samples_per_window = 2",
        "samples_per_window = 2\npath_samples = 6",
    ) + "[costs.clearance]\nweight = 1.0\nmargin = 0.1\n";
    std::fs::write(&path, config).unwrap();
    let extensions = Extensions::default();
    let options = PlanOptions {
        seeds: Some(1),
        vary: vec![Factor::parse("optimiser.iterations=1").unwrap()],
        ..PlanOptions::default()
    };
    let study = planned(&path, &options, &extensions);
    let plan = &study.plan;
    let rows = measure_all(&study, &extensions);
    assert_eq!(rows.len(), 2);
    for r in &rows {
        let per_window: Vec<f64> = r.windows.iter().map(|w| w.min_clearance.unwrap()).collect();
        let smallest = per_window.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(r.min_clearance, Some(smallest), "{r:?}");
        let inside: f64 = r
            .windows
            .iter()
            .map(|w| w.time_inside_margin.unwrap())
            .sum::<f64>()
            / r.windows.len() as f64;
        assert!((r.inside_margin.unwrap() - inside).abs() < 1e-12);
        assert!((0.0..=1.0).contains(&inside));
    }
    let md = StudySummary::new(plan, &rows).markdown(plan, &StudyContext::default());
    assert!(
        md.contains("| min clearance | time inside margin |"),
        "{md}"
    );
}

/// A study reads its config file once: with the file gone once read, the plan, its check,
/// every run's config and the evaluation's are still made (from the typed configs), and each
/// is the config that loading the file with the same `--set` edits gives.
#[test]
fn a_study_reads_its_config_file_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = config(dir.path());
    let file = ConfigFile::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let extensions = Extensions::default();
    let options = PlanOptions {
        vary: vec![
            Factor::parse("optimiser.iterations=2").unwrap(),
            Factor::parse("camera={width=16,height=12}").unwrap(),
        ],
        ..PlanOptions::default()
    };
    let study = PlannedStudy::new(&file, &options, &extensions).unwrap();
    let runs = study.plan.runs_of(None);
    let check = study
        .check(&runs, Some(&dir.path().join("out")), &extensions)
        .unwrap();
    assert_eq!(check.variants, 3);
    let configs: Vec<_> = runs
        .iter()
        .map(|run| study.run_config(run, &extensions).unwrap())
        .collect();
    let evaluation = study.evaluation_config(&extensions).unwrap();

    // The same configs as loading the file again with each edit as `--set` text.
    std::fs::write(&path, TINY).unwrap();
    for (run, config) in runs.iter().zip(&configs) {
        let mut set = study.plan.variants[run.variant].overrides.clone();
        set.push(format!("seed={}", 3 + run.repeat));
        assert_eq!(
            *config,
            splatraj_experiment::Config::load(&path, &set).unwrap(),
            "run {}",
            run.index
        );
    }
    let sizes = [
        "output.width=40",
        "output.height=30",
        "output.metric_samples=2",
        "output.ldj_samples=11",
    ]
    .map(String::from);
    assert_eq!(
        evaluation,
        splatraj_experiment::Config::load(&path, &sizes).unwrap()
    );
}
