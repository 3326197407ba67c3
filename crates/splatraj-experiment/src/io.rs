//! Reading the small input files of the commands: camera files (JSON).

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use splatraj_render::camera_file::{CameraFile, CameraSpec};

/// Reads and checks a camera JSON file (schema: [`splatraj_render::camera_file`]); errors
/// name the file and the key.
pub fn read_camera_file(path: &Path) -> Result<CameraSpec> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the camera file {}", path.display()))?;
    // serde names the unknown or missing key and lists the expected ones.
    let file: CameraFile =
        serde_json::from_str(&text).map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    file.camera()
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))
}
