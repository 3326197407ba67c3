//! Camera paths as files: a run's `trajectory.json` (evaluated from its model at any number of
//! frames) or another tool's camera file (nerfstudio, COLMAP, INRIA, SuperSplat), read as
//! frames to render or export; and frames written in every interchange format
//! (`exports/<format>/`). `splatraj export`, `splatraj render-path` and the end of
//! `splatraj run` all go through here, so a run's exports hold exactly the poses of its frames.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use serde::Deserialize;
use splatraj_camera_paths::supersplat::Focus;
use splatraj_camera_paths::{CameraPath, ExportOptions, Format, Frame};
use splatraj_lift::cameras::checked_intrinsics;
use splatraj_render::camera::{CameraPose, Intrinsics};
use splatraj_render::camera_file::{check_pose_range, resize};
use splatraj_traj::optimise::sampling::window_of;
use splatraj_traj::trajectory::{Basis, ShotSpans, TrajectoryRecord, uniform_times};

use crate::outputs::output_folder::OutputFolder;
use crate::outputs::records::SceneRecord;
use crate::resources::check_path_frames;
use crate::write::write_into_folder;

/// Frames per second when neither the command line, the run's config nor the file says.
pub const DEFAULT_FPS: f64 = 30.0;

/// Length of an exported or rendered `trajectory.json` when nothing else says, in seconds.
pub const DEFAULT_SECONDS: f64 = 5.0;

/// Frames of a camera path: a pose and a camera for each, at times t ∈ [0, 1].
#[derive(Debug, Clone, PartialEq)]
pub struct PathFrames {
    /// Time of each frame in [0, 1] (the query windows split this range).
    pub times: Vec<f64>,
    /// Φ = [ω, c] of each frame (OpenCV camera axes).
    pub poses: Vec<[f64; 6]>,
    /// The camera of each frame.
    pub cameras: Vec<Intrinsics>,
    /// Frames per second.
    pub fps: f64,
    /// The frames that begin a new shot after a cut, ascending (empty: one shot).
    pub cuts: Vec<usize>,
}

/// The frames at `times` that begin a new shot of `shots` (the first frame of each shot but
/// the first).
pub fn frame_cuts(times: &[f64], shots: &ShotSpans) -> Vec<usize> {
    (1..times.len())
        .filter(|&k| !shots.same_shot(times[k - 1], times[k]))
        .collect()
}

impl PathFrames {
    /// The frames as a [`CameraPath`] of `splatraj-report`.
    pub fn camera_path(&self) -> CameraPath {
        CameraPath {
            frames: self
                .poses
                .iter()
                .zip(&self.cameras)
                .map(|(&pose, k)| Frame {
                    pose: CameraPose::from_phi(pose),
                    camera: Some(*k),
                })
                .collect(),
            fps: Some(self.fps),
            seconds: None,
            cuts: self.cuts.clone(),
        }
    }
}

/// How many frames to take of a path, and at which size; `None` leaves it to the file.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameRequest {
    /// Frames per second.
    pub fps: Option<f64>,
    /// Length in seconds (a `trajectory.json` is evaluated at fps × seconds times; another
    /// tool's file keeps its own frames).
    pub seconds: Option<f64>,
    /// Image width (rescales the camera; alone, keeps the aspect ratio).
    pub width: Option<usize>,
    /// Image height (rescales the camera; alone, keeps the aspect ratio).
    pub height: Option<usize>,
}

impl FrameRequest {
    fn check(&self) -> Result<()> {
        for (name, value) in [("--fps", self.fps), ("--seconds", self.seconds)] {
            if let Some(v) = value
                && !(v.is_finite() && v > 0.0)
            {
                bail!("{name} {v} must be a positive number");
            }
        }
        if let Some(fps) = self.fps {
            check_fps(fps).with_context(|| format!("--fps {fps:?}"))?;
        }
        Ok(())
    }
}

/// Refuses a frame rate the video cannot hold (outside [`splatraj_report::video::MIN_FPS`],
/// [`splatraj_report::video::MAX_FPS`]); the caller names where it came from.
pub fn check_fps(fps: f64) -> Result<()> {
    splatraj_report::video::check_fps(fps)?;
    Ok(())
}

