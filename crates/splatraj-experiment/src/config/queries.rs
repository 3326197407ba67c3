//! `[[queries]]`: the things to look at, one time window each.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use splatraj_traj::shots::{Hold, ShotSpec};

/// `[[queries]]`: one thing to look at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QueryConfig {
    /// The query (label name, phrase, region name), or a name for a `mask` target.
    pub text: String,
    /// Share of the frame the object should cover; default `[camera] target_ratio`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_ratio: Option<f64>,
    /// A per-Gaussian 0/1 mask (`.npy`, one value per Gaussian) used instead of the source.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<PathBuf>,
    /// A shot preset for this window (orbit, dolly; trajectory runs): its start and its cost.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shot: Option<ShotSpec>,
    /// What the camera does while it holds on the part (`still`, `orbit`, `push`): a shot
    /// preset by its short name ([`Hold::shot`]); not together with `shot`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold: Option<Hold>,
}

impl QueryConfig {
    /// The window's shot: `shot`, or the preset `hold` names (validation refuses both).
    pub fn window_shot(&self) -> Option<ShotSpec> {
        self.shot.clone().or_else(|| self.hold.and_then(Hold::shot))
    }
}
