//! A cost defined outside splatraj: keep the camera at a preferred height above the floor.
//!
//! The cost is a config struct (its weight and parameter, read from the config's
//! `[costs.custom.height]` table) whose `init()` builds it, and a tensor function of the
//! camera poses; it reads no rendered image, so it declares no channels. It is registered
//! under a name, and a config turns it on. Run it with
//!
//! ```sh
//! cargo run --release --example custom_cost
//! ```
//!
//! which optimises a short trajectory to the red mug of the demo room with and without the
//! cost and prints the camera's mean height in both.

use anyhow::Result;
use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};
use splatraj::experiment::{Config, Experiment, Extensions, optimise::observer};
use splatraj::traj::costs::{Cost, CostConfig, CostError, CostInputs, check_weight};
use splatraj::traj::trajectory::uniform_times;

/// `[costs.custom.height]`: (c·up − height)², the squared distance of the camera centre c
/// from the preferred height along world up.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeightCost {
    /// Weight of the term.
    pub weight: f64,
    /// Preferred camera height along world up, scene units.
    pub height: f64,
}

impl CostConfig for HeightCost {
    fn init(&self) -> Result<Box<dyn Cost>, CostError> {
        self.validate()?;
        Ok(Box::new(self.clone()))
    }
}

impl Cost for HeightCost {
    fn name(&self) -> &'static str {
        "height"
    }

    fn weight(&self, _step: usize) -> f64 {
        self.weight
    }

    fn validate(&self) -> Result<(), CostError> {
        check_weight("custom.height", "weight", self.weight)
    }

    fn evaluate(&self, inputs: &CostInputs) -> Result<Tensor<1>, CostError> {
        let up = inputs.row(inputs.query().unit_up()); // [1, 3]
        let height = (inputs.centres() * up).sum_dim(1).reshape([inputs.batch()]); // [B]
        let off = height.sub_scalar(self.height);
        Ok(off.clone() * off)
    }
}

/// A small experiment: the demo room, the red mug, a short RBF trajectory.
pub const CONFIG: &str = r#"
name = "custom-cost"
seed = 3
[scene]
demo = { gaussians = 8000 }
[[queries]]
text = "red mug"
[camera]
width = 32
height = 24
[optimiser]
iterations = 25
samples_per_window = 2
learning_rate = 0.05
"#;

/// The registries with the height cost added.
pub fn extensions() -> Extensions {
    let mut extensions = Extensions::default();
    extensions.costs.register::<HeightCost>("height");
    extensions
}

/// Optimises the trajectory of [`CONFIG`] plus `extra` TOML (e.g. the cost's table) and
/// returns the mean camera height along world up over 50 times.
pub fn mean_height(extra: &str) -> Result<f64> {
    let extensions = extensions();
    let text = format!("{CONFIG}\n{extra}");
    let config = Config::from_toml(&text, std::path::Path::new("."), &extensions)?;
    let experiment = Experiment::prepare_with(&config, &extensions)?;
    let run = experiment.run_trajectory(&mut observer::quiet())?;
    let trajectory = experiment.trajectory(&run.best().best)?;
    let up = experiment.up.up;
    let poses = trajectory.poses_at(&uniform_times(50));
    let heights: Vec<f64> = poses
        .iter()
        .map(|p| p[3] * up[0] + p[4] * up[1] + p[5] * up[2])
        .collect();
    Ok(heights.iter().sum::<f64>() / heights.len() as f64)
}

/// The default costs (tables listed so that adding one keeps them on) and the height cost.
pub const WITH_HEIGHT: &str = r#"
[costs.tce]
[costs.tre]
[costs.upright]
[costs.prior]
[costs.custom.height]
weight = 5.0
height = 2.0
"#;

fn main() -> Result<()> {
    let without = mean_height("")?;
    let with = mean_height(WITH_HEIGHT)?;
    println!("mean camera height without the cost {without:.3}, with it {with:.3} (preferred 2.0)");
    Ok(())
}
