//! Scene file formats: detection, reading (then validation) and writing.

pub mod bytes;
pub mod compressed_ply;
pub mod compressed_ply_writer;
pub mod inria_ply;
pub mod ksplat;
pub mod labels_json;
pub mod ply_table;
pub mod ply_writer;
pub mod sog;
pub mod splat;
pub mod spz;
pub mod spz_writer;

use std::path::{Path, PathBuf};

use serde::Serialize;

pub use compressed_ply_writer::write_compressed_ply;
pub use labels_json::{read_label_sidecar, write_label_sidecar};
pub use ply_writer::write_inria_ply;
pub use spz_writer::write_spz;

use crate::error::{Result, SceneError};
use crate::scene::Scene;
use crate::validate::{InvalidPolicy, validate};

/// The scene file formats splatraj reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneFormat {
    /// INRIA 3DGS PLY (ASCII or binary, either byte order).
    InriaPly,
    /// PlayCanvas/SuperSplat compressed PLY (chunks of 256 with quantised values).
    CompressedPly,
    /// Niantic SPZ (gzip-wrapped versions 1-3, or version 4).
    Spz,
    /// PlayCanvas SOG: WebP images and `meta.json`, zipped (`.sog`) or in a folder.
    Sog,
    /// antimatter15's `.splat` (32-byte records, no header), the web viewers' format.
    Splat,
    /// GaussianSplats3D's `.ksplat` (compression levels 0-2).
    Ksplat,
}

impl SceneFormat {
    /// The formats [`write_scene`] writes.
    pub const WRITABLE: [SceneFormat; 3] = [
        SceneFormat::InriaPly,
        SceneFormat::CompressedPly,
        SceneFormat::Spz,
    ];

    /// The format's name on the command line (`--format`) and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            SceneFormat::InriaPly => "inria-ply",
            SceneFormat::CompressedPly => "compressed-ply",
            SceneFormat::Spz => "spz",
            SceneFormat::Sog => "sog",
            SceneFormat::Splat => "splat",
            SceneFormat::Ksplat => "ksplat",
        }
    }

    /// The file-name ending that selects the format for writing.
    pub fn extension(self) -> &'static str {
        match self {
            SceneFormat::InriaPly => ".ply",
            SceneFormat::CompressedPly => ".compressed.ply",
            SceneFormat::Spz => ".spz",
            SceneFormat::Sog => ".sog",
            SceneFormat::Splat => ".splat",
            SceneFormat::Ksplat => ".ksplat",
        }
    }

    /// The format a name means (`inria-ply` or `ply`, `compressed-ply`, `spz`, …).
    pub fn from_name(name: &str) -> Option<SceneFormat> {
        let name = name.to_ascii_lowercase();
        if name == "ply" {
            return Some(SceneFormat::InriaPly);
        }
        [
            SceneFormat::InriaPly,
            SceneFormat::CompressedPly,
            SceneFormat::Spz,
            SceneFormat::Sog,
            SceneFormat::Splat,
            SceneFormat::Ksplat,
        ]
        .into_iter()
        .find(|f| f.name() == name)
    }

    /// The format a file's name ends in (`.compressed.ply`, `.ply`, `.spz`, `.sog`, `.splat`,
    /// `.ksplat`, case-insensitive), if any.
    pub fn from_extension(path: &Path) -> Option<SceneFormat> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())?;
        // Longest ending first: `.compressed.ply` also ends in `.ply`.
        [
            SceneFormat::CompressedPly,
            SceneFormat::Ksplat,
            SceneFormat::Splat,
            SceneFormat::InriaPly,
            SceneFormat::Spz,
            SceneFormat::Sog,
        ]
        .into_iter()
        .find(|f| name.ends_with(f.extension()))
    }

    /// The format an output file's name asks for: `.compressed.ply`, `.ply` or `.spz`. Any
    /// other ending is refused, naming it, rather than guessed.
    pub fn for_output(path: &Path) -> Result<SceneFormat> {
        if let Some(format) = SceneFormat::from_extension(path) {
            format.check_writable(path)?;
            return Ok(format);
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let extension = match name.rfind('.') {
            Some(dot) if dot > 0 => format!("the extension '{}'", &name[dot..]),
            _ => "a name without an extension".to_string(),
        };
        Err(SceneError::Unwritable {
            path: path.to_path_buf(),
            detail: format!(
                "{extension} names no format splatraj writes; use {} (or name the format \
                 explicitly)",
                written_extensions()
            ),
        })
    }

    /// The format to write `path` in: `explicit` (a `--format`) when given, which may name any
    /// file but not one whose name says another format (that file would mislead whoever opens
    /// it by its name); else the one its name asks for ([`SceneFormat::for_output`]).
    pub fn for_output_as(path: &Path, explicit: Option<SceneFormat>) -> Result<SceneFormat> {
        let Some(format) = explicit else {
            return SceneFormat::for_output(path);
        };
        format.check_writable(path)?;
        match SceneFormat::from_extension(path) {
            Some(named) if named != format => Err(SceneError::Unwritable {
                path: path.to_path_buf(),
                detail: format!(
                    "the name says {} ({}) but the format asked is {}; rename the output or \
                     drop the format",
                    named.name(),
                    named.extension(),
                    format.name()
                ),
            }),
            _ => Ok(format),
        }
    }

    /// A format splatraj writes, by its name (`inria-ply`, `compressed-ply`, `spz`), or why not.
    pub fn writable_from_name(name: &str) -> std::result::Result<SceneFormat, String> {
        let names: Vec<&str> = SceneFormat::WRITABLE.iter().map(|f| f.name()).collect();
        match SceneFormat::from_name(name) {
            Some(format) if SceneFormat::WRITABLE.contains(&format) => Ok(format),
            Some(_) => Err(format!(
                "splatraj reads {name} but does not write it (it writes {})",
                names.join(", ")
            )),
            None => Err(format!(
                "unknown format '{name}' (splatraj writes {})",
                names.join(", ")
            )),
        }
    }

    /// The extras of `scene` this format has no place for (labels, feature channels, named
    /// properties); INRIA PLY keeps them all.
    pub fn dropped_extras(self, scene: &Scene) -> Vec<String> {
        if self == SceneFormat::InriaPly {
            return Vec::new();
        }
        let extras = &scene.extras;
        let mut dropped = Vec::new();
        if extras.labels.is_some() {
            dropped.push("labels".to_string());
        }
        if let Some(features) = &extras.features {
            dropped.push(format!("{} feature channels", features.dim));
        }
        dropped.extend(extras.properties.iter().map(|p| format!("'{}'", p.name)));
        dropped
    }

    /// Refuses a format splatraj reads but does not write.
    pub fn check_writable(self, path: &Path) -> Result<()> {
        if SceneFormat::WRITABLE.contains(&self) {
            return Ok(());
        }
        Err(SceneError::Unwritable {
            path: path.to_path_buf(),
            detail: format!(
                "splatraj reads {} ({}) but does not write it; it writes {}",
                self.name(),
                self.extension(),
                written_extensions()
            ),
        })
    }
}

