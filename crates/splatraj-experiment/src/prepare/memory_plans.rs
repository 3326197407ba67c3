//! The peak memory and the time of a prepared experiment's work, stage by stage: `splatraj
//! run`'s optimisation, history, model and outputs, `splatraj pose`'s restarts and chains,
//! from the per-item costs of [`crate::resources`].

use anyhow::Result;

use crate::prepare::experiment::Experiment;
use crate::resources::{
    HISTORY_BYTES_PER_WINDOW_STEP, MAX_STEPS_PER_SECOND, MIN_SECONDS_PER_STEP, MemoryLimit,
    MemoryPlan, RESTART_BYTES_PER_BASIS, TimePlan, basis_bytes, pixels, render_bytes,
    render_seconds, scene_bytes,
};

impl Experiment {
    /// The memory limit of this experiment's work (`max_memory_gb`, else the default share).
    pub fn memory_limit(&self) -> Result<MemoryLimit> {
        MemoryLimit::new(self.config.max_memory_gb)
    }

    /// Peak memory of preparing this experiment after its scene is loaded: the view search and
    /// the working distances render batches of poses at the camera's size (before the plans
    /// of the work, which need the prepared windows).
    pub fn preparation_memory(&self) -> MemoryPlan {
        let mut plan = MemoryPlan::default();
        let (n, fb) = (self.scene.len(), self.dtype.size());
        let base = scene_bytes(n, fb);
        let camera = &self.config.camera;
        let camera_pixels = camera.width as f64 * camera.height as f64;
        let batch = splatraj_traj::optimise::VIEW_SEARCH_BATCH;
        plan.stage(format!("the scene ({n} Gaussians)"), base);
        // Each batch is also read back as f64 on the host, while the next one renders (its
        // mask and alpha held on the device meanwhile).
        plan.stage(
            format!(
                "the view search: {batch} poses at once at `camera.width` × `camera.height` = \
                 {} × {}",
                camera.width, camera.height
            ),
            base + render_bytes(batch, camera_pixels, n, false, fb)
                + batch as f64 * camera_pixels * (8.0 + 2.0 * fb as f64),
        );
        plan
    }

    /// The stages every piece of work shares: the scene, metrics and frames at the output size.
    fn output_stages(&self, plan: &mut MemoryPlan, metric_poses: usize) {
        let (n, fb) = (self.scene.len(), self.dtype.size());
        let base = scene_bytes(n, fb);
        let output = &self.config.output;
        let pixels = output.width as f64 * output.height as f64;
        plan.stage(format!("the scene ({n} Gaussians)"), base);
        // Metrics render each pose twice (the object in the scene, and alone).
        plan.stage(
            format!(
                "the metrics: {metric_poses} poses (`output.metric_samples` per window) at \
                 `output.width` × `output.height` = {} × {}",
                output.width, output.height
            ),
            base + 2.0 * render_bytes(metric_poses, pixels, n, false, fb),
        );
    }

    /// Peak memory of `splatraj run` on this experiment, stage by stage.
    pub fn trajectory_memory(&self) -> Result<MemoryPlan> {
        let mut plan = MemoryPlan::default();
        let (n, fb) = (self.scene.len(), self.dtype.size());
        let base = scene_bytes(n, fb);
        // The optimisation renders the coarse copy when there is one, held beside the scene.
        let (optimised, selected) = match &self.coarse {
            None => (n, self.selected.clone()),
            Some(c) => (
                c.scene.len(),
                c.masks
                    .iter()
                    .map(|m| m.iter().filter(|&&v| v != 0.0).count())
                    .collect(),
            ),
        };
        let held = base
            + if optimised < n {
                scene_bytes(optimised, fb)
            } else {
                0.0
            };
        let windows = self.windows.len();
        let spw = self.config.optimiser.samples_per_window;
        let camera = &self.config.camera;
        let camera_pixels = camera.width as f64 * camera.height as f64;
        // The visibility cost also renders each part alone: the same poses again in the step's
        // one pass, drawing only the part's Gaussians.
        let alone = if self.config.costs.visibility.is_some() {
            let largest = selected.iter().copied().max().unwrap_or(0);
            render_bytes(
                windows.saturating_mul(spw),
                camera_pixels,
                largest,
                true,
                fb,
            )
        } else {
            0.0
        };
        plan.stage(
            format!(
                "an optimisation step: {windows} windows × `optimiser.samples_per_window` = {spw} \
                 poses at `camera.width` × `camera.height` = {} × {} of {optimised} Gaussians \
                 (`optimise_gaussians`){}",
                camera.width,
                camera.height,
                if alone > 0.0 {
                    " (and each part alone, for the visibility cost)"
                } else {
                    ""
                }
            ),
            held + render_bytes(
                windows.saturating_mul(spw),
                camera_pixels,
                optimised,
                true,
                fb,
            ) + alone,
        );
        let basis = self.model.basis().count();
        let output = &self.config.output;
        let optimiser = &self.config.optimiser;
        let samples = [
            splatraj_traj::optimise::start::START_FIT_SAMPLES,
            output.trajectory_samples,
            output.ldj_samples,
            output.frame_count(windows),
            windows.saturating_mul(spw),
            windows.saturating_mul(optimiser.path_samples),
        ]
        .into_iter()
        .max()
        .unwrap_or(1);
        plan.stage(
            format!(
                "the trajectory model (`trajectory`: `trajectory.centres_per_window`, or the \
                 model's other size keys): {basis} basis functions sampled at {samples} \
                 times (`output.trajectory_samples`, `output.ldj_samples`, `output.frames`, \
                 `output.fps` × `output.seconds`, `optimiser.path_samples`)"
            ),
            base + basis_bytes(basis, samples),
        );
        // Every step of every restart keeps a history row per window; a time limit caps the
        // steps that can run.
        let restarts = self.config.start.restarts.max(1);
        let steps = restarts as f64 * optimiser.iterations as f64;
        let steps = match optimiser.time_limit_s {
            Some(limit) => steps.min(limit * MAX_STEPS_PER_SECOND),
            None => steps,
        };
        plan.stage(
            format!(
                "the optimisation's history and starts: `start.restarts` × \
                 `optimiser.iterations` = {restarts} × {} steps (fewer under \
                 `optimiser.time_limit_s`) of {windows} windows, {basis} basis functions each",
                optimiser.iterations
            ),
            base + steps * windows as f64 * HISTORY_BYTES_PER_WINDOW_STEP
                + restarts as f64 * basis as f64 * RESTART_BYTES_PER_BASIS,
        );
        self.output_stages(&mut plan, self.config.output.metric_samples);
        Ok(plan)
    }

