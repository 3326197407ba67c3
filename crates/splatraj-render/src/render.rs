//! A render request: which channels, for which batch of poses, with how much pruning.
//!
//! Only the work a request asks for is done: SH is evaluated only when RGB is asked for, and a
//! mask pass with [`Pruning::ObjectOnly`] visits only the tiles the object touches and the
//! Gaussians in front of its last one there (exact: same image and gradient).

use std::sync::Arc;

use burn::tensor::{DType, Device, Tensor, TensorData};
use rayon::prelude::*;
use splatraj_scene::Scene;

use crate::camera::{Intrinsics, Pose};
use crate::decide::{HostGeometry, decide_zoomed};
use crate::focus::{ObjectFocus, PoseFocus, Surroundings};
use crate::fused::colours::colours_of_rows;
use crate::fused::projection::{
    PackedColumn, ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS, project_packed_zoomed,
};
use crate::fused::{CompositePlan, composite_packed};
use crate::host::{OnDevice, to_host, upload};
use crate::pass_size::{PassBuffer, first_oversized, max_poses};
use crate::project::{NEAR_PLANE, SceneTensors, project_zoomed};
pub use crate::rasterize::AlphaChannel;
use crate::rasterize::{
    Approximations, CompositeOptions, Composited, RenderStats, SplatInputs, composite,
};
use crate::rows::{LaidOutRows, PoseRows, lay_out_rows};
use crate::sh::{ShTensors, sh_colours_of_rows};
use crate::stages::{self, Stage};
use crate::tiles::{TileGrid, TileSelection, bin_tiles};

/// One channel of a render.
#[derive(Debug, Clone)]
pub enum Channel {
    /// Colour from SH at the scene's degree, view dependent (3 values).
    Rgb,
    /// Camera depth z, composited (1 value; divide by alpha for the expected depth).
    Depth,
    /// A per-Gaussian 0/1 (or fractional) mask, one value per Gaussian (1 value).
    Mask(Vec<f32>),
    /// Several objects' masks in one pass (1 value): each pose composites its own object's
    /// mask, drawn in the scene or alone ([`ObjectMasks`]).
    ObjectMasks(ObjectMasks),
    /// Per-Gaussian feature vectors, flat `[N, dim]` (dim values).
    Features {
        /// Length of each vector.
        dim: usize,
        /// Flat values.
        values: Vec<f32>,
    },
}

impl Channel {
    /// Number of image channels this produces.
    pub fn width(&self) -> usize {
        match self {
            Channel::Rgb => 3,
            Channel::Depth | Channel::Mask(_) | Channel::ObjectMasks(_) => 1,
            Channel::Features { dim, .. } => *dim,
        }
    }
}

/// The masks of several objects and which one each pose of the batch renders: how every
/// window of an optimisation step (and each window's object alone) shares one pass, so the
/// launches of a step do not grow with the number of windows (docs/gpu.md).
#[derive(Debug, Clone)]
pub struct ObjectMasks {
    /// One value per Gaussian for each object, shared: a step's request is cloned each pass
    /// with only its views changed, and the masks are `M·N` values. `[M][N]`
    pub masks: Arc<[Vec<f32>]>,
    /// Per pose of the batch, its object and what it draws around it. `[B]`
    pub views: Vec<ObjectView>,
}

/// One pose's object in an [`ObjectMasks`] pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectView {
    /// Index into [`ObjectMasks::masks`].
    pub object: usize,
    /// The scene around the object (pruned to what can cover it when the request prunes), or
    /// nothing (the object alone, always pruned to it).
    pub surroundings: Surroundings,
}

/// Which tiles and Gaussians a pass visits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pruning {
    /// Every tile and every Gaussian touching it.
    #[default]
    None,
    /// For a single-mask pass (one [`Channel::Mask`], or one [`Channel::ObjectMasks`] with
    /// each pose's own object): only what can change that mask (exact for the mask channel).
    ObjectOnly,
}

/// Which implementation composites the tiles; both follow the same rules (docs/conventions.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rasterizer {
    /// One burn operation with a hand-written forward and backward (fast; the default).
    #[default]
    Fused,
    /// Chunked burn tensor ops: the readable specification and the yardstick of the tests.
    Tensor,
}

impl std::str::FromStr for Rasterizer {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fused" => Ok(Rasterizer::Fused),
            "tensor" => Ok(Rasterizer::Tensor),
            other => Err(format!(
                "unknown rasterizer `{other}`: expected `fused` or `tensor`"
            )),
        }
    }
}

