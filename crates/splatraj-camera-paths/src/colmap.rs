//! COLMAP text model: `cameras.txt`, `images.txt` (and an empty `points3D.txt`, so that COLMAP
//! and the 3DGS trainers that read COLMAP folders accept the export as a model).
//!
//! - `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`; we write `PINHOLE` with
//!   `fx fy cx cy` in pixels, one camera per distinct intrinsics.
//! - `images.txt`: two lines per image. The first is `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID
//!   NAME`: the **world-to-camera** rotation R_cw = R_wcᵀ as a unit quaternion (Hamilton,
//!   scalar first; we write qw ≥ 0) and the translation t = −R_cw·c, so a world point p is at
//!   R_cw·p + t in the camera. The second lists the image's 2D points (`X Y POINT3D_ID`
//!   triples); we write it empty.
//! - Camera axes are OpenCV's (x right, y down, z forward), as ours; pixel (i, j) has its
//!   centre at (i + 0.5, j + 0.5), as ours. Units are the scene's.
//!
//! Reading accepts `SIMPLE_PINHOLE` and `PINHOLE`, and takes the focal lengths and principal
//! point of the distorted perspective models (`SIMPLE_RADIAL`, `RADIAL`, `OPENCV`,
//! `FULL_OPENCV`), ignoring their distortion. Images are returned in the order of their ids
//! (COLMAP numbers images in the order of their names when it imports them, and our export
//! numbers frames in time order); `cameras.txt` is optional (without it the frames carry no
//! intrinsics).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use glam::{DMat3, DQuat, DVec3};

use crate::camera::{CameraPath, CameraPose, Frame, Intrinsics};
use crate::check_export;
use crate::error::{Result, invalid, read_text};

const FORMAT: &str = "COLMAP text model";

/// The three files of a COLMAP text model.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapFiles {
    /// `cameras.txt`.
    pub cameras: String,
    /// `images.txt`.
    pub images: String,
    /// `points3D.txt` (header only).
    pub points3d: String,
}

/// The image name of frame `i` (as our run folders name their frames).
pub fn frame_name(i: usize) -> String {
    format!("frame_{i:04}.png")
}

/// Hamilton quaternion (w, x, y, z) of `r`, with w ≥ 0.
pub fn quaternion_wxyz(r: DMat3) -> [f64; 4] {
    let mut q = DQuat::from_mat3(&r).normalize();
    if q.w < 0.0 {
        q = -q;
    }
    [q.w, q.x, q.y, q.z]
}

/// `path` as a COLMAP text model; image `i` (from 1) is named [`frame_name`]`(i - 1)`.
pub fn export(path: &CameraPath) -> Result<ColmapFiles> {
    let frames = check_export(path, FORMAT)?;
    let mut cameras: Vec<Intrinsics> = Vec::new();
    let mut images = String::from(
        "# Image list with two lines of data per image:\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(
        images,
        "# Number of images: {}, mean observations per image: 0",
        frames.len()
    );
    path.check_cuts()
        .map_err(|p| crate::error::export_error(FORMAT, p))?;
    if !path.cuts.is_empty() {
        let list: Vec<String> = path.cuts.iter().map(|c| c.to_string()).collect();
        let _ = writeln!(images, "{CUTS_COMMENT} {}", list.join(" "));
    }
    for (i, (pose, camera)) in frames.iter().enumerate() {
        let camera_id = match cameras.iter().position(|c| c == camera) {
            Some(k) => k + 1,
            None => {
                cameras.push(*camera);
                cameras.len()
            }
        };
        let [qw, qx, qy, qz] = quaternion_wxyz(pose.world_to_camera_rotation());
        let t = pose.world_to_camera_translation();
        let _ = writeln!(
            images,
            "{} {qw} {qx} {qy} {qz} {} {} {} {camera_id} {}\n",
            i + 1,
            t.x,
            t.y,
            t.z,
            frame_name(i)
        );
    }
    let mut cameras_txt = String::from(
        "# Camera list with one line of data per camera:\n\
         #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(cameras_txt, "# Number of cameras: {}", cameras.len());
    for (k, c) in cameras.iter().enumerate() {
        let _ = writeln!(
            cameras_txt,
            "{} PINHOLE {} {} {} {} {} {}",
            k + 1,
            c.width,
            c.height,
            c.fx,
            c.fy,
            c.cx,
            c.cy
        );
    }
    let points3d = "# 3D point list with one line of data per point:\n\
                    #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                    # Number of points: 0, mean track length: 0\n"
        .to_string();
    Ok(ColmapFiles {
        cameras: cameras_txt,
        images,
        points3d,
    })
}

/// Data lines of a COLMAP text file: (1-based line number, trimmed text), comments and blank
/// lines skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn number<T: std::str::FromStr>(file: &str, element: &str, name: &str, token: &str) -> Result<T> {
    token
        .parse()
        .map_err(|_| invalid(file, element, format!("{name} {token:?} is not a number")))
}

