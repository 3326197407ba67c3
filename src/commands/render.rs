//! `splatraj render`: one camera, one scene: RGB and object-mask images, optionally the costs
//! and their pose gradient.
//!
//! The camera file is JSON: `{"fx", "fy", "cx", "cy", "width", "height"}` plus exactly one of
//! `"pose"` (Φ = [ω, c], the rotation vector of camera-to-world and the camera centre) or
//! `"world_to_camera"` (4×4, row-major, as nested rows or 16 numbers). The object is a
//! per-Gaussian mask from a `.npy` file or a label of the scene. Every input is checked before
//! anything is rendered or written, and each output file appears whole or not at all.

use std::fs::File;
use std::io::{BufReader, Cursor};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, bail};
use burn::tensor::{DType, Device, Tensor, TensorData};
use clap::{Args, ValueEnum};
use glam::DMat4;
use serde::{Deserialize, Serialize};
use splatraj_render::backend::{BackendKind, Precision};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::render::{Channel, DeviceScene, Pruning, RenderRequest, render};
use splatraj_scene::atomic::write_atomically;
use splatraj_scene::{Scene, read_scene};

use super::scene::ReadArgs;
use splatraj_traj::costs::{DEFAULT_TARGET_RATIO, coverage, tce, tre};

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
}

/// Float precision on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DtypeArg {
    /// 32-bit floats.
    F32,
    /// 64-bit floats (CPU backends).
    F64,
}

impl DtypeArg {
    /// The render precision.
    pub fn precision(self) -> Precision {
        match self {
            DtypeArg::F32 => Precision::F32,
            DtypeArg::F64 => Precision::F64,
        }
    }
}

