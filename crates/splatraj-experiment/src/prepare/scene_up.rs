//! World up for a config's scene, one rule for `run` and `query`: `[scene] up` when given (and
//! the demo room's own), else the capture's cameras ([`splatraj_scene::cameras_up()`]): the file
//! `[scene] cameras` names, or one found beside the scene file under its usual name
//! ([`camera_files_beside`]), else the guess from the geometry ([`splatraj_scene::resolve_up`]).
//!
//! Cameras the config names must give up: a file that cannot be read, cameras that disagree
//! or that stand far from the scene (another capture, another scale) are an error naming
//! `scene.cameras` and the file. Cameras found by name are only a likely match, so the same
//! faults are a warning naming the file, and up falls back to the guess.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use glam::{DMat3, DVec3};
use splatraj_scene::{ResolvedUp, Scene, cameras_up, resolve_up};

use crate::config::Config;

/// Camera files looked for in the scene file's folder, in this order: INRIA 3DGS and gsplat
/// (`cameras.json`), nerfstudio and Instant-NGP (`transforms.json`), COLMAP's text model, then
/// its binary one (what `colmap mapper` writes by default).
pub const CAMERA_FILE_NAMES: [&str; 6] = [
    "cameras.json",
    "transforms.json",
    "sparse/0/images.txt",
    "images.txt",
    "sparse/0/images.bin",
    "images.bin",
];

/// Cameras whose median distance from the scene's centre exceeds this many diagonals of its
/// robust box are not this scene's (another capture, or the scene scaled since).
pub const NEAR_SCENE_DIAGONALS: f64 = 10.0;

/// World up for `config`'s `scene`: see the module docs.
pub fn scene_up(config: &Config, scene: &Scene) -> Result<ResolvedUp> {
    let is_demo = config.scene.demo.is_some();
    if is_demo && config.scene.cameras.is_some() {
        // Never read otherwise: a file set and silently ignored is worse than a refusal.
        anyhow::bail!(
            "`scene.cameras` needs a scene file (`scene.path`): the demo room has no capture, and \
             its up is known"
        );
    }
    if config.scene.up.is_some() || is_demo {
        return Ok(resolve_up(config.scene.up, is_demo, scene));
    }
    if let Some(cameras) = &config.scene.cameras {
        let path = config.resolve(cameras);
        return up_from_file(&path, scene).map_err(|e| anyhow!("`scene.cameras`: {e}"));
    }
    Ok(match config.scene_file() {
        Some(file) => up_beside(&file, scene),
        None => resolve_up(None, false, scene),
    })
}

/// World up for the scene read from `scene_file` without a config: the cameras found beside
/// it ([`camera_files_beside`]) when they agree, else the geometry's guess (with a warning
/// naming the file that was found and why it was not used).
pub fn up_beside(scene_file: &Path, scene: &Scene) -> ResolvedUp {
    if let Some(path) = camera_files_beside(scene_file)
        .into_iter()
        .find(|p| p.is_file())
    {
        match up_from_file(&path, scene) {
            Ok(up) => return up,
            Err(e) => tracing::warn!(
                "found {} beside the scene but took up from the geometry instead: {e} (set \
                 `scene.up`, or `scene.cameras` to the right file)",
                path.display()
            ),
        }
    }
    resolve_up(None, false, scene)
}

/// Where a capture's cameras usually lie beside `scene_file`: [`CAMERA_FILE_NAMES`] in its
/// folder, then, for the INRIA layout (`<model>/point_cloud/iteration_N/point_cloud.ply`), the
/// model folder's `cameras.json`.
pub fn camera_files_beside(scene_file: &Path) -> Vec<PathBuf> {
    let Some(dir) = scene_file.parent() else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = CAMERA_FILE_NAMES.iter().map(|n| dir.join(n)).collect();
    let iteration = dir
        .file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with("iteration_"));
    let point_cloud = dir.parent();
    if iteration
        && point_cloud.and_then(Path::file_name) == Some("point_cloud".as_ref())
        && let Some(model) = point_cloud.and_then(Path::parent)
    {
        files.push(model.join("cameras.json"));
    }
    files
}

/// Up from the cameras of `path`, checked for agreement and for standing near `scene`.
fn up_from_file(path: &Path, scene: &Scene) -> Result<ResolvedUp> {
    let (_, cameras) = splatraj_camera_paths::read_camera_path(path).map_err(|e| anyhow!("{e}"))?;
    let rotations: Vec<DMat3> = cameras.frames.iter().map(|f| f.pose.rotation).collect();
    let centres: Vec<DVec3> = cameras.frames.iter().map(|f| f.pose.centre).collect();
    check_near_scene(&centres, scene, path)?;
    let up = cameras_up(&rotations, &path.display().to_string())?;
    Ok(ResolvedUp::from(up))
}

/// Refuses cameras whose median distance from the scene's centre exceeds
/// [`NEAR_SCENE_DIAGONALS`] diagonals of its robust box.
fn check_near_scene(centres: &[DVec3], scene: &Scene, path: &Path) -> Result<()> {
    let Some(bounds) = scene.robust_bounds(0.02) else {
        return Ok(());
    };
    let centre = DVec3::from_array(bounds.center().map(f64::from));
    let diagonal = DVec3::from_array(bounds.size().map(f64::from)).length();
    let mut distances: Vec<f64> = centres.iter().map(|c| c.distance(centre)).collect();
    distances.sort_by(f64::total_cmp);
    let Some(&median) = distances.get(distances.len() / 2) else {
        return Ok(());
    };
    if median > NEAR_SCENE_DIAGONALS * diagonal.max(f64::MIN_POSITIVE) {
        anyhow::bail!(
            "{}: the cameras stand {median:.3} from the scene's centre (median), {:.0} times its \
             size ({diagonal:.3}): not this scene's cameras, or the scene was moved or scaled \
             since",
            path.display(),
            median / diagonal
        );
    }
    Ok(())
}