    /// A lower bound of the time of `splatraj run`: the optimisation (bounded by
    /// `optimiser.time_limit_s`), and what comes before and after it (the start views, the
    /// metrics and the frames, which nothing bounds).
    pub fn trajectory_time(&self) -> (TimePlan, TimePlan) {
        let windows = self.windows.len() as f64;
        let optimiser = &self.config.optimiser;
        let restarts = self.config.start.restarts.max(1) as f64;
        let steps = restarts * optimiser.iterations as f64;
        let camera = &self.config.camera;
        let mut optimisation = TimePlan::default();
        optimisation.item(
            format!(
                "the optimisation: `start.restarts` × `optimiser.iterations` = {restarts} × {} \
                 steps of {windows} windows × `optimiser.samples_per_window` = {} renders at \
                 `camera.width` × `camera.height` = {} × {}",
                optimiser.iterations, optimiser.samples_per_window, camera.width, camera.height
            ),
            steps * MIN_SECONDS_PER_STEP
                + render_seconds(
                    steps * windows * optimiser.samples_per_window as f64,
                    pixels(camera.width, camera.height),
                ),
        );
        let output = &self.config.output;
        let frames = output.frame_count(self.windows.len()) as f64;
        let mut rest = TimePlan::default();
        let start = &self.config.start;
        if start.kind == crate::config::StartKind::Search
            && start.pose.is_none()
            && start.trajectory.is_none()
        {
            // Each restart picks its start views among every window's candidates, avoiding
            // the ones earlier restarts took: quadratic in the restarts (measured 1.5 µs ×
            // restarts² per window).
            rest.item(
                format!(
                    "choosing the start views (`start.kind` = \"search\") of `start.restarts` = \
                     {restarts} restarts"
                ),
                restarts * restarts * windows * 1e-7,
            );
        }
        // Measured 50 µs per restart (object and random starts).
        rest.item(
            format!("the starts of `start.restarts` = {restarts} restarts"),
            restarts * windows * 1e-5,
        );
        rest.item(
            format!(
                "the metrics and frames: `output.metric_samples` = {} and {frames} frames \
                 (`output.frames`, `output.fps` × `output.seconds`) at `output.width` × \
                 `output.height` = {} × {}",
                output.metric_samples, output.width, output.height
            ),
            render_seconds(
                2.0 * output.metric_samples as f64 + frames,
                pixels(output.width, output.height),
            ),
        );
        (optimisation, rest)
    }

    /// A lower bound of the time of `splatraj pose` with `chains` SGLD chains.
    pub fn pose_time(&self, chains: usize) -> TimePlan {
        let restarts = self.config.start.restarts.max(1) as f64;
        let iterations = self.config.pose.optimiser.iterations as f64;
        let camera = &self.config.camera;
        let mut time = TimePlan::default();
        time.item(
            format!(
                "the pose optimisation: `pose.optimiser.iterations` = {iterations} steps of \
                 `start.restarts` (--restarts) = {restarts} renders at `camera.width` × \
                 `camera.height` = {} × {}",
                camera.width, camera.height
            ),
            iterations * MIN_SECONDS_PER_STEP
                + render_seconds(iterations * restarts, pixels(camera.width, camera.height)),
        );
        if chains > 0 {
            // The chains step together, one batch of renders per SGLD iteration.
            let steps = self.config.sgld.iterations as f64;
            time.item(
                format!(
                    "SGLD: `sgld.iterations` = {steps} steps of --sgld {chains} chains at \
                     `camera.width` × `camera.height` = {} × {}",
                    camera.width, camera.height
                ),
                steps * MIN_SECONDS_PER_STEP
                    + render_seconds(steps * chains as f64, pixels(camera.width, camera.height)),
            );
        }
        time
    }

    /// Peak memory of `splatraj pose` with `chains` SGLD chains (0: none), stage by stage.
    pub fn pose_memory(&self, chains: usize) -> MemoryPlan {
        let mut plan = MemoryPlan::default();
        let (n, fb) = (self.scene.len(), self.dtype.size());
        let base = scene_bytes(n, fb);
        let camera = &self.config.camera;
        let pixels = camera.width as f64 * camera.height as f64;
        let restarts = self.config.start.restarts;
        plan.stage(
            format!(
                "the pose optimisation: `start.restarts` (--restarts) = {restarts} poses at \
                 `camera.width` × `camera.height` = {} × {}",
                camera.width, camera.height
            ),
            base + render_bytes(restarts, pixels, n, true, fb),
        );
        plan.stage(
            format!(
                "SGLD: --sgld {chains} chains at `camera.width` × `camera.height` = {} × {}",
                camera.width, camera.height
            ),
            base + render_bytes(chains, pixels, n, true, fb),
        );
        self.output_stages(&mut plan, 1);
        plan
    }
}