/// What `render --grad` prints.
#[derive(Debug, Serialize)]
struct GradReport {
    tce: f64,
    tre: f64,
    loss: f64,
    /// d loss / dΦ, Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z].
    grad_pose: Vec<f64>,
    coverage: f64,
    target_ratio: f64,
    repeats: usize,
    /// Median time of mask render + loss (no autodiff).
    forward_ms: f64,
    /// Median time of mask render + loss + backward on the autodiff device.
    forward_backward_ms: f64,
    gaussians: usize,
    width: usize,
    height: usize,
    backend: String,
    dtype: String,
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
    let device = args.backend.device()?;
    let dtype = args.dtype.precision().dtype();
    let camera = read_camera(&args.camera)?;
    let intrinsics = resized(&camera.intrinsics, args.width, args.height)?;
    let loaded = read_scene(&args.scene, &args.read.options())?;
    if loaded.dropped > 0 {
        eprintln!(
            "warning: {}: dropped {} invalid Gaussians",
            args.scene.display(),
            loaded.dropped
        );
    }
    let scene = loaded.scene;
    let mask = match (&args.mask, &args.label) {
        (Some(path), _) => Some(read_mask(path, scene.len())?),
        (None, Some(label)) => Some(label_mask(&scene, label, &args.scene)?),
        (None, None) => None,
    };
    if args.grad && mask.is_none() {
        bail!("--grad needs an object: give --mask MASK.npy or --label NAME");
    }

    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let pose = camera.pose;
    let rgb = render_rgb(&uploaded, &pose, &intrinsics, &device, dtype)?;
    let mut outputs = vec![("rgb.png", encode_png_rgb(&rgb, &intrinsics)?)];
    let mut report = None;
    if let Some(mask) = &mask {
        let request = mask_request(intrinsics, mask.clone(), Pruning::ObjectOnly);
        let image = render_mask(&uploaded, &pose, &request, &device, dtype)?;
        outputs.push(("mask.png", encode_png_gray(&image, &intrinsics)?));
        outputs.push(("mask.npy", encode_npy(&image, &intrinsics)?));
        if args.grad {
            report = Some(grad_report(
                &args, &scene, &uploaded, &pose, &request, &device, dtype,
            )?);
        }
    }

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output folder {}", args.out.display()))?;
    for (name, bytes) in &outputs {
        let path = args.out.join(name);
        write_atomically(&path, |w| w.write_all(bytes))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    eprintln!(
        "wrote {} to {} ({}×{}, {} Gaussians)",
        outputs
            .iter()
            .map(|(n, _)| *n)
            .collect::<Vec<_>>()
            .join(", "),
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

/// A parsed camera file.
#[derive(Debug, Clone, Copy)]
pub struct CameraSpec {
    /// Intrinsics as written in the file.
    pub intrinsics: Intrinsics,
    /// Pose Φ.
    pub pose: Pose,
}

/// The camera file as written; unknown keys are rejected by serde, naming the key.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z]: rotation vector of camera-to-world, camera centre.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<[f64; 6]>,
    /// 4×4 world-to-camera matrix, row-major.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_to_camera: Option<Matrix4>,
}

/// A 4×4 matrix written as four rows or as 16 numbers, row-major.
#[derive(Debug, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Matrix4 {
    /// `[[r0], [r1], [r2], [r3]]`.
    Rows([[f64; 4]; 4]),
    /// 16 numbers, row by row.
    Flat([f64; 16]),
}

impl Matrix4 {
    fn to_dmat4(&self) -> DMat4 {
        let rows = match self {
            Matrix4::Rows(rows) => *rows,
            Matrix4::Flat(flat) => {
                std::array::from_fn(|r| std::array::from_fn(|c| flat[r * 4 + c]))
            }
        };
        // glam is column-major: the rows read as columns give the transpose.
        DMat4::from_cols_array_2d(&rows).transpose()
    }
}

/// Reads and checks a camera JSON file (see the module docs).
pub fn read_camera(path: &Path) -> Result<CameraSpec> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the camera file {}", path.display()))?;
    let file: CameraFile = serde_json::from_str(&text).map_err(|e| {
        // serde names the unknown or missing key and lists the expected ones.
        anyhow!("camera file {}: {e}", path.display())
    })?;
    let intrinsics = Intrinsics::new(file.fx, file.fy, file.cx, file.cy, file.width, file.height)
        .map_err(|e| anyhow!("camera file {}: {e}", path.display()))?;
    let pose = match (&file.pose, &file.world_to_camera) {
        (Some(phi), None) => {
            if let Some(bad) = phi.iter().position(|v| !v.is_finite()) {
                bail!(
                    "camera file {}: key `pose` holds a non-finite value at index {bad}",
                    path.display()
                );
            }
            Pose(*phi)
        }
        (None, Some(m)) => Pose::from_world_to_camera(m.to_dmat4())
            .map_err(|e| anyhow!("camera file {}: key `world_to_camera`: {e}", path.display()))?,
        (Some(_), Some(_)) => bail!(
            "camera file {}: give either key `pose` or key `world_to_camera`, not both",
            path.display()
        ),
        (None, None) => bail!(
            "camera file {}: missing the camera pose: add key `pose` (rotation vector of \
             camera-to-world, then camera centre) or key `world_to_camera` (4×4, row-major)",
            path.display()
        ),
    };
    Ok(CameraSpec { intrinsics, pose })
}

/// The intrinsics at the asked resolution; one side alone keeps the aspect ratio.
fn resized(k: &Intrinsics, width: Option<usize>, height: Option<usize>) -> Result<Intrinsics> {
    let aspect = k.height as f64 / k.width as f64;
    let (w, h) = match (width, height) {
        (None, None) => return Ok(*k),
        (Some(w), Some(h)) => (w, h),
        (Some(w), None) => (w, ((w as f64 * aspect).round() as usize).max(1)),
        (None, Some(h)) => (((h as f64 / aspect).round() as usize).max(1), h),
    };
    if w == 0 || h == 0 {
        bail!("--width and --height must be at least 1 (got {w}×{h})");
    }
    Ok(k.rescaled(w, h)?)
}

