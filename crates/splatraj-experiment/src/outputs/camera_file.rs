//! Reading a camera file (JSON, `splatraj render`'s camera): intrinsics and a pose, strictly.

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use splatraj_render::camera_file::{CameraFile, CameraSpec};

use crate::json::strict_json;

/// Reads and checks a camera JSON file (schema: [`splatraj_render::camera_file`]); errors
/// name the file and the key.
pub fn read_camera_file(path: &Path) -> Result<CameraSpec> {
    let text = splatraj_scene::input::read_text(path)
        .with_context(|| format!("cannot read the camera file {}", path.display()))?;
    // serde names the unknown or missing key and lists the expected ones; the path says which
    // key a wrong value or length is at.
    let file: CameraFile = strict_json(&text).map_err(|(key, e)| match key.as_str() {
        "." | "" => anyhow!("camera file {}: {e}", path.display()),
        "world_to_camera" => anyhow!(
            "camera file {}: key `world_to_camera` must be a 4×4 matrix, as 4 rows of 4 numbers \
             or 16 numbers row by row ({e})",
            path.display()
        ),
        _ => anyhow!("camera file {}: key `{key}`: {e}", path.display()),
    })?;
    let camera = file
        .camera()
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    super::camera_paths::check_image_side(&camera.intrinsics)
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    Ok(camera)
}
