//! `[scene]`: where the Gaussians come from.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// `[scene]`: a file or the built-in demo room (exactly one of `path` and `demo`).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneConfig {
    /// Scene file (INRIA PLY, compressed PLY, SPZ).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// The built-in demo room.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub demo: Option<DemoSceneConfig>,
    /// Label sidecar (Segments.ai JSON or a JSON array of ids).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<PathBuf>,
    /// Drop invalid Gaussians (with a warning) instead of stopping.
    pub drop_invalid: bool,
    /// World up; by default from the capture's cameras (`cameras`, or a camera file beside
    /// the scene), else guessed from the scene (the demo's is +z).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub up: Option<[f64; 3]>,
    /// The capture's cameras (INRIA `cameras.json`, nerfstudio `transforms.json`, COLMAP
    /// `images.txt`), for world up; by default one found beside the scene under its usual
    /// name (the experiment's `scene_up`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cameras: Option<PathBuf>,
}

/// `[scene.demo]`: the demo room's generator settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemoSceneConfig {
    /// Number of Gaussians.
    pub gaussians: usize,
    /// Generator seed.
    pub seed: u64,
}

impl Default for DemoSceneConfig {
    fn default() -> Self {
        let d = splatraj_scene::demo::DemoConfig::default();
        Self {
            gaussians: d.gaussians,
            seed: d.seed,
        }
    }
}
