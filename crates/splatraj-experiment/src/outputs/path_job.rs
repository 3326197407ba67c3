//! `splatraj render-path` as one library call: every input read and checked before anything is
//! rendered or written (the camera path, its frames, the scene or the experiment config whose
//! scene and queries give each frame's object), then the frames, video and metrics of
//! [`super::path_render`]. The command only parses its flags into a [`PathJob`] (SCENE as
//! given: [`SceneArgument`]), calls [`render_path_job`] and prints.

use std::path::Path;

use anyhow::{Result, bail};
use burn::tensor::DType;
use splatraj_render::backend::{BackendKind, Hardware};
use splatraj_render::render::{DeviceScene, Rasterizer};
use splatraj_scene::formats::ReadOptions;

use crate::config::{Config, MaskOverlay};
use crate::outputs::camera_paths::{FrameRequest, PathFile, SceneMismatch};
use crate::outputs::path_render::{PathRender, RenderedPath, Video, render_path_to};
use crate::outputs::records::SceneRecord;
use crate::prepare::experiment::Experiment;
use crate::prepare::scene_files::read_scene_to_render;

/// Where `render-path`'s scene comes from.
#[derive(Debug, Clone)]
pub enum PathScene<'a> {
    /// An experiment config: its scene, its queries (each frame's object, for the metrics and
    /// the tint), its backend and rasterizer; `set` overrides its keys.
    Config {
        /// The config file.
        path: &'a Path,
        /// `KEY=VALUE` overrides.
        set: &'a [String],
    },
    /// A scene file, read with `read`, rendered on `backend`; no objects.
    File {
        /// The scene file.
        path: &'a Path,
        /// How to read it (invalid Gaussians, a label sidecar).
        read: ReadOptions,
        /// The tensor backend.
        backend: BackendKind,
    },
}

/// `render-path`'s SCENE as given, with what goes with a config (`set`) or a scene file
/// (`read`, `backend`); [`PathScene::of`] tells which it is.
#[derive(Debug, Clone)]
pub struct SceneArgument<'a> {
    /// A scene file or an experiment config.
    pub path: &'a Path,
    /// `KEY=VALUE` overrides (a config only).
    pub set: &'a [String],
    /// How a scene file is read (invalid Gaussians, a label sidecar).
    pub read: ReadOptions,
    /// The tensor backend of a scene file (a config names its own).
    pub backend: BackendKind,
}

impl<'a> PathScene<'a> {
    /// A config when `path` is a TOML table with `[scene]`, else a scene file: what
    /// `render-path SCENE` means by its first argument. Overrides (`set`) need a config.
    pub fn of(argument: &SceneArgument<'a>) -> Result<Self> {
        let (path, set) = (argument.path, argument.set);
        let is_config = splatraj_scene::input::read_text(path)
            .ok()
            .and_then(|text| toml::from_str::<toml::Table>(&text).ok())
            .is_some_and(|table| table.contains_key("scene"));
        if is_config {
            return Ok(PathScene::Config { path, set });
        }
        if !set.is_empty() {
            bail!(
                "{}: overrides (--set) need an experiment config as SCENE, not a scene file",
                path.display()
            );
        }
        Ok(PathScene::File {
            path,
            read: argument.read.clone(),
            backend: argument.backend,
        })
    }
}

/// Everything `render-path` is asked for.
#[derive(Debug, Clone)]
pub struct PathJob<'a> {
    /// The scene, or the config whose scene it is, as given.
    pub scene: SceneArgument<'a>,
    /// The camera path file (a run folder, `trajectory.json` or another tool's file).
    pub path: &'a Path,
    /// Frame rate, length and size asked for.
    pub frames: FrameRequest,
    /// Whether each frame's object is tinted (needs a config).
    pub overlay: MaskOverlay,
    /// The compositing; None: the config's, else fused.
    pub rasterizer: Option<Rasterizer>,
    /// What to do with a `trajectory.json` made on another scene.
    pub scene_mismatch: SceneMismatch,
    /// Whether to make `video.mp4`.
    pub video: Video,
}

/// What is about to be rendered, told once before the first frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PathPlan {
    /// The path file in words.
    pub description: String,
    /// Frames to render.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Frame size in pixels.
    pub width: usize,
    /// Frame size in pixels.
    pub height: usize,
    /// Invalid Gaussians dropped from a scene file (under `InvalidPolicy::Drop`).
    pub dropped: usize,
    /// What the frames are rendered on.
    pub hardware: Hardware,
}

/// Reads and checks `job`'s inputs, tells `plan` what will be rendered, then renders the frames
/// (telling `progress` each one done) into `out`, written whole.
pub fn render_path_job(
    job: &PathJob<'_>,
    out: &Path,
    plan: &mut dyn FnMut(&PathPlan),
    progress: &mut dyn FnMut(usize),
) -> Result<RenderedPath> {
    let scene = PathScene::of(&job.scene)?;
    if let PathScene::File { path: scene, .. } = &scene
        && job.overlay == MaskOverlay::Tint
    {
        bail!(
            "--mask-overlay tint needs the objects to tint: give an experiment config (TOML) \
             with its queries as SCENE instead of {}",
            scene.display()
        );
    }
    let path = PathFile::read(job.path)?;
    let frames = path.frames(&job.frames)?;
    // The experiment outlives the objects borrowed from it.
    let mut experiment = None;
    let (scene, objects, rasterizer, dropped) = match &scene {
        PathScene::Config { path: config, set } => {
            let e: &Experiment =
                experiment.insert(Experiment::prepare(&Config::load(config, set)?)?);
            if let PathFile::Trajectory(t) = &path {
                t.check_windows(e.windows.len())?;
                t.check_scene(&SceneRecord::of(e), job.scene_mismatch)?;
            }
            (
                e.plain_scene(),
                e.path_objects(),
                job.rasterizer.unwrap_or(e.config.rasterizer),
                0,
            )
        }
        PathScene::File {
            path: file,
            read,
            backend,
        } => {
            let loaded = read_scene_to_render(file, read)?;
            if let PathFile::Trajectory(t) = &path {
                let given = SceneRecord {
                    name: file.display().to_string(),
                    gaussians: loaded.scene.len(),
                };
                t.check_scene(&given, job.scene_mismatch)?;
            }
            (
                DeviceScene::new(&loaded.scene, &backend.device()?, DType::F32),
                Vec::new(),
                job.rasterizer.unwrap_or_default(),
                loaded.dropped,
            )
        }
    };
    plan(&PathPlan {
        description: path.describe(),
        frames: frames.poses.len(),
        fps: frames.fps,
        width: frames.cameras[0].width,
        height: frames.cameras[0].height,
        dropped,
        hardware: Hardware::of(&scene.geometry.means.device()),
    });
    let render = PathRender {
        frames: &frames,
        objects,
        overlay: job.overlay,
        rasterizer,
        video: job.video,
    };
    render_path_to(&scene, &render, out, progress)
}
