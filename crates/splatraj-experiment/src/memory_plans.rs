//! The peak memory of a prepared experiment's work, stage by stage: `splatraj run`'s
//! optimisation, model and outputs, `splatraj pose`'s restarts and chains, from the per-item
//! costs of [`crate::resources`].

use anyhow::Result;

use crate::experiment::Experiment;
use crate::resources::{MemoryLimit, MemoryPlan, basis_bytes, render_bytes, scene_bytes};

impl Experiment {
    /// The memory limit of this experiment's work (`max_memory_gb`, else the default share).
    pub fn memory_limit(&self) -> Result<MemoryLimit> {
        MemoryLimit::new(self.config.max_memory_gb)
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
                "the metrics: {metric_poses} poses at `output.width` × `output.height` = {} × {}",
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
        let windows = self.windows.len();
        let spw = self.config.optimiser.samples_per_window;
        let camera = &self.config.camera;
        let camera_pixels = camera.width as f64 * camera.height as f64;
        // The visibility cost also renders each part alone, from its own copy of the part's
        // Gaussians on the autodiff device.
        let alone = if self.config.costs.visibility.is_some() {
            let largest = self.selected.iter().copied().max().unwrap_or(0);
            self.selected
                .iter()
                .map(|&s| scene_bytes(s, fb))
                .sum::<f64>()
                + render_bytes(
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
                 poses at `camera.width` × `camera.height` = {} × {}{}",
                camera.width,
                camera.height,
                if alone > 0.0 {
                    " (and each part alone, for the visibility cost)"
                } else {
                    ""
                }
            ),
            base + render_bytes(windows.saturating_mul(spw), camera_pixels, n, true, fb) + alone,
        );
        let basis = self.model()?.basis().count();
        let output = &self.config.output;
        let samples = [
            splatraj_traj::optimise::start::START_FIT_SAMPLES,
            output.trajectory_samples,
            output.ldj_samples,
            output.frame_count(windows),
            windows.saturating_mul(spw),
        ]
        .into_iter()
        .max()
        .unwrap_or(1);
        plan.stage(
            format!(
                "the trajectory model (`trajectory`): {basis} basis functions sampled at {samples} \
                 times (`output.trajectory_samples`, `output.ldj_samples`, `output.frames`)"
            ),
            base + basis_bytes(basis, samples),
        );
        self.output_stages(&mut plan, self.config.output.metric_samples);
        Ok(plan)
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
