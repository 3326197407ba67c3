//! `splatraj bench frames` as a library: how long a run's output frames take (render, metrics,
//! read-back, PNG, H.264, writing), per frame and for a whole video, at the sizes users share.
//!
//! Each scene is framed as `bench render` frames it ([`crate::bench::scenes`]: the demo scene
//! looking at one object, a real scene with a sphere at its centre as the object), and the
//! camera orbits the object by [`ORBIT_DEGREES`] over the video, so that each frame is a
//! different view as in a run. The frames go through [`render_path_with`], the code
//! `splatraj run` and `splatraj render-path` use, once per [`FrameSchedule`], into a temporary
//! folder; with `frames` below the video's frame count the video's time is extrapolated from
//! the frames timed.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::DType;
use glam::DVec3;
use serde::Serialize;
use splatraj_render::backend::{BackendKind, Hardware};
use splatraj_render::camera::Intrinsics;
use splatraj_render::counters::{self, Counts};
use splatraj_render::orbit::Orbit;
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_render::stages::{self, Stage};

use crate::bench::scenes::{BenchScene, demo_bench_scene, file_bench_scene};
use crate::bench::{cpu_seconds, rasterizer_name};
use crate::config::MaskOverlay;
use crate::outputs::camera_paths::{PathFrames, check_fps};
use crate::outputs::path_render::{FrameSchedule, PathObject, PathRender, Video, render_path_with};
use crate::resources::{MemoryLimit, RenderWork};

/// How far the camera turns around the object over the video, degrees.
pub const ORBIT_DEGREES: f64 = 60.0;

/// What every row of `bench frames` shares.
#[derive(Debug, Clone)]
pub struct FramesBench {
    /// Tensor backend.
    pub backend: BackendKind,
    /// Gaussians of the demo scene (none: no demo rows).
    pub demo_gaussians: Option<usize>,
    /// A real scene (its rows follow the demo's).
    pub scene: Option<PathBuf>,
    /// Frame sizes (width, height).
    pub sizes: Vec<(usize, usize)>,
    /// Frames timed per row (at most the video's; evenly spread over it).
    pub frames: usize,
    /// Length of the video, seconds.
    pub seconds: f64,
    /// Frames per second of the video.
    pub fps: f64,
    /// Schedules timed on every scene and size, in order.
    pub schedules: Vec<FrameSchedule>,
    /// Which compositing renders the frames.
    pub rasterizer: Rasterizer,
    /// Demo object the camera frames.
    pub object: String,
    /// Share of the frame the object covers at the first frame.
    pub target_ratio: f64,
    /// Horizontal field of view, degrees.
    pub fov: f64,
    /// SH degree every timed scene is brought to ([`splatraj_scene::Scene::with_sh_degree`]:
    /// higher degrees add zeros, so the pictures stay the same); None: as built or read. Real
    /// captures mostly hold degree 3, the demo scene degree 1.
    pub sh_degree: Option<u8>,
}

impl FramesBench {
    /// Frames of the whole video.
    pub fn video_frames(&self) -> usize {
        (self.seconds * self.fps).round().max(1.0) as usize
    }
}

/// One row: one scene, size and schedule.
#[derive(Debug, Clone, Serialize)]
pub struct FramesRow {
    /// `demo` or the file's name.
    pub scene: String,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// The scene's SH degree as rendered.
    pub sh_degree: u8,
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// The schedule's name ([`FrameSchedule::name`]).
    pub schedule: String,
    /// Frames timed.
    pub frames: usize,
    /// Mean ms per frame in each part: the render stages (decide, bin, project, composite),
    /// then `metrics`, `read_back`, `png`, `video` (H.264) and `write`. Parts that overlap
    /// (a pipelined schedule encodes while it renders) add up to more than `frame_ms`.
    pub parts_ms: Vec<(String, f64)>,
    /// Wall ms per frame (the whole call over the frames timed).
    pub frame_ms: f64,
    /// Seconds for the whole video (render + metrics + PNG + H.264 + files), measured when
    /// every frame was timed, else `frame_ms` × frames.
    pub video_s: f64,
    /// Whether `video_s` was measured (every frame of the video rendered).
    pub measured: bool,
    /// CPU time over wall time (≈ cores kept busy).
    pub cpu_per_wall: Option<f64>,
    /// Seconds to build or read the scene, place the camera and upload it (once per scene).
    pub setup_s: f64,
    /// What the frames launched, read back and uploaded, summed over the frames timed (on a
    /// GPU a frame's read-back is its size in floats, or 4 bytes a pixel where the levels are
    /// made on the device: docs/gpu.md).
    pub counts: Counts,
}

