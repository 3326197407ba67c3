//! Tile compositing as differentiable burn tensor ops.
//!
//! Input: screen-space Gaussians of a batch of poses (flattened to `[B·N, …]`), per-Gaussian
//! channel values, and the host-side tile lists of [`crate::tiles`]. Each tile's list is
//! processed in depth chunks of at most `chunk` Gaussians, carrying each pixel's
//! transmittance and stop state from chunk to chunk, so that long lists are exact and memory
//! stays bounded. Tiles are processed in groups of similar list length to limit padding.
//!
//! The rules are INRIA's (DESIGN.md): α = min(0.99, o·exp(power)), skipped when α < 1/255 or
//! power > 0; a pixel stops before the Gaussian that would bring T below 1e-4. The skip and
//! stop decisions are made on detached values (integer data, no gradient); the gradient flows
//! through α of the Gaussians that are kept, and through the channel values.

use burn::tensor::{Bool, Int, Tensor, TensorData};

use crate::compositing::exclusive_transmittance;
use crate::tiles::{TILE_PIXELS, TILE_SIZE, TileGrid, TileWork};

/// Largest alpha a Gaussian can reach (INRIA).
pub const MAX_ALPHA: f64 = 0.99;
/// Smallest alpha that counts (INRIA: 1/255).
pub const MIN_ALPHA: f64 = 1.0 / 255.0;
/// A pixel stops before T would fall below this.
pub const MIN_TRANSMITTANCE: f64 = 1e-4;

/// Screen-space Gaussians of a batch, flat over (pose, Gaussian): row b·N + g.
#[derive(Debug, Clone)]
pub struct SplatInputs {
    /// Pixel coordinates of the means. `[B·N, 2]`
    pub means_2d: Tensor<2>,
    /// Inverse 2D covariances (a, b, c) of [[a, b], [b, c]]. `[B·N, 3]`
    pub conics: Tensor<2>,
    /// Opacities. `[B·N]`
    pub opacities: Tensor<1>,
    /// Channel values to composite (mask, colour, depth, features). `[B·N, C]`
    pub values: Tensor<2>,
}

/// How the compositing is cut into pieces; the result does not depend on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CompositeOptions {
    /// Gaussians per depth chunk (the K of `[tiles, 256, K]`).
    pub chunk: usize,
    /// Tiles processed together.
    pub tile_group: usize,
}

impl Default for CompositeOptions {
    fn default() -> Self {
        CompositeOptions {
            chunk: 256,
            tile_group: 32,
        }
    }
}

/// Rendered images of a batch.
#[derive(Debug, Clone)]
pub struct Composited {
    /// Channel images. `[B, H, W, C]`
    pub images: Tensor<4>,
    /// Accumulated opacity 1 − T_final. `[B, H, W]`
    pub alpha: Tensor<3>,
}