/// What to render.
#[derive(Debug, Clone)]
pub struct RenderRequest {
    /// Camera intrinsics (and so the resolution).
    pub intrinsics: Intrinsics,
    /// Channels, stacked in this order in the output.
    pub channels: Vec<Channel>,
    /// Tile/Gaussian pruning.
    pub pruning: Pruning,
    /// Near plane (camera z); Gaussians at or behind it are culled.
    pub near: f64,
    /// How the tensor path chunks compositing (does not change the result).
    pub composite: CompositeOptions,
    /// Which compositing implementation runs.
    pub rasterizer: Rasterizer,
    /// Shortcuts that trade accuracy for time (default: none, the exact rendering).
    pub approximations: Approximations,
    /// Per-Gaussian channel values as a tensor `[N, C]` on the scene's device, composited after
    /// `channels`; unlike [`Channel::Features`] the render is differentiable in it (the route
    /// of [`crate::lift`]).
    pub gaussian_values: Option<Tensor<2>>,
    /// A zoom per pose (focal lengths fx·s, fy·s about the fixed principal point); the render
    /// is differentiable in it. `None`: s = 1 for every pose.
    pub zoom: Option<Zoom>,
    /// Whether the render returns alpha beside the channels (default: returned). Passes that
    /// never read it drop it: on a GPU that saves launches and an image-sized buffer a pass.
    pub alpha: AlphaChannel,
}

/// A zoom s_b > 0 per pose: the tensor `[B]` the render is differentiable in, and optionally
/// its values on the host (as [`render_at`]'s host poses: the pass then reads nothing back).
#[derive(Debug, Clone)]
pub struct Zoom {
    /// s per pose, on the poses' device. `[B]`
    pub values: Tensor<1>,
    /// The same values on the host; `None` reads them back for the host decisions.
    pub host: Option<Vec<f64>>,
}

impl Zoom {
    /// A zoom whose values the render reads back when it needs them on the host.
    pub fn new(values: Tensor<1>) -> Self {
        Zoom { values, host: None }
    }

    /// A zoom whose values are already on the host (`host`: the values of `values`, in order).
    pub fn at(values: Tensor<1>, host: Vec<f64>) -> Self {
        Zoom {
            values,
            host: Some(host),
        }
    }
}

impl RenderRequest {
    /// A request with default near plane, no pruning and default chunking.
    pub fn new(intrinsics: Intrinsics, channels: Vec<Channel>) -> Self {
        RenderRequest {
            intrinsics,
            channels,
            pruning: Pruning::None,
            near: NEAR_PLANE,
            composite: CompositeOptions::default(),
            rasterizer: Rasterizer::default(),
            approximations: Approximations::default(),
            gaussian_values: None,
            zoom: None,
            alpha: AlphaChannel::Returned,
        }
    }
}

