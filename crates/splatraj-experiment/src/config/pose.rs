//! `[pose]`: the single-pose optimisation of `splatraj pose` and the paper's ablations.

use serde::{Deserialize, Serialize};
use splatraj_traj::costs::CostsConfig;
use splatraj_traj::optimise::SinglePoseOptions;

/// The paper's single-pose ablations: which image costs join the prior.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Ablation {
    /// Every cost of `[costs]` as configured.
    Full,
    /// The prior alone.
    Prior,
    /// Prior and TCE.
    PriorTce,
    /// Prior and TRE.
    PriorTre,
    /// Prior, TCE and TRE.
    PriorTceTre,
}

impl Ablation {
    /// Every ablation, in the order of the paper's table.
    pub const ALL: [Ablation; 5] = [
        Ablation::Full,
        Ablation::Prior,
        Ablation::PriorTce,
        Ablation::PriorTre,
        Ablation::PriorTceTre,
    ];

    /// The name used in configs and on the command line (`prior-tce`, …).
    pub fn name(self) -> &'static str {
        match self {
            Ablation::Full => "full",
            Ablation::Prior => "prior",
            Ablation::PriorTce => "prior-tce",
            Ablation::PriorTre => "prior-tre",
            Ablation::PriorTceTre => "prior-tce-tre",
        }
    }

    /// The costs of `config` restricted to this ablation: TCE and TRE on or off as named, the
    /// prior on (with its configured weights, or the defaults), upright as configured.
    pub fn apply(self, config: &CostsConfig) -> CostsConfig {
        let (tce, tre) = match self {
            Ablation::Full => return config.clone(),
            Ablation::Prior => (false, false),
            Ablation::PriorTce => (true, false),
            Ablation::PriorTre => (false, true),
            Ablation::PriorTceTre => (true, true),
        };
        CostsConfig {
            tce: tce.then(|| config.tce.clone().unwrap_or_default()),
            tre: tre.then(|| config.tre.clone().unwrap_or_default()),
            prior: Some(config.prior.clone().unwrap_or_default()),
            // Every other cost (upright, custom, …) as configured.
            ..config.clone()
        }
    }
}

impl std::str::FromStr for Ablation {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ablation::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Ablation::ALL.iter().map(|a| a.name()).collect();
                format!(
                    "unknown ablation `{s}`: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// `[pose]`: single-pose optimisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    /// Which costs (the paper's Table I ablations).
    pub ablation: Ablation,
    /// Which query of `[[queries]]` to frame (0-based).
    pub query: usize,
    /// Adam settings (`[pose.optimiser]`).
    pub optimiser: SinglePoseOptions,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            ablation: Ablation::Full,
            query: 0,
            optimiser: SinglePoseOptions::default(),
        }
    }
}
