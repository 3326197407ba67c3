//! Rendering a camera path into a folder: `frames/frame_NNNN.png`, each frame's TCE, TRE and
//! coverage of the object its window shows (`frame_metrics.csv`), and `video.mp4` made from
//! the PNGs (so the video shows exactly the frames). `splatraj run` renders its trajectory
//! with it and `splatraj render-path` any camera path.
//!
//! Every file is written whole or not at all; the video is encoded in memory while the frames
//! are rendered and written once the last frame is in.
//!
//! **Keyframes.** The frames stay clean by default (`[output] mask_overlay = "none"`: what a
//! talk shows); the report's keyframes ([`keyframe_indices`]) are also written tinted and
//! small into `keyframes/`, so the report still shows which part each window is about.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use splatraj_render::camera::Pose;
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::images::{highlight, png_rgb};
use splatraj_render::render::{Channel, DeviceScene, Rasterizer, RenderRequest, render};
use splatraj_report::video::VideoEncoder;
use splatraj_traj::costs::{coverage, tce, tre};
use splatraj_traj::optimise::sampling::window_of;

use crate::camera_paths::PathFrames;
use crate::config::MaskOverlay;
use crate::outputs::{TINT_ALPHA, write_bytes, write_csv};

/// One window's object: the Gaussians to measure (and tint) in the frames of its window.
#[derive(Debug, Clone, Copy)]
pub struct PathObject<'a> {
    /// Per-Gaussian 0/1 mask.
    pub mask: &'a [f32],
    /// The share of the frame it should cover (TRE's target).
    pub target_ratio: f64,
}

/// Whether a path render also makes `video.mp4`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Video {
    /// `video.mp4` (H.264) at the frames' rate.
    Mp4,
    /// PNG frames only.
    None,
}

/// What to render of a path.
#[derive(Debug, Clone)]
pub struct PathRender<'a> {
    /// The frames.
    pub frames: &'a PathFrames,
    /// One object per query window, in order (a frame at time t shows window
    /// `window_of(t, n)`'s); empty when the path has no objects.
    pub objects: Vec<PathObject<'a>>,
    /// Whether the object is tinted in the frames.
    pub overlay: MaskOverlay,
    /// Which compositing renders the frames.
    pub rasterizer: Rasterizer,
    /// Whether to make `video.mp4`.
    pub video: Video,
}

/// One frame's metrics for the object of its window (a row of `frame_metrics.csv`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMetrics {
    /// Frame index.
    pub frame: usize,
    /// Time t ∈ [0, 1].
    pub t: f64,
    /// Its window.
    pub window: usize,
    /// Target centring error.
    pub tce: f64,
    /// Target ratio error.
    pub tre: f64,
    /// Share of the frame the visible object covers.
    pub coverage: f64,
}

/// The file of per-frame metrics in a rendered folder.
pub const FRAME_METRICS_FILE: &str = "frame_metrics.csv";

/// The video in a rendered folder.
pub const VIDEO_FILE: &str = "video.mp4";

/// What [`render_path`] wrote.
#[derive(Debug, Clone)]
pub struct RenderedPath {
    /// Each frame's metrics (empty when the path has no objects).
    pub metrics: Vec<FrameMetrics>,
    /// The video, if made.
    pub video: Option<PathBuf>,
}