impl PathFrames {
    /// Refuses frames that could not be rendered or written: a pose out of the renderer's
    /// range ([`check_pose_range`]), or a frame rate the video cannot hold. `file` names
    /// where they came from. Every reader of a camera path ends here.
    fn checked(self, file: &Path) -> Result<Self> {
        for (i, pose) in self.poses.iter().enumerate() {
            check_pose_range(pose)
                .map_err(|e| anyhow!("{}: frame {i}: pose {e}", file.display()))?;
        }
        check_fps(self.fps).with_context(|| format!("{}: key `fps`", file.display()))?;
        for (i, camera) in self.cameras.iter().enumerate() {
            check_image_side(camera)
                .with_context(|| format!("{}: frame {i} (or --width, --height)", file.display()))?;
        }
        Ok(self)
    }
}

/// The largest image side a camera may have (pixels): larger than any display or video
/// format, small enough that no camera file claims an image no tool could make.
pub const MAX_IMAGE_SIDE: usize = 65_536;

/// Refuses a camera larger than [`MAX_IMAGE_SIDE`] on a side.
pub(crate) fn check_image_side(k: &Intrinsics) -> Result<()> {
    if k.width > MAX_IMAGE_SIDE || k.height > MAX_IMAGE_SIDE {
        bail!(
            "a {}×{} image is larger than {MAX_IMAGE_SIDE} pixels on a side",
            k.width,
            k.height
        );
    }
    Ok(())
}

/// A camera of a `trajectory.json` (key `key`): valid intrinsics of a sane size.
fn check_file_camera(file: &Path, key: &str, k: &Intrinsics) -> Result<()> {
    Intrinsics::new(k.fx, k.fy, k.cx, k.cy, k.width, k.height)
        .map_err(anyhow::Error::from)
        .and_then(|k| check_image_side(&k))
        .with_context(|| format!("{}: key `{key}`", file.display()))
}

/// One window of a run, as `trajectory.json` lists it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct WindowEntry {
    /// The query.
    #[serde(default)]
    pub query: String,
    /// The object's centre.
    pub object_centre: [f64; 3],
    /// Start of the window in t, when the file gives it.
    #[serde(default)]
    pub start: Option<f64>,
    /// End of the window in t, when the file gives it.
    #[serde(default)]
    pub end: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct SampledPose {
    pose: [f64; 6],
    /// The zoom there (files of a zooming lens; absent: 1).
    #[serde(default)]
    zoom: Option<f64>,
}

/// What paths need of a `trajectory.json` besides the model and weights.
#[derive(Debug, Deserialize)]
struct TrajectoryExtras {
    output_intrinsics: Intrinsics,
    #[serde(default)]
    intrinsics: Option<Intrinsics>,
    #[serde(default)]
    world_up: Option<[f64; 3]>,
    #[serde(default)]
    windows: Vec<WindowEntry>,
    #[serde(default)]
    poses: Vec<SampledPose>,
    /// Absent from files written before it was recorded.
    #[serde(default)]
    scene: Option<SceneRecord>,
}

/// Refuses windows that cannot be a run's: a window that does not lie in [0, 1] or ends
/// before it starts, or (for the RBF and cut models, which know their windows) a list of
/// another length.
fn check_windows(file: &Path, record: &TrajectoryRecord, windows: &[WindowEntry]) -> Result<()> {
    for (i, w) in windows.iter().enumerate() {
        if let (Some(start), Some(end)) = (w.start, w.end)
            && !(0.0 <= start && start < end && end <= 1.0)
        {
            bail!(
                "{}: key `windows.{i}`: start {start} and end {end} must satisfy 0 ≤ start < \
                 end ≤ 1",
                file.display()
            );
        }
    }
    let model_windows = match &record.model {
        splatraj_traj::trajectory::TrajectoryModel::Rbf(rbf) => Some(rbf.windows),
        splatraj_traj::trajectory::TrajectoryModel::Cuts(cuts) => Some(cuts.spans().windows),
        _ => None,
    };
    if let Some(model_windows) = model_windows
        && !windows.is_empty()
        && windows.len() != model_windows
    {
        bail!(
            "{}: key `windows` lists {} windows, key `model.windows` says {model_windows}",
            file.display(),
            windows.len(),
        );
    }
    Ok(())
}

