//! One camera, one scene, into a folder (`splatraj render`, one call: the camera file and the
//! scene read, the memory plan checked, the images rendered and written): `rgb.png`, and with an object
//! `mask.png` and `mask.npy`; with a gradient request also TCE + TRE of the mask and their pose
//! gradient ([`MaskProbe`]). Every input is checked and every image rendered before anything is
//! written, and the folder is written whole ([`OutputFolder`]): a re-run replaces an earlier
//! render (no `mask.png` of an earlier object beside a new `rgb.png`), a failure leaves it as
//! it was, and a second writer of the same folder is refused.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use serde::Serialize;
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::Intrinsics;
use splatraj_render::camera_file::resize;
use splatraj_render::host::to_host;
use splatraj_render::images::{png_gray, png_rgb};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render_poses,
};
use splatraj_scene::ReadOptions;
use splatraj_semantic::{label_mask, read_mask_file};

use super::camera_file::read_camera_file;
use crate::optimise::probe::{MaskProbe, ProbeReport};
use crate::outputs::npy_f32;
use crate::outputs::output_folder::OutputFolder;
use crate::prepare::scene_files::read_scene_to_render;
use crate::resources::{MemoryLimit, RenderWork};
use crate::write::write_into_folder;

/// The object whose mask is rendered.
#[derive(Debug, Clone, PartialEq)]
pub enum RenderObject {
    /// A `.npy` file with one value per Gaussian.
    MaskFile(PathBuf),
    /// One of the scene's labels, by name or id.
    Label(String),
}

/// The costs and pose gradient to measure, with the object's mask.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GradRequest {
    /// Target ratio r_t of TRE.
    pub target_ratio: f64,
    /// Timed runs (the median is reported).
    pub repeats: usize,
}

/// What [`render_camera`] renders and where: the files `splatraj render` names, read and
/// checked by it.
#[derive(Debug, Clone)]
pub struct CameraRenderRequest {
    /// The scene file.
    pub scene: PathBuf,
    /// How to read it (labels sidecar, invalid Gaussians).
    pub read: ReadOptions,
    /// The camera file (`splatraj_render::camera_file`: intrinsics and a pose).
    pub camera: PathBuf,
    /// The width to render at (`None`: the camera's; alone, the aspect ratio is kept).
    pub width: Option<usize>,
    /// The height to render at (`None`: the camera's; alone, the aspect ratio is kept).
    pub height: Option<usize>,
    /// The object, if any.
    pub object: Option<RenderObject>,
    /// The costs and gradient to measure (needs an object).
    pub grad: Option<GradRequest>,
    /// The backend to render on.
    pub backend: BackendKind,
    /// Float precision.
    pub precision: Precision,
    /// Compositing.
    pub rasterizer: Rasterizer,
    /// The most memory (GB) the render may plan to use (`None`: the default limit).
    pub max_memory_gb: Option<f64>,
    /// The output folder, written whole: new, or holding only an earlier render
    /// ([`RENDER_NAMES`]).
    pub out: PathBuf,
}

/// What a render folder may hold: the names [`render_camera`] writes.
pub const RENDER_NAMES: [&str; 3] = ["rgb.png", "mask.png", "mask.npy"];

/// The gradient line `splatraj render --grad` prints: the probe's figures and what they were
/// measured on.
#[derive(Debug, Serialize)]
pub struct GradReport {
    /// The costs, the gradient and the timings.
    #[serde(flatten)]
    pub probe: ProbeReport,
    /// Target ratio r_t.
    pub target_ratio: f64,
    /// Timed runs.
    pub repeats: usize,
    /// Gaussians in the scene.
    pub gaussians: usize,
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Backend name.
    pub backend: String,
    /// Precision name (`f32`, `f64`).
    pub dtype: String,
    /// Compositing.
    pub rasterizer: Rasterizer,
}

/// What [`render_camera`] wrote.
#[derive(Debug)]
pub struct CameraRender {
    /// The files written into the output folder, in order.
    pub files: Vec<&'static str>,
    /// The size rendered at.
    pub intrinsics: Intrinsics,
    /// Gaussians in the scene rendered.
    pub gaussians: usize,
    /// The measured costs and gradient, when asked.
    pub grad: Option<GradReport>,
}