/// Renders `job` into `dir` (`frames/`, `frame_metrics.csv` when there are objects,
/// `video.mp4` when asked); `progress` is told after each frame.
pub fn render_path(
    scene: &DeviceScene,
    job: &PathRender<'_>,
    dir: &Path,
    progress: &mut dyn FnMut(usize),
) -> Result<RenderedPath> {
    let frames = job.frames;
    if frames.poses.is_empty() {
        bail!("the path has no frames");
    }
    let size = (frames.cameras[0].width, frames.cameras[0].height);
    let mut encoder = match job.video {
        Video::Mp4 => {
            if let Some((i, k)) = frames
                .cameras
                .iter()
                .enumerate()
                .find(|(_, k)| (k.width, k.height) != size)
            {
                bail!(
                    "frame {i} is {}×{} but frame 0 is {}×{}: a video needs one size (give \
                     --width and --height)",
                    k.width,
                    k.height,
                    size.0,
                    size.1
                );
            }
            Some(VideoEncoder::new(size.0, size.1, frames.fps)?)
        }
        Video::None => None,
    };
    let frames_dir = dir.join("frames");
    std::fs::create_dir_all(&frames_dir)
        .with_context(|| format!("cannot create {}", frames_dir.display()))?;
    // Tinted keyframes for the report, when the frames themselves are not tinted.
    let keyframes: Vec<usize> = match job.overlay {
        MaskOverlay::None if !job.objects.is_empty() => {
            keyframe_indices(&frames.times, job.objects.len())
                .into_iter()
                .flatten()
                .collect()
        }
        _ => Vec::new(),
    };
    let keyframes_dir = dir.join(KEYFRAMES_DIR);
    if !keyframes.is_empty() {
        std::fs::create_dir_all(&keyframes_dir)
            .with_context(|| format!("cannot create {}", keyframes_dir.display()))?;
    }
    let mut metrics = Vec::new();
    for (index, ((&t, &pose), intrinsics)) in frames
        .times
        .iter()
        .zip(&frames.poses)
        .zip(&frames.cameras)
        .enumerate()
    {
        let window = window_of(t, job.objects.len());
        let object = job.objects.get(window);
        let mut channels = vec![Channel::Rgb];
        if let Some(o) = object {
            channels.push(Channel::Mask(o.mask.to_vec()));
        }
        let request = RenderRequest {
            rasterizer: job.rasterizer,
            ..RenderRequest::new(*intrinsics, channels)
        };
        let images = render(scene, scene.poses(&[Pose(pose)]), &request)
            .with_context(|| format!("rendering frame {index}"))?
            .images; // [1, H, W, 3 or 4]
        if let Some(o) = object {
            let [_, h, w, _] = images.dims();
            let mask = images.clone().narrow(3, 3, 1).reshape([1, h, w]);
            let first = |v: Vec<f64>| v.first().copied().unwrap_or(f64::NAN);
            metrics.push(FrameMetrics {
                frame: index,
                t,
                window,
                tce: first(to_host(tce(mask.clone()))?),
                tre: first(to_host(tre(mask.clone(), o.target_ratio))?),
                coverage: first(to_host(coverage(mask))?),
            });
        }
        let values = to_host(images)?;
        if keyframes.contains(&index) {
            let tinted = png_rgb(&highlight(&values, TINT_ALPHA), intrinsics)?;
            write_bytes(
                &keyframes_dir.join(frame_name(index)),
                &shrunk_png(&tinted, KEYFRAME_WIDTH)?,
            )?;
        }
        let rgb = match (object, job.overlay) {
            (Some(_), MaskOverlay::Tint) => highlight(&values, TINT_ALPHA),
            (Some(_), MaskOverlay::None) => values
                .chunks_exact(4)
                .flat_map(|p| p[..3].to_vec())
                .collect(),
            (None, _) => values,
        };
        let png = png_rgb(&rgb, intrinsics)?;
        if let Some(encoder) = &mut encoder {
            // The video is made from the PNG's own bytes, so it shows exactly the frames.
            let decoded = image::load_from_memory_with_format(&png, image::ImageFormat::Png)
                .context("reading back a frame")?
                .into_rgb8();
            encoder.push(decoded.as_raw())?;
        }
        write_bytes(&frames_dir.join(frame_name(index)), &png)?;
        progress(index + 1);
    }
    if !metrics.is_empty() {
        let header = ["frame", "t", "window", "tce", "tre", "coverage"].map(String::from);
        let rows: Vec<Vec<String>> = metrics
            .iter()
            .map(|m| {
                vec![
                    m.frame.to_string(),
                    m.t.to_string(),
                    m.window.to_string(),
                    m.tce.to_string(),
                    m.tre.to_string(),
                    m.coverage.to_string(),
                ]
            })
            .collect();
        write_csv(&dir.join(FRAME_METRICS_FILE), &header, &rows)?;
    }
    let video = match encoder {
        Some(encoder) => {
            let path = dir.join(VIDEO_FILE);
            write_bytes(&path, &encoder.finish()?)?;
            Some(path)
        }
        None => None,
    };
    Ok(RenderedPath { metrics, video })
}

/// The folder of the report's tinted keyframes in a rendered folder.
pub const KEYFRAMES_DIR: &str = "keyframes";

/// Width of the tinted keyframes (the report shows them 220 pixels wide).
const KEYFRAME_WIDTH: u32 = 480;

/// Keyframes shown per window.
pub const KEYFRAMES_PER_WINDOW: usize = 5;

/// The frames the report shows for each of `windows` windows: up to
/// [`KEYFRAMES_PER_WINDOW`] of the frames at `times` in each window, evenly spread over them.
pub fn keyframe_indices(times: &[f64], windows: usize) -> Vec<Vec<usize>> {
    let windows = windows.max(1);
    (0..windows)
        .map(|w| {
            let mine: Vec<usize> = (0..times.len())
                .filter(|&i| window_of(times[i], windows) == w)
                .collect();
            let take = mine.len().min(KEYFRAMES_PER_WINDOW);
            (0..take)
                .map(|k| {
                    mine[if take == 1 {
                        mine.len() / 2
                    } else {
                        k * (mine.len() - 1) / (take - 1)
                    }]
                })
                .collect()
        })
        .collect()
}

/// `png` scaled down to `width` pixels wide (kept when narrower), as PNG bytes.
fn shrunk_png(png: &[u8], width: u32) -> Result<Vec<u8>> {
    let image = image::load_from_memory_with_format(png, image::ImageFormat::Png)
        .context("reading back a keyframe")?
        .into_rgb8();
    if image.width() <= width {
        return Ok(png.to_vec());
    }
    let height =
        ((image.height() as f64 * width as f64 / image.width() as f64).round() as u32).max(1);
    let small = image::imageops::resize(&image, width, height, image::imageops::Triangle);
    let mut bytes = Vec::new();
    small
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .context("encoding a keyframe")?;
    Ok(bytes)
}

/// The file name of frame `index`.
pub fn frame_name(index: usize) -> String {
    format!("frame_{index:04}.png")
}
