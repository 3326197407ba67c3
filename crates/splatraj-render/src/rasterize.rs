//! Tile compositing as differentiable burn tensor ops.
//!
//! Input: screen-space Gaussians of a batch of poses (a row per pose and Gaussian, `[R, …]`), per-row
//! channel values, and the host-side tile lists of [`crate::tiles`]. Each tile's list is
//! processed in depth chunks of at most `chunk` Gaussians, carrying each pixel's
//! transmittance and stop state from chunk to chunk, so that long lists are exact and memory
//! stays bounded. Tiles are processed in groups of similar list length to limit padding.
//!
//! The rules are INRIA's (docs/conventions.md): α = min(0.99, o·exp(power)), skipped when α < 1/255
//! (power is clamped at 0: for the positive-definite conics that survive culling it can only
//! exceed 0 by rounding); a pixel stops before the Gaussian that would bring T below 1e-4. The
//! skip and stop decisions carry no gradient; the gradient flows through α of the Gaussians
//! that are kept, and through the channel values.

use burn::tensor::{Tensor, TensorData};
use splatraj_config::ConfigError;

use crate::host::{upload, upload_ints};
use crate::rows::PoseRows;
use crate::tiles::{TILE_PIXELS, TILE_SIZE, TileGrid, TileWork};

pub use crate::composite_rules::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};

/// Screen-space Gaussians of a batch, one row per (pose, Gaussian), pose after pose as a
/// [`PoseRows`] lays them out.
#[derive(Debug, Clone)]
pub struct SplatInputs {
    /// Pixel coordinates of the means. `[R, 2]`
    pub means_2d: Tensor<2>,
    /// Inverse 2D covariances (a, b, c) of [[a, b], [b, c]]. `[R, 3]`
    pub conics: Tensor<2>,
    /// Opacities. `[R]`
    pub opacities: Tensor<1>,
    /// Channel values to composite (mask, colour, depth, features). `[R, C]`
    pub values: Tensor<2>,
}

/// How the tensor path cuts the compositing into pieces (the result does not depend on
/// `chunk` and `tile_group`), and its stopping rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompositeOptions {
    /// Gaussians per depth chunk (the K of `[tiles, 256, K]`).
    pub chunk: usize,
    /// Tiles processed together.
    pub tile_group: usize,
    /// A pixel stops before T would fall below this ([`MIN_TRANSMITTANCE`] is the exact rule).
    pub stop_transmittance: f64,
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions {
            chunk: 128,
            tile_group: 16,
            stop_transmittance: MIN_TRANSMITTANCE,
        }
    }
}

/// Rendering shortcuts that trade accuracy for time; the default is the exact rendering.
///
/// Both change images and gradients, so they are meant for optimisation passes only (output
/// frames and metrics stay exact). They are measured by `splatraj study`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Approximations {
    /// A pixel stops before T would fall below this; larger values stop pixels earlier (exact:
    /// [`MIN_TRANSMITTANCE`] = 1e-4).
    pub stop_transmittance: f64,
    /// Gaussians with a lower opacity are left out of the pass altogether (exact: 0, none).
    pub min_opacity: f64,
}

impl Default for Approximations {
    fn default() -> Self {
        Approximations {
            stop_transmittance: MIN_TRANSMITTANCE,
            min_opacity: 0.0,
        }
    }
}

impl Approximations {
    /// Whether these are the exact rules.
    pub fn is_exact(&self) -> bool {
        *self == Approximations::default()
    }

    /// Checks the values: `stop_transmittance` in [1e-4, 1), `min_opacity` in [0, 1); an error
    /// names the key within the approximations' table.
    pub fn check(&self) -> Result<(), ConfigError> {
        if !(MIN_TRANSMITTANCE..1.0).contains(&self.stop_transmittance) {
            return Err(ConfigError::new(
                "stop_transmittance",
                format!(
                    "= {} must lie in [{MIN_TRANSMITTANCE}, 1) ({MIN_TRANSMITTANCE} is exact)",
                    self.stop_transmittance
                ),
            ));
        }
        if !(0.0..1.0).contains(&self.min_opacity) {
            return Err(ConfigError::new(
                "min_opacity",
                format!("= {} must lie in [0, 1) (0 is exact)", self.min_opacity),
            ));
        }
        Ok(())
    }
}

