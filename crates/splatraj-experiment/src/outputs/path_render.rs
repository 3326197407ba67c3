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

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::{DType, Int, Tensor};
use rayon::prelude::*;
use splatraj_render::backend::Execution;
use splatraj_render::camera::Pose;
use splatraj_render::host::{OnDevice, read_data, to_host};
use splatraj_render::images::{packed_rgb8, png_rgb8, rgb8, unpack_rgb8};
use splatraj_render::pass_size::poses_per_pass;
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Rasterizer, RenderRequest, render_poses,
};
use splatraj_report::video::VideoEncoder;
use splatraj_traj::costs::{HostMoments, moment_sums, tce_on_host, tre_on_host};
use splatraj_traj::optimise::sampling::window_of;

use crate::config::MaskOverlay;
pub use crate::frame_metrics::FrameMetrics;
use crate::outputs::TINT_ALPHA;
use crate::outputs::camera_paths::PathFrames;
use crate::outputs::output_folder::OutputFolder;
use crate::prepare::experiment::Experiment;
use crate::resources::{MemoryLimit, RenderWork};
use crate::write::{write_bytes, write_csv};

/// One window's object: the Gaussians to measure (and tint) in the frames of its window.
#[derive(Debug, Clone, Copy)]
pub struct PathObject<'a> {
    /// Per-Gaussian 0/1 mask.
    pub mask: &'a [f32],
    /// The share of the frame it should cover (TRE's target).
    pub target_ratio: f64,
}

impl Experiment {
    /// Each window's object, for path renders.
    pub fn path_objects(&self) -> Vec<PathObject<'_>> {
        self.windows
            .iter()
            .map(|w| PathObject {
                mask: &w.mask,
                target_ratio: w.context.target_ratio,
            })
            .collect()
    }
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
    /// Where the time went.
    pub timings: PathTimings,
}

impl RenderedPath {
    /// Mean TCE over the frames that show their object (some coverage); `None` when none
    /// does: an object never in view has no centring error (an empty mask's TCE is 0).
    pub fn mean_tce_in_view(&self) -> Option<f64> {
        let seen: Vec<f64> = self.metrics.iter().filter_map(|m| m.tce).collect();
        (!seen.is_empty()).then(|| seen.iter().sum::<f64>() / seen.len() as f64)
    }
}

/// Time spent in each part of a path render, summed over its frames (the render stages'
/// own split is [`splatraj_render::stages`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PathTimings {
    /// `render()` calls: decide, bin, project, composite.
    pub render: Duration,
    /// TCE, TRE and coverage of the object's mask.
    pub metrics: Duration,
    /// Reading the images back and making 8-bit pixels (tint included).
    pub read_back: Duration,
    /// PNG encoding (frames and keyframes), summed over the frames encoded at once; at the
    /// same time as the video's.
    pub png: Duration,
    /// H.264: the groups' conversion and encoding, summed over their threads (which run at
    /// once and beside the PNGs), and the muxing.
    pub video: Duration,
    /// Writing files, summed over the frames written at once.
    pub write: Duration,
    /// The whole call, wall clock.
    pub wall: Duration,
}

/// How [`render_path_with`] orders its work; every schedule writes the same files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSchedule {
    /// One frame at a time, in order: render, read back, write the PNG and hand the frame to
    /// the video's encoder (its group's thread), then the next (the reference).
    Sequential,
    /// Up to `batch` frames rendered per pass, the next pass queued on the device before this
    /// one is read back, while a thread encodes and writes the frames before them: the PNGs
    /// of several frames at once, and the video's groups of pictures `groups` at a time (their
    /// frames rendered interleaved, [`VideoEncoder::encoding_runs`]).
    Pipelined {
        /// Poses per render pass.
        batch: usize,
        /// Video groups encoded at once; `None`: as many as [`VideoEncoder::new`] chooses for
        /// this machine.
        groups: Option<usize>,
    },
}

