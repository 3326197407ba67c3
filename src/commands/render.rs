//! `splatraj render`: one camera, one scene: RGB and object-mask images, optionally the costs
//! and their pose gradient.
//!
//! The camera file is JSON (schema: `splatraj_render::camera_file`): `{"fx", "fy", "cx", "cy",
//! "width", "height"}` plus exactly one of `"pose"` (Φ = [ω, c]) or `"world_to_camera"` (4×4,
//! row-major). The object is a per-Gaussian mask from a `.npy` file or a label of the scene.
//! Every input is checked before anything is rendered or written, and the output folder
//! (`--out`, `render/` by default) is written whole: a re-run replaces it, a failure leaves it
//! as it was. `--grad` computes TCE + TRE through the optimiser's loss path.
//! The work is the library's ([`splatraj::experiment::outputs::camera_render`]: one call that
//! reads the camera and the scene, checks, renders and writes); this file checks the options,
//! calls it and prints.

use std::path::PathBuf;
use std::str::FromStr;

use anyhow::{Result, bail};
use clap::Args;
use splatraj::experiment::outputs::camera_render::{
    CameraRenderRequest, GradRequest, RenderObject, render_camera,
};
use splatraj_render::backend::BackendKind;
use splatraj_render::render::Rasterizer;
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
    /// Output folder for rgb.png, mask.png and mask.npy, written whole: a new folder, or one
    /// holding only an earlier render (replaced); other files in it are refused.
    #[arg(long, default_value = "render")]
    out: PathBuf,
    #[command(flatten)]
    memory: MemoryArgs,
}

/// Runs `splatraj render`.
pub fn run(args: RenderArgs) -> Result<()> {
    // Cheap checks first, then every input, then the renders; files are written last.
    if !(args.target_ratio > 0.0 && args.target_ratio <= 1.0) {
        bail!(
            "--target-ratio {} must be a share of the frame in (0, 1]",
            args.target_ratio
        );
    }
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    if args.width == Some(0) || args.height == Some(0) {
        bail!("--width and --height must be at least 1");
    }
    let request = CameraRenderRequest {
        scene: args.scene,
        read: args.read.options(),
        camera: args.camera,
        width: args.width,
        height: args.height,
        object: match (args.mask, args.label) {
            (Some(path), _) => Some(RenderObject::MaskFile(path)),
            (None, Some(label)) => Some(RenderObject::Label(label)),
            (None, None) => None,
        },
        grad: args.grad.then_some(GradRequest {
            target_ratio: args.target_ratio,
            repeats: args.repeats,
        }),
        backend: args.backend,
        precision: args.dtype.precision(),
        rasterizer: args.rasterizer,
        max_memory_gb: args.memory.max_memory,
        out: args.out,
    };
    let rendered = render_camera(&request, |warning| eprintln!("warning: {warning}"))?;
    eprintln!(
        "wrote {} to {} ({}×{}, {} Gaussians)",
        rendered.files.join(", "),
        request.out.display(),
        rendered.intrinsics.width,
        rendered.intrinsics.height,
        rendered.gaussians
    );
    if let Some(report) = rendered.grad {
        println!("{}", serde_json::to_string(&report)?);
    }
    Ok(())
}