/// The written formats' endings, for messages.
fn written_extensions() -> String {
    let shown: Vec<String> = SceneFormat::WRITABLE
        .iter()
        .map(|f| format!("{} ({})", f.extension(), f.name()))
        .collect();
    shown.join(", ")
}

/// Refuses an output path that exists and is not a regular file (a folder, a link, a device)
/// before any work: writing replaces the target by renaming over it, which must not destroy
/// such things (the same rule [`crate::atomic::write_atomically`] applies when it writes).
pub fn check_output_target(path: &Path) -> Result<()> {
    crate::atomic::refuse_special(path).map_err(|e| SceneError::Unwritable {
        path: path.to_path_buf(),
        detail: format!("{e}; it is not replaced"),
    })
}

/// Writes `scene` to `path` in `format` (one of [`SceneFormat::WRITABLE`]), whole or not at all.
/// An existing target that is not a regular file is not replaced ([`check_output_target`]).
pub fn write_scene(scene: &Scene, path: &Path, format: SceneFormat) -> Result<()> {
    format.check_writable(path)?;
    check_output_target(path)?;
    match format {
        SceneFormat::InriaPly => write_inria_ply(scene, path),
        SceneFormat::CompressedPly => write_compressed_ply(scene, path),
        SceneFormat::Spz => write_spz(scene, path),
        SceneFormat::Sog | SceneFormat::Splat | SceneFormat::Ksplat => {
            unreachable!("check_writable refused {format:?}")
        }
    }
}

/// How to read a scene file.
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// What to do with Gaussians holding values that cannot be rendered.
    pub invalid: InvalidPolicy,
    /// A ground-truth label sidecar (SuperSplat segments JSON) to attach as labels.
    pub labels: Option<PathBuf>,
}

/// A scene with where it came from.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    /// The validated scene.
    pub scene: Scene,
    /// The format it was read from.
    pub format: SceneFormat,
    /// Gaussians dropped as invalid (only under [`InvalidPolicy::Drop`]).
    pub dropped: usize,
}