/// Everything `bench frames` reports.
#[derive(Debug, Clone, Serialize)]
pub struct FramesReport {
    /// Tensor backend.
    pub backend: String,
    /// What the frames were rendered on ([`Hardware`]): a GPU by name, an emulated one, or the
    /// CPU.
    pub device: String,
    /// Compositing.
    pub rasterizer: String,
    /// Threads of rayon's pool.
    pub rayon_threads: usize,
    /// Cores available.
    pub cores: usize,
    /// 1-minute load average when the bench started (other work on the machine).
    pub load_before: Option<f64>,
    /// 1-minute load average when it ended.
    pub load_after: Option<f64>,
    /// Video length, seconds, and its frame rate.
    pub seconds: f64,
    /// Frames per second.
    pub fps: f64,
    /// One row per scene, size and schedule.
    pub rows: Vec<FramesRow>,
}

/// The 1-minute load average (from /proc/loadavg), None where missing.
pub fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// The frames of a video of `bench`'s length orbiting `setup`'s object from its pose; only
/// `count` of them, evenly spread, when fewer. Every frame shows the object (one window).
fn orbit_frames(setup: &BenchScene, k: Intrinsics, bench: &FramesBench) -> Result<PathFrames> {
    let total = bench.video_frames();
    let count = bench.frames.clamp(1, total);
    let (sum, members) = setup
        .scene
        .means
        .iter()
        .zip(&setup.mask)
        .filter(|&(_, &m)| m != 0.0)
        .fold((DVec3::ZERO, 0usize), |(sum, n), (m, _)| {
            (sum + DVec3::from_array(m.map(f64::from)), n + 1)
        });
    if members == 0 {
        bail!("the bench object of {} has no Gaussian", setup.name);
    }
    let target = sum / members as f64;
    let eye = setup.pose.centre();
    // Orbit about the camera's own up (−y), so the first frame is the calibrated view.
    let up = -setup.pose.rotation_wc().y_axis;
    let distance = (eye - target).length();
    let orbit = Orbit::new(target, up, eye - target, distance);
    let elevation = ((eye - target) / distance).dot(orbit.up).asin();
    let mut frames = PathFrames {
        times: Vec::with_capacity(count),
        poses: Vec::with_capacity(count),
        cameras: vec![k; count],
        fps: bench.fps,
        cuts: Vec::new(),
    };
    for i in 0..count {
        // Frame index in the whole video, spread evenly.
        let f = if count == 1 {
            0
        } else {
            i * (total - 1) / (count - 1)
        };
        let t = f as f64 / (total - 1).max(1) as f64;
        let pose = orbit.pose(t * ORBIT_DEGREES.to_radians(), elevation, distance)?;
        frames.times.push(t);
        frames.poses.push(pose.0);
    }
    Ok(frames)
}