/// Whether a render returns its accumulated opacity (alpha) beside its channel images.
///
/// Most passes (the optimisation's, the metrics', the frames') never read it. On a GPU a
/// packed image `[B, H, W, C + 1]` must be cut to give the channels alone, and the cut's
/// backward fills a zero gradient of the whole packed image and copies the channels' into it:
/// three launches and an image-sized buffer a pass, for a value nobody reads (docs/gpu.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum AlphaChannel {
    /// Alpha is returned ([`Composited::alpha`] is `Some`).
    #[default]
    Returned,
    /// Only the channel images are made.
    Dropped,
}

impl AlphaChannel {
    /// Values per pixel of a compositing output with `channels` channel values.
    pub fn image_width(self, channels: usize) -> usize {
        match self {
            AlphaChannel::Returned => channels + 1,
            AlphaChannel::Dropped => channels,
        }
    }
}

/// Rendered images of a batch.
#[derive(Debug, Clone)]
pub struct Composited {
    /// Channel images. `[B, H, W, C]`
    pub images: Tensor<4>,
    /// The accumulated opacity, read with [`Composited::alpha`].
    alpha: Alpha,
    /// How much work the pass had (the same for both rasterizers).
    pub stats: RenderStats,
}

/// Where a render's accumulated opacity is. It is cut out of the packed image only when read:
/// on a GPU every queued cut is a launch whether anything reads it or not.
#[derive(Debug, Clone)]
enum Alpha {
    /// The last channel of the packed image. `[B, H, W, C + 1]`
    Packed(Tensor<4>),
    /// On its own. `[B, H, W]`
    Alone(Tensor<3>),
    /// Not made ([`AlphaChannel::Dropped`]).
    Dropped,
}

impl Composited {
    /// The render in a packed image `[B, H, W, C + 1]`: the channels, then alpha.
    pub(crate) fn from_packed(packed: Tensor<4>, stats: RenderStats) -> Self {
        let channels = packed.dims()[3] - 1;
        Composited {
            images: packed.clone().narrow(3, 0, channels),
            alpha: Alpha::Packed(packed),
            stats,
        }
    }

    /// A render whose images `[B, H, W, C]` and alpha `[B, H, W]` are apart.
    pub(crate) fn from_parts(images: Tensor<4>, alpha: Tensor<3>, stats: RenderStats) -> Self {
        Composited {
            images,
            alpha: Alpha::Alone(alpha),
            stats,
        }
    }

    /// A render of channel images `[B, H, W, C]` alone ([`AlphaChannel::Dropped`]).
    pub(crate) fn without_alpha(images: Tensor<4>, stats: RenderStats) -> Self {
        Composited {
            images,
            alpha: Alpha::Dropped,
            stats,
        }
    }

    /// This render, keeping its alpha only where `alpha` asks for it.
    pub(crate) fn keeping(self, alpha: AlphaChannel) -> Self {
        match alpha {
            AlphaChannel::Returned => self,
            AlphaChannel::Dropped => Composited {
                alpha: Alpha::Dropped,
                ..self
            },
        }
    }

    /// This render's alpha and work with other channel images `[B, H, W, C']`.
    #[cfg_attr(not(feature = "wgpu"), allow(dead_code))] // channel groups: GPU only
    pub(crate) fn with_images(self, images: Tensor<4>) -> Self {
        Composited { images, ..self }
    }

    /// Accumulated opacity 1 − T_final `[B, H, W]`; `None` where the render was asked to drop
    /// it ([`AlphaChannel::Dropped`]).
    pub fn alpha(&self) -> Option<Tensor<3>> {
        match &self.alpha {
            Alpha::Packed(packed) => {
                let [batch, height, width, channels] = packed.dims();
                Some(
                    packed
                        .clone()
                        .narrow(3, channels - 1, 1)
                        .reshape([batch, height, width]),
                )
            }
            Alpha::Alone(alpha) => Some(alpha.clone()),
            Alpha::Dropped => None,
        }
    }
}

/// Size of a render's compositing work, for benchmarks (ns per pixel–Gaussian pair).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderStats {
    /// (pose, tile) pairs with a non-empty list.
    pub tiles: usize,
    /// Tile–Gaussian pairs over the batch (sum of list lengths); × 256 gives pixel–Gaussian pairs.
    pub pairs: usize,
    /// Distinct Gaussians some tile uses (a render's count; the composite functions alone,
    /// which see only rows, give the most rows one pose has).
    pub gaussians_used: usize,
}

