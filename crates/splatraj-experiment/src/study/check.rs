//! A study checked before its first run: what `splatraj study --dry-run` reports and every
//! study starts with, so that a study left running overnight does not fail run after run on
//! what could be known up front.
//!
//! Every variant of the runs asked for is prepared as its runs will be (its config loaded and
//! validated, the scene read, every query grounded) and checked as `splatraj run --check`
//! (trajectory) or `splatraj pose` (single pose) checks a run: costs, starts, memory and time
//! against their limits. The fixed evaluation is prepared from the base config and its memory
//! and time checked, naming `study.evaluation.*`: once per run, over all the runs. The study
//! folder (`--out`, or a new one under `output.runs_dir`) must be one that can be made. Nothing
//! is optimised and nothing is left behind.
//!
//! Variants are prepared one at a time, each dropped before the next. The scene file is read
//! once for the variants that share `[scene]` (a large scene's reading is most of a
//! preparation); the queries are grounded again for each, because a variant's camera,
//! precision and rasterizer change what the preparation measures.

use std::path::Path;

use anyhow::{Context, Result};

use super::StudyTask;
use super::files::STUDY_NAMES;
use super::plan::{PlannedStudy, Run};
use crate::config::Config;
use crate::config::scene::SceneConfig;
use crate::extensions::Extensions;
use crate::outputs::output_folder::OutputFolder;
use crate::outputs::run_folder::check_writable;
use crate::prepare::experiment::{Experiment, load_scene};
use crate::resources::{
    MemoryPlan, RAISE_LIMIT, Stage, TimeBound, TimePlan, basis_bytes, pixels, render_bytes,
    render_seconds, scene_bytes,
};

/// What a study's check found.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyCheck {
    /// Variants prepared and checked.
    pub variants: usize,
    /// The largest stage of any checked run's or the evaluation's memory plan.
    pub peak: Option<Stage>,
}

impl PlannedStudy {
    /// Checks `runs` of this plan (all of them, or a shard's) and the study folder `out`
    /// (default: a new folder under the base config's `output.runs_dir`) without running any;
    /// an error names the variant, and the key, file or query to blame.
    pub fn check(
        &self,
        runs: &[Run],
        out: Option<&Path>,
        extensions: &Extensions,
    ) -> Result<StudyCheck> {
        match out {
            Some(dir) => OutputFolder::check(dir, &STUDY_NAMES)?,
            None => check_writable(
                &self
                    .base
                    .output
                    .runs_dir
                    .join(format!("{}-study", self.plan.name)),
            )?,
        }
        let mut scenes = SceneCache::default();
        let mut peaks: Vec<Stage> = Vec::new();
        let mut checked: Vec<usize> = Vec::new();
        for run in runs {
            if checked.contains(&run.variant) {
                continue;
            }
            checked.push(run.variant);
            let label = &self.plan.variants[run.variant].label;
            let config = self.run_config(run, extensions)?;
            let experiment = scenes
                .prepare(&config, extensions)
                .with_context(|| format!("study variant `{label}`"))?;
            let plan = match self.plan.task {
                StudyTask::Trajectory => experiment.check_trajectory_work(),
                StudyTask::Pose => experiment.check_pose_run(None),
            }
            .with_context(|| format!("study variant `{label}`"))?;
            peaks.extend(plan.memory.peak().cloned());
        }
        let evaluation = scenes
            .prepare(&self.evaluation_config(extensions)?, extensions)
            .context("the study's evaluation")?;
        let (memory, time) = self.evaluation_plans(&evaluation, runs.len())?;
        memory.check(evaluation.memory_limit()?, RAISE_LIMIT)?;
        time.check(TimeBound::Unbounded)?;
        peaks.extend(memory.peak().cloned());
        Ok(StudyCheck {
            variants: checked.len(),
            peak: peaks.into_iter().max_by(|a, b| a.bytes.total_cmp(&b.bytes)),
        })
    }

    /// The memory of one run's evaluation on `evaluation` (prepared from
    /// [`PlannedStudy::evaluation_config`]), and the time of `runs` of them.
    fn evaluation_plans(
        &self,
        evaluation: &Experiment,
        runs: usize,
    ) -> Result<(MemoryPlan, TimePlan)> {
        let e = &evaluation.config.output;
        let (n, fb) = (evaluation.scene.len(), evaluation.dtype.size());
        let windows = evaluation.windows.len();
        let size = format!(
            "`study.evaluation.width` × `study.evaluation.height` = {} × {}",
            e.width, e.height
        );
        // A trajectory is judged at `samples` poses per window; a single-pose run at each of
        // its starts' poses, one at a time.
        let (what, at_once, renders) = match self.plan.task {
            StudyTask::Trajectory => (
                format!(
                    "`study.evaluation.samples` = {} poses per window of {windows} windows",
                    e.metric_samples
                ),
                e.metric_samples,
                e.metric_samples as f64 * windows as f64,
            ),
            StudyTask::Pose => (
                format!("the pose of each of `--seeds` = {} starts", self.plan.seeds),
                1,
                self.plan.seeds as f64,
            ),
        };
        // The run's own experiment is still held while its evaluation renders: two scenes.
        let held = 2.0 * scene_bytes(n, fb);
        let mut memory = MemoryPlan::default();
        // Each pose is rendered twice (the object in the scene, and alone).
        memory.stage(
            format!("the study's evaluation of a run: {what}, at {size}"),
            held + 2.0 * render_bytes(at_once, pixels(e.width, e.height), n, false, fb),
        );
        if self.plan.task == StudyTask::Trajectory {
            let basis = evaluation.model.basis().count();
            memory.stage(
                format!(
                    "the study's evaluation of a run: LDJ of {basis} basis functions sampled at \
                     `study.evaluation.ldj_samples` = {} times",
                    e.ldj_samples
                ),
                held + basis_bytes(basis, e.ldj_samples),
            );
        }
        let mut time = TimePlan::default();
        time.item(
            format!("the study's evaluation of {runs} runs: {what}, at {size}"),
            render_seconds(runs as f64 * 2.0 * renders, pixels(e.width, e.height)),
        );
        Ok((memory, time))
    }
}

/// The last scene read, for the next config with the same `[scene]`.
#[derive(Default)]
struct SceneCache {
    last: Option<(SceneConfig, (splatraj_scene::Scene, String))>,
}

impl SceneCache {
    /// `config` prepared on its scene, read unless the last config shared its `[scene]`.
    fn prepare(&mut self, config: &Config, extensions: &Extensions) -> Result<Experiment> {
        let loaded = match &self.last {
            Some((key, loaded)) if *key == config.scene => loaded.clone(),
            _ => {
                let loaded = load_scene(config)?;
                self.last = Some((config.scene.clone(), loaded.clone()));
                loaded
            }
        };
        Experiment::prepare_on(config, extensions, loaded)
    }
}