/// Times one size and schedule on a framed, uploaded scene.
fn time_frames(
    bench: &FramesBench,
    setup: &BenchScene,
    uploaded: &DeviceScene,
    size: (usize, usize),
    schedule: FrameSchedule,
    setup_s: f64,
) -> Result<FramesRow> {
    let k = Intrinsics::from_fov_x(bench.fov, size.0, size.1)?;
    let frames = orbit_frames(setup, k, bench)?;
    let count = frames.poses.len();
    let job = PathRender {
        frames: &frames,
        objects: vec![PathObject {
            mask: &setup.mask,
            target_ratio: bench.target_ratio,
        }],
        overlay: MaskOverlay::None,
        rasterizer: bench.rasterizer,
        video: Video::Mp4,
    };
    let dir = std::env::temp_dir().join(format!(
        "splatraj-bench-frames-{}-{}",
        std::process::id(),
        schedule.name().replace(':', "-")
    ));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    stages::reset();
    let counted = counters::snapshot();
    let cpu_before = cpu_seconds();
    let wall = Instant::now();
    let rendered = render_path_with(uploaded, &job, &dir, &mut |_| {}, schedule);
    let wall = wall.elapsed();
    let counts = counters::snapshot().since(&counted);
    // The frames were only written to be timed.
    let _ = std::fs::remove_dir_all(&dir);
    let rendered = rendered?;
    let cpu_per_wall = match (cpu_before, cpu_seconds()) {
        (Some(a), Some(b)) if wall.as_secs_f64() > 0.0 => Some((b - a) / wall.as_secs_f64()),
        _ => None,
    };
    let per_frame = |d: Duration| 1e3 * d.as_secs_f64() / count as f64;
    let mut parts_ms: Vec<(String, f64)> = stages::ms_per(count)
        .iter()
        .filter(|(stage, _)| *stage != Stage::CompositeBackward)
        .map(|&(stage, ms)| (stage.name().to_string(), ms))
        .collect();
    let t = rendered.timings;
    for (name, d) in [
        ("metrics", t.metrics),
        ("read_back", t.read_back),
        ("png", t.png),
        ("video", t.video),
        ("write", t.write),
    ] {
        parts_ms.push((name.into(), per_frame(d)));
    }
    let frame_ms = per_frame(wall);
    let measured = count == bench.video_frames();
    Ok(FramesRow {
        scene: setup.name.clone(),
        gaussians: setup.scene.len(),
        sh_degree: setup.scene.sh_degree,
        width: size.0,
        height: size.1,
        schedule: schedule.name(),
        frames: count,
        parts_ms,
        frame_ms,
        video_s: if measured {
            wall.as_secs_f64()
        } else {
            frame_ms * bench.video_frames() as f64 / 1e3
        },
        measured,
        cpu_per_wall,
        setup_s,
        counts,
    })
}

/// Runs the bench: every scene, size and schedule; `progress` is told each row's name first.
pub fn run_frames(bench: &FramesBench, progress: &mut dyn FnMut(&str)) -> Result<FramesReport> {
    if bench.sizes.is_empty() || bench.schedules.is_empty() {
        bail!("nothing to time: give at least one size and one schedule");
    }
    if let Some(&(w, h)) = bench.sizes.iter().find(|&&(w, h)| w == 0 || h == 0) {
        bail!("{w}×{h} is not a frame size");
    }
    check_fps(bench.fps).with_context(|| format!("--fps {:?}", bench.fps))?;
    if !(bench.seconds.is_finite() && bench.seconds > 0.0) {
        bail!("--seconds {} must be a positive number", bench.seconds);
    }
    Intrinsics::from_fov_x(bench.fov, 64, 64).with_context(|| format!("--fov {}", bench.fov))?;
    // Sizes and counts come from flags: refused before any scene is built when they cannot
    // fit (the pipelined schedule holds two frames at once). The time is the whole video's,
    // which the report gives (measured, or extrapolated from the frames timed).
    for &size in &bench.sizes {
        RenderWork {
            what: format!(
                "`--seconds` × `--fps` = {} video frames (`--frames` = {} timed) × {} \
                 schedules (--schedule) of {} demo Gaussians (--gaussians) at `--sizes`",
                bench.video_frames(),
                bench.frames,
                bench.schedules.len(),
                bench.demo_gaussians.unwrap_or(0)
            ),
            renders: bench.video_frames().max(bench.frames) as f64 * bench.schedules.len() as f64,
            at_once: 2,
            size,
            gaussians: bench.demo_gaussians.unwrap_or(0),
            gradient: false,
            float_bytes: DType::F32.size(),
        }
        .check(MemoryLimit::new(None)?, "")?;
    }
    let device = bench.backend.device()?;
    let load_before = load_average();
    // Camera placement is calibrated at 64² so every size sees the same view.
    let calibration = Intrinsics::from_fov_x(bench.fov, 64, 64)?;
    let mut sources: Vec<Box<dyn Fn() -> Result<BenchScene>>> = Vec::new();
    if let Some(n) = bench.demo_gaussians {
        let (object, ratio, device) = (bench.object.clone(), bench.target_ratio, device.clone());
        sources.push(Box::new(move || {
            demo_bench_scene(&object, n, ratio, &calibration, &device)
        }));
    }
    if let Some(path) = &bench.scene {
        let (path, ratio, device) = (path.clone(), bench.target_ratio, device.clone());
        sources.push(Box::new(move || {
            file_bench_scene(&path, ratio, &calibration, &device)
        }));
    }
    if sources.is_empty() {
        bail!("nothing to time: no demo scene and no --scene");
    }
    let mut rows = Vec::new();
    for source in sources {
        let clock = Instant::now();
        let mut setup = source()?;
        if let Some(degree) = bench.sh_degree {
            setup.scene = setup.scene.with_sh_degree(degree);
        }
        // Frames are rendered on the plain device, as `Experiment::plain_scene` uploads them.
        let uploaded = DeviceScene::new(&setup.scene, &device, DType::F32);
        let setup_s = clock.elapsed().as_secs_f64();
        for &size in &bench.sizes {
            for &schedule in &bench.schedules {
                progress(&format!(
                    "{} {}×{} {}",
                    setup.name,
                    size.0,
                    size.1,
                    schedule.name()
                ));
                rows.push(time_frames(
                    bench, &setup, &uploaded, size, schedule, setup_s,
                )?);
            }
        }
    }
    Ok(FramesReport {
        backend: bench.backend.to_string(),
        device: Hardware::of(&device).to_string(),
        rasterizer: rasterizer_name(bench.rasterizer).into(),
        rayon_threads: rayon::current_num_threads(),
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        load_before,
        load_after: load_average(),
        seconds: bench.seconds,
        fps: bench.fps,
        rows,
    })
}

