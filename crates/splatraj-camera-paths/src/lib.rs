//! Camera paths to and from other tools' camera files, for splatraj.
//!
//! splatraj's trajectories are poses Φ = [ω, c] in OpenCV camera axes (`docs/conventions.md`);
//! this crate writes a sampled path ([`CameraPath`]) as
//!
//! - [`nerfstudio`] `camera_path.json` (`ns-render camera-path`, the nerfstudio viewer),
//! - [`colmap`] `cameras.txt` + `images.txt` (+ an empty `points3D.txt`),
//! - [`inria`] `cameras.json` (INRIA 3DGS viewers, SuperSplat's camera import),
//! - [`supersplat`] `settings.json` with one animation track (the SuperSplat viewer),
//!
//! and reads the first three (and the SuperSplat track, COLMAP's binary model
//! ([`colmap_binary`]), and nerfstudio's training-data [`transforms`] `transforms.json`) back
//! into poses and, where the file has them, intrinsics, image names and cuts
//! ([`read_named_cameras`]). Each module's documentation states its format's axes and units;
//! `docs/interchange.md` gathers them. Errors name the file, the element and the problem
//! ([`InterchangeError`]); nothing panics on a bad file.
//!
//! It converts files and nothing else: it does not sample a trajectory into a path or read
//! `trajectory.json` (the experiment crate's `outputs::camera_paths` does both, and chooses
//! what a run exports), render, encode video (`splatraj-report`), or read scene files (those
//! are `splatraj-scene`'s `formats`). The pose and intrinsics types are `splatraj-camera`'s; the
//! crate does not depend on burn.

#![warn(missing_docs)]

pub mod camera;
pub mod colmap;
pub mod colmap_binary;
pub mod error;
pub mod inria;
pub mod nerfstudio;
pub mod supersplat;
pub mod transforms;

use std::path::Path;

pub use camera::{CameraPath, CameraPose, Frame, Intrinsics};
pub use error::{InterchangeError, Result};

use error::{export_error, read_text};

/// The camera file formats this crate reads; it writes all but [`Format::Transforms`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// nerfstudio `camera_path.json`.
    Nerfstudio,
    /// COLMAP model: text (read and written) or binary `images.bin` (read).
    Colmap,
    /// INRIA 3DGS `cameras.json`.
    Inria,
    /// SuperSplat viewer `settings.json`.
    Supersplat,
    /// nerfstudio training data `transforms.json` (read only).
    Transforms,
}

impl Format {
    /// Every format written, in the order the CLI lists them.
    pub const ALL: [Format; 4] = [
        Format::Nerfstudio,
        Format::Colmap,
        Format::Inria,
        Format::Supersplat,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Format::Nerfstudio => "nerfstudio",
            Format::Colmap => "colmap",
            Format::Inria => "inria",
            Format::Supersplat => "supersplat",
            Format::Transforms => "transforms",
        }
    }

    /// The files an export writes.
    pub fn file_names(self) -> &'static [&'static str] {
        match self {
            Format::Nerfstudio => &["camera_path.json"],
            Format::Colmap => &["cameras.txt", "images.txt", "points3D.txt"],
            Format::Inria => &["cameras.json"],
            Format::Supersplat => &["settings.json"],
            Format::Transforms => &["transforms.json"],
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Format::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                format!("unknown format {s:?} (nerfstudio, colmap, inria or supersplat)")
            })
    }
}

/// Options of [`export`] (each format uses those it has a place for).
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Frames per second.
    pub fps: f64,
    /// nerfstudio: viewer keyframes per second.
    pub keyframes_per_second: f64,
    /// SuperSplat: focus distance of the look-at targets.
    pub focus: supersplat::Focus,
    /// SuperSplat: which frames become keyframes.
    pub supersplat_keyframes: supersplat::Keyframes,
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self {
            fps: 30.0,
            keyframes_per_second: nerfstudio::NerfstudioOptions::default().keyframes_per_second,
            focus: supersplat::Focus::Distance(1.0),
            supersplat_keyframes: supersplat::SupersplatOptions::default().keyframes,
        }
    }
}

/// `path` in `format`: (file name, contents) for each file of [`Format::file_names`].
pub fn export(
    path: &CameraPath,
    format: Format,
    options: &ExportOptions,
) -> Result<Vec<(&'static str, String)>> {
    let names = format.file_names();
    Ok(match format {
        Format::Nerfstudio => vec![(
            names[0],
            nerfstudio::export(
                path,
                &nerfstudio::NerfstudioOptions {
                    fps: options.fps,
                    keyframes_per_second: options.keyframes_per_second,
                },
            )?,
        )],
        Format::Colmap => {
            let files = colmap::export(path)?;
            vec![
                (names[0], files.cameras),
                (names[1], files.images),
                (names[2], files.points3d),
            ]
        }
        Format::Inria => vec![(names[0], inria::export(path)?)],
        Format::Supersplat => vec![(
            names[0],
            supersplat::export(
                path,
                &supersplat::SupersplatOptions {
                    fps: options.fps,
                    focus: options.focus.clone(),
                    keyframes: options.supersplat_keyframes,
                },
            )?,
        )],
        Format::Transforms => {
            return Err(export_error(
                "nerfstudio transforms.json",
                "training-data cameras are read, not written (export nerfstudio for \
                 camera_path.json)",
            ));
        }
    })
}

