//! Reading the small input files of the commands: camera files (JSON), and JSON read strictly.

use std::path::Path;

use anyhow::{Context, Result, anyhow};
use serde::de::DeserializeOwned;
use splatraj_render::camera_file::{CameraFile, CameraSpec};

/// `text` as exactly one JSON value of type `T`: anything but white space after the value is
/// refused (serde_json's reader stops after one value, so a file with a second object or stray
/// text after it would otherwise be read as if it ended there). On an error, the key path where
/// it happened (`.` for the whole document, or after the value) and serde's message.
pub fn strict_json<T: DeserializeOwned>(text: &str) -> Result<T, (String, serde_json::Error)> {
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize(&mut deserializer)
        .map_err(|e| (e.path().to_string(), e.into_inner()))?;
    deserializer.end().map_err(|e| (".".to_string(), e))?;
    Ok(value)
}

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
    crate::camera_paths::check_image_side(&camera.intrinsics)
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    Ok(camera)
}