impl FramesReport {
    /// The table: one line per row, ms per frame by part, then the video's seconds.
    pub fn table(&self) -> String {
        let load = |l: Option<f64>| l.map_or("-".into(), |l| format!("{l:.2}"));
        let mut out = format!(
            "output frames (RGB + object mask, metrics, PNG, H.264), backend {} on {}, {} \
             rasterizer, \
             rayon pool {} threads on {} cores, load {} → {}; ms per frame; video = {} s at {} \
             fps (~: extrapolated from the frames timed)\n",
            self.backend,
            self.device,
            self.rasterizer,
            self.rayon_threads,
            self.cores,
            load(self.load_before),
            load(self.load_after),
            self.seconds,
            self.fps
        );
        let Some(first) = self.rows.first() else {
            return out;
        };
        out += &format!(
            "{:<20} {:>9} {:>2} {:>9} {:>11} {:>6}",
            "scene", "gaussians", "sh", "size", "schedule", "frames"
        );
        for (name, _) in &first.parts_ms {
            out += &format!(" {:>9}", name);
        }
        out += &format!(
            " {:>9} {:>9} {:>6} {:>8} {:>10}\n",
            "frame ms", "video s", "cpu/w", "launches", "KB down"
        );
        for row in &self.rows {
            out += &format!(
                "{:<20} {:>9} {:>2} {:>9} {:>11} {:>6}",
                row.scene,
                row.gaussians,
                row.sh_degree,
                format!("{}×{}", row.width, row.height),
                row.schedule,
                row.frames
            );
            for (_, ms) in &row.parts_ms {
                out += &format!(" {ms:>9.1}");
            }
            let per_frame = |total: u64| total as f64 / row.frames.max(1) as f64;
            out += &format!(
                " {:>9.1} {:>8.1}{} {:>6} {:>8.1} {:>10.1}\n",
                row.frame_ms,
                row.video_s,
                if row.measured { " " } else { "~" },
                row.cpu_per_wall.map_or("-".into(), |v| format!("{v:.2}")),
                per_frame(row.counts.launches),
                per_frame(row.counts.bytes_down) / 1e3
            );
        }
        out
    }
}

/// A frame size `WIDTHxHEIGHT` (`1920x1080`), or `720p` / `1080p`.
pub fn parse_size(text: &str) -> Result<(usize, usize)> {
    match text {
        "720p" => return Ok((1280, 720)),
        "1080p" => return Ok((1920, 1080)),
        _ => {}
    }
    let (w, h) = text
        .split_once(['x', '×'])
        .ok_or_else(|| anyhow!("{text:?}: expected WIDTHxHEIGHT, 720p or 1080p"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|_| anyhow!("{text:?}: expected WIDTHxHEIGHT, 720p or 1080p"))
    };
    Ok((parse(w)?, parse(h)?))
}

/// The real scene `bench frames` times by default: biker from `$SPLATRAJ_DATA` (else
/// `/work/shared/data`), when it is there.
pub fn default_scene() -> Option<std::path::PathBuf> {
    let data = std::env::var_os("SPLATRAJ_DATA").map_or_else(
        || std::path::PathBuf::from("/work/shared/data"),
        std::path::PathBuf::from,
    );
    Some(data.join("biker.compressed.ply")).filter(|p| p.is_file())
}
