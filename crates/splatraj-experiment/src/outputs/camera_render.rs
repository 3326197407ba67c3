//! One camera, one scene, into a folder (`splatraj render`): `rgb.png`, and with an object
//! `mask.png` and `mask.npy`; with a gradient request also TCE + TRE of the mask and their pose
//! gradient ([`MaskProbe`]). Every input is checked and every image rendered before anything is
//! written, and the folder is written whole ([`OutputFolder`]): a re-run replaces an earlier
//! render (no `mask.png` of an earlier object beside a new `rgb.png`), a failure leaves it as
//! it was, and a second writer of the same folder is refused.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use burn::tensor::Device;
use serde::Serialize;
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::images::{png_gray, png_rgb};
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_scene::Scene;
use splatraj_semantic::{label_mask, read_mask_file};

use crate::optimise::probe::{MaskProbe, ProbeReport};
use crate::outputs::npy_f32;
use crate::outputs::output_folder::OutputFolder;
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

/// What [`render_camera`] renders and where.
#[derive(Debug, Clone)]
pub struct CameraRenderRequest {
    /// The camera's pose.
    pub pose: Pose,
    /// The camera, at the size to render.
    pub intrinsics: Intrinsics,
    /// The object, if any.
    pub object: Option<RenderObject>,
    /// The costs and gradient to measure (needs an object).
    pub grad: Option<GradRequest>,
    /// The backend the device belongs to (for the report).
    pub backend: BackendKind,
    /// The device to render on.
    pub device: Device,
    /// Float precision.
    pub precision: Precision,
    /// Compositing.
    pub rasterizer: Rasterizer,
    /// Memory the render may use.
    pub limit: MemoryLimit,
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
    /// The measured costs and gradient, when asked.
    pub grad: Option<GradReport>,
}

/// Renders `scene` (read from `scene_path`, named in messages) as `request` asks and writes the
/// images into `request.out`: the memory plan is checked first, files are written last.
pub fn render_camera(
    scene: &Scene,
    scene_path: &Path,
    request: &CameraRenderRequest,
) -> Result<CameraRender> {
    let intrinsics = request.intrinsics;
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
    .check(request.limit, "--max-memory GB")?;
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

    let pose = request.pose;
    let uploaded = DeviceScene::new(scene, &request.device, dtype);
    let image = |render_request: RenderRequest| -> Result<Vec<f64>> {
        let render_request = RenderRequest {
            rasterizer: request.rasterizer,
            ..render_request
        };
        Ok(to_host(
            render(&uploaded, uploaded.poses(&[pose]), &render_request)?.images,
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
                (&request.device, dtype),
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