/// The cameras of `cameras.txt` text by id.
pub fn import_cameras(text: &str, file: &str) -> Result<HashMap<u64, Intrinsics>> {
    let mut cameras = HashMap::new();
    for (line, data) in data_lines(text) {
        let tokens: Vec<&str> = data.split_whitespace().collect();
        let element = format!("line {line}");
        if tokens.len() < 4 {
            return Err(invalid(
                file,
                element,
                "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]",
            ));
        }
        let id: u64 = number(file, &element, "CAMERA_ID", tokens[0])?;
        let element = format!("line {line} (camera {id})");
        let width: usize = number(file, &element, "WIDTH", tokens[2])?;
        let height: usize = number(file, &element, "HEIGHT", tokens[3])?;
        let params = tokens[4..]
            .iter()
            .map(|t| number::<f64>(file, &element, "parameter", t))
            .collect::<Result<Vec<_>>>()?;
        // (parameter count, focal lengths shared?) of the perspective models we read.
        let (count, shared_focal) = match tokens[1] {
            "SIMPLE_PINHOLE" => (3, true),
            "PINHOLE" => (4, false),
            "SIMPLE_RADIAL" => (4, true),
            "RADIAL" => (5, true),
            "OPENCV" => (8, false),
            "FULL_OPENCV" => (12, false),
            other => {
                return Err(invalid(
                    file,
                    element,
                    format!(
                        "camera model {other} is not supported (PINHOLE, SIMPLE_PINHOLE, \
                         SIMPLE_RADIAL, RADIAL, OPENCV or FULL_OPENCV)"
                    ),
                ));
            }
        };
        if params.len() != count {
            return Err(invalid(
                file,
                element,
                format!(
                    "{} takes {count} parameters, the line has {}",
                    tokens[1],
                    params.len()
                ),
            ));
        }
        let camera = if shared_focal {
            Intrinsics {
                fx: params[0],
                fy: params[0],
                cx: params[1],
                cy: params[2],
                width,
                height,
            }
        } else {
            Intrinsics {
                fx: params[0],
                fy: params[1],
                cx: params[2],
                cy: params[3],
                width,
                height,
            }
        };
        camera.validate().map_err(|p| invalid(file, &element, p))?;
        if cameras.insert(id, camera).is_some() {
            return Err(invalid(
                file,
                element,
                format!("camera id {id} appears twice"),
            ));
        }
    }
    Ok(cameras)
}

/// The path of `images.txt` text, with intrinsics from `cameras` (from [`import_cameras`]) when
/// given. `file` names `images.txt` in errors.
pub fn import(
    text: &str,
    file: &str,
    cameras: Option<&HashMap<u64, Intrinsics>>,
) -> Result<CameraPath> {
    import_named(text, file, cameras).map(|(path, _)| path)
}