impl Default for FrameSchedule {
    fn default() -> Self {
        FrameSchedule::Pipelined {
            batch: 1,
            groups: None,
        }
    }
}

impl FrameSchedule {
    /// `sequential`, `pipelined:BATCH` or `pipelined:BATCH:GROUPS`.
    pub fn name(&self) -> String {
        match self {
            FrameSchedule::Sequential => "sequential".into(),
            FrameSchedule::Pipelined {
                batch,
                groups: None,
            } => format!("pipelined:{batch}"),
            FrameSchedule::Pipelined {
                batch,
                groups: Some(groups),
            } => format!("pipelined:{batch}:{groups}"),
        }
    }
}

impl std::str::FromStr for FrameSchedule {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || {
            format!(
                "unknown schedule {s:?}: expected sequential, pipelined, pipelined:BATCH or \
                 pipelined:BATCH:GROUPS (counts above 0)"
            )
        };
        let count = |n: &str| match n.parse::<usize>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(bad()),
        };
        let mut parts = s.split(':');
        match (parts.next(), parts.next(), parts.next(), parts.next()) {
            (Some("sequential"), None, ..) => Ok(FrameSchedule::Sequential),
            (Some("pipelined"), None, ..) => Ok(FrameSchedule::default()),
            (Some("pipelined"), Some(batch), groups, None) => Ok(FrameSchedule::Pipelined {
                batch: count(batch)?,
                groups: groups.map(count).transpose()?,
            }),
            _ => Err(bad()),
        }
    }
}

/// Renders `job` into `dir` (`frames/`, `frame_metrics.csv` when there are objects,
/// `video.mp4` when asked); `progress` is told after each frame. Frames too large or too many
/// are refused before any is rendered; a stop requested meanwhile ([`splatraj_scene::stop`])
/// ends the work after a whole frame with [`splatraj_scene::stop::Stopped`].
pub fn render_path(
    scene: &DeviceScene,
    job: &PathRender<'_>,
    dir: &Path,
    progress: &mut dyn FnMut(usize),
) -> Result<RenderedPath> {
    render_path_with(scene, job, dir, progress, FrameSchedule::default())
}

/// What a rendered folder may hold: the names [`render_path`] writes.
pub const PATH_RENDER_NAMES: [&str; 4] = ["frames", KEYFRAMES_DIR, FRAME_METRICS_FILE, VIDEO_FILE];

/// [`render_path`] into the folder `out` as a whole ([`OutputFolder`]): written beside it and
/// renamed into place, so a re-run replaces an earlier render whole, a failure leaves `out` as
/// it was, and a second writer of the same folder is refused. `out` may hold only an earlier
/// render ([`PATH_RENDER_NAMES`]).
pub fn render_path_to(
    scene: &DeviceScene,
    job: &PathRender<'_>,
    out: &Path,
    progress: &mut dyn FnMut(usize),
) -> Result<RenderedPath> {
    let folder = OutputFolder::begin(out, &PATH_RENDER_NAMES)?;
    let mut rendered = render_path(scene, job, folder.path(), progress)?;
    let out = folder.commit()?;
    rendered.video = rendered.video.map(|_| out.join(VIDEO_FILE));
    Ok(rendered)
}