/// Composites `work` (from [`crate::tiles::bin_tiles`]) into full images.
///
/// The inputs hold one row per (pose, Gaussian) as `rows` lays them out; a list entry of pose
/// b names row `rows.start(b) + entry`. Tiles absent from `work` render as zero.
pub fn composite(
    inputs: &SplatInputs,
    work: &[TileWork],
    rows: &PoseRows,
    grid: &TileGrid,
    options: CompositeOptions,
) -> Composited {
    let batch = rows.batch();
    let device = inputs.means_2d.device();
    let dtype = inputs.means_2d.dtype();
    let channels = inputs.values.dims()[1];
    let padded = pad_with_transparent_row(inputs);
    let dummy = rows.total() as i64;

    // Longest lists first, so that a group's lists have similar lengths.
    let mut order: Vec<usize> = (0..work.len()).collect();
    order.sort_by_key(|&w| std::cmp::Reverse(work[w].gaussians.len()));

    // [work, 256, C + 1]: channels, then alpha, in `order`.
    let mut pieces = Vec::new();
    for group in order.chunks(options.tile_group.max(1)) {
        pieces.push(composite_group(
            &padded, work, group, grid, rows, dummy, options, channels,
        ));
    }
    // One zero tile for every (pose, tile) that has no work.
    let empty = Tensor::<3>::zeros([1, TILE_PIXELS, channels + 1], (&device, dtype));
    pieces.push(empty);
    let tiles = Tensor::cat(pieces, 0); // [work + 1, 256, C + 1]

    let mut slot_from_tile = vec![work.len() as i64; batch * grid.len()];
    for (slot, &w) in order.iter().enumerate() {
        slot_from_tile[work[w].batch * grid.len() + work[w].tile] = slot as i64;
    }
    let index = upload_ints(slot_from_tile, [batch * grid.len()], &device);
    let full = tiles.select(0, index); // [B · tiles, 256, C + 1]
    let image = full
        .reshape([
            batch,
            grid.tiles_y,
            grid.tiles_x,
            TILE_SIZE,
            TILE_SIZE,
            channels + 1,
        ])
        .swap_dims(2, 3) // [B, ty, 16, tx, 16, C + 1]
        .reshape([
            batch,
            grid.tiles_y * TILE_SIZE,
            grid.tiles_x * TILE_SIZE,
            channels + 1,
        ])
        .narrow(1, 0, grid.height)
        .narrow(2, 0, grid.width);
    let stats = RenderStats {
        tiles: work.len(),
        pairs: work.iter().map(|w| w.gaussians.len()).sum(),
        gaussians_used: rows.largest(),
    };
    Composited::from_packed(image, stats)
}

/// The inputs with one extra, fully transparent row at index R, which padding points to.
fn pad_with_transparent_row(inputs: &SplatInputs) -> SplatInputs {
    let zero_row =
        |t: &Tensor<2>| Tensor::cat(vec![t.clone(), t.clone().narrow(0, 0, 1).zeros_like()], 0);
    let padded_opacity = {
        let o = inputs.opacities.clone();
        let zero = o.clone().narrow(0, 0, 1).zeros_like();
        Tensor::cat(vec![o, zero], 0)
    };
    SplatInputs {
        means_2d: zero_row(&inputs.means_2d),
        conics: zero_row(&inputs.conics),
        opacities: padded_opacity,
        values: zero_row(&inputs.values),
    }
}