/// A problem with a render request.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// A per-Gaussian channel does not have one value (or vector) per Gaussian.
    #[error("channel {index} has {got} values for {gaussians} Gaussians")]
    ChannelLength {
        /// Position of the channel in the request.
        index: usize,
        /// Values given.
        got: usize,
        /// Gaussians in the scene.
        gaussians: usize,
    },
    /// Object-only pruning needs exactly one mask channel.
    #[error("pruning to the object needs exactly one channel, a mask")]
    PruningNeedsOneMask,
    /// A request has more than one [`Channel::ObjectMasks`] (each says what its poses draw).
    #[error("a render takes at most one object-masks channel, got {got}")]
    ManyObjectMasks {
        /// Object-masks channels in the request.
        got: usize,
    },
    /// An [`ObjectMasks`] channel does not give one view per pose, or names a missing object.
    #[error("object-masks channel: {reason}")]
    ObjectViews {
        /// What is wrong.
        reason: String,
    },
    /// The request has no channel.
    #[error("a render needs at least one channel")]
    NoChannel,
    /// A channel has no values per Gaussian.
    #[error("channel {index} has width 0")]
    ZeroWidth {
        /// Position of the channel in the request (`channels.len()` for `gaussian_values`).
        index: usize,
    },
    /// Lifting got a pixel buffer whose length is not `B·H·W·dim`.
    #[error("lifting needs B·H·W·dim = {expected} pixel values, got {got}")]
    PixelCount {
        /// Values given.
        got: usize,
        /// Values the poses, intrinsics and dim call for.
        expected: usize,
    },
    /// Lifting got a NaN or infinite pixel value (it would poison every Gaussian of its tile).
    #[error("pixel value {index} is not finite")]
    NonFinitePixel {
        /// Position in the flat pixel buffer.
        index: usize,
    },
    /// Lifting takes a gradient, which needs the scene on an autodiff device.
    #[error("lifting needs the scene on an autodiff device (`device.autodiff()`)")]
    NeedsAutodiff,
    /// Poses or a gradient could not be read back to the host.
    #[error("reading back to the host: {0}")]
    ReadBack(String),
    /// The host poses given to [`render_at`] are not one per pose of the tensor.
    #[error("{host} host poses for a batch of {tensor} poses")]
    PoseCount {
        /// Poses in the tensor.
        tensor: usize,
        /// Host poses given.
        host: usize,
    },
    /// A buffer of the pass (or of the scene) is larger than the device's largest buffer.
    #[error(
        "{what} take {mb:.0} MB in one buffer, more than this device's largest buffer ({max_mb:.0} \
         MB): render with the CPU backend (`backend = \"flex\"`) or on a device with larger \
         buffers",
        mb = *bytes as f64 / 1e6,
        max_mb = *max as f64 / 1e6
    )]
    BufferTooLarge {
        /// What the buffer holds.
        what: String,
        /// Its size, bytes.
        bytes: u64,
        /// The device's largest buffer, bytes.
        max: u64,
    },
    /// More poses in one pass than the device's launch grids hold ([`max_poses`]).
    #[error(
        "a render pass of {batch} poses: a pass on this device holds at most {max}; render them \
         in passes (`pass_size::passes` with `pass_size::poses_per_pass`)"
    )]
    TooManyPoses {
        /// Poses in the pass.
        batch: usize,
        /// The most a pass may hold.
        max: usize,
    },
    /// Alpha was read from a render whose request dropped it ([`RenderRequest::alpha`]).
    #[error("the render's request dropped alpha (`RenderRequest::alpha`)")]
    AlphaDropped,
    /// The zoom (tensor or host values) is not one value per pose.
    #[error("{got} zoom values for a batch of {batch} poses")]
    ZoomCount {
        /// Poses in the batch.
        batch: usize,
        /// Zoom values given.
        got: usize,
    },
    /// A zoom value is not a finite positive number.
    #[error("zoom {index} is {value}: a zoom must be finite and > 0")]
    BadZoom {
        /// Pose whose zoom it is.
        index: usize,
        /// The value.
        value: f64,
    },
}

/// A scene uploaded to a device, ready to render many times.
#[derive(Debug, Clone)]
pub struct DeviceScene {
    /// Pose-independent geometry.
    pub geometry: SceneTensors,
    /// SH coefficients (uploaded once, used only by RGB passes).
    pub sh: ShTensors,
    /// Host copy of the geometry for the per-pass decisions (shared between clones).
    pub host: Arc<HostGeometry>,
}

impl DeviceScene {
    /// Uploads `scene` to `device` in `dtype`.
    pub fn new(scene: &Scene, device: &Device, dtype: DType) -> Self {
        let floats = scene.len() * (3 + 9 + 1) + scene.sh.len();
        crate::counters::scene_upload(floats * dtype.size());
        DeviceScene {
            geometry: SceneTensors::new(scene, None, device, dtype),
            sh: ShTensors::new(scene, None, device, dtype),
            host: Arc::new(HostGeometry::new(scene)),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.geometry.len()
    }

    /// True for a scene without Gaussians.
    pub fn is_empty(&self) -> bool {
        self.geometry.is_empty()
    }
}

impl OnDevice for DeviceScene {
    fn device(&self) -> Device {
        self.geometry.means.device()
    }