/// [`render_path`] with the given schedule.
///
/// One loop renders the frames (in passes of up to `batch` poses of one window and size, in
/// the order of the video's groups of pictures, [`VideoEncoder::encoding_runs`]), computes
/// their metrics and turns them into 8-bit pixels; a frame writer hands each frame to the
/// video's encoders (threads of their own) and writes its PNG, inline
/// ([`FrameSchedule::Sequential`], in frame order) or on a thread of its own fed through a
/// bounded queue. The first error stops both.
pub fn render_path_with(
    scene: &DeviceScene,
    job: &PathRender<'_>,
    dir: &Path,
    progress: &mut dyn FnMut(usize),
    schedule: FrameSchedule,
) -> Result<RenderedPath> {
    let started = Instant::now();
    let frames = job.frames;
    if frames.poses.is_empty() {
        bail!("the path has no frames");
    }
    // Only a stop requested from now on cuts the frames short (a run stopped while it
    // optimised still renders the frames of its best trajectory).
    let since = splatraj_scene::stop::Since::now();
    splatraj_scene::stop::honour();
    let size = (frames.cameras[0].width, frames.cameras[0].height);
    let groups = match schedule {
        FrameSchedule::Pipelined {
            groups: Some(groups),
            ..
        } => groups,
        _ => VideoEncoder::parallel_for(size.0, size.1),
    };
    let png_batch = png_batch(schedule, size);
    // The writer's buffers sit beside the renders all along: a batch of PNG frames with their
    // keyframes, and the video's groups (up to 128 MB and 256 MB). Checked before the encoder
    // is made: it refuses frames too large for H.264 in words that name no option.
    let video_bytes = match job.video {
        Video::Mp4 => VideoEncoder::held_bytes_for(size.0, size.1, groups),
        Video::None => 0,
    };
    let writer_bytes = png_batch as f64 * png_frame_bytes(size) as f64 + video_bytes as f64;
    check_path_render(scene.len(), job, schedule, writer_bytes)?;
    let encoder = match job.video {
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
            Some(VideoEncoder::with_parallel(
                size.0, size.1, frames.fps, groups,
            )?)
        }
        Video::None => None,
    };
    // The order frames are rendered in: the video's groups interleaved when they are encoded
    // several at once; the reference in frame order.
    let count = frames.poses.len();
    let runs = match (schedule, &encoder) {
        (FrameSchedule::Pipelined { batch, .. }, Some(encoder)) => {
            encoder.encoding_runs(count, batch)
        }
        // One run of every frame (a one-element list, not the frames' indices).
        _ => std::iter::once(0..count).collect(),
    };
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
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
    let mut writer = FrameWriter {
        frames_dir,
        keyframes_dir,
        encoder,
        timings: PathTimings::default(),
        pending: Vec::new(),
        png_batch,
    };
    let mut timings = PathTimings::default();
    let (metrics, mut writer) = match schedule {
        FrameSchedule::Sequential => {
            let metrics = render_frames(
                scene,
                job,
                (schedule, since),
                (&runs, &keyframes),
                &mut timings,
                progress,
                &mut |frame| writer.write(frame),
            )?;
            writer.flush()?;
            (metrics, writer)
        }
        FrameSchedule::Pipelined { .. } => std::thread::scope(|threads| {
            // Two frames queued: enough to keep the writer busy, and a 1080p frame with its
            // keyframe is ~12 MB, so the queue stays small.
            let (queue, frames_in) = std::sync::mpsc::sync_channel::<Frame>(2);
            // Started with a Builder: `scope.spawn` panics where the system refuses a thread
            // (as under an address-space limit, which every thread's stack counts against).
            let encoding = std::thread::Builder::new()
                .name("frame writer".into())
                .spawn_scoped(threads, move || -> Result<FrameWriter> {
                    for frame in frames_in {
                        writer.write(frame)?;
                    }
                    writer.flush()?;
                    Ok(writer)
                })
                .map_err(|e| {
                    anyhow!(
                        "could not start the frame writer's thread ({e}): the process is short \
                         of memory or threads; under an address-space limit (`ulimit -v`) every \
                         thread's stack counts, so raise it or render smaller frames"
                    )
                })?;
            let rendered = render_frames(
                scene,
                job,
                (schedule, since),
                (&runs, &keyframes),
                &mut timings,
                progress,
                &mut |frame| {
                    // A closed queue means the writer failed: its error is reported below.
                    queue
                        .send(frame)
                        .map_err(|_| anyhow!("the frame writer stopped"))
                },
            );
            drop(queue);
            let written = encoding
                .join()
                .map_err(|_| anyhow!("the frame writer panicked"))?;
            // The writer's error is the cause when both failed.
            let writer = written?;
            Ok::<_, anyhow::Error>((rendered?, writer))
        })?,
    };
    if !metrics.is_empty() {
        let header = ["frame", "t", "window", "tce", "tre", "coverage"].map(String::from);
        let rows: Vec<Vec<String>> = metrics
            .iter()
            .map(|m| {
                vec![
                    m.frame.to_string(),
                    m.t.to_string(),
                    m.window.to_string(),
                    m.tce.map_or(String::new(), |tce| tce.to_string()),
                    m.tre.to_string(),
                    m.coverage.to_string(),
                ]
            })
            .collect();
        write_csv(&dir.join(FRAME_METRICS_FILE), &header, &rows)?;
    }
    let video = match writer.encoder.take() {
        Some(mut encoder) => {
            let path = dir.join(VIDEO_FILE);
            if encoder.frames() != count {
                bail!(
                    "the video was given {} of its {count} frames",
                    encoder.frames()
                );
            }
            encoder.wait_for_groups()?;
            writer.timings.video += encoder.encoding_time();
            let clock = Instant::now();
            let bytes = encoder.finish()?;
            writer.timings.video += clock.elapsed();
            write_bytes(&path, &bytes)?;
            Some(path)
        }
        None => None,
    };
    timings.png = writer.timings.png;
    timings.video = writer.timings.video;
    timings.write = writer.timings.write;
    timings.wall = started.elapsed();
    Ok(RenderedPath {
        metrics,
        video,
        timings,
    })
}