/// Composites one group of tiles over all their depth chunks. Returns `[group, 256, C + 1]`.
///
/// Depth chunks start small and double up to `options.chunk`: most pixels of opaque surfaces
/// stop within the first few dozen Gaussians, and a tile leaves the group as soon as all its
/// pixels stopped or its list ended, so that long lists cost only where pixels stay open.
#[allow(clippy::too_many_arguments)] // one internal call site; a struct would only rename them
fn composite_group(
    inputs: &SplatInputs,
    work: &[TileWork],
    group: &[usize],
    grid: &TileGrid,
    rows: &PoseRows,
    dummy: i64,
    options: CompositeOptions,
    channels: usize,
) -> Tensor<3> {
    let device = inputs.means_2d.device();
    let dtype = inputs.means_2d.dtype();
    let pixels = pixel_features(&device, dtype); // [1, 256, 6]

    // Rows of the running state belong to the group positions in `active`.
    let mut active: Vec<usize> = (0..group.len()).collect();
    let mut accumulated =
        Tensor::<3>::zeros([group.len(), TILE_PIXELS, channels], (&device, dtype));
    let mut log_t = Tensor::<2>::zeros([group.len(), TILE_PIXELS], (&device, dtype)); // ln T before the chunk
    let mut stopped = Tensor::<2>::zeros([group.len(), TILE_PIXELS], (&device, dtype)); // 1 once stopped
    let mut finished: Vec<(Vec<usize>, Tensor<3>)> = Vec::new();

    let mut start = 0;
    let mut chunk = FIRST_CHUNK.min(options.chunk.max(1));
    while !active.is_empty() {
        let tiles = active.len();
        let longest = active
            .iter()
            .map(|&p| work[group[p]].gaussians.len())
            .max()
            .unwrap_or(0);
        let k = chunk.min(longest.saturating_sub(start)).max(1);
        let mut index = Vec::with_capacity(tiles * k);
        let mut centres = Vec::with_capacity(2 * tiles);
        for &p in &active {
            let w = &work[group[p]];
            let base = rows.start(w.batch) as i64;
            index.extend(
                (start..start + k).map(|j| w.gaussians.get(j).map_or(dummy, |&g| base + g as i64)),
            );
            let (tx, ty) = (w.tile % grid.tiles_x, w.tile / grid.tiles_x);
            centres.push((
                (tx * TILE_SIZE) as f64 + 0.5 * TILE_SIZE as f64,
                (ty * TILE_SIZE) as f64 + 0.5 * TILE_SIZE as f64,
            ));
        }
        let index = upload_ints(index, [tiles * k], &device);
        let centre_x: Vec<f64> = centres.iter().map(|c| c.0).collect();
        let centre_y: Vec<f64> = centres.iter().map(|c| c.1).collect();
        let centre_x: Tensor<3> = upload(TensorData::new(centre_x, [tiles, 1, 1]), &device, dtype);
        let centre_y: Tensor<3> = upload(TensorData::new(centre_y, [tiles, 1, 1]), &device, dtype);

        let means = inputs
            .means_2d
            .clone()
            .select(0, index.clone())
            .reshape([tiles, k, 2]);
        let conics = inputs
            .conics
            .clone()
            .select(0, index.clone())
            .reshape([tiles, k, 3]);
        let opacity = inputs
            .opacities
            .clone()
            .select(0, index.clone())
            .reshape([tiles, 1, k]);
        let values = inputs
            .values
            .clone()
            .select(0, index)
            .reshape([tiles, k, channels]);

        // power = −½ dᵀ·conic·d as one matmul of pixel features [x², xy, y², x, y, 1] with
        // per-Gaussian coefficients. Coordinates are relative to the tile centre, which keeps
        // the expanded quadratic free of cancellation in f32.
        let mx = means.clone().narrow(2, 0, 1) - centre_x; // [G, K, 1]
        let my = means.narrow(2, 1, 1) - centre_y;
        let a = conics.clone().narrow(2, 0, 1);
        let b = conics.clone().narrow(2, 1, 1);
        let c = conics.narrow(2, 2, 1);
        let ax_by = a.clone() * mx.clone() + b.clone() * my.clone();
        let bx_cy = b.clone() * mx.clone() + c.clone() * my.clone();
        let constant = ax_by.clone() * mx + bx_cy.clone() * my;
        let coefficients = Tensor::cat(
            vec![
                a,
                b.mul_scalar(2.0),
                c,
                ax_by.mul_scalar(-2.0),
                bx_cy.mul_scalar(-2.0),
                constant,
            ],
            2,
        )
        .mul_scalar(-0.5)
        .swap_dims(1, 2); // [G, 6, K]
        let power = pixels
            .clone()
            .expand([tiles, TILE_PIXELS, 6])
            .matmul(coefficients); // [G, 256, K]
        // A positive-definite conic gives power ≤ 0; clamping only removes rounding (INRIA's
        // `power > 0` skip can only trigger on such rounding for the Gaussians we keep).
        let alpha = (power.clamp_max(0.0).exp() * opacity).clamp_max(MAX_ALPHA);
        let alpha = alpha.clone().mask_fill(alpha.lower_elem(MIN_ALPHA), 0.0);

        // Stop decisions on detached values. T only decreases along the list, so "this
        // Gaussian would bring T below 1e-4" stays true for all later ones: it is the mask of
        // dropped Gaussians, together with pixels that stopped in an earlier chunk.
        let log_keep = alpha.clone().neg().log1p(); // [G, 256, K]
        let log_t_after =
            log_keep.clone().detach().cumsum(2) + log_t.clone().detach().unsqueeze_dim::<3>(2);
        let stop = log_t_after
            .lower_elem(options.stop_transmittance.ln())
            .float()
            .cast(dtype);
        let dropped = (stop.clone() + stopped.clone().unsqueeze_dim::<3>(2)).greater_elem(0.5);
        let alpha = alpha.mask_fill(dropped.clone(), 0.0);
        let log_keep = log_keep.mask_fill(dropped, 0.0);

        let inclusive = log_keep.clone().cumsum(2);
        let t = (inclusive.clone() - log_keep + log_t.clone().unsqueeze_dim::<3>(2)).exp(); // exclusive T
        accumulated = accumulated + (alpha * t).matmul(values); // [G, 256, C]
        log_t = log_t + inclusive.narrow(2, k - 1, 1).reshape([tiles, TILE_PIXELS]);
        stopped = (stopped + stop.narrow(2, k - 1, 1).reshape([tiles, TILE_PIXELS])).clamp_max(1.0);
        start += k;
        chunk = (2 * chunk).min(options.chunk.max(1));

        // Tiles whose pixels all stopped, or whose list ended, are done (exact).
        let all_stopped: Vec<bool> = stopped
            .clone()
            .min_dim(1)
            .greater_elem(0.5)
            .into_data()
            .try_to_vec::<bool>()
            .unwrap_or_else(|_| vec![false; tiles]);
        let done: Vec<usize> = (0..tiles)
            .filter(|&r| all_stopped[r] || work[group[active[r]]].gaussians.len() <= start)
            .collect();
        if done.is_empty() {
            continue;
        }
        let keep: Vec<usize> = (0..tiles).filter(|r| !done.contains(r)).collect();
        let rows = |rows: &[usize]| {
            let rows: Vec<i64> = rows.iter().map(|&r| r as i64).collect();
            upload_ints(rows.clone(), [rows.len()], &device)
        };
        let done_rows = rows(&done);
        let result = finish(
            accumulated.clone().select(0, done_rows.clone()),
            log_t.clone().select(0, done_rows),
        );
        finished.push((done.iter().map(|&r| active[r]).collect(), result));
        if keep.is_empty() {
            break;
        }
        let keep_rows = rows(&keep);
        accumulated = accumulated.select(0, keep_rows.clone());
        log_t = log_t.select(0, keep_rows.clone());
        stopped = stopped.select(0, keep_rows);
        active = keep.iter().map(|&r| active[r]).collect();
    }

    // Back to group order.
    let mut position_of = vec![0i64; group.len()];
    let mut next = 0;
    let mut parts = Vec::with_capacity(finished.len());
    for (positions, part) in finished {
        for p in positions {
            position_of[p] = next;
            next += 1;
        }
        parts.push(part);
    }
    let order = upload_ints(position_of, [group.len()], &device);
    Tensor::cat(parts, 0).select(0, order)
}