    fn dtype(&self) -> DType {
        self.geometry.means.dtype()
    }
}

/// The device buffers a pass of `batch` poses over `u` Gaussians laid out in `rows` with
/// `pairs` tile–Gaussian pairs and `width` channel values a pixel needs (the slots of the
/// backward when `gradient`; the tensor projection's `[B, U]` outputs with `rasterizer`'s
/// tensor path), and the scene's largest ones, each in one buffer.
fn pass_buffers(
    scene: &DeviceScene,
    (batch, u, rows): (usize, usize, &PoseRows),
    rasterizer: Rasterizer,
    pairs: usize,
    (grid, width): (&TileGrid, usize),
    gradient: bool,
) -> Vec<PassBuffer> {
    let float = scene.dtype().size() as u64;
    let n = scene.len();
    let r = rows.total();
    let buffer = |what: String, values: usize, bytes: u64| PassBuffer {
        what,
        bytes: values as u64 * bytes,
    };
    let mut buffers = vec![
        buffer(
            format!("the scene's SH coefficients ({n} Gaussians)"),
            scene.sh.coeffs.shape().num_elements(),
            float,
        ),
        buffer(
            format!("the scene's means and covariance components ({n} Gaussians)"),
            scene.geometry.components.shape().num_elements(),
            float,
        ),
        buffer(
            format!("a pass's packed rows ({r} pose–Gaussian rows × {SPLAT_COLUMNS} values)"),
            r * SPLAT_COLUMNS,
            float,
        ),
        buffer(
            format!("a pass's channel values ({r} pose–Gaussian rows × {width})"),
            r * width,
            float,
        ),
        buffer(
            format!(
                "a pass's images ({batch} poses × {}×{} pixels × {} values)",
                grid.width,
                grid.height,
                width + 1
            ),
            batch * grid.width * grid.height * (width + 1),
            float,
        ),
        buffer(format!("a pass's tile lists ({pairs} pairs)"), pairs, 4),
    ];
    if rasterizer == Rasterizer::Tensor {
        buffers.push(buffer(
            format!("the tensor projection's outputs ({batch} poses × {u} Gaussians × 7 values)"),
            batch * u * SPLAT_COLUMNS,
            float,
        ));
    }
    if gradient {
        buffers.push(buffer(
            format!(
                "a pass's gradient slots ({pairs} pairs × {} values)",
                width + 6
            ),
            pairs * (width + 6),
            float,
        ));
    }
    buffers
}

/// Renders the requested channels for every pose in `poses` `[B, 6]` (Φ = ω, c).
///
/// Differentiable in `poses` when they live on an autodiff device. Returns images
/// `[B, H, W, C]` (channels in request order) and alpha `[B, H, W]`. The host decisions read
/// the poses back (on a GPU, a wait for the device); [`render_at`] takes them from the caller.
pub fn render(
    scene: &DeviceScene,
    poses: Tensor<2>,
    request: &RenderRequest,
) -> Result<Composited, RenderError> {
    render_at(scene, poses, None, request)
}

/// [`render`] of poses given on the host: uploaded, and the pass's host decisions take them
/// as the device holds them ([`crate::host::as_stored`]), so it reads nothing back (no wait
/// for the device before its decisions on a GPU). Not differentiable in the poses.
pub fn render_poses(
    scene: &DeviceScene,
    poses: &[Pose],
    request: &RenderRequest,
) -> Result<Composited, RenderError> {
    let dtype = scene.dtype();
    let stored = crate::host::as_stored(poses, dtype);
    render_at(scene, scene.poses(poses), stored.as_deref(), request)
}

/// [`render`] with the values of `poses` already on the host (`host_poses`, the same values
/// in the same order, e.g. read once per optimisation step for every pass of the step): the
/// pass then reads nothing back. `None` reads them. A zoom's host values come the same way
/// ([`Zoom::at`]).
pub fn render_at(
    scene: &DeviceScene,
    poses: Tensor<2>,
    host_poses: Option<&[Pose]>,
    request: &RenderRequest,
) -> Result<Composited, RenderError> {
    let n = scene.len();
    let [batch, _] = poses.dims();
    let device = poses.device();
    let dtype = scene.geometry.means.dtype();
    if request.channels.is_empty() && request.gaussian_values.is_none() {
        return Err(RenderError::NoChannel);
    }
    if let Some(max) = max_poses(&device).filter(|&max| batch > max) {
        return Err(RenderError::TooManyPoses { batch, max });
    }
    for (index, channel) in request.channels.iter().enumerate() {
        if channel.width() == 0 {
            return Err(RenderError::ZeroWidth { index });
        }
        let got = match channel {
            Channel::Mask(values) => values.len(),
            Channel::ObjectMasks(objects) => objects
                .masks
                .iter()
                .map(Vec::len)
                .find(|&len| len != n)
                .unwrap_or(n),
            Channel::Features { dim, values } => values.len() / (*dim).max(1),
            Channel::Rgb | Channel::Depth => n,
        };
        if got != n {
            return Err(RenderError::ChannelLength {
                index,
                got,
                gaussians: n,
            });
        }
    }
    let tensor_width = match &request.gaussian_values {
        Some(values) => {
            let [rows, width] = values.dims();
            let index = request.channels.len();
            if width == 0 {
                return Err(RenderError::ZeroWidth { index });
            }
            if rows != n {
                return Err(RenderError::ChannelLength {
                    index,
                    got: rows,
                    gaussians: n,
                });
            }
            width
        }
        None => 0,
    };
    let started = std::time::Instant::now();
    let counted = crate::counters::snapshot();
    crate::counters::render();
    let focus = pose_focus(scene, request, batch)?;
    // Decisions (cull, tiles, order, pruning) on all Gaussians without gradient, then the
    // differentiable pass on only the Gaussians some tile uses.
    let grid = TileGrid::new(request.intrinsics.width, request.intrinsics.height);
    let host_poses: Vec<Pose> = match host_poses {
        Some(given) => given.to_vec(),
        None => to_host(poses.clone().without_autodiff())
            .map_err(|e| RenderError::ReadBack(e.to_string()))?
            .chunks_exact(6)
            .map(|p| Pose([p[0], p[1], p[2], p[3], p[4], p[5]]))
            .collect(),
    };
    if host_poses.len() != batch {
        return Err(RenderError::PoseCount {
            tensor: batch,
            host: host_poses.len(),
        });
    }
    let host_zoom: Option<Vec<f64>> = match &request.zoom {
        None => None,
        Some(zoom) => {
            let [got] = zoom.values.dims();
            if got != batch {
                return Err(RenderError::ZoomCount { batch, got });
            }
            let host = match &zoom.host {
                Some(given) => given.clone(),
                None => to_host(zoom.values.clone().without_autodiff())
                    .map_err(|e| RenderError::ReadBack(e.to_string()))?,
            };
            if host.len() != batch {
                return Err(RenderError::ZoomCount {
                    batch,
                    got: host.len(),
                });
            }
            if let Some((index, &value)) = host
                .iter()
                .enumerate()
                .find(|(_, s)| !(s.is_finite() && **s > 0.0))
            {
                return Err(RenderError::BadZoom { index, value });
            }
            Some(host)
        }
    };
    // The zoom in the poses' float type (the kernels and the tensor ops mix the two).
    let zoom: Option<Tensor<1>> = request.zoom.as_ref().map(|zoom| {
        let values = zoom.values.clone();
        if values.dtype() == poses.dtype() {
            values
        } else {
            values.cast(poses.dtype())
        }
    });
    // Each pose's decisions (cull, radii, tiles) through its own zoomed intrinsics.
    let pose_focus: Vec<Option<PoseFocus>> = focus.iter().map(PoseObject::focus).collect();
    let mut decisions = decide_zoomed(
        &scene.host,
        &host_poses,
        host_zoom.as_deref(),
        &request.intrinsics,
        request.near,
        &pose_focus,
    );
    let min_opacity = request.approximations.min_opacity as f32;
    if min_opacity > 0.0 {
        for kept in &mut decisions.kept {
            kept.retain(|decided| scene.host.opacities[decided.gaussian as usize] >= min_opacity);
        }
    }
    let decided = started.elapsed();
    let selection: Vec<TileSelection> = pose_focus
        .iter()
        .map(|focus| match focus {
            Some(focus) => TileSelection::Object(&focus.object.scene),
            None => TileSelection::All,
        })
        .collect();
    let mut work = bin_tiles(&decisions, &grid, &selection);
    let binned = started.elapsed();

    // Each pose's rows: only the Gaussians its own lists read, in increasing scene index
    // (crate::rows); the lists now name rows of their pose. Bit sets, not [N] arrays:
    // O(N / 64) a pose beside the lists' length.
    let LaidOutRows {
        rows,
        scene_of_row,
        used,
    } = lay_out_rows(&mut work, batch, n);
    let u = used.count();
    // The projection's plan holds the scene index of each row's Gaussian `[R]`, which the
    // channel values read too (shared, not copied).
    let plan = Arc::new(ProjectionPlan::new(
        scene_of_row,
        rows.clone(),
        ProjectionCamera::new(&request.intrinsics, request.near),
    ));
    let scene_of_row = &plan.gaussians;
    let pairs: usize = work.iter().map(|list| list.gaussians.len()).sum();
    crate::counters::composite(pairs, rows.total());
    let width: usize = request.channels.iter().map(Channel::width).sum::<usize>() + tensor_width;
    let gradient = poses.is_require_grad();
    let buffers = || {
        let layout = (batch, u, &rows);
        pass_buffers(
            scene,
            layout,
            request.rasterizer,
            pairs,
            (&grid, width),
            gradient,
        )
    };
    if let Some((buffer, max)) = first_oversized(&device, buffers) {
        return Err(RenderError::BufferTooLarge {
            what: buffer.what,
            bytes: buffer.bytes,
            max,
        });
    }
    if u == 0 {
        // Nothing to draw: zeros that still hang off the pose graph, so a gradient exists (0).
        let mut zero = poses.sum().mul_scalar(0.0);
        if let Some(zoom) = &zoom {
            zero = zero + zoom.clone().sum().mul_scalar(0.0);
        }
        let images = Tensor::<4>::zeros([batch, grid.height, grid.width, width], (&device, dtype));
        let alpha = Tensor::<3>::zeros([batch, grid.height, grid.width], (&device, dtype));
        return Ok(Composited::from_parts(
            images + zero.clone().reshape([1, 1, 1, 1]),
            alpha + zero.reshape([1, 1, 1]),
            RenderStats::default(),
        )
        .keeping(request.alpha));
    }
    // Index tensors `[R]`, uploaded once and only when a select needs them: each row's scene
    // index (per-Gaussian tensors and the tensor path's SH colours select with it) and its
    // pose (each row's camera centre for the tensor path's SH colours).
    let index_tensor = |values: Vec<i64>| {
        let len = values.len();
        crate::host::upload_ints(values, [len], &device)
    };
    let scene_index = std::cell::OnceCell::new();
    let scene_index = || {
        scene_index
            .get_or_init(|| index_tensor(scene_of_row.iter().map(|&g| g as i64).collect()))
            .clone()
    };
    let pose_of_row = || {
        let poses = (0..batch).flat_map(|b| std::iter::repeat_n(b as i64, rows.count(b)));
        index_tensor(poses.collect())
    };
    // Screen space: the fused projection's packed rows, or the tensor projection's outputs.
    let splats = match request.rasterizer {
        Rasterizer::Fused => {
            let packed = project_packed_zoomed(&scene.geometry, poses.clone(), zoom, plan.clone()); // [R, 7]
            Splats::Packed(Box::new(packed))
        }
        Rasterizer::Tensor => {
            // The tensor projection of every used Gaussian from every pose `[B, U]`, then the
            // rows each pose reads (flat index b·U + u, u the Gaussian's rank among the used).
            let compact_from_scene = used.ranks();
            let index: Vec<i64> = (0..batch)
                .flat_map(|b| {
                    let own = &scene_of_row[rows.start(b)..rows.start(b) + rows.count(b)];
                    let compact_from_scene = &compact_from_scene;
                    own.iter().map(move |&g| {
                        (b * u) as i64 + i64::from(compact_from_scene.rank(g as usize))
                    })
                })
                .collect();
            let flat = index_tensor(index);
            let compact: Vec<i64> = used.iter().map(|g| g as i64).collect();
            let geometry = scene.geometry.select(index_tensor(compact));
            let projected = project_zoomed(
                &geometry,
                poses.clone(),
                zoom,
                &request.intrinsics,
                request.near,
            );
            let per_row = |t: Tensor<3>| {
                let [_, _, width] = t.dims();
                t.reshape([batch * u, width]).select(0, flat.clone())
            };
            let depth = per_row(projected.depth.clone().unsqueeze_dim::<3>(2)); // [R, 1]
            let opacities = geometry
                .opacities
                .unsqueeze_dim::<2>(0)
                .repeat_dim(0, batch)
                .reshape([batch * u])
                .select(0, flat.clone());
            let splats = SplatInputs {
                means_2d: per_row(projected.means_2d),
                conics: per_row(projected.conics),
                opacities,
                values: depth, // the depth (`Splats::depth`) until the channel values replace it
            };
            Splats::Separate(Box::new(splats))
        }
    };

    let upload_rows = |dim: usize, values: Vec<f32>| {
        upload::<2>(TensorData::new(values, [rows.total(), dim]), &device, dtype)
    };
    let mut values = Vec::with_capacity(request.channels.len());
    for channel in &request.channels {
        values.push(match channel {
            // The fused colours: one launch, where the tensor path's ~20 ops each pass over
            // `[R, K, 3]` values (a frame of a million degree-3 Gaussians: most of its time).
            Channel::Rgb if request.rasterizer == Rasterizer::Fused => {
                colours_of_rows(&scene.geometry, &scene.sh, poses.clone(), plan.clone())
            }
            Channel::Rgb => {
                let index = scene_index();
                let sh = ShTensors {
                    degree: scene.sh.degree,
                    coeffs: scene.sh.coeffs.clone().select(0, index.clone()),
                };
                let means = scene.geometry.means.clone().select(0, index);
                let centres = poses.clone().narrow(1, 3, 3).select(0, pose_of_row());
                sh_colours_of_rows(&sh, means, centres)
            }
            Channel::Depth => splats.depth(),
            Channel::Mask(mask) => upload_rows(
                1,
                per_row_values(&rows, scene_of_row, 1, &|_, g| {
                    std::slice::from_ref(&mask[g])
                }),
            ),
            Channel::ObjectMasks(objects) => upload_rows(
                1,
                per_row_values(&rows, scene_of_row, 1, &|b, g| {
                    std::slice::from_ref(&objects.masks[objects.views[b].object][g])
                }),
            ),
            Channel::Features { dim, values } => upload_rows(
                *dim,
                per_row_values(&rows, scene_of_row, *dim, &|_, g| {
                    &values[g * dim..(g + 1) * dim]
                }),
            ),
        });
    }
    if let Some(tensor) = &request.gaussian_values {
        // A differentiable select: the gradient of each row reaches the caller's [N, C].
        let tensor = if tensor.dtype() == dtype {
            tensor.clone()
        } else {
            tensor.clone().cast(dtype)
        };
        values.push(tensor.select(0, scene_index())); // [R, C]
    }
    // One channel as it is: a concatenation of one tensor is still a copy (a GPU launch).
    let values = match values.len() {
        1 => values.remove(0),
        _ => Tensor::cat(values, 1),
    }; // [R, width]
    let prepared = started.elapsed();
    let stop_transmittance = request.approximations.stop_transmittance;
    let mut composited = match splats {
        Splats::Packed(packed) => composite_packed(
            *packed,
            values,
            CompositePlan::new(&work, &rows, grid)
                .with_stop_transmittance(stop_transmittance)
                .with_alpha(request.alpha),
        ),
        Splats::Separate(splats) => composite(
            &SplatInputs { values, ..*splats },
            &work,
            &rows,
            &grid,
            CompositeOptions {
                stop_transmittance,
                ..request.composite
            },
        )
        .keeping(request.alpha),
    };
    composited.stats.gaussians_used = u;
    let composited_at = started.elapsed();
    for (stage, elapsed) in [
        (Stage::Decide, decided),
        (Stage::Bin, binned - decided),
        (Stage::Project, prepared - binned),
        (Stage::Composite, composited_at - prepared),
    ] {
        stages::add(stage, elapsed);
    }
    // Stage times of the forward graph (backends may defer work, so they are indicative), and
    // what the forward moved and launched.
    let counts = crate::counters::snapshot().since(&counted);
    tracing::debug!(
        launches = counts.launches,
        reads = counts.reads,
        bytes_up = counts.bytes_up,
        decide_ms = decided.as_secs_f64() * 1e3,
        bin_ms = (binned - decided).as_secs_f64() * 1e3,
        project_ms = (prepared - binned).as_secs_f64() * 1e3,
        composite_ms = (composited_at - prepared).as_secs_f64() * 1e3,
        gaussians_used = u,
        tiles = work.len(),
        pairs = composited.stats.pairs,
        // A GPU composites a tile in one workgroup, entry after entry: the longest list, not
        // the pairs, may set a kernel's time (docs/gpu.md, "Open").
        longest_list = work.iter().map(|w| w.gaussians.len()).max().unwrap_or(0),
        "render"
    );
    Ok(composited)
}

/// A pose's object in a pass that prunes to it or draws it alone.
#[derive(Clone)]
struct PoseObject {
    object: Arc<ObjectFocus>,
    surroundings: Surroundings,
}

impl PoseObject {
    fn focus(pose: &Option<PoseObject>) -> Option<PoseFocus<'_>> {
        pose.as_ref().map(|p| PoseFocus {
            object: &p.object,
            surroundings: p.surroundings,
        })
    }
}