/// Reads the camera and the scene `request` names, checks the memory plan, renders and
/// writes the images into `request.out` (files last); `warn` hears what reading the scene
/// dropped.
pub fn render_camera(
    request: &CameraRenderRequest,
    mut warn: impl FnMut(String),
) -> Result<CameraRender> {
    let device = request.backend.device_for(request.precision.dtype())?;
    let camera = read_camera_file(&request.camera)?;
    let intrinsics = resize(&camera.intrinsics, request.width, request.height)?;
    let limit = MemoryLimit::new(request.max_memory_gb)?;
    let loaded = read_scene_to_render(&request.scene, &request.read)?;
    if loaded.dropped > 0 {
        warn(format!(
            "{}: dropped {} invalid Gaussians",
            request.scene.display(),
            loaded.dropped
        ));
    }
    let (scene, scene_path) = (&loaded.scene, request.scene.as_path());
    let dtype = request.precision.dtype();
    let float_bytes = dtype.size();
    let repeats = request.grad.as_ref().map_or(1, |grad| grad.repeats);
    RenderWork {
        what: format!(
            "`--repeats` = {repeats} renders of {} Gaussians at the camera's `width` × `height` \
             (--width, --height)",
            scene.len()
        ),
        renders: repeats as f64,
        at_once: 1,
        size: (intrinsics.width, intrinsics.height),
        gaussians: scene.len(),
        gradient: request.grad.is_some(),
        float_bytes,
    }
    .check(limit, "--max-memory GB")?;
    let mask = match &request.object {
        Some(RenderObject::MaskFile(path)) => Some(read_mask_file(path, scene.len())?),
        Some(RenderObject::Label(label)) => {
            if scene.extras.labels.is_none() {
                bail!(
                    "{} has no labels, so --label {label:?} cannot pick an object (give --mask \
                     MASK.npy, or a scene with a `label` property)",
                    scene_path.display()
                );
            }
            Some(label_mask(scene, label).with_context(|| scene_path.display().to_string())?)
        }
        None => None,
    };
    if request.grad.is_some() && mask.is_none() {
        bail!("--grad needs an object: give --mask MASK.npy or --label NAME");
    }
    // Before the renders: a folder of other files, or one another process writes, is refused.
    let folder = OutputFolder::begin(&request.out, &RENDER_NAMES)?;

    let pose = camera.pose;
    let uploaded = DeviceScene::new(scene, &device, dtype);
    let image = |render_request: RenderRequest| -> Result<Vec<f64>> {
        let render_request = RenderRequest {
            rasterizer: request.rasterizer,
            alpha: AlphaChannel::Dropped,
            ..render_request
        };
        Ok(to_host(
            render_poses(&uploaded, &[pose], &render_request)?.images,
        )?)
    };
    let rgb = image(RenderRequest::new(intrinsics, vec![Channel::Rgb]))?;
    check_finite("the RGB image", &rgb)?;
    let mut outputs = vec![("rgb.png", png_rgb(&rgb, &intrinsics)?)];
    let mut grad = None;
    if let Some(mask) = mask {
        let values = image(RenderRequest {
            pruning: Pruning::ObjectOnly,
            ..RenderRequest::new(intrinsics, vec![Channel::Mask(mask.clone())])
        })?;
        check_finite("the mask image", &values)?;
        outputs.push(("mask.png", png_gray(&values, &intrinsics)?));
        let shape = [intrinsics.height as u64, intrinsics.width as u64];
        outputs.push(("mask.npy", npy_f32(&values, &shape)?));
        if let Some(asked) = request.grad {
            let probe = MaskProbe::new(
                scene,
                (&device, dtype),
                mask,
                asked.target_ratio,
                intrinsics,
                request.rasterizer,
            )?;
            let measured = probe.measure(&pose, asked.repeats)?;
            check_finite("the costs and pose gradient", &measured.values())?;
            grad = Some(GradReport {
                probe: measured,
                target_ratio: asked.target_ratio,
                repeats: asked.repeats,
                gaussians: scene.len(),
                width: intrinsics.width,
                height: intrinsics.height,
                backend: request.backend.to_string(),
                dtype: format!("{:?}", request.precision).to_lowercase(),
                rasterizer: request.rasterizer,
            });
        }
    }
    write_into_folder(folder.path(), &outputs)?;
    folder.commit()?;
    Ok(CameraRender {
        files: outputs.iter().map(|(name, _)| *name).collect(),
        intrinsics,
        gaussians: scene.len(),
        grad,
    })
}

/// A non-finite value must never reach a file: it is an error naming what held it.
fn check_finite(what: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => bail!(
            "{what} holds a non-finite value ({} at index {i}); nothing was written. The \
             camera or the scene's values are out of the range the renderer can handle",
            values[i]
        ),
        None => Ok(()),
    }
}