/// A run's `trajectory.json`, read back.
#[derive(Debug, Clone)]
pub struct RunTrajectory {
    /// The file.
    pub file: PathBuf,
    /// Model and weights.
    pub record: TrajectoryRecord,
    /// The run's frame camera.
    pub output_intrinsics: Intrinsics,
    /// The run's query windows.
    pub windows: Vec<WindowEntry>,
    /// The densely sampled poses the file holds (for a custom model, whose basis needs its
    /// registry).
    pub sampled: Vec<[f64; 6]>,
    /// The zoom at each sampled pose (1 where the file gives none).
    pub sampled_zoom: Vec<f64>,
    /// The run's frame rate and frame count (its `config.toml` beside the file), if known.
    pub run_frames: Option<(f64, usize)>,
    /// The scene it was made on, where the file records it.
    pub scene: Option<SceneRecord>,
}

/// What a render does with a trajectory made on a scene other than the one given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SceneMismatch {
    /// Refuse it, naming both scenes.
    #[default]
    Refuse,
    /// Render it anyway, with a warning (e.g. over a decimated copy of the scene).
    Allow,
}

impl std::str::FromStr for SceneMismatch {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "refuse" => Ok(Self::Refuse),
            "allow" => Ok(Self::Allow),
            other => Err(format!(
                "unknown scene mismatch {other:?} (refuse or allow)"
            )),
        }
    }
}

impl RunTrajectory {
    /// Reads `path`: a run folder (its `trajectory.json`) or a `trajectory.json`.
    pub fn read(path: &Path) -> Result<Self> {
        let file = if path.is_dir() {
            path.join("trajectory.json")
        } else {
            path.to_path_buf()
        };
        let text = splatraj_scene::input::read_text(&file)
            .with_context(|| format!("cannot read the trajectory {}", file.display()))?;
        Self::parse(&file, &text)
    }

    fn parse(file: &Path, text: &str) -> Result<Self> {
        let record: TrajectoryRecord = serde_json::from_str(text).with_context(|| {
            format!(
                "{} is not a trajectory.json (needs `model` and `weights`)",
                file.display()
            )
        })?;
        let extras: TrajectoryExtras = serde_json::from_str(text).with_context(|| {
            format!("{}: no frame camera (`output_intrinsics`)", file.display())
        })?;
        record
            .validate()
            .with_context(|| format!("{}: keys `model`, `weights`", file.display()))?;
        check_file_camera(file, "output_intrinsics", &extras.output_intrinsics)?;
        if let Some(k) = &extras.intrinsics {
            check_file_camera(file, "intrinsics", k)?;
        }
        if let Some(up) = extras.world_up
            && !(up.iter().all(|v| v.is_finite()) && glam::DVec3::from(up).length() > 1e-9)
        {
            bail!(
                "{}: key `world_up` = {up:?} is not a direction",
                file.display()
            );
        }
        check_windows(file, &record, &extras.windows)?;
        let folder = file.parent().unwrap_or(Path::new("."));
        Ok(Self {
            file: file.to_path_buf(),
            record,
            output_intrinsics: extras.output_intrinsics,
            windows: extras.windows,
            sampled_zoom: extras.poses.iter().map(|p| p.zoom.unwrap_or(1.0)).collect(),
            sampled: extras.poses.into_iter().map(|p| p.pose).collect(),
            run_frames: run_frames(folder),
            scene: extras.scene,
        })
    }

    /// Refuses (or with [`SceneMismatch::Allow`] warns about) rendering this trajectory on
    /// `scene` when the file records another scene, told apart by the Gaussian count (a
    /// moved or converted copy of the scene keeps it). A file without `scene` passes.
    pub fn check_scene(&self, scene: &SceneRecord, policy: SceneMismatch) -> Result<()> {
        let Some(made) = &self.scene else {
            return Ok(());
        };
        if made.gaussians == scene.gaussians {
            return Ok(());
        }
        let problem = format!(
            "{} (key `scene`) was made on the scene {} of {} Gaussians, not on {} of {} \
             Gaussians",
            self.file.display(),
            made.name,
            made.gaussians,
            scene.name,
            scene.gaussians
        );
        match policy {
            SceneMismatch::Refuse => bail!(
                "{problem}: give the trajectory's own scene, or --scene-mismatch allow to \
                 render it anyway"
            ),
            SceneMismatch::Allow => {
                tracing::warn!("{problem}: rendered anyway (--scene-mismatch allow)");
                Ok(())
            }
        }
    }

