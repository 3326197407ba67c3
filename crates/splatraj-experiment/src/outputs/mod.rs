//! The run folder and its files: every file is written whole or not at all.
//!
//! `runs/<name>/<timestamp>/` is created fresh (never reused: a second run in the same second
//! gets a `-2` suffix). Files go through `write_atomically` (temporary name, then rename), so
//! an interrupted run leaves complete files or none.
//!
//! **This folder** is the outputs stage: what a finished optimisation becomes on disk. The run
//! folder ([`run_folder`], [`output_folder`]), the trajectory's metrics and verdicts
//! ([`evaluation`]), its records ([`records`]) and the rest of its files ([`run_files`]:
//! [`run_files::RunOutputs`], the stage's state), the
//! frames and video of a camera path ([`path_render`], [`path_checks`], [`camera_render`] with
//! its [`camera_file`]; `render-path` whole: [`path_job`]), other tools' camera files
//! ([`camera_paths`]) and `report.html`'s data ([`run_report`]).

pub mod camera_file;
pub mod camera_paths;
pub mod camera_render;
pub mod evaluation;
pub mod output_folder;
pub mod path_checks;
pub mod path_job;
pub mod path_render;
pub mod records;
pub mod run_files;
pub mod run_folder;
pub mod run_report;

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::images::{highlight, png_rgb};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Rasterizer, RenderRequest, render,
};

/// A CSV table: header and rows ([`crate::write::write_csv`]).
pub type Csv = (Vec<String>, Vec<Vec<String>>);

/// Creates a fresh `<runs_dir>/<name>/<UTC timestamp>/` folder.
pub fn create_run_dir(runs_dir: &Path, name: &str) -> Result<PathBuf> {
    let parent = runs_dir.join(name);
    std::fs::create_dir_all(&parent)
        .with_context(|| format!("cannot create {}", parent.display()))?;
    let stamp = utc_timestamp(SystemTime::now());
    for attempt in 1..1000 {
        let dir = if attempt == 1 {
            parent.join(&stamp)
        } else {
            parent.join(format!("{stamp}-{attempt}"))
        };
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("cannot create {}", dir.display())),
        }
    }
    anyhow::bail!(
        "cannot find a fresh run folder name under {}",
        parent.display()
    )
}

/// `YYYY-MM-DDTHH-MM-SSZ` (UTC; dashes so the name is valid on every file system).
pub fn utc_timestamp(time: SystemTime) -> String {
    let secs = time
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}-{:02}-{:02}Z",
        rem / 3600,
        (rem % 3600) / 60,
        rem % 60
    )
}

/// One frame to render: its pose and the object mask to tint (if any).
pub struct FrameSpec<'a> {
    /// Φ = [ω, c].
    pub pose: [f64; 6],
    /// Per-Gaussian mask of the object to tint.
    pub tint: Option<&'a [f32]>,
}

/// Strength of the mask overlay's tint (lighter than `query`'s, so the object stays legible
/// in a sequence).
pub(crate) const TINT_ALPHA: f64 = 0.45;

/// One frame as PNG bytes: the RGB render, with the object tinted where asked.
pub fn frame_png(
    scene: &DeviceScene,
    (intrinsics, rasterizer): (&Intrinsics, Rasterizer),
    frame: &FrameSpec<'_>,
) -> Result<Vec<u8>> {
    let mut channels = vec![Channel::Rgb];
    if let Some(mask) = frame.tint {
        channels.push(Channel::Mask(mask.to_vec()));
    }
    let pose = scene.poses(&[Pose(frame.pose)]);
    let request = RenderRequest {
        rasterizer,
        alpha: AlphaChannel::Dropped,
        ..RenderRequest::new(*intrinsics, channels)
    };
    let images = render(scene, pose, &request)?.images;
    let values = to_host(images)?; // [1, H, W, 3 or 4]
    let rgb = if frame.tint.is_some() {
        highlight(&values, TINT_ALPHA)
    } else {
        values
    };
    Ok(png_rgb(&rgb, intrinsics)?)
}

/// `.npy` bytes of float32 values with the given shape.
pub fn npy_f32(values: &[f64], shape: &[u64]) -> Result<Vec<u8>> {
    use npyz::WriterBuilder;
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut bytes)
        .begin_nd()?;
    writer.extend(values.iter().map(|&v| v as f32))?;
    writer.finish()?;
    Ok(bytes)
}