/// Reads a per-Gaussian mask from a `.npy` file: uint8, bool, int32/64 or float32/64 values
/// in [0, 1], shape `[N]` or `[N, 1]`.
pub fn read_mask(path: &Path, gaussians: usize) -> Result<Vec<f32>> {
    let context = || format!("mask file {}", path.display());
    let file = File::open(path).with_context(|| format!("cannot open the {}", context()))?;
    let npy = npyz::NpyFile::new(BufReader::new(file))
        .with_context(|| format!("{} is not a readable .npy file", context()))?;
    let shape = npy.shape().to_vec();
    if !(shape.len() == 1 || (shape.len() == 2 && shape[1] == 1)) {
        bail!(
            "{}: shape {shape:?} must be [N] or [N, 1], one value per Gaussian",
            context()
        );
    }
    let dtype = npy.dtype().descr();
    // Each supported dtype in turn: `try_data` hands the file back when the dtype differs.
    let values: Vec<f64> = (|| -> Result<Vec<f64>> {
        let npy = match npy.try_data::<u8>() {
            Ok(data) => return as_f64(data, f64::from),
            Err(npy) => npy,
        };
        let npy = match npy.try_data::<bool>() {
            Ok(data) => return as_f64(data, |b| if b { 1.0 } else { 0.0 }),
            Err(npy) => npy,
        };
        let npy = match npy.try_data::<f32>() {
            Ok(data) => return as_f64(data, f64::from),
            Err(npy) => npy,
        };
        let npy = match npy.try_data::<f64>() {
            Ok(data) => return as_f64(data, |v| v),
            Err(npy) => npy,
        };
        let npy = match npy.try_data::<i64>() {
            Ok(data) => return as_f64(data, |v| v as f64),
            Err(npy) => npy,
        };
        match npy.try_data::<i32>() {
            Ok(data) => as_f64(data, f64::from),
            Err(_) => bail!(
                "dtype {dtype} is not supported (use uint8, bool, int32, int64, float32 or \
                 float64)"
            ),
        }
    })()
    .with_context(context)?;
    if values.len() != gaussians {
        bail!(
            "{}: holds {} values but the scene has {gaussians} Gaussians (one value per Gaussian \
             is needed)",
            context(),
            values.len()
        );
    }
    if let Some(i) = values
        .iter()
        .position(|v| !(v.is_finite() && (0.0..=1.0).contains(v)))
    {
        bail!(
            "{}: value {} at index {i} is not in [0, 1]",
            context(),
            values[i]
        );
    }
    Ok(values.into_iter().map(|v| v as f32).collect())
}

/// All values of an .npy payload, converted to f64.
fn as_f64<T: npyz::Deserialize, R: std::io::Read>(
    data: npyz::NpyReader<T, R>,
    convert: impl Fn(T) -> f64,
) -> Result<Vec<f64>> {
    data.map(|v| v.map(&convert))
        .collect::<std::io::Result<Vec<f64>>>()
        .map_err(Into::into)
}

/// The 0/1 mask of the Gaussians with label `query` (a name, case-insensitive, or an id).
pub fn label_mask(scene: &Scene, query: &str, scene_path: &Path) -> Result<Vec<f32>> {
    let Some(labels) = &scene.extras.labels else {
        bail!(
            "{} has no labels, so --label {query:?} cannot pick an object (give --mask \
             MASK.npy, or a scene with a `label` property)",
            scene_path.display()
        );
    };
    let wanted = query.trim();
    let by_name = labels
        .names
        .iter()
        .find(|(_, name)| name.trim().eq_ignore_ascii_case(wanted))
        .map(|(&id, _)| id);
    let by_id = wanted
        .parse::<i32>()
        .ok()
        .filter(|id| labels.names.contains_key(id) || labels.ids.contains(id));
    let Some(id) = by_name.or(by_id) else {
        let mut available: Vec<String> = labels
            .names
            .iter()
            .map(|(id, name)| format!("{id} {name:?}"))
            .collect();
        if available.is_empty() {
            available = labels.counts().keys().map(|id| id.to_string()).collect();
        }
        bail!(
            "{}: no label matches {query:?}; available: {}",
            scene_path.display(),
            available.join(", ")
        );
    };
    let mask: Vec<f32> = labels
        .ids
        .iter()
        .map(|&l| if l == id { 1.0 } else { 0.0 })
        .collect();
    if !mask.contains(&1.0) {
        bail!(
            "{}: label {query:?} (id {id}) has no Gaussians",
            scene_path.display()
        );
    }
    Ok(mask)
}