/// Each pose's object (None: the whole frame), from the request's pruning and its masks;
/// the objects' foci come from the scene's cache, each built once.
fn pose_focus(
    scene: &DeviceScene,
    request: &RenderRequest,
    batch: usize,
) -> Result<Vec<Option<PoseObject>>, RenderError> {
    let focus_of = |mask: &[f32]| scene.host.focus.focus(&scene.host.scene_from_sorted, mask);
    let object_masks: Vec<&ObjectMasks> = request
        .channels
        .iter()
        .filter_map(|c| match c {
            Channel::ObjectMasks(m) => Some(m),
            _ => None,
        })
        .collect();
    if let [_, _, ..] = object_masks.as_slice() {
        return Err(RenderError::ManyObjectMasks {
            got: object_masks.len(),
        });
    }
    let pruned = request.pruning == Pruning::ObjectOnly;
    if pruned {
        let one_mask = matches!(
            request.channels.as_slice(),
            [Channel::Mask(_) | Channel::ObjectMasks(_)]
        );
        if !one_mask || request.gaussian_values.is_some() {
            return Err(RenderError::PruningNeedsOneMask);
        }
    }
    if let Some(objects) = object_masks.first() {
        if objects.views.len() != batch {
            return Err(RenderError::ObjectViews {
                reason: format!("{} views for a batch of {batch} poses", objects.views.len()),
            });
        }
        if let Some(view) = objects
            .views
            .iter()
            .find(|v| v.object >= objects.masks.len())
        {
            return Err(RenderError::ObjectViews {
                reason: format!(
                    "a view names object {}, but there are {} masks",
                    view.object,
                    objects.masks.len()
                ),
            });
        }
        let mut foci: Vec<Option<Arc<ObjectFocus>>> = vec![None; objects.masks.len()];
        return Ok(objects
            .views
            .iter()
            .map(|view| {
                let drawn_alone = view.surroundings == Surroundings::Nothing;
                (pruned || drawn_alone).then(|| PoseObject {
                    object: Arc::clone(
                        foci[view.object]
                            .get_or_insert_with(|| focus_of(&objects.masks[view.object])),
                    ),
                    surroundings: view.surroundings,
                })
            })
            .collect());
    }
    let object = match request.channels.as_slice() {
        [Channel::Mask(mask)] if pruned => Some(PoseObject {
            object: focus_of(mask),
            surroundings: Surroundings::Scene,
        }),
        _ => None,
    };
    Ok(vec![object; batch])
}

