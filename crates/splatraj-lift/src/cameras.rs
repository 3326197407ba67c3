//! The capture's cameras as views to lift from, read from the files other tools write.
//!
//! [`read_views`] reads any camera file `splatraj_camera_paths` reads (INRIA `cameras.json`, COLMAP
//! `images.txt` with `cameras.txt` beside it, nerfstudio `transforms.json` or
//! `camera_path.json`, a SuperSplat track) and keeps, with each view, the image it was taken
//! for, so that masks and photos can be matched to it by name. Both crates share the
//! `splatraj-camera` types; a file's intrinsics are checked as the renderer needs them
//! ([`checked_intrinsics`]).

use std::path::Path;

use splatraj_camera_paths::colmap::frame_name;
use splatraj_camera_paths::{CameraPath, Frame};
use splatraj_render::camera::{CameraError, CameraPose, Intrinsics, Pose};

use crate::error::{LiftError, Result};
use crate::views::View;

/// A view with the name of the image it was taken for.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedView {
    /// The image name as the camera file gives it (INRIA `img_name`, COLMAP `NAME`, transforms
    /// `file_path`), or `frame_NNNN.png` (as `render-path` names its frames) where it has none.
    pub name: String,
    /// The camera.
    pub view: View,
}

impl NamedView {
    /// The name that files for this view are matched by: see [`image_stem`].
    pub fn stem(&self) -> &str {
        image_stem(&self.name)
    }
}

/// Image file extensions dropped from a camera's image name to match files by stem (INRIA
/// `img_name` usually has none, and a name such as `IMG.0001` keeps its dot).
const IMAGE_EXTENSIONS: [&str; 9] = [
    "png", "jpg", "jpeg", "tif", "tiff", "exr", "webp", "bmp", "heic",
];

/// The last path component of an image name without its image extension:
/// `images/frame_0001.jpg` → `frame_0001`.
pub fn image_stem(name: &str) -> &str {
    let file = name.rsplit(['/', '\\']).next().unwrap_or(name);
    match file.rsplit_once('.') {
        Some((stem, ext))
            if !stem.is_empty()
                && IMAGE_EXTENSIONS
                    .iter()
                    .any(|known| ext.eq_ignore_ascii_case(known)) =>
        {
            stem
        }
        _ => file,
    }
}

/// Reads the cameras of `path` (any format [`splatraj_camera_paths::detect`] recognises) as views,
/// in file order. Every camera needs intrinsics (COLMAP: `cameras.txt` beside `images.txt`).
pub fn read_views(path: &Path) -> Result<Vec<NamedView>> {
    let cameras = splatraj_camera_paths::read_named_cameras(path)?;
    cameras
        .path
        .frames
        .iter()
        .zip(cameras.names)
        .enumerate()
        .map(|(i, (frame, name))| {
            let name = name.unwrap_or_else(|| frame_name(i));
            let camera = frame.camera.ok_or_else(|| {
                LiftError::file(
                    path,
                    format!(
                        "camera {i} ({name}) has no intrinsics{}",
                        if cameras.format == splatraj_camera_paths::Format::Colmap {
                            " (put COLMAP's cameras.txt beside images.txt)"
                        } else {
                            ""
                        }
                    ),
                )
            })?;
            let intrinsics = checked_intrinsics(&camera)
                .map_err(|e| LiftError::file(path, format!("camera {i} ({name}): {e}")))?;
            Ok(NamedView {
                name,
                view: View {
                    pose: Pose::from(frame.pose),
                    intrinsics,
                },
            })
        })
        .collect()
}

/// The intrinsics of a camera file, checked as the renderer checks them
/// ([`Intrinsics::new`]: a file only needs them positive and finite).
pub fn checked_intrinsics(p: &Intrinsics) -> Result<Intrinsics, CameraError> {
    Intrinsics::new(p.fx, p.fy, p.cx, p.cy, p.width, p.height)
}

/// `views` as a camera path, to write with `splatraj_camera_paths::export` (frame `i` is named
/// `frame_NNNN` by every writer).
pub fn camera_path(views: &[View]) -> CameraPath {
    CameraPath {
        cuts: Vec::new(),
        frames: views
            .iter()
            .map(|v| Frame {
                pose: CameraPose::from(v.pose),
                camera: Some(v.intrinsics),
            })
            .collect(),
        fps: None,
        seconds: None,
    }
}