/// Which format a camera file is in: `images.txt` or `images.bin` (or `*.txt`, `*.bin` that
/// is not `cameras.*`) is COLMAP's text or binary model; a JSON object with `camera_path` is nerfstudio, one with `animTracks` SuperSplat,
/// one with `frames` whose first entry has `transform_matrix` nerfstudio's `transforms.json`; a
/// JSON array of objects with `rotation` is INRIA.
pub fn detect(path: &Path) -> Result<Format> {
    let file = path.display().to_string();
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    if name == "cameras.txt" || name == "cameras.bin" {
        return Err(InterchangeError::UnknownFormat {
            file,
            problem: "give COLMAP's images.txt or images.bin (the cameras file beside it is \
                      read with it)"
                .into(),
        });
    }
    if name.ends_with(".txt") || name.ends_with(".bin") {
        return Ok(Format::Colmap);
    }
    let text = read_text(path)?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|error| InterchangeError::Json {
            file: file.clone(),
            format: "camera (JSON)",
            error,
        })?;
    if value.get("camera_path").is_some() {
        Ok(Format::Nerfstudio)
    } else if value.get("animTracks").is_some() {
        Ok(Format::Supersplat)
    } else if value
        .get("frames")
        .and_then(|f| f.as_array())
        .and_then(|f| f.first())
        .is_some_and(|e| e.get("transform_matrix").is_some())
    {
        Ok(Format::Transforms)
    } else if value
        .as_array()
        .and_then(|a| a.first())
        .is_some_and(|e| e.get("rotation").is_some())
    {
        Ok(Format::Inria)
    } else {
        Err(InterchangeError::UnknownFormat {
            file,
            problem: "not a camera file this reads: expected a nerfstudio camera_path.json \
                      (`camera_path`), an INRIA cameras.json (an array of cameras with \
                      `rotation`), a SuperSplat settings.json (`animTracks`), a nerfstudio \
                      transforms.json (`frames` with `transform_matrix`) or COLMAP's images.txt"
                .into(),
        })
    }
}

/// Reads a camera file of any format this crate reads (see [`detect`]); a SuperSplat track,
/// which has no image size, gets 480-pixel-high 4:3 cameras.
pub fn read_camera_path(path: &Path) -> Result<(Format, CameraPath)> {
    let cameras = read_named_cameras(path)?;
    Ok((cameras.format, cameras.path))
}

/// A camera file's frames with the image each was taken for.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedCameras {
    /// The file's format.
    pub format: Format,
    /// The frames.
    pub path: CameraPath,
    /// Per frame, the image name as the file gives it (INRIA `img_name`, COLMAP `NAME`,
    /// transforms `file_path`); `None` where the format or the entry has none.
    pub names: Vec<Option<String>>,
}

/// [`read_camera_path`] with the image names of the formats that have them.
pub fn read_named_cameras(path: &Path) -> Result<NamedCameras> {
    let format = detect(path)?;
    let some = |names: Vec<String>| names.into_iter().map(Some).collect();
    let (camera_path, names) = match format {
        Format::Nerfstudio => (nerfstudio::read(path)?, Vec::new()),
        Format::Colmap => {
            let (p, n) = colmap::read_named(path)?;
            (p, some(n))
        }
        Format::Inria => inria::read_named(path)?,
        Format::Supersplat => (supersplat::read(path, 480, 4.0 / 3.0)?, Vec::new()),
        Format::Transforms => {
            let (p, n) = transforms::read_named(path)?;
            (p, some(n))
        }
    };
    let names = if names.is_empty() {
        vec![None; camera_path.frames.len()]
    } else {
        names
    };
    Ok(NamedCameras {
        format,
        path: camera_path,
        names,
    })
}

/// The frames of `path` with their intrinsics, checked for export (at least one frame, every
/// frame with valid intrinsics and a finite pose).
pub(crate) fn check_export(
    path: &CameraPath,
    format: &'static str,
) -> Result<Vec<(CameraPose, Intrinsics)>> {
    if path.frames.is_empty() {
        return Err(export_error(format, "the path has no frames"));
    }
    path.frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let camera = f
                .camera
                .ok_or_else(|| export_error(format, format!("frame {i} has no intrinsics")))?;
            camera
                .validate()
                .map_err(|p| export_error(format, format!("frame {i}: {p}")))?;
            if !(f.pose.rotation.is_finite() && f.pose.centre.is_finite()) {
                return Err(export_error(
                    format,
                    format!("frame {i}: pose is not finite"),
                ));
            }
            Ok((f.pose, camera))
        })
        .collect()
}

/// Checks a frame rate.
pub(crate) fn check_fps(fps: f64, format: &'static str) -> Result<()> {
    if fps.is_finite() && fps > 0.0 {
        Ok(())
    } else {
        Err(export_error(
            format,
            format!("fps {fps} is not a positive number"),
        ))
    }
}