    /// Whether the model is built in (so it can be evaluated at any time).
    pub fn evaluable(&self) -> bool {
        self.record.model.validate().is_ok()
    }

    /// Φ(t) = Ψ(t)·W on the host at `times` (`None` for a custom model).
    pub fn poses_at(&self, times: &[f64]) -> Option<Vec<[f64; 6]>> {
        if !self.evaluable() {
            return None;
        }
        let k = self.record.model.count();
        Some(
            self.record
                .model
                .matrix(times)
                .chunks_exact(k)
                .map(|row| {
                    let mut pose = [0.0; 6];
                    for (psi, w) in row.iter().zip(&self.record.weights) {
                        for (p, wj) in pose.iter_mut().zip(w) {
                            *p += psi * wj;
                        }
                    }
                    pose
                })
                .collect(),
        )
    }

    /// The frames `request` asks for: fps × seconds evenly spaced times over [0, 1] (by
    /// default the run's own frames: its `output.fps` and frame count), through the run's
    /// frame camera rescaled. A custom model gives the sampled poses instead.
    pub fn frames(&self, request: &FrameRequest) -> Result<PathFrames> {
        request.check()?;
        let fps = request
            .fps
            .or(self.run_frames.map(|r| r.0))
            .unwrap_or(DEFAULT_FPS);
        let count = match (request.seconds, self.run_frames) {
            (Some(s), _) => (fps * s).round().max(1.0),
            (None, Some((_, frames))) => frames as f64,
            (None, None) => (fps * DEFAULT_SECONDS).round().max(1.0),
        };
        // Sized by the options, the run's config and the file's model: checked before the
        // times and the basis matrix (frames × basis functions) are made.
        check_path_frames(
            &format!(
                "the path of {} (`--fps` × `--seconds`, or the run's `output.fps`, \
                 `output.seconds`, `output.frames`; the model's basis functions)",
                self.file.display()
            ),
            count,
            self.record.model.count(),
        )?;
        let count = count as usize;
        let camera = resize(&self.output_intrinsics, request.width, request.height)?;
        let (times, poses, zooms) = match self.poses_at(&uniform_times(count)) {
            Some(poses) => {
                let times = uniform_times(count);
                let zooms = self.record.zooms_at(&times);
                (times, poses, zooms)
            }
            None => {
                tracing::warn!(
                    "model {} is not built in: using the {} poses sampled in {}",
                    self.record.model.name(),
                    self.sampled.len(),
                    self.file.display()
                );
                (
                    uniform_times(self.sampled.len()),
                    self.sampled.clone(),
                    self.sampled_zoom.clone(),
                )
            }
        };
        // The lens over time: each frame's camera zoomed by its s(t).
        let cameras = zooms
            .iter()
            .map(|&s| camera.zoomed(s))
            .collect::<Result<Vec<_>, _>>()
            .with_context(|| format!("{}: key `lens`", self.file.display()))?;
        if poses.is_empty() {
            bail!("{}: no poses", self.file.display());
        }
        // A cut model switches shots between two frames: those frames are its cuts.
        let cuts = frame_cuts(&times, &self.record.model.shots(self.windows.len()));
        PathFrames {
            cameras,
            times,
            poses,
            fps,
            cuts,
        }
        .checked(&self.file)
    }

    /// Refuses a trajectory whose windows are not the `queries` query windows of the config
    /// it is rendered with (its frames would be judged against the wrong objects).
    pub fn check_windows(&self, queries: usize) -> Result<()> {
        let windows = self.windows.len();
        if windows != queries {
            bail!(
                "{} has {windows} query windows but the config has {queries} queries: render it \
                 with the config of its run",
                self.file.display()
            );
        }
        Ok(())
    }

    /// The object centre of each window.
    pub fn object_centres(&self) -> Vec<[f64; 3]> {
        self.windows.iter().map(|w| w.object_centre).collect()
    }
}

/// The frame rate and frame count of the run whose `config.toml` is in `folder`.
fn run_frames(folder: &Path) -> Option<(f64, usize)> {
    let text = splatraj_scene::input::read_text(&folder.join("config.toml")).ok()?;
    let config: toml::Value = toml::from_str(&text).ok()?;
    let output = config.get("output")?;
    let fps = output
        .get("fps")
        .and_then(|v| v.as_float())
        .unwrap_or(DEFAULT_FPS);
    let frames = match output.get("seconds").and_then(|v| v.as_float()) {
        Some(seconds) => (fps * seconds).round() as usize,
        None => usize::try_from(output.get("frames")?.as_integer()?).ok()?,
    };
    (frames > 0).then_some((fps, frames))
}