/// A pass's Gaussians in screen space, as its rasterizer takes them.
enum Splats {
    /// The fused projection's rows `[R, 7]`.
    Packed(Box<Tensor<2>>),
    /// The tensor projection's outputs per row (their values still to be set).
    Separate(Box<SplatInputs>),
}

impl Splats {
    /// Each row's depth `[R, 1]`. Cut out of the packed rows only when a depth channel asks:
    /// on a GPU a slice is a launch even when nothing reads it.
    fn depth(&self) -> Tensor<2> {
        match self {
            Splats::Packed(packed) => (**packed)
                .clone()
                .narrow(1, PackedColumn::Depth as usize, 1),
            // The values stand in for the channels until these are set: the depth.
            Splats::Separate(splats) => splats.values.clone(),
        }
    }
}

/// A constant channel per row, made on the host: `value(pose, scene index)` of every row of
/// `rows` (`scene_of_row` `[R]`), `dim` values each. `[R · dim]`
fn per_row_values<'a>(
    rows: &PoseRows,
    scene_of_row: &[u32],
    dim: usize,
    value: &(dyn Fn(usize, usize) -> &'a [f32] + Sync),
) -> Vec<f32> {
    // Poses in parallel, each into its own part, and within a pose chunks of rows: a step's
    // half a million rows, made before every pass, sit mostly in a few wide shots' poses, and
    // a pose a task left one core with them (first-try guitar: 1.6 ms on two threads for
    // 2.3 ms of work).
    const ROWS_PER_TASK: usize = 4096;
    let mut values = vec![0.0; rows.total() * dim];
    let lengths = (0..rows.batch()).map(|b| rows.count(b) * dim);
    let parts = crate::rows::parts_mut(&mut values, lengths);
    parts.into_par_iter().enumerate().for_each(|(b, part)| {
        let own = &scene_of_row[rows.start(b)..rows.start(b) + rows.count(b)];
        part.par_chunks_mut(ROWS_PER_TASK * dim.max(1))
            .zip(own.par_chunks(ROWS_PER_TASK))
            .for_each(|(part, own)| {
                for (out, &g) in part.chunks_exact_mut(dim).zip(own) {
                    out.copy_from_slice(value(b, g as usize));
                }
            });
    });
    values
}