/// First depth chunk; later chunks double up to [`CompositeOptions::chunk`].
const FIRST_CHUNK: usize = 32;

/// Channels and alpha = 1 − T of finished tiles. `[G, 256, C + 1]`
fn finish(accumulated: Tensor<3>, log_t: Tensor<2>) -> Tensor<3> {
    let alpha = log_t.exp().neg().add_scalar(1.0).unsqueeze_dim::<3>(2);
    Tensor::cat(vec![accumulated, alpha], 2)
}

/// Quadratic features [x², xy, y², x, y, 1] of the 256 pixel centres of a tile, relative to the
/// tile's centre. `[1, 256, 6]`
fn pixel_features(device: &burn::tensor::Device, dtype: burn::tensor::DType) -> Tensor<3> {
    let mut features = Vec::with_capacity(TILE_PIXELS * 6);
    for p in 0..TILE_PIXELS {
        let x = (p % TILE_SIZE) as f64 + 0.5 - 0.5 * TILE_SIZE as f64;
        let y = (p / TILE_SIZE) as f64 + 0.5 - 0.5 * TILE_SIZE as f64;
        features.extend([x * x, x * y, y * y, x, y, 1.0]);
    }
    upload(
        TensorData::new(features, [1, TILE_PIXELS, 6]),
        device,
        dtype,
    )
}