/// A camera path file: ours or another tool's.
#[derive(Debug, Clone)]
pub enum PathFile {
    /// A run's `trajectory.json` (boxed: it is several times the size of the other).
    Trajectory(Box<RunTrajectory>),
    /// Another tool's camera file.
    Imported {
        /// The file.
        file: PathBuf,
        /// Its format.
        format: Format,
        /// Its frames.
        path: CameraPath,
    },
}

impl PathFile {
    /// Reads a run folder or `trajectory.json`, or a camera file of any format
    /// `splatraj-report` reads (told apart by their contents).
    pub fn read(path: &Path) -> Result<Self> {
        let ours = path.is_dir() || {
            let text = splatraj_scene::input::read_text(path).unwrap_or_default();
            serde_json::from_str::<serde_json::Value>(&text)
                .is_ok_and(|v| v.get("model").is_some() && v.get("weights").is_some())
        };
        if ours {
            return Ok(Self::Trajectory(Box::new(RunTrajectory::read(path)?)));
        }
        let (format, camera_path) = splatraj_camera_paths::read_camera_path(path)?;
        Ok(Self::Imported {
            file: path.to_path_buf(),
            format,
            path: camera_path,
        })
    }

    /// What the file is, in words.
    pub fn describe(&self) -> String {
        match self {
            Self::Trajectory(t) => format!(
                "{} (model {}, {} windows{})",
                t.file.display(),
                t.record.model.name(),
                t.windows.len(),
                shots_note(t.record.model.shots(t.windows.len()).len())
            ),
            Self::Imported { file, format, path } => format!(
                "{} ({format}, {} frames{})",
                file.display(),
                path.frames.len(),
                shots_note(path.cuts.len() + 1)
            ),
        }
    }

    /// The frames to render. Another tool's file keeps its own frames, spread evenly over
    /// t ∈ [0, 1] (as `[start] trajectory` spreads them), at its own frame rate unless
    /// `request.fps` says; `request.seconds` applies to a `trajectory.json` only.
    pub fn frames(&self, request: &FrameRequest) -> Result<PathFrames> {
        match self {
            Self::Trajectory(t) => t.frames(request),
            Self::Imported { file, format, path } => imported_frames(file, *format, path, request),
        }
    }
}

/// `", N shots"` for a path cut into N > 1 shots, else nothing.
fn shots_note(shots: usize) -> String {
    if shots > 1 {
        format!(", {shots} shots")
    } else {
        String::new()
    }
}