/// A one-pose tensor `[1, 6]`.
pub fn pose_tensor(pose: &Pose, device: &Device, dtype: DType) -> Tensor<2> {
    Tensor::from_data(TensorData::new(pose.0.to_vec(), [1, 6]), (device, dtype))
}

/// A mask-only request with the given pruning.
pub fn mask_request(intrinsics: Intrinsics, mask: Vec<f32>, pruning: Pruning) -> RenderRequest {
    let mut request = RenderRequest::new(intrinsics, vec![Channel::Mask(mask)]);
    request.pruning = pruning;
    request
}

/// Host copy of a float tensor.
pub fn host<const D: usize>(t: Tensor<D>) -> Result<Vec<f64>> {
    t.into_data()
        .convert::<f64>()
        .try_to_vec::<f64>()
        .map_err(|e| anyhow!("reading a tensor back: {e:?}"))
}

/// RGB image `[H·W·3]` of one pose, unpruned.
fn render_rgb(
    scene: &DeviceScene,
    pose: &Pose,
    intrinsics: &Intrinsics,
    device: &Device,
    dtype: DType,
) -> Result<Vec<f64>> {
    let request = RenderRequest::new(*intrinsics, vec![Channel::Rgb]);
    let out = render(scene, pose_tensor(pose, device, dtype), &request)?;
    host(out.images)
}

/// Mask image `[H·W]` of one pose.
fn render_mask(
    scene: &DeviceScene,
    pose: &Pose,
    request: &RenderRequest,
    device: &Device,
    dtype: DType,
) -> Result<Vec<f64>> {
    let out = render(scene, pose_tensor(pose, device, dtype), request)?;
    host(out.images)
}

/// TCE and TRE `[B]` of a mask render's images `[B, H, W, 1]`.
pub fn mask_costs(images: Tensor<4>, target_ratio: f64) -> (Tensor<1>, Tensor<1>) {
    let mask = as_mask(images);
    (tce(mask.clone()), tre(mask, target_ratio))
}

/// `[B, H, W, 1]` → `[B, H, W]`.
fn as_mask(images: Tensor<4>) -> Tensor<3> {
    let [b, h, w, _] = images.dims();
    images.reshape([b, h, w])
}

/// Loss values and pose gradient of one forward + backward pass.
#[derive(Debug, Clone)]
pub struct LossAndGradient {
    /// TCE of the pose.
    pub tce: f64,
    /// TRE of the pose.
    pub tre: f64,
    /// d(TCE + TRE)/dΦ.
    pub grad_pose: Vec<f64>,
    /// Share of the frame the mask covers.
    pub coverage: f64,
}

/// Mask render + (TCE + TRE), no gradient; returns the loss (read back, so timing is complete).
pub fn forward_loss(
    scene: &DeviceScene,
    pose: &Pose,
    request: &RenderRequest,
    target_ratio: f64,
    device: &Device,
    dtype: DType,
) -> Result<f64> {
    let out = render(scene, pose_tensor(pose, device, dtype), request)?;
    let (t, r) = mask_costs(out.images, target_ratio);
    Ok(host((t + r).sum())?[0])
}

/// Mask render + (TCE + TRE) + backward on an autodiff device (`scene` uploaded there).
pub fn forward_backward(
    scene: &DeviceScene,
    pose: &Pose,
    request: &RenderRequest,
    target_ratio: f64,
    autodiff: &Device,
    dtype: DType,
) -> Result<LossAndGradient> {
    let poses = pose_tensor(pose, autodiff, dtype).require_grad();
    let out = render(scene, poses.clone(), request)?;
    let cov = coverage(as_mask(out.images.clone()));
    let (t, r) = mask_costs(out.images, target_ratio);
    let grads = (t.clone() + r.clone()).sum().backward();
    let grad_pose = poses
        .grad(&grads)
        .map(host)
        .transpose()?
        // No gradient at all means nothing in the graph depended on the pose.
        .unwrap_or_else(|| vec![0.0; 6]);
    Ok(LossAndGradient {
        tce: host(t)?[0],
        tre: host(r)?[0],
        grad_pose,
        coverage: host(cov)?[0],
    })
}