/// Refuses frames too large for the memory, or too many for the time, before any is
/// rendered (their count and size come from options or from the path file).
fn check_path_render(
    gaussians: usize,
    job: &PathRender<'_>,
    schedule: FrameSchedule,
    writer_bytes: f64,
) -> Result<()> {
    let frames = job.frames;
    let size = frames
        .cameras
        .iter()
        .map(|k| (k.width, k.height))
        .max_by(|a, b| (a.0 as f64 * a.1 as f64).total_cmp(&(b.0 as f64 * b.1 as f64)))
        .unwrap_or((1, 1));
    // A pipelined pass is queued while the one before it is still held.
    let at_once = match schedule {
        FrameSchedule::Sequential => 1,
        FrameSchedule::Pipelined { batch, .. } => 2 * batch.max(1),
    };
    RenderWork {
        what: format!(
            "{} frames (`--fps` × `--seconds`, or the path file's) of {gaussians} Gaussians at \
             the largest frame size (`--width` × `--height`, or the path file's)",
            frames.poses.len()
        ),
        renders: frames.poses.len() as f64,
        at_once,
        size,
        gaussians,
        gradient: false,
        float_bytes: 4,
    }
    .check_beside(
        Some(("the frame writer's buffers", writer_bytes)),
        MemoryLimit::new(None)?,
        "",
    )
}

/// `frame`'s PNG (into `frames_dir`) and keyframe (into `keyframes_dir`) encoded and written:
/// (encoding time, writing time).
fn write_png(
    (frames_dir, keyframes_dir): (&Path, &Path),
    frame: &Frame,
) -> Result<(Duration, Duration)> {
    let clock = Instant::now();
    let png = png_rgb8(&frame.rgb, frame.width, frame.height)?;
    let keyframe = match &frame.keyframe {
        Some(tinted) => Some(shrunk_png(
            tinted,
            frame.width,
            frame.height,
            KEYFRAME_WIDTH,
        )?),
        None => None,
    };
    let encoded = clock.elapsed();
    let clock = Instant::now();
    let name = frame_name(frame.index);
    if let Some(keyframe) = keyframe {
        write_bytes(&keyframes_dir.join(&name), &keyframe)?;
    }
    write_bytes(&frames_dir.join(&name), &png)?;
    Ok((encoded, clock.elapsed()))
}

