//! The tiling of an image into 16×16 tiles (INRIA 3DGS): sizes, which tiles a square touches,
//! and the cast-based rounding the per-Gaussian paths use. A leaf: the host decisions, the
//! binning and the compositing kernels all read it.

/// Tile edge in pixels (INRIA 3DGS).
pub const TILE_SIZE: usize = 16;
/// Pixels per tile.
pub const TILE_PIXELS: usize = TILE_SIZE * TILE_SIZE;

/// The tiling of one image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileGrid {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Tiles per row, ceil(width / 16).
    pub tiles_x: usize,
    /// Tiles per column, ceil(height / 16).
    pub tiles_y: usize,
}

impl TileGrid {
    /// The grid covering a `width` × `height` image (the last row/column may be partial).
    pub fn new(width: usize, height: usize) -> Self {
        TileGrid {
            width,
            height,
            tiles_x: width.div_ceil(TILE_SIZE),
            tiles_y: height.div_ceil(TILE_SIZE),
        }
    }

    /// Number of tiles.
    pub fn len(&self) -> usize {
        self.tiles_x * self.tiles_y
    }

    /// True for an image without pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Tiles touched by the square [u − r, u + r] × [v − r, v + r]: columns
    /// floor((u − r)/16) ..< ceil((u + r)/16), clipped to the grid (the reference renderer's rule).
    pub fn touched(
        &self,
        u: f64,
        v: f64,
        radius: f64,
    ) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        // Clamping before rounding is the same as after (the bounds are integers) and keeps
        // the values small enough for the cast-based rounding.
        let span = |centre: f64, count: usize| {
            let tiles = |edge: f64| (edge / TILE_SIZE as f64).clamp(0.0, count as f64);
            let lo = floor_small(tiles(centre - radius)) as usize;
            let hi = ceil_small(tiles(centre + radius)) as usize;
            lo..hi.max(lo)
        };
        (span(u, self.tiles_x), span(v, self.tiles_y))
    }
}

/// ⌊x⌋ for |x| well inside the i64 range, as a cast: the baseline x86-64 target has no
/// rounding instruction, and `f64::floor` is a libm call on paths run once per Gaussian or pair.
#[inline(always)]
pub(crate) fn floor_small(x: f64) -> i64 {
    let truncated = x as i64;
    if (truncated as f64) > x {
        truncated - 1
    } else {
        truncated
    }
}

/// ⌈x⌉ for |x| well inside the i64 range.
#[inline(always)]
pub(crate) fn ceil_small(x: f64) -> i64 {
    let truncated = x as i64;
    if (truncated as f64) < x {
        truncated + 1
    } else {
        truncated
    }
}