/// Composites `work` (from [`crate::tiles::bin_tiles`]) into full images.
///
/// `n` is the number of Gaussians per pose; tiles absent from `work` render as zero.
pub fn composite(
    inputs: &SplatInputs,
    work: &[TileWork],
    n: usize,
    batch: usize,
    grid: &TileGrid,
    options: CompositeOptions,
) -> Composited {
    let device = inputs.means_2d.device();
    let dtype = inputs.means_2d.dtype();
    let channels = inputs.values.dims()[1];
    let padded = pad_with_transparent_row(inputs);
    let dummy = (batch * n) as i64;

    // Longest lists first, so that a group's lists have similar lengths.
    let mut order: Vec<usize> = (0..work.len()).collect();
    order.sort_by_key(|&w| std::cmp::Reverse(work[w].gaussians.len()));

    // [work, 256, C + 1]: channels, then alpha, in `order`.
    let mut pieces = Vec::new();
    for group in order.chunks(options.tile_group.max(1)) {
        pieces.push(composite_group(
            &padded,
            work,
            group,
            grid,
            n,
            dummy,
            options.chunk.max(1),
            channels,
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
    let index = Tensor::<1, Int>::from_data(
        TensorData::new(slot_from_tile, [batch * grid.len()]),
        &device,
    );
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
    let alpha = image
        .clone()
        .narrow(3, channels, 1)
        .reshape([batch, grid.height, grid.width]);
    Composited {
        images: image.narrow(3, 0, channels),
        alpha,
    }
}

/// The inputs with one extra, fully transparent row at index B·N, which padding points to.
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
fn composite_group(
    inputs: &SplatInputs,
    work: &[TileWork],
    group: &[usize],
    grid: &TileGrid,
    n: usize,
    dummy: i64,
    chunk: usize,
    channels: usize,
) -> Tensor<3> {
    let device = inputs.means_2d.device();
    let dtype = inputs.means_2d.dtype();
    let tiles = group.len();
    let longest = group
        .iter()
        .map(|&w| work[w].gaussians.len())
        .max()
        .unwrap_or(0);

    let (px, py) = pixel_centres(work, group, grid, &device, dtype); // [G, 256, 1] each
    let mut accumulated = Tensor::<3>::zeros([tiles, TILE_PIXELS, channels], (&device, dtype));
    let mut transmittance = Tensor::<2>::ones([tiles, TILE_PIXELS], (&device, dtype)); // T before the chunk
    let mut stopped = Tensor::<2>::zeros([tiles, TILE_PIXELS], (&device, dtype)); // 1 once a pixel stopped

    for start in (0..longest).step_by(chunk) {
        let k = chunk.min(longest - start);
        let mut index = Vec::with_capacity(tiles * k);
        for &w in group {
            let list = &work[w].gaussians;
            let base = (work[w].batch * n) as i64;
            index.extend(
                (start..start + k).map(|j| list.get(j).map_or(dummy, |&g| base + g as i64)),
            );
        }
        let index = Tensor::<1, Int>::from_data(TensorData::new(index, [tiles * k]), &device);

        let means = inputs
            .means_2d
            .clone()
            .select(0, index.clone())
            .reshape([tiles, 1, k, 2]);
        let conics = inputs
            .conics
            .clone()
            .select(0, index.clone())
            .reshape([tiles, 1, k, 3]);
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

        let dx = px.clone() - means.clone().narrow(3, 0, 1).reshape([tiles, 1, k]); // [G, 256, K]
        let dy = py.clone() - means.narrow(3, 1, 1).reshape([tiles, 1, k]);
        let a = conics.clone().narrow(3, 0, 1).reshape([tiles, 1, k]);
        let b = conics.clone().narrow(3, 1, 1).reshape([tiles, 1, k]);
        let c = conics.narrow(3, 2, 1).reshape([tiles, 1, k]);
        let power =
            (a * dx.clone().square() + c * dy.clone().square()).mul_scalar(-0.5) - b * dx * dy;
        let alpha = (power.clone().exp() * opacity).clamp_max(MAX_ALPHA);

        // Skip decisions: power > 0 (numerical garbage far from the mean) or α < 1/255.
        let skip: Tensor<3, Bool> = power
            .greater_elem(0.0)
            .bool_or(alpha.clone().lower_elem(MIN_ALPHA));
        let alpha = alpha.mask_fill(skip, 0.0);

        // Stop decisions on detached values: keep a Gaussian while no earlier Gaussian of this
        // pixel (in this or a previous chunk) would have brought T below 1e-4.
        let log_keep = alpha.clone().detach().neg().log1p();
        let log_t_after =
            log_keep.cumsum(2) + transmittance.clone().detach().log().unsqueeze_dim::<3>(2);
        let stop_here = log_t_after
            .lower_elem(MIN_TRANSMITTANCE.ln())
            .float()
            .cast(dtype);
        let stops_so_far = stop_here.cumsum(2) + stopped.clone().unsqueeze_dim::<3>(2);
        let dropped: Tensor<3, Bool> = stops_so_far.clone().greater_elem(0.5);
        let alpha = alpha.mask_fill(dropped, 0.0);

        let t =
            exclusive_transmittance(alpha.clone()) * transmittance.clone().unsqueeze_dim::<3>(2); // [G, 256, K]
        let weights = alpha.clone() * t;
        accumulated = accumulated + weights.matmul(values); // [G, 256, C]
        let log_kept = alpha.neg().log1p().sum_dim(2).reshape([tiles, TILE_PIXELS]);
        transmittance = transmittance * log_kept.exp();
        stopped = stops_so_far
            .narrow(2, k - 1, 1)
            .reshape([tiles, TILE_PIXELS])
            .clamp_max(1.0);

        // Exact shortcut: once every pixel of the group stopped, later chunks add nothing.
        if stopped.clone().lower_elem(0.5).any().into_scalar::<bool>() {
            continue;
        }
        break;
    }
    let alpha = transmittance.neg().add_scalar(1.0).unsqueeze_dim::<3>(2); // [G, 256, 1]
    Tensor::cat(vec![accumulated, alpha], 2)
}

/// Pixel centres (i + 0.5, j + 0.5) of each tile of the group, x and y, `[G, 256, 1]` each.
fn pixel_centres(
    work: &[TileWork],
    group: &[usize],
    grid: &TileGrid,
    device: &burn::tensor::Device,
    dtype: burn::tensor::DType,
) -> (Tensor<3>, Tensor<3>) {
    let mut xs = Vec::with_capacity(group.len() * TILE_PIXELS);
    let mut ys = Vec::with_capacity(group.len() * TILE_PIXELS);
    for &w in group {
        let (tx, ty) = (work[w].tile % grid.tiles_x, work[w].tile / grid.tiles_x);
        for p in 0..TILE_PIXELS {
            xs.push((tx * TILE_SIZE + p % TILE_SIZE) as f64 + 0.5);
            ys.push((ty * TILE_SIZE + p / TILE_SIZE) as f64 + 0.5);
        }
    }
    let shape = [group.len(), TILE_PIXELS, 1];
    (
        Tensor::from_data(TensorData::new(xs, shape), (device, dtype)),
        Tensor::from_data(TensorData::new(ys, shape), (device, dtype)),
    )
}