/// [`import`] with each image's `NAME`, in the same order.
pub fn import_named(
    text: &str,
    file: &str,
    cameras: Option<&HashMap<u64, Intrinsics>>,
) -> Result<(CameraPath, Vec<String>)> {
    let mut images: Vec<(String, u64, Frame)> = Vec::new();
    // COLMAP's reader: an image line, then its points line, which may be empty.
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((line, data)) = lines.next() {
        if data.is_empty() || data.starts_with('#') {
            continue;
        }
        let tokens: Vec<&str> = data.split_whitespace().collect();
        let element = format!("line {line}");
        if tokens.len() < 10 {
            return Err(invalid(
                file,
                element,
                format!(
                    "{} fields, expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
                    tokens.len()
                ),
            ));
        }
        let id: u64 = number(file, &element, "IMAGE_ID", tokens[0])?;
        let element = format!("line {line} (image {id})");
        let mut v = [0.0f64; 7];
        for (k, name) in ["QW", "QX", "QY", "QZ", "TX", "TY", "TZ"]
            .iter()
            .enumerate()
        {
            v[k] = number(file, &element, name, tokens[k + 1])?;
            if !v[k].is_finite() {
                return Err(invalid(file, &element, format!("{name} is not finite")));
            }
        }
        let camera_id: u64 = number(file, &element, "CAMERA_ID", tokens[8])?;
        // Names may hold spaces: the rest of the line.
        let name = tokens[9..].join(" ");
        let q = DQuat::from_xyzw(v[1], v[2], v[3], v[0]);
        let norm = q.length();
        if norm <= 1e-12 {
            return Err(invalid(file, element, "the quaternion QW QX QY QZ is zero"));
        }
        if (norm - 1.0).abs() > 1e-3 {
            return Err(invalid(
                file,
                element,
                format!("the quaternion QW QX QY QZ has norm {norm:.6}, not 1"),
            ));
        }
        let r_cw = DMat3::from_quat(q / norm);
        let t = DVec3::new(v[4], v[5], v[6]);
        let pose = CameraPose::new(r_cw.transpose(), -(r_cw.transpose() * t))
            .map_err(|p| invalid(file, &element, p))?;
        let camera = match cameras {
            Some(cameras) => Some(*cameras.get(&camera_id).ok_or_else(|| {
                invalid(
                    file,
                    &element,
                    format!("CAMERA_ID {camera_id} is not in cameras.txt"),
                )
            })?),
            None => None,
        };
        if images.iter().any(|(_, other, _)| *other == id) {
            return Err(invalid(
                file,
                element,
                format!("image id {id} appears twice"),
            ));
        }
        images.push((name, id, Frame { pose, camera }));
        // The points line (skipped whatever it holds).
        lines.next();
    }
    if images.is_empty() {
        return Err(invalid(file, "images", "the file lists no images"));
    }
    images.sort_by_key(|(_, id, _)| *id);
    let (names, frames): (Vec<String>, Vec<Frame>) =
        images.into_iter().map(|(n, _, f)| (n, f)).unzip();
    let mut path = CameraPath::untimed(frames);
    path.cuts = comment_cuts(text, file)?;
    path.check_cuts()
        .map_err(|p| invalid(file, CUTS_COMMENT, p))?;
    Ok((path, names))
}

/// The comment line of `images.txt` that lists the cuts: the 0-based indices, in image id
/// order, of the images that begin a new shot. COLMAP lists views, not a timed path, and
/// skips comments; splatraj reads the cuts back from it.
pub const CUTS_COMMENT: &str = "# splatraj cuts:";

/// The cuts the [`CUTS_COMMENT`] line of `text` lists (none without one).
fn comment_cuts(text: &str, file: &str) -> Result<Vec<usize>> {
    let Some(line) = text
        .lines()
        .find_map(|l| l.trim().strip_prefix(CUTS_COMMENT))
    else {
        return Ok(Vec::new());
    };
    line.split_whitespace()
        .map(|token| number(file, CUTS_COMMENT, "cut", token))
        .collect()
}

/// Reads `images.txt` and, when it is there, `cameras.txt` beside it.
pub fn read(images: &Path) -> Result<CameraPath> {
    read_named(images).map(|(path, _)| path)
}

/// [`read`] with each image's `NAME`. A binary `images.bin` is read with `cameras.bin` (or
/// `cameras.txt`) beside it ([`crate::colmap_binary`]).
pub fn read_named(images: &Path) -> Result<(CameraPath, Vec<String>)> {
    let binary = images
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bin"));
    let mut cameras = None;
    for (name, is_binary) in [("cameras.bin", true), ("cameras.txt", false)] {
        let path = images.with_file_name(name);
        if (binary || !is_binary) && path.is_file() {
            let file = path.display().to_string();
            let text = if is_binary {
                crate::colmap_binary::cameras_text(
                    &crate::colmap_binary::read_bytes(&path)?,
                    &file,
                )?
            } else {
                read_text(&path)?
            };
            cameras = Some(import_cameras(&text, &file)?);
            break;
        }
    }
    let file = images.display().to_string();
    let text = if binary {
        crate::colmap_binary::images_text(&crate::colmap_binary::read_bytes(images)?, &file)?
    } else {
        read_text(images)?
    };
    import_named(&text, &file, cameras.as_ref())
}