/// Frames whose PNGs are written at once: one in the sequential reference; else as many as
/// threads (rayon's count, which `RAYON_NUM_THREADS` sets), at most 8 and at most 128 MB of
/// frames (with their keyframes) held.
fn png_batch(schedule: FrameSchedule, size: (usize, usize)) -> usize {
    const HELD_BYTES: usize = 128 << 20;
    match schedule {
        FrameSchedule::Sequential => 1,
        FrameSchedule::Pipelined { .. } => rayon::current_num_threads()
            .min(8)
            .min(HELD_BYTES / png_frame_bytes(size).max(1))
            .max(1),
    }
}

/// Bytes a frame waiting for its PNG holds: its RGB and its keyframe's (saturating: sizes
/// come from files, and the memory check must not overflow before it refuses them).
fn png_frame_bytes((width, height): (usize, usize)) -> usize {
    [width, height, 3]
        .into_iter()
        .fold(2usize, usize::saturating_mul)
}

/// One rendered frame on its way to the files.
struct Frame {
    /// Frame index.
    index: usize,
    /// Frame size, pixels.
    width: usize,
    height: usize,
    /// 8-bit RGB as the frame shows it. `[H·W·3]`
    rgb: Vec<u8>,
    /// 8-bit RGB with the object tinted, for a keyframe. `[H·W·3]`
    keyframe: Option<Vec<u8>>,
}

/// Encodes and writes frames: each frame's video frame when given, the PNGs a batch at a time.
struct FrameWriter {
    frames_dir: PathBuf,
    keyframes_dir: PathBuf,
    encoder: Option<VideoEncoder>,
    /// PNG, video and write times.
    timings: PathTimings,
    /// Frames whose PNGs are not written yet.
    pending: Vec<Frame>,
    /// Frames whose PNGs are encoded at once, each on a thread of its own.
    png_batch: usize,
}

impl FrameWriter {
    /// Gives `frame` to the video (its group's encoder runs on a thread of its own) and writes
    /// its PNG (and keyframe) with the batch it completes. On a GPU the device renders a frame
    /// faster than one thread encodes it, so this thread would set the pace.
    fn write(&mut self, frame: Frame) -> Result<()> {
        if let Some(encoder) = &mut self.encoder {
            // PNG is lossless: these are the bytes the PNG holds, so the video shows exactly
            // the frames. The encoding's time is its threads' (`encoding_time`).
            encoder.push(frame.index, &frame.rgb)?;
        }
        self.pending.push(frame);
        if self.pending.len() >= self.png_batch {
            self.flush()?;
        }
        Ok(())
    }