/// Recognises the format from the file's first bytes (not its name).
pub fn detect_format(bytes: &[u8], path: &Path) -> Result<SceneFormat> {
    if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
        // Compressed PLY is a PLY whose header declares a `chunk` element and packed vertices.
        let head = &bytes[..bytes.len().min(64 * 1024)];
        let header_end = find(head, b"end_header").unwrap_or(head.len());
        let header = String::from_utf8_lossy(&head[..header_end]);
        let compressed = header
            .lines()
            .any(|l| l.trim() == "property uint packed_position")
            || header.lines().any(|l| l.starts_with("element chunk "));
        return Ok(if compressed {
            SceneFormat::CompressedPly
        } else {
            SceneFormat::InriaPly
        });
    }
    if bytes.starts_with(&[0x1f, 0x8b]) || bytes.starts_with(spz::MAGIC_BYTES) {
        return Ok(SceneFormat::Spz);
    }
    if sog::is_sog_bundle(bytes) || sog::is_sog_meta(bytes) {
        return Ok(SceneFormat::Sog);
    }
    if ksplat::looks_like_ksplat(bytes) {
        return Ok(SceneFormat::Ksplat);
    }
    // Only the name says more: a damaged .ksplat gets the reader's precise error, and a
    // .splat has no header at all, so its size and records must also look right.
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("ksplat") => return Ok(SceneFormat::Ksplat),
        Some("splat") if splat::looks_like_splat(bytes) => return Ok(SceneFormat::Splat),
        Some("splat") => {
            return Err(SceneError::UnknownFormat {
                path: path.to_path_buf(),
                detail: format!(
                    "named .splat but its {} bytes are not {}-byte records of Gaussians                      (antimatter15 .splat: 3 f32 position, 3 positive f32 scales, RGBA, rotation)",
                    bytes.len(),
                    splat::RECORD_LEN
                ),
            });
        }
        _ => {}
    }
    let shown: String = String::from_utf8_lossy(&bytes[..bytes.len().min(16)])
        .chars()
        .map(|c| if c.is_ascii_graphic() { c } else { '.' })
        .collect();
    Err(SceneError::UnknownFormat {
        path: path.to_path_buf(),
        detail: format!(
            "the file starts with {shown:?}; expected a PLY ('ply' header: INRIA 3DGS or \
             compressed), SPZ (gzip or 'NGSP'), SOG (a zip with meta.json, or meta.json \
             itself), a GaussianSplats3D .ksplat header, or an antimatter15 .splat (by its \
             extension)"
        ),
    })
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Reads, decodes and validates a scene file of any supported format. A folder is read as an
/// unbundled SOG scene (its `meta.json`).
pub fn read_scene(path: &Path, options: &ReadOptions) -> Result<LoadedScene> {
    let meta;
    let path = if path.is_dir() {
        meta = path.join(sog::META_NAME);
        if !meta.is_file() {
            return Err(SceneError::UnknownFormat {
                path: path.to_path_buf(),
                detail: format!(
                    "a folder is read as an unbundled SOG scene, but it has no {}",
                    sog::META_NAME
                ),
            });
        }
        meta.as_path()
    } else {
        path
    };
    let bytes = crate::input::read_bytes(path).map_err(|e| SceneError::io(path, e))?;
    let format = detect_format(&bytes, path)?;
    let mut scene = decode(&bytes, format, path)?;
    let report = validate(&mut scene, path, options.invalid)?;
    if let Some(sidecar) = &options.labels {
        if report.dropped > 0 {
            return Err(SceneError::sidecar(
                sidecar,
                "cannot attach a label sidecar after dropping invalid Gaussians: the indices \
                 would no longer match",
            ));
        }
        scene.extras.labels = Some(read_label_sidecar(sidecar, scene.len())?);
    }
    Ok(LoadedScene {
        scene,
        format,
        dropped: report.dropped,
    })
}

/// Decodes bytes of a known format into a scene that is not yet validated.
pub fn decode(bytes: &[u8], format: SceneFormat, path: &Path) -> Result<Scene> {
    match format {
        SceneFormat::InriaPly => {
            inria_ply::scene_from_tables(&ply_table::read_ply_tables(bytes, path)?, path)
        }
        SceneFormat::CompressedPly => {
            compressed_ply::scene_from_tables(&ply_table::read_ply_tables(bytes, path)?, path)
        }
        SceneFormat::Spz => spz::decode_spz(bytes, path),
        SceneFormat::Sog => sog::decode_sog(bytes, path),
        SceneFormat::Splat => splat::decode_splat(bytes, path),
        SceneFormat::Ksplat => ksplat::decode_ksplat(bytes, path),
    }
}
