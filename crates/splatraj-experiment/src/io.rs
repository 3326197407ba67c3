//! Reading the small input files of the commands: camera files (JSON).

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use splatraj_render::camera_file::{CameraFile, CameraSpec};

/// Reads and checks a camera JSON file (schema: [`splatraj_render::camera_file`]); errors
/// name the file and the key.
pub fn read_camera_file(path: &Path) -> Result<CameraSpec> {
    let text = splatraj_scene::input::read_text(path)
        .with_context(|| format!("cannot read the camera file {}", path.display()))?;
    // serde names the unknown or missing key and lists the expected ones; the path says which
    // key a wrong value or length is at.
    let deserializer = &mut serde_json::Deserializer::from_str(&text);
    let file: CameraFile = serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let key = e.path().to_string();
        match key.as_str() {
            "." | "" => anyhow!("camera file {}: {}", path.display(), e.inner()),
            "world_to_camera" => anyhow!(
                "camera file {}: key `world_to_camera` must be a 4×4 matrix, as 4 rows of 4 \
                 numbers or 16 numbers row by row ({})",
                path.display(),
                e.inner()
            ),
            _ => anyhow!("camera file {}: key `{key}`: {}", path.display(), e.inner()),
        }
    })?;
    let camera = file
        .camera()
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    crate::camera_paths::check_image_side(&camera.intrinsics)
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    Ok(camera)
}
