//! The loss of one object at one camera, through the optimiser's own loss path
//! ([`Problem::loss_at`]): what `splatraj render --grad` prints and `splatraj bench` times.

use std::time::Instant;

use anyhow::Result;
use burn::tensor::{DType, Device};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::Scene;
use splatraj_traj::costs::{CostsConfig, QueryContext, WeightedCosts};
use splatraj_traj::optimise::{PoseLoss, Problem, WindowTarget};

/// One object's TCE + TRE (weight 1 each) at a camera, on a plain and an autodiff device.
#[derive(Debug)]
pub struct MaskProbe {
    plain: DeviceScene,
    autodiff: DeviceScene,
    window: [WindowTarget; 1],
    costs: WeightedCosts,
    /// The camera.
    pub intrinsics: Intrinsics,
    /// The rasterizer.
    pub rasterizer: Rasterizer,
    /// Prune the mask pass to the object (exact; off to measure the unpruned cost).
    pub prune: bool,
}

impl MaskProbe {
    /// Uploads `scene` to `device` (plain and autodiff) in `dtype` for the object `mask`
    /// framed at `target_ratio`.
    pub fn new(
        scene: &Scene,
        (device, dtype): (&Device, DType),
        mask: Vec<f32>,
        target_ratio: f64,
        intrinsics: Intrinsics,
        rasterizer: Rasterizer,
    ) -> Result<Self> {
        let costs = CostsConfig {
            upright: None,
            prior: None,
            ..CostsConfig::default()
        }
        .build()
        .map_err(anyhow::Error::msg)?;
        let window = [WindowTarget {
            name: "object".into(),
            mask,
            // TCE and TRE read only the mask and the target ratio; the rest must be valid.
            context: QueryContext {
                object_centre: [0.0; 3],
                prior_radius: 1.0,
                world_up: [0.0, 0.0, 1.0],
                target_ratio,
            },
        }];
        Ok(Self {
            plain: DeviceScene::new(scene, device, dtype),
            autodiff: DeviceScene::new(scene, &device.clone().autodiff(), dtype),
            window,
            costs,
            intrinsics,
            rasterizer,
            prune: true,
        })
    }

    fn problem<'a>(&'a self, scene: &'a DeviceScene) -> Problem<'a> {
        Problem {
            prune: self.prune,
            ..Problem::new(scene, &self.window, &self.costs, self.intrinsics)
                .with_rasterizer(self.rasterizer)
        }
    }

    /// Render + loss, no gradient (read back, so a timing is complete).
    pub fn forward(&self, pose: &Pose) -> Result<PoseLoss> {
        Ok(self.problem(&self.plain).loss_at(0, pose, false)?)
    }

    /// Render + loss + backward to the pose.
    pub fn forward_backward(&self, pose: &Pose) -> Result<PoseLoss> {
        Ok(self.problem(&self.autodiff).loss_at(0, pose, true)?)
    }

    /// The plain-device scene.
    pub fn scene(&self) -> &DeviceScene {
        &self.plain
    }

    /// Costs and pose gradient at `pose`, and the median of `repeats` timings of the forward
    /// and forward + backward passes.
    pub fn measure(&self, pose: &Pose, repeats: usize) -> Result<ProbeReport> {
        let result = self.forward_backward(pose)?;
        let forward_ms = median_ms(repeats, || self.forward(pose).map(|_| ()))?;
        let forward_backward_ms = median_ms(repeats, || self.forward_backward(pose).map(|_| ()))?;
        let coverage = result.coverage.unwrap_or(0.0);
        Ok(ProbeReport {
            tce: (coverage > 0.0).then(|| result.term("tce")),
            tre: result.term("tre"),
            loss: result.total,
            grad_pose: result.grad_pose.unwrap_or_else(|| vec![0.0; 6]),
            coverage,
            forward_ms,
            forward_backward_ms,
        })
    }
}

/// What [`MaskProbe::measure`] found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ProbeReport {
    /// TCE; None (JSON null) when the object covers none of the frame: an object not seen
    /// has no framing error (as in `frame_metrics.csv`), though the loss counts it as 0.
    pub tce: Option<f64>,
    /// TRE.
    pub tre: f64,
    /// TCE + TRE, as the optimiser weighs them (an unseen object's TCE counting 0).
    pub loss: f64,
    /// d loss / dΦ, Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z].
    pub grad_pose: Vec<f64>,
    /// Share of the frame the object covers.
    pub coverage: f64,
    /// Median time of mask render + loss (no autodiff).
    pub forward_ms: f64,
    /// Median time of mask render + loss + backward on the autodiff device.
    pub forward_backward_ms: f64,
}

impl ProbeReport {
    /// Every number that reaches a file (for the non-finite check).
    pub fn values(&self) -> Vec<f64> {
        let mut values: Vec<f64> = self.tce.into_iter().collect();
        values.extend([self.tre, self.loss, self.coverage]);
        values.extend(&self.grad_pose);
        values
    }
}

/// Median of `runs` timings of `f`, in milliseconds.
pub fn median_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut times = Vec::with_capacity(runs.min(1 << 16));
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let n = times.len();
    Ok(if n % 2 == 1 {
        times[n / 2]
    } else {
        0.5 * (times[n / 2 - 1] + times[n / 2])
    })
}