    /// Writes the PNGs of the frames given and not written yet, each on a thread of its own.
    ///
    /// Not on rayon's pool: the writer is not one of its threads, and the render loop, which
    /// is, may be its only one (`RAYON_NUM_THREADS=1`) and wait for this writer, so a job
    /// handed to the pool would never run.
    fn flush(&mut self) -> Result<()> {
        let frames = std::mem::take(&mut self.pending);
        let dirs = (self.frames_dir.as_path(), self.keyframes_dir.as_path());
        let written: Vec<(Duration, Duration)> = match frames.as_slice() {
            [frame] => vec![write_png(dirs, frame)?],
            _ => std::thread::scope(|threads| {
                // A frame whose thread the system refuses (short of memory or threads, as under
                // `ulimit -v`) is written on this thread instead: slower, not a failure.
                let handles: Vec<_> = frames
                    .iter()
                    .map(|frame| {
                        std::thread::Builder::new()
                            .name("png writer".into())
                            .spawn_scoped(threads, move || write_png(dirs, frame))
                            .map_err(|_| frame)
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|handle| match handle {
                        Ok(handle) => handle
                            .join()
                            .map_err(|_| anyhow!("a PNG writer panicked"))?,
                        Err(frame) => write_png(dirs, frame),
                    })
                    .collect::<Result<_>>()
            })?,
        };
        for (png, write) in written {
            self.timings.png += png;
            self.timings.write += write;
        }
        Ok(())
    }
}

/// Renders every frame of `job`, run after run of `runs`, in passes of up to `batch`
/// consecutive frames that share a window and a size, hands each frame's pixels to `deliver`
/// in that order and tells `progress` how many are delivered; returns the frames' metrics in
/// frame order (empty without objects) and adds render, metrics and read-back times to
/// `timings`.
///
/// [`FrameSchedule::Pipelined`] keeps one pass in flight while the one before it is read back:
/// on a GPU the host decides and bins the next frames while the device composites these (the
/// host backends run each pass when it is made, so there the order of the work is all that
/// changes). [`FrameSchedule::Sequential`] renders a frame only after the one before is written.
fn render_frames(
    scene: &DeviceScene,
    job: &PathRender<'_>,
    (schedule, since): (FrameSchedule, splatraj_scene::stop::Since),
    (runs, keyframes): (&[Range<usize>], &[usize]),
    timings: &mut PathTimings,
    progress: &mut dyn FnMut(usize),
    deliver: &mut dyn FnMut(Frame) -> Result<()>,
) -> Result<Vec<FrameMetrics>> {
    let frames = job.frames;
    let context = FrameContext {
        job,
        windows: frames
            .times
            .iter()
            .map(|&t| window_of(t, job.objects.len()))
            .collect(),
        keyframes,
    };
    let (batch, ahead) = match schedule {
        FrameSchedule::Sequential => (1, 0),
        FrameSchedule::Pipelined { batch, .. } => (batch, 1),
    };
    let total = frames.poses.len();
    let mut delivered = 0;
    // Each frame handed on, counted, told, and the boundary where a stop takes effect.
    let mut deliver_one = |frame: Frame| -> Result<()> {
        deliver(frame)?;
        delivered += 1;
        progress(delivered);
        if delivered < total {
            since.stop_point(|| format!("{delivered} of {total} frames are written, no video"))?;
        }
        Ok(())
    };
    let mut metrics = Vec::new();
    let mut in_flight: std::collections::VecDeque<QueuedFrames> = Default::default();
    for run in runs {
        let mut first = run.start;
        while first < run.end {
            let queued = context.queue(scene, first, batch.min(run.end - first), timings)?;
            first = queued.frames.end;
            in_flight.push_back(queued);
            if in_flight.len() > ahead
                && let Some(done) = in_flight.pop_front()
            {
                context.finish(done, timings, &mut metrics, &mut deliver_one)?;
            }
        }
    }
    for done in in_flight {
        context.finish(done, timings, &mut metrics, &mut deliver_one)?;
    }
    // Runs of several groups come interleaved: the metrics go in frame order.
    metrics.sort_by_key(|m| m.frame);
    Ok(metrics)
}

/// What every pass of [`render_frames`] reads.
struct FrameContext<'a> {
    job: &'a PathRender<'a>,
    /// The window each frame shows.
    windows: Vec<usize>,
    keyframes: &'a [usize],
}

/// A pass of frames queued on the device, not read back yet.
struct QueuedFrames {
    /// Which frames.
    frames: std::ops::Range<usize>,
    /// Their images, as they will be read back.
    images: QueuedImages,
    /// What their framing figures are made of, when the window has an object.
    framing: Option<QueuedFraming>,
}

/// A pass's framing figures queued: the object's mask moments, made into TCE, TRE and
/// coverage on the host once read back.
struct QueuedFraming {
    /// The moment sums of each frame's mask `[B, 4]` ([`moment_sums`]).
    sums: Tensor<2>,
    /// The object's target ratio, for TRE.
    target_ratio: f64,
}

/// What a pass's frames read back.
enum QueuedImages {
    /// The channels as rendered `[B, H, W, 3 or 4]`; the host makes the 8-bit levels (and the
    /// tint). On the host backends always: their values are in memory already.
    Values(Tensor<4>),
    /// The 8-bit RGB levels made and packed on the GPU `[B, H, W]` (`images::packed_rgb8`):
    /// 4 bytes a pixel read back instead of 4 a channel. For a GPU's passes in which no frame
    /// is tinted or a keyframe, the two pictures that need the mask on the host.
    PackedRgb8(Tensor<3, Int>),
}

