//! `splatraj render`: one camera, one scene: RGB and object-mask images, optionally the costs
//! and their pose gradient.
//!
//! The camera file is JSON (schema: `splatraj_render::camera_file`): `{"fx", "fy", "cx", "cy",
//! "width", "height"}` plus exactly one of `"pose"` (Φ = [ω, c]) or `"world_to_camera"` (4×4,
//! row-major). The object is a per-Gaussian mask from a `.npy` file or a label of the scene.
//! Every input is checked before anything is rendered or written, and each output file
//! appears whole or not at all. `--grad` computes TCE + TRE through the optimiser's loss path.

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;
use splatraj::experiment::io::read_camera_file;
use splatraj::experiment::outputs::{npy_f32, write_bytes};
use splatraj::experiment::probe::{MaskProbe, ProbeReport};
use splatraj::experiment::resources::{MemoryLimit, RenderWork};
use splatraj_render::backend::BackendKind;
use splatraj_render::camera_file::resize;
use splatraj_render::host::{OnDevice, to_host};
use splatraj_render::images::{png_gray, png_rgb};
use splatraj_render::render::{Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render};
use splatraj_semantic::{label_mask, read_mask_file};
use splatraj_traj::costs::DEFAULT_TARGET_RATIO;

use crate::cli::{DtypeArg, MemoryArgs, ReadArgs};

/// Arguments of `splatraj render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Scene file (INRIA PLY, compressed PLY or SPZ).
    #[arg(long)]
    scene: PathBuf,
    #[command(flatten)]
    read: ReadArgs,
    /// Camera JSON: fx, fy, cx, cy, width, height and either `pose` or `world_to_camera`.
    #[arg(long)]
    camera: PathBuf,
    /// Object mask: a .npy array with one value (0/1, uint8, bool or float) per Gaussian.
    #[arg(long, conflicts_with = "label")]
    mask: Option<PathBuf>,
    /// Object as one of the scene's labels: a name (case-insensitive) or a numeric id.
    #[arg(long)]
    label: Option<String>,
    /// Render width in pixels (rescales the intrinsics; alone, keeps the aspect ratio).
    #[arg(long)]
    width: Option<usize>,
    /// Render height in pixels (rescales the intrinsics; alone, keeps the aspect ratio).
    #[arg(long)]
    height: Option<usize>,
    /// Tensor backend: flex (CPU, default), ndarray or wgpu, among those compiled in.
    #[arg(long, default_value = "flex", value_parser = BackendKind::from_str)]
    backend: BackendKind,
    /// Float precision of the render.
    #[arg(long, value_enum, default_value_t = DtypeArg::F32)]
    dtype: DtypeArg,
    /// Compositing: fused (one op with its own backward, default) or tensor (the reference).
    #[arg(long, default_value = "fused", value_parser = Rasterizer::from_str)]
    rasterizer: Rasterizer,
    /// Also compute TCE + TRE of the mask and its gradient with respect to the pose, and print
    /// them as one JSON object on stdout.
    #[arg(long)]
    grad: bool,
    /// Target ratio r_t of TRE (share of the frame the object should cover).
    #[arg(long, default_value_t = DEFAULT_TARGET_RATIO)]
    target_ratio: f64,
    /// With --grad: time this many runs and report the median.
    #[arg(long, default_value_t = 1)]
    repeats: usize,
    /// Output folder for rgb.png, mask.png and mask.npy (created if missing).
    #[arg(long, default_value = ".")]
    out: PathBuf,
    #[command(flatten)]
    memory: MemoryArgs,
}

/// What `render --grad` prints.
/// The `--grad` line: the probe's figures and what they were measured on.
#[derive(Debug, Serialize)]
struct GradReport {
    #[serde(flatten)]
    probe: ProbeReport,
    target_ratio: f64,
    repeats: usize,
    gaussians: usize,
    width: usize,
    height: usize,
    backend: String,
    dtype: String,
    rasterizer: Rasterizer,
}