fn imported_frames(
    file: &Path,
    format: Format,
    path: &CameraPath,
    request: &FrameRequest,
) -> Result<PathFrames> {
    request.check()?;
    if path.frames.is_empty() {
        bail!("{}: no frames", file.display());
    }
    let cameras = path
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let p = f.camera.with_context(|| {
                format!("{}: frame {i} has no camera intrinsics", file.display())
            })?;
            let k =
                checked_intrinsics(&p).with_context(|| format!("{}: frame {i}", file.display()))?;
            resize(&k, request.width, request.height)
                .with_context(|| format!("{}: frame {i}", file.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let fps = request.fps.or(path.fps).unwrap_or(DEFAULT_FPS);
    // The length the file states is sized like `--seconds`: a path of 10¹⁵ s is a broken
    // file, whatever few frames it lists.
    if let Some(seconds) = path.seconds {
        let key = match format {
            Format::Supersplat => "animTracks[0].duration",
            _ => "seconds",
        };
        check_path_frames(
            &format!("{}: key `{key}` = {seconds} s at {fps} fps", file.display()),
            (seconds * fps).ceil(),
            0,
        )?;
    }
    path.check_cuts()
        .map_err(|p| anyhow!("{}: cuts: {p}", file.display()))?;
    PathFrames {
        times: uniform_times(path.frames.len()),
        poses: path.phis(),
        cameras,
        fps,
        cuts: path.cuts.clone(),
    }
    .checked(file)
}

/// The files of `frames` in `format`. SuperSplat's look-at targets sit at the distance of the
/// object each frame's window shows (`object_centres`, one per window; 1 scene unit without).
pub fn export_files(
    frames: &PathFrames,
    object_centres: &[[f64; 3]],
    format: Format,
) -> Result<Vec<(&'static str, String)>> {
    let focus = if object_centres.is_empty() {
        Focus::Distance(1.0)
    } else {
        Focus::PerFrame(
            frames
                .times
                .iter()
                .zip(&frames.poses)
                .map(|(&t, pose)| {
                    let o = object_centres[window_of(t, object_centres.len())];
                    let d = (0..3).map(|k| (o[k] - pose[3 + k]).powi(2)).sum::<f64>();
                    d.sqrt().max(1e-3)
                })
                .collect(),
        )
    };
    let options = ExportOptions {
        fps: frames.fps,
        focus,
        ..ExportOptions::default()
    };
    Ok(splatraj_camera_paths::export(
        &frames.camera_path(),
        format,
        &options,
    )?)
}

/// Writes `frames` in `format` into `dir` (created if missing), each file whole or not at all;
/// returns the file names.
pub fn write_export(
    dir: &Path,
    frames: &PathFrames,
    object_centres: &[[f64; 3]],
    format: Format,
) -> Result<Vec<&'static str>> {
    let files = export_files(frames, object_centres, format)?;
    write_into_folder(dir, &files)?;
    Ok(files.iter().map(|f| f.0).collect())
}

/// [`write_export`] into the folder `out` as a whole ([`OutputFolder`]): a re-export replaces
/// an earlier one whole, a failure leaves `out` as it was. `out` may hold only an earlier
/// export (any format's files).
pub fn export_to(
    out: &Path,
    frames: &PathFrames,
    object_centres: &[[f64; 3]],
    format: Format,
) -> Result<Vec<&'static str>> {
    let ours: Vec<&str> = Format::ALL
        .iter()
        .chain(&[Format::Transforms])
        .flat_map(|f| f.file_names().iter().copied())
        .collect();
    let folder = OutputFolder::begin(out, &ours)?;
    let names = write_export(folder.path(), frames, object_centres, format)?;
    folder.commit()?;
    Ok(names)
}

/// What `splatraj export` asks for: a run's trajectory in one format.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportRequest {
    /// A run folder (holding `trajectory.json`) or a `trajectory.json`.
    pub input: PathBuf,
    /// The camera file format.
    pub format: Format,
    /// Frame rate, length and size (unset: the run's own).
    pub frames: FrameRequest,
    /// Output folder; `None`: `exports/<format>/` beside `trajectory.json`.
    pub out: Option<PathBuf>,
}

/// What [`export_run`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOutcome {
    /// The folder written.
    pub dir: PathBuf,
    /// The file names written in it.
    pub files: Vec<&'static str>,
    /// The frames exported.
    pub frames: PathFrames,
}

/// Reads a run's trajectory, evaluates it at the requested frames and writes it in the
/// requested format ([`write_export`]): the whole of `splatraj export`.
pub fn export_run(request: &ExportRequest) -> Result<ExportOutcome> {
    let trajectory = RunTrajectory::read(&request.input)?;
    let frames = trajectory.frames(&request.frames)?;
    let dir = match &request.out {
        Some(out) => out.clone(),
        None => trajectory
            .file
            .parent()
            .unwrap_or(Path::new("."))
            .join("exports")
            .join(request.format.name()),
    };
    let files = export_to(&dir, &frames, &trajectory.object_centres(), request.format)?;
    Ok(ExportOutcome { dir, files, frames })
}

/// Writes `frames` in every format into `exports/<format>/` under `run_dir`; a stop
/// requested `since` ends it between two formats ([`splatraj_scene::stop::Stopped`]), each
/// format written being whole.
pub fn write_all_exports(
    run_dir: &Path,
    frames: &PathFrames,
    object_centres: &[[f64; 3]],
    since: splatraj_scene::stop::Since,
) -> Result<()> {
    for (done, format) in Format::ALL.into_iter().enumerate() {
        since.stop_point(|| {
            format!(
                "{done} of {} export formats are written under {}",
                Format::ALL.len(),
                run_dir.join("exports").display()
            )
        })?;
        let dir = run_dir.join("exports").join(format.name());
        write_export(&dir, frames, object_centres, format)
            .with_context(|| format!("exporting {format}"))?;
    }
    Ok(())
}