impl FrameContext<'_> {
    /// Queues the render of the frames from `first` on (up to `batch` that share a window and
    /// a size, and fit the device), their framing figures, and has the device start on them.
    fn queue(
        &self,
        scene: &DeviceScene,
        first: usize,
        batch: usize,
        timings: &mut PathTimings,
    ) -> Result<QueuedFrames> {
        let frames = self.job.frames;
        let windows = &self.windows;
        let intrinsics = frames.cameras[first];
        let same = |i: usize| windows[i] == windows[first] && frames.cameras[i] == intrinsics;
        let object = self.job.objects.get(windows[first]);
        // Never more poses than the device can hold the images of (RGB, and the mask).
        let fits = poses_per_pass(
            &scene.device(),
            scene.dtype(),
            intrinsics.width,
            intrinsics.height,
            3 + usize::from(object.is_some()),
        );
        let end = (first..frames.poses.len().min(first + batch.clamp(1, fits)))
            .take_while(|&i| same(i))
            .last()
            .map_or(first + 1, |i| i + 1);
        let mut channels = vec![Channel::Rgb];
        if let Some(o) = object {
            channels.push(Channel::Mask(o.mask.to_vec()));
        }
        let request = RenderRequest {
            rasterizer: self.job.rasterizer,
            alpha: AlphaChannel::Dropped,
            ..RenderRequest::new(intrinsics, channels)
        };
        let poses: Vec<Pose> = frames.poses[first..end].iter().map(|&p| Pose(p)).collect();
        let clock = Instant::now();
        let images = render_poses(scene, &poses, &request)
            .with_context(|| format!("rendering frame {first}"))?
            .images; // [B, H, W, 3 or 4]
        timings.render += clock.elapsed();
        let clock = Instant::now();
        // The moments, read back whole (one wait on a GPU, and two launches where TCE, TRE and
        // coverage as tensor ops were 16: docs/gpu.md, "Made on the host from what is read
        // anyway").
        let framing = object.map(|o| QueuedFraming {
            sums: moment_sums(images.clone(), 3),
            target_ratio: o.target_ratio,
        });
        let mask_on_host = object.is_some()
            && (self.job.overlay == MaskOverlay::Tint
                || (first..end).any(|i| self.keyframes.contains(&i)));
        let images = match Execution::of(&scene.device()) {
            Execution::Kernels if !mask_on_host => QueuedImages::PackedRgb8(packed_rgb8(images)),
            _ => QueuedImages::Values(images),
        };
        scene
            .device()
            .flush()
            .map_err(|e| anyhow!("starting frame {first} on the device: {e}"))?;
        timings.metrics += clock.elapsed();
        Ok(QueuedFrames {
            frames: first..end,
            images,
            framing,
        })
    }

    /// Reads `done` back, records its metrics, and delivers its frames in order.
    fn finish(
        &self,
        done: QueuedFrames,
        timings: &mut PathTimings,
        metrics: &mut Vec<FrameMetrics>,
        deliver: &mut dyn FnMut(Frame) -> Result<()>,
    ) -> Result<()> {
        let frames = self.job.frames;
        let first = done.frames.start;
        // The frames of a window with an object have framing figures, and may be tinted.
        let tinted = done.framing.is_some() && self.job.overlay == MaskOverlay::Tint;
        if let Some(framing) = done.framing {
            let clock = Instant::now();
            let camera = frames.cameras[first];
            let pixels = camera.width * camera.height;
            let moments = HostMoments::from_sums(&to_host(framing.sums)?, pixels);
            for (index, m) in done.frames.clone().zip(&moments) {
                metrics.push(FrameMetrics {
                    frame: index,
                    t: frames.times[index],
                    window: self.windows[index],
                    tce: (m.coverage() > 0.0).then(|| tce_on_host(m)),
                    tre: tre_on_host(m, framing.target_ratio),
                    coverage: m.coverage(),
                });
            }
            timings.metrics += clock.elapsed();
        }
        let clock = Instant::now();
        let reading = || format!("reading frame {first} back");
        // Values a pixel `c`: the channels, or one packed value.
        let (pixels, [h, w, c]) = match done.images {
            QueuedImages::Values(images) => {
                let [_, h, w, c] = images.dims();
                // f32 images stay f32 on the host (the f64 copy cost as much as the PNG); any
                // other dtype is read as f64, as `to_host` reads it.
                let data = read_data(images).with_context(reading)?;
                let pixels = match data.dtype() {
                    DType::F32 => {
                        Pixels::F32(data.try_into_vec::<f32>().map_err(|e| anyhow!("{e:?}"))?)
                    }
                    _ => Pixels::F64(
                        data.convert::<f64>()
                            .try_into_vec::<f64>()
                            .map_err(|e| anyhow!("{e:?}"))?,
                    ),
                };
                (pixels, [h, w, c])
            }
            QueuedImages::PackedRgb8(packed) => {
                let [_, h, w] = packed.dims();
                let levels = read_data(packed)
                    .with_context(reading)?
                    .convert::<i32>()
                    .try_into_vec::<i32>()
                    .map_err(|e| anyhow!("{e:?}"))?;
                (Pixels::PackedRgb8(levels), [h, w, 1])
            }
        };
        timings.read_back += clock.elapsed();
        for (i, index) in done.frames.enumerate() {
            let clock = Instant::now();
            let frame_pixels = h * w * c;
            let range = i * frame_pixels..(i + 1) * frame_pixels;
            let rgb = pixels.rgb8(range.clone(), c, tinted.then_some(TINT_ALPHA));
            let keyframe = self
                .keyframes
                .contains(&index)
                .then(|| pixels.rgb8(range, c, Some(TINT_ALPHA)));
            timings.read_back += clock.elapsed();
            // A whole frame is the boundary: what was delivered gets written whole.
            deliver(Frame {
                index,
                width: w,
                height: h,
                rgb,
                keyframe,
            })?;
        }
        Ok(())
    }
}

