//! `splatraj study` as a library: what accuracy costs in time.
//!
//! A study runs variants of one experiment and measures each the same way. [`plan`] makes the
//! variants (factors from `--vary KEY=V1,V2`, the `[study]` table, a preset or the default
//! sweep of every accuracy-for-time knob; one factor at a time around the config, or the full
//! grid) and the runs (variant × seed), and slices them into shards, with its typed configs
//! (the base and one per variant) made from the config file read once; [`configs`] makes
//! each run's and the evaluation's config from those with typed fields changed. [`measure`] runs one run
//! in this process: the variant's optimisation, timed (wall time, per-stage times), its peak
//! memory, then one fixed evaluation built from the base config that no variant changes.
//! [`rows`] holds the measured rows; [`summary`] aggregates them per variant (mean ± sd over
//! seeds), finds the Pareto frontier of quality against time and the cheapest variant within
//! 5 % of the best quality, and writes `summary.md`; [`plot`] draws `frontier.svg`; [`files`]
//! writes and reads the study folder and merges shards. [`check`] checks a plan before its
//! first run (`--dry-run` stops there): every variant prepared and checked as `run --check`
//! checks a run, the fixed evaluation's sizes, and the study folder; [`conduct`] measures the
//! runs (each in a child process or here) and writes the study.
//!
//! Peak memory is a process-wide high-water mark, so the command runs each run in a child
//! process of its own (as `bench render` does); in-process runs report none.

pub mod check;
pub mod conduct;
pub mod configs;
pub mod context;
pub mod files;
pub mod lines;
pub mod measure;
pub mod plan;
pub mod plot;
pub mod rows;
pub mod summary;
pub mod text;

pub use crate::config::study::{
    Design, EvaluationConfig, FactorConfig, Quality, StudyConfig, StudyTask,
};
pub use check::StudyCheck;
pub use conduct::{
    RunPlace, StudyEnd, StudyNews, StudyOutcome, StudyRequest, conduct_study, measure_one,
    run_study, study_dir,
};
pub use files::{StudyFile, merge_into, merge_studies, read_study, study_folder, write_study};
pub use measure::measure_run;
pub use plan::{Factor, PlannedStudy, Preset, Run, Shard, StudyPlan, Variant};
pub use rows::StudyRow;
pub use summary::StudySummary;