/// Median of `runs` timings of `f`, in milliseconds.
pub fn median_ms(runs: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    let n = times.len();
    Ok(if n % 2 == 1 {
        times[n / 2]
    } else {
        0.5 * (times[n / 2 - 1] + times[n / 2])
    })
}

fn grad_report(
    args: &RenderArgs,
    scene: &Scene,
    plain_scene: &DeviceScene,
    pose: &Pose,
    request: &RenderRequest,
    device: &Device,
    dtype: DType,
) -> Result<GradReport> {
    let autodiff = device.clone().autodiff();
    let ad_scene = DeviceScene::new(scene, &autodiff, dtype);
    let target = args.target_ratio;
    let result = forward_backward(&ad_scene, pose, request, target, &autodiff, dtype)?;
    let forward_ms = median_ms(args.repeats, || {
        forward_loss(plain_scene, pose, request, target, device, dtype).map(|_| ())
    })?;
    let forward_backward_ms = median_ms(args.repeats, || {
        forward_backward(&ad_scene, pose, request, target, &autodiff, dtype).map(|_| ())
    })?;
    Ok(GradReport {
        tce: result.tce,
        tre: result.tre,
        loss: result.tce + result.tre,
        grad_pose: result.grad_pose,
        coverage: result.coverage,
        target_ratio: target,
        repeats: args.repeats,
        forward_ms,
        forward_backward_ms,
        gaussians: scene.len(),
        width: request.intrinsics.width,
        height: request.intrinsics.height,
        backend: args.backend.to_string(),
        dtype: format!("{:?}", args.dtype).to_lowercase(),
    })
}

fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Colour of the object highlight in pictures (magenta).
pub const HIGHLIGHT_RGB: [f64; 3] = [1.0, 0.2, 0.8];

/// RGB values `[H·W·3]` from an RGB + mask render `[H·W·4]`, the masked pixels tinted with
/// [`HIGHLIGHT_RGB`] in proportion to the mask (`strength` at a full mask).
pub fn highlight(pixels: &[f64], strength: f64) -> Vec<f64> {
    pixels
        .chunks_exact(4)
        .flat_map(|px| {
            let m = strength * px[3].clamp(0.0, 1.0);
            (0..3).map(move |c| px[c].clamp(0.0, 1.0) * (1.0 - m) + m * HIGHLIGHT_RGB[c])
        })
        .collect()
}

/// PNG bytes of RGB values `[H·W·3]` in [0, 1] at the size of `k`.
pub fn encode_png_rgb(rgb: &[f64], k: &Intrinsics) -> Result<Vec<u8>> {
    let pixels: Vec<u8> = rgb.iter().map(|&v| to_u8(v)).collect();
    let image = image::RgbImage::from_raw(k.width as u32, k.height as u32, pixels)
        .ok_or_else(|| anyhow!("RGB render has the wrong size"))?;
    let mut bytes = Cursor::new(Vec::new());
    image.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}

fn encode_png_gray(mask: &[f64], k: &Intrinsics) -> Result<Vec<u8>> {
    let pixels: Vec<u8> = mask.iter().map(|&v| to_u8(v)).collect();
    let image = image::GrayImage::from_raw(k.width as u32, k.height as u32, pixels)
        .ok_or_else(|| anyhow!("mask render has the wrong size"))?;
    let mut bytes = Cursor::new(Vec::new());
    image.write_to(&mut bytes, image::ImageFormat::Png)?;
    Ok(bytes.into_inner())
}

fn encode_npy(mask: &[f64], k: &Intrinsics) -> Result<Vec<u8>> {
    use npyz::WriterBuilder;
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::<f32>::new()
        .default_dtype()
        .shape(&[k.height as u64, k.width as u64])
        .writer(&mut bytes)
        .begin_nd()?;
    writer.extend(mask.iter().map(|&v| v as f32))?;
    writer.finish()?;
    Ok(bytes)
}