/// Runs `splatraj render`.
pub fn run(args: RenderArgs) -> Result<()> {
    // Cheap checks first, then every input, then the renders; files are written last.
    if !(args.target_ratio.is_finite() && (0.0..=1.0).contains(&args.target_ratio)) {
        bail!(
            "--target-ratio {} must be a share of the frame in [0, 1]",
            args.target_ratio
        );
    }
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    if args.width == Some(0) || args.height == Some(0) {
        bail!("--width and --height must be at least 1");
    }
    let device = args.backend.device()?;
    let dtype = args.dtype.precision().dtype();
    let camera = read_camera_file(&args.camera)?;
    let intrinsics = resize(&camera.intrinsics, args.width, args.height)?;
    let limit = MemoryLimit::new(args.memory.max_memory)?;
    let scene = args.read.load_to_render(&args.scene)?.scene;
    RenderWork {
        what: format!(
            "`--repeats` = {} renders of {} Gaussians at the camera's `width` × `height` \
             (--width, --height)",
            args.repeats,
            scene.len()
        ),
        renders: args.repeats as f64,
        at_once: 1,
        size: (intrinsics.width, intrinsics.height),
        gaussians: scene.len(),
        gradient: args.grad,
        float_bytes: dtype.size(),
    }
    .check(limit, "--max-memory GB")?;
    let mask = match (&args.mask, &args.label) {
        (Some(path), _) => Some(read_mask_file(path, scene.len())?),
        (None, Some(label)) => {
            if scene.extras.labels.is_none() {
                bail!(
                    "{} has no labels, so --label {label:?} cannot pick an object (give --mask \
                     MASK.npy, or a scene with a `label` property)",
                    args.scene.display()
                );
            }
            Some(label_mask(&scene, label).with_context(|| args.scene.display().to_string())?)
        }
        (None, None) => None,
    };
    if args.grad && mask.is_none() {
        bail!("--grad needs an object: give --mask MASK.npy or --label NAME");
    }

    let pose = camera.pose;
    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let image = |request: RenderRequest| -> Result<Vec<f64>> {
        let request = RenderRequest {
            rasterizer: args.rasterizer,
            ..request
        };
        Ok(to_host(
            render(&uploaded, uploaded.poses(&[pose]), &request)?.images,
        )?)
    };
    let rgb = image(RenderRequest::new(intrinsics, vec![Channel::Rgb]))?;
    check_finite("the RGB image", &rgb)?;
    let mut outputs = vec![("rgb.png", png_rgb(&rgb, &intrinsics)?)];
    let mut report = None;
    if let Some(mask) = mask {
        let values = image(RenderRequest {
            pruning: Pruning::ObjectOnly,
            ..RenderRequest::new(intrinsics, vec![Channel::Mask(mask.clone())])
        })?;
        check_finite("the mask image", &values)?;
        outputs.push(("mask.png", png_gray(&values, &intrinsics)?));
        let shape = [intrinsics.height as u64, intrinsics.width as u64];
        outputs.push(("mask.npy", npy_f32(&values, &shape)?));
        if args.grad {
            let probe = MaskProbe::new(
                &scene,
                (&device, dtype),
                mask,
                args.target_ratio,
                intrinsics,
                args.rasterizer,
            )?;
            let measured = probe.measure(&pose, args.repeats)?;
            check_finite("the costs and pose gradient", &measured.values())?;
            report = Some(GradReport {
                probe: measured,
                target_ratio: args.target_ratio,
                repeats: args.repeats,
                gaussians: scene.len(),
                width: intrinsics.width,
                height: intrinsics.height,
                backend: args.backend.to_string(),
                dtype: format!("{:?}", args.dtype).to_lowercase(),
                rasterizer: args.rasterizer,
            });
        }
    }

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    for (name, bytes) in &outputs {
        write_bytes(&args.out.join(name), bytes)?;
    }
    let names: Vec<&str> = outputs.iter().map(|(n, _)| *n).collect();
    eprintln!(
        "wrote {} to {} ({}×{}, {} Gaussians)",
        names.join(", "),
        args.out.display(),
        intrinsics.width,
        intrinsics.height,
        scene.len()
    );
    if let Some(report) = report {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
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