/// A batch's images on the host, `[B·H·W·C]`, in the precision they were rendered in, or
/// their RGB levels packed on the device `[B·H·W]` (C = 1; a pass none of whose frames is
/// tinted or a keyframe: [`QueuedImages::PackedRgb8`]).
enum Pixels {
    F32(Vec<f32>),
    F64(Vec<f64>),
    PackedRgb8(Vec<i32>),
}

impl Pixels {
    /// [`rgb8`] of the values in `range`, rows split over the rayon pool (packed levels are
    /// never tinted: their passes have no tinted frame).
    fn rgb8(&self, range: std::ops::Range<usize>, channels: usize, tint: Option<f64>) -> Vec<u8> {
        fn rows<E: Copy + Into<f64> + Sync>(
            values: &[E],
            channels: usize,
            tint: Option<f64>,
        ) -> Vec<u8> {
            // Whole pixels per chunk; the chunks' bytes are joined in order.
            let chunk = channels * 4096;
            values
                .par_chunks(chunk)
                .map(|part| rgb8(part, channels, tint))
                .collect::<Vec<Vec<u8>>>()
                .concat()
        }
        match self {
            Pixels::F32(v) => rows(&v[range], channels, tint),
            Pixels::F64(v) => rows(&v[range], channels, tint),
            Pixels::PackedRgb8(v) => unpack_rgb8(&v[range]),
        }
    }
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

/// The 8-bit RGB picture `rgb` (`[H·W·3]`, `w` × `h`) scaled down to `width` pixels wide
/// (kept when narrower), as PNG bytes.
fn shrunk_png(rgb: &[u8], w: usize, h: usize, width: u32) -> Result<Vec<u8>> {
    if w <= width as usize {
        return Ok(png_rgb8(rgb, w, h)?);
    }
    let image = image::RgbImage::from_raw(w as u32, h as u32, rgb.to_vec())
        .ok_or_else(|| anyhow!("a keyframe of {} bytes is not {w}×{h} RGB", rgb.len()))?;
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
