//! The fused compositing kernels in plain Rust: forward and backward of one (pose, tile), run
//! in parallel over tiles with rayon, generic over f32 and f64.
//!
//! Per pixel the forward keeps T (transmittance), the running channel sums and the number of
//! list entries up to its last contributing Gaussian; it saves the final T and that count for
//! the backward, which replays the list back to front (T before Gaussian i is T after it divided
//! by 1 − α_i, safe since α ≤ 0.99) and keeps the sum of what lies behind. Each list entry gets
//! its own gradient slot; slots are summed per Gaussian afterwards in list order, so the result
//! is the same on every run and thread count (no atomics).
//!
//! The rules and their gradient conventions are exactly the tensor path's (`rasterize.rs`):
//! power = −½ dᵀ·conic·d clamped at 0 (no gradient where power > 0), α = min(0.99, o·e^power)
//! (no gradient where o·e^power > 0.99; at exactly 0.99 it flows), skip when α < 1/255, stop
//! before the Gaussian that would bring T below 1e-4. The tensor path decides the stop in log
//! space (ln T summed); here T is a running product. Both are the same rule; they can disagree
//! only when T lands within rounding of 1e-4.
//!
//! f32 passes run the 8-lane kernels of `simd` where the processor has AVX2 and FMA (checked
//! at run time, [`Kernels::detect`]), with the same bits as the scalar kernels here; f64
//! passes, and f32 on other processors, run the scalar kernels, which stay the definition.

use std::any::Any;
use std::ops::Range;

use rayon::prelude::*;

use super::plan::CompositePlan;
pub use super::real::Real;
use crate::rasterize::{MAX_ALPHA, MIN_ALPHA};
use crate::tile_grid::{TILE_PIXELS, TILE_SIZE, ceil_small, floor_small};

mod gradient_sums;
#[cfg(target_arch = "x86_64")]
mod lanes_exp;
#[cfg(target_arch = "x86_64")]
mod simd;

/// Which implementation of the tile kernels a pass runs. Both compute the same numbers, bit for
/// bit (`tests/fused_lanes.rs`); the lanes are faster.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernels {
    /// One pixel at a time, plain Rust: every float type and processor.
    Scalar,
    /// f32 in 8 lanes, one half row of a tile per Gaussian (AVX2 + FMA on x86-64); f64 passes,
    /// and processors without AVX2 and FMA, run [`Kernels::Scalar`].
    Lanes8,
}

impl Kernels {
    /// The fastest this processor runs: [`Kernels::Lanes8`] where it has AVX2 and FMA.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if simd::Lanes::new().is_some() {
            return Kernels::Lanes8;
        }
        Kernels::Scalar
    }
}

/// `value` as a `B` where `A` is `B` (how an `E: Real` pass reaches the f32-only kernels).
fn cast_ref<A: 'static, B: 'static>(value: &A) -> Option<&B> {
    (value as &dyn Any).downcast_ref()
}

/// `value` as a `B` where `A` is `B`.
fn cast<A: 'static, B: 'static>(value: A) -> Option<B> {
    (Box::new(value) as Box<dyn Any>)
        .downcast()
        .ok()
        .map(|b| *b)
}

/// Screen-space Gaussians on the host, one per row (as [`crate::rasterize::SplatInputs`]).
#[derive(Debug, Clone)]
pub struct HostSplats<E> {
    /// `[R, 2]`
    pub means: Vec<E>,
    /// `[R, 3]`
    pub conics: Vec<E>,
    /// `[R]`
    pub opacities: Vec<E>,
    /// `[R, C]`
    pub values: Vec<E>,
    /// C.
    pub channels: usize,
}

/// What the forward pass hands to the backward pass.
#[derive(Debug, Clone)]
pub struct ForwardState<E> {
    /// Each work tile's pixels, in plan order. `[work]`: kept as the tiles made them, since
    /// joining them into one buffer was a serial copy of the whole state per pass (at 1280×720
    /// and 30 poses, 220 MB on one thread while the other cores waited).
    tiles: Vec<TileState<E>>,
    /// Each row's footprint, for the backward to reuse. `[R]`
    pub footprints: Vec<Footprint<E>>,
}

/// One work tile's pixels after its forward.
#[derive(Debug, Clone)]
struct TileState<E> {
    /// T after the last contributing Gaussian. `[256]`
    final_t: Vec<E>,
    /// Number of list entries up to and including the last contributor. `[256]`
    last: Vec<u32>,
}

impl<E: Copy> ForwardState<E> {
    /// Work tile `w`'s T after its last contributor and its count of list entries up to that
    /// contributor, per pixel. `[256]` each
    fn tile(&self, w: usize) -> (&[E], &[u32]) {
        let tile = &self.tiles[w];
        (&tile.final_t, &tile.last)
    }

    /// T after the last contributing Gaussian, per work tile and pixel (a copy). `[work, 256]`
    pub fn final_t(&self) -> Vec<E> {
        self.tiles
            .iter()
            .flat_map(|t| t.final_t.iter().copied())
            .collect()
    }

    /// Number of list entries up to and including the last contributor, per work tile and
    /// pixel (a copy). `[work, 256]`
    pub fn last(&self) -> Vec<u32> {
        self.tiles
            .iter()
            .flat_map(|t| t.last.iter().copied())
            .collect()
    }
}

/// Gradients of the four inputs, shaped like them.
#[derive(Debug, Clone)]
pub struct HostGradients<E> {
    /// `[R, 2]`
    pub means: Vec<E>,
    /// `[R, 3]`
    pub conics: Vec<E>,
    /// `[R]`
    pub opacities: Vec<E>,
    /// `[R, C]`
    pub values: Vec<E>,
}

/// What compositing needs of one row, whatever the tile: computed once per row and pass (it
/// used to be once per tile–Gaussian pair, in the forward and again in the backward, and that
/// logarithm, two square roots and a division were a fifth of a real capture's pass), and kept
/// in one record so that a pair reads one cache line rather than three arrays.
#[derive(Debug, Clone, Copy)]
pub struct Footprint<E> {
    /// The Gaussian in image coordinates.
    splat: Splat<E>,
    /// The image columns and rows (first and last, inclusive; none where first > last) of the
    /// pixels whose α can reach 1/255 ([`Footprint::extent`]), so that placing the footprint
    /// on a tile is integer clamps: in f64 per list entry it was 6 % of a run's CPU time.
    pixel_columns: [i32; 2],
    pixel_rows: [i32; 2],
}

/// Where a row can reach α ≥ 1/255.
#[derive(Debug, Clone, Copy)]
enum Extent {
    /// Nowhere: o < 1/255 (or NaN).
    Nowhere,
    /// Anywhere, as far as the bound can tell (it is not finite): test every pixel of a tile.
    Anywhere,
    /// Within these half-widths, in pixels, of the mean.
    Ellipse { half_x: f64, half_y: f64 },
}

/// Pixel bounds that hold no pixel.
const NO_PIXELS: [i32; 2] = [1, 0];

/// Pixel bounds beyond every image: every pixel of every tile.
const ALL_PIXELS: [i32; 2] = [-(1 << 30), 1 << 30];

/// A tile's corner, in pixels and in the kernels' float type (computed once per tile).
#[derive(Debug, Clone, Copy)]
struct Corner<E> {
    pixels: [i64; 2],
    at: [E; 2],
}

impl<E: Real> Corner<E> {
    fn new((x0, y0): (usize, usize)) -> Self {
        Corner {
            pixels: [x0 as i64, y0 as i64],
            at: [E::of(x0 as f64), E::of(y0 as f64)],
        }
    }
}

impl<E: Real> Footprint<E> {
    fn new(splats: &HostSplats<E>, row: usize) -> Self {
        let [mx, my] = [splats.means[2 * row], splats.means[2 * row + 1]];
        let [a, b, c] = [0, 1, 2].map(|k| splats.conics[3 * row + k]);
        let opacity = splats.opacities[row];
        // In f64 like the bound it feeds: α at exactly 1/255 must not round out of the box.
        let reach = (255.0 * opacity.to_f64()).ln();
        let (pixel_columns, pixel_rows) =
            match Self::extent([mx, my, a, b, c].map(E::to_f64), reach) {
                Extent::Nowhere => (NO_PIXELS, NO_PIXELS),
                Extent::Anywhere => (ALL_PIXELS, ALL_PIXELS),
                Extent::Ellipse { half_x, half_y } => (
                    Self::pixel_span(mx.to_f64(), half_x),
                    Self::pixel_span(my.to_f64(), half_y),
                ),
            };
        Footprint {
            splat: Splat {
                mx,
                my,
                a,
                b,
                c,
                opacity,
                skip_below: E::of(-reach) - E::of(1e-3),
            },
            pixel_columns,
            pixel_rows,
        }
    }

    /// The image pixels X (columns or rows) with |X + 0.5 − m| ≤ half + δ, as first and last.
    ///
    /// The kernels measure a pixel's offset from the mean relative to its tile's corner, as
    /// that corner's f32 (or f64) difference m − x0, which lies within u·|m − x0| of the exact
    /// one; on a tile the box reaches |m − x0| ≤ half + 17, so δ = 2u·(half + 17) keeps
    /// every pixel that the box about the rounded mean would keep.
    fn pixel_span(m: f64, half: f64) -> [i32; 2] {
        let reach = half + 2.0 * E::UNIT_ROUNDOFF * (half + 17.0);
        let limit = f64::from(1 << 30);
        let first = ceil_small((m - reach - 0.5).clamp(-limit, limit));
        let last = floor_small((m + reach - 0.5).clamp(-limit, limit));
        [first as i32, last as i32]
    }

    /// The box outside which the kernels' α is below 1/255 for sure, from the ellipse
    /// q(d) = ½dᵀ·conic·d ≤ t with t = ln(255·o): half-widths sqrt(2t·Σ_xx), sqrt(2t·Σ_yy)
    /// with Σ = conic⁻¹ (Σ_xx = c/det, Σ_yy = a/det), since q ≥ dx²/(2Σ_xx) on a column dx
    /// away from the mean (and likewise for rows).
    ///
    /// Only t grows, by what the kernels' rounding can hide (docs/rasterizer.md, "The box"):
    /// α ≥ 1/255 in E needs q_E ≤ t + 16u, and q_E is within 16u/(1 − ρ) of q relative to it
    /// (u: E's unit roundoff, ρ = |b|/sqrt(ac) < 1 the conic's correlation: the terms of q
    /// can be 2/(1 − ρ) times q itself). So q > (t + 16u)/(1 − 16u/(1 − ρ)) leaves α < 1/255,
    /// and so does q > (t + 16u)/(1 − 32u·ac/det), which is what is computed.
    /// The box used to carry a pixel of margin instead, which on a mask pass of 96×54 doubled
    /// the half rows the kernels visited (most splats there are a few pixels wide); a needle
    /// (1 − ρ of 10⁻⁵) needs far less than a pixel of it, and a conic too close to degenerate
    /// for the bound to hold (ac/det ≥ 1/(64u)) is tested on the whole tile.
    fn extent([mx, my, a, b, c]: [f64; 5], t: f64) -> Extent {
        if t.is_nan() || t < 0.0 {
            return Extent::Nowhere;
        }
        let det = a * c - b * b;
        if det.is_nan() || det <= 0.0 {
            return Extent::Anywhere;
        }
        let u = E::UNIT_ROUNDOFF;
        let inverse = 1.0 / det;
        // 1/(1 − ρ) ≤ 2/(1 − ρ²) = 2ac/det: a bound at most twice as loose, without the square
        // root and the divisions that made this a long chain per row and pass.
        let relative = 32.0 * u * a * c * inverse;
        if relative.is_nan() || relative >= 0.5 {
            return Extent::Anywhere;
        }
        let reach = (t + 16.0 * u) / (1.0 - relative);
        // The f64 arithmetic here and of the pixel bounds is covered by a millionth, relative
        // and in pixels.
        let half = |variance: f64| (2.0 * reach * variance * inverse).sqrt() * (1.0 + 1e-6) + 1e-6;
        let (half_x, half_y) = (half(c), half(a));
        if !(half_x.is_finite() && half_y.is_finite() && mx.is_finite() && my.is_finite()) {
            return Extent::Anywhere;
        }
        Extent::Ellipse { half_x, half_y }
    }

    /// This row on the tile with corner `corner`, and the tile pixels `(xs, ys)` of its box
    /// ([`Self::extent`]); `None` if there are none. The rest of the tile is skipped: its α is
    /// below 1/255, so this changes no value and no decision.
    fn on_tile(&self, corner: Corner<E>) -> Option<(Splat<E>, Range<usize>, Range<usize>)> {
        let span = |[first, last]: [i32; 2], origin: i64| {
            let tile = TILE_SIZE as i64;
            let lo = (i64::from(first) - origin).clamp(0, tile);
            let hi = (i64::from(last) + 1 - origin).clamp(lo, tile);
            lo as usize..hi as usize
        };
        let xs = span(self.pixel_columns, corner.pixels[0]);
        let ys = span(self.pixel_rows, corner.pixels[1]);
        if xs.is_empty() || ys.is_empty() {
            return None;
        }
        // Coordinates relative to the tile's corner keep dx, dy small (as the tensor path does
        // with its tile centre), so f32 loses nothing to cancellation.
        let splat = Splat {
            mx: self.splat.mx - corner.at[0],
            my: self.splat.my - corner.at[1],
            ..self.splat
        };
        Some((splat, xs, ys))
    }
}

/// List entries whose footprints are read in one go.
const GATHER: usize = 32;

/// Which way a kernel walks a tile's list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Walk {
    /// The forward: nearest entry first.
    FrontToBack,
    /// The backward's replay: deepest entry first.
    BackToFront,
}

/// The footprints of a tile's list entries, read [`GATHER`] at a time. Lists are in depth
/// order, so their rows are scattered over memory: read one by one between the pixel loops,
/// each stalled the kernel on a cache miss (a sixth of a real capture's pass), while a tight
/// loop of independent reads has the processor fetch them all at once. The block after it (in
/// the walk's direction) is prefetched while this one is composited: without it, the gather's
/// misses were still 3–6 % of the kernels' samples (perf, first-try guitar run).
struct Gathered<'a, E> {
    footprints: &'a [Footprint<E>],
    list: &'a [u32],
    walk: Walk,
    /// First list entry of `block` (`usize::MAX` before the first read).
    start: usize,
    block: Vec<Footprint<E>>,
}

impl<'a, E: Real> Gathered<'a, E> {
    fn new(footprints: &'a [Footprint<E>], list: &'a [u32], walk: Walk) -> Self {
        Gathered {
            footprints,
            list,
            walk,
            start: usize::MAX,
            block: Vec::with_capacity(GATHER),
        }
    }

    /// The footprint of list entry `j`; blocks are aligned, so walking the list either way
    /// reads each block once.
    #[inline(always)]
    fn get(&mut self, j: usize) -> &Footprint<E> {
        let start = j / GATHER * GATHER;
        if start != self.start {
            self.load(start);
        }
        &self.block[j - start]
    }

    /// Reads the block of entries from `start` and prefetches the next one. Kept out of line:
    /// it runs once every [`GATHER`] entries, and inlined with `get` the whole of it had the
    /// kernels call `get` for every entry (perf: 2.7 % of a run).
    #[inline(never)]
    fn load(&mut self, start: usize) {
        self.start = start;
        let rows = &self.list[start..(start + GATHER).min(self.list.len())];
        self.block.clear();
        self.block
            .extend(rows.iter().map(|&row| self.footprints[row as usize]));
        let next = match self.walk {
            Walk::FrontToBack => start + GATHER..(start + 2 * GATHER).min(self.list.len()),
            Walk::BackToFront => start.saturating_sub(GATHER)..start,
        };
        for &row in self.list.get(next).unwrap_or_default() {
            prefetch(&self.footprints[row as usize]);
        }
    }
}

/// Asks the processor to bring `value`'s cache lines in (a hint: nothing else happens).
#[inline(always)]
fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let first = std::ptr::from_ref(value).cast::<i8>();
        let last = first.wrapping_add(std::mem::size_of::<T>() - 1);
        // SAFETY: a prefetch reads nothing and faults on no address; SSE is in every x86-64.
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(first);
            _mm_prefetch::<_MM_HINT_T0>(last);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// Work tiles per rayon task at most. A tile's cost varies a hundredfold (an empty corner, the
/// object's middle), and rayon otherwise cuts a loop into about four pieces per thread, so one
/// thread was often left alone with a heavy piece it could not share: on the first-try guitar
/// one of two cores idled through a third of the compositing.
const TILES_PER_TASK: usize = 4;

/// Every row's footprint, in parallel.
fn footprints<E: Real>(splats: &HostSplats<E>) -> Vec<Footprint<E>> {
    (0..splats.opacities.len())
        .into_par_iter()
        .map(|row| Footprint::new(splats, row))
        .collect()
}

/// One Gaussian of a list: its mean (in image coordinates in a [`Footprint`], in the tile's
/// once placed on one), conic, opacity and 1/255 skip threshold.
#[derive(Debug, Clone, Copy)]
struct Splat<E> {
    mx: E,
    my: E,
    a: E,
    b: E,
    c: E,
    opacity: E,
    /// Below this power α < 1/255 for sure (−ln(255·o) less a margin for rounding).
    skip_below: E,
}

impl<E: Real> Splat<E> {
    /// (dx, dy, power before the clamp, e^min(power, 0)) at tile pixel `p`, or `None` where
    /// α is surely below 1/255 (no exp needed there).
    #[inline(always)]
    fn at(&self, p: usize) -> Option<(E, E, E, E)> {
        let half = E::of(0.5);
        let dx = E::of((p % TILE_SIZE) as f64 + 0.5) - self.mx;
        let dy = E::of((p / TILE_SIZE) as f64 + 0.5) - self.my;
        let power = -(half * (self.a * dx * dx + self.c * dy * dy)) - self.b * dx * dy;
        if power < self.skip_below {
            return None;
        }
        let clamped = if power > E::ZERO { E::ZERO } else { power };
        Some((dx, dy, power, clamped.exp()))
    }
}

/// α from the unclamped o·e^power.
#[inline(always)]
fn clamp_alpha<E: Real>(raw: E) -> E {
    let max = E::of(MAX_ALPHA);
    if raw > max { max } else { raw }
}

/// The result of one tile's forward pass.
struct TileForward<E> {
    /// `[C + 1, 256]`: channel sums, then alpha = 1 − T.
    planes: Vec<E>,
    final_t: Vec<E>,
    last: Vec<u32>,
}

/// One bit per tile pixel: bit x of entry y stands for pixel 16·y + x.
type RowBits = [u16; TILE_SIZE];

/// The pixels 16·y + x of the box `xs` × `ys` whose bit is set, in row-major order. Most of a
/// footprint's box has stopped (forward) or not yet started (backward) on real captures, three
/// pixels in four; visiting only the set bits skips them without a test each.
fn pixels_of(rows: RowBits, xs: Range<usize>, ys: Range<usize>) -> impl Iterator<Item = usize> {
    let columns = column_bits(&xs);
    ys.flat_map(move |y| {
        let mut bits = rows[y] & columns;
        std::iter::from_fn(move || {
            (bits != 0).then(|| {
                let x = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                y * TILE_SIZE + x
            })
        })
    })
}

/// Pixels of tile `tile` that lie inside the image (partial tiles at the right/bottom edge).
fn valid_pixels(plan: &CompositePlan, tile: usize) -> [bool; TILE_PIXELS] {
    let (x0, y0) = plan.tile_origin(tile);
    let mut valid = [false; TILE_PIXELS];
    for (p, v) in valid.iter_mut().enumerate() {
        *v = x0 + p % TILE_SIZE < plan.grid.width && y0 + p / TILE_SIZE < plan.grid.height;
    }
    valid
}

/// The bits of tile `tile`'s pixels inside the image, and how many there are.
fn valid_bits(plan: &CompositePlan, tile: usize) -> (RowBits, usize) {
    let valid = valid_pixels(plan, tile);
    let bits: RowBits = std::array::from_fn(|y| {
        (0..TILE_SIZE).fold(0, |bits, x| {
            bits | (u16::from(valid[y * TILE_SIZE + x]) << x)
        })
    });
    (bits, valid.iter().filter(|&&v| v).count())
}

/// The columns `xs` of a tile row as bits (bit x for column x).
fn column_bits(xs: &Range<usize>) -> u16 {
    ((1u32 << xs.end) - (1u32 << xs.start)) as u16
}

fn forward_tile<E: Real>(
    splats: &HostSplats<E>,
    footprints: &[Footprint<E>],
    plan: &CompositePlan,
    w: usize,
) -> TileForward<E> {
    let channels = splats.channels;
    let corner = Corner::new(plan.tile_origin(plan.tiles[w]));
    let min_alpha = E::of(MIN_ALPHA);
    let min_t = E::of(plan.stop_transmittance);

    let (mut open, mut open_count) = valid_bits(plan, plan.tiles[w]);
    let mut t = vec![E::ONE; TILE_PIXELS];
    let mut last = vec![0u32; TILE_PIXELS];
    let mut planes = vec![E::ZERO; (channels + 1) * TILE_PIXELS];
    let list = plan.list(w);
    let mut gathered = Gathered::new(footprints, list, Walk::FrontToBack);
    for (j, &row) in list.iter().enumerate() {
        if open_count == 0 {
            break;
        }
        let row = row as usize;
        let Some((splat, xs, ys)) = gathered.get(j).on_tile(corner) else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        for p in pixels_of(open, xs, ys) {
            let Some((_, _, _, exp_power)) = splat.at(p) else {
                continue;
            };
            let alpha = clamp_alpha(splat.opacity * exp_power);
            if alpha < min_alpha {
                continue;
            }
            let t_next = t[p] * (E::ONE - alpha);
            if t_next < min_t {
                open[p / TILE_SIZE] &= !(1 << (p % TILE_SIZE));
                open_count -= 1;
                continue;
            }
            let weight = alpha * t[p];
            for (k, &value) in values.iter().enumerate() {
                planes[k * TILE_PIXELS + p] += value * weight;
            }
            t[p] = t_next;
            last[p] = j as u32 + 1;
        }
    }
    for p in 0..TILE_PIXELS {
        planes[channels * TILE_PIXELS + p] = E::ONE - t[p];
    }
    TileForward {
        planes,
        final_t: t,
        last,
    }
}

/// Forward pass of every work tile with the fastest kernels this processor runs
/// ([`Kernels::detect`]). Returns the packed image `[B, H, W, C + 1]` and the state.
pub fn forward<E: Real>(splats: &HostSplats<E>, plan: &CompositePlan) -> (Vec<E>, ForwardState<E>) {
    forward_with(splats, plan, Kernels::detect())
}

/// [`forward`] with the given kernels.
pub fn forward_with<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    kernels: Kernels,
) -> (Vec<E>, ForwardState<E>) {
    let footprints = footprints(splats);
    let tiles: Vec<TileForward<E>> = forward_tiles_in_lanes(splats, &footprints, plan, kernels)
        .unwrap_or_else(|| {
            (0..plan.tiles.len())
                .into_par_iter()
                .with_max_len(TILES_PER_TASK)
                .map(|w| forward_tile(splats, &footprints, plan, w))
                .collect()
        });
    let image = assemble(plan, splats.channels, &tiles);
    let tiles = tiles
        .into_iter()
        .map(|tile| TileState {
            final_t: tile.final_t,
            last: tile.last,
        })
        .collect();
    (image, ForwardState { tiles, footprints })
}

/// Every work tile's forward in 8 lanes, where `kernels` asks for them, E is f32 and the
/// processor has them; `None` otherwise.
#[cfg(target_arch = "x86_64")]
fn forward_tiles_in_lanes<E: Real>(
    splats: &HostSplats<E>,
    footprints: &Vec<Footprint<E>>,
    plan: &CompositePlan,
    kernels: Kernels,
) -> Option<Vec<TileForward<E>>> {
    let lanes = simd::Lanes::new().filter(|_| kernels == Kernels::Lanes8)?;
    let splats = cast_ref::<_, HostSplats<f32>>(splats)?;
    let footprints = cast_ref::<_, Vec<Footprint<f32>>>(footprints)?;
    let tiles: Vec<TileForward<f32>> = (0..plan.tiles.len())
        .into_par_iter()
        .with_max_len(TILES_PER_TASK)
        .map(|w| lanes.forward_tile(splats, footprints, plan, w))
        .collect();
    cast(tiles)
}

/// No 8-lane kernels off x86-64.
#[cfg(not(target_arch = "x86_64"))]
fn forward_tiles_in_lanes<E: Real>(
    _: &HostSplats<E>,
    _: &Vec<Footprint<E>>,
    _: &CompositePlan,
    _: Kernels,
) -> Option<Vec<TileForward<E>>> {
    None
}

/// The packed image `[B, H, W, C + 1]` (or `[B, H, W, C]` where the plan drops alpha) of the
/// work tiles' planes (zero where no tile drew), one band of 16 image rows per task: a 1080p
/// frame is 10 M values to place, and placed tile by tile on one thread that was a tenth of its
/// compositing.
fn assemble<E: Real>(plan: &CompositePlan, channels: usize, tiles: &[TileForward<E>]) -> Vec<E> {
    let grid = plan.grid;
    let stride = plan.image_width(channels);
    // Work tile of each (pose, tile), or usize::MAX where none. `[B · tiles]`
    let mut work_of = vec![usize::MAX; plan.batch() * grid.len()];
    for (w, (&b, &tile)) in plan.batches.iter().zip(&plan.tiles).enumerate() {
        work_of[b * grid.len() + tile] = w;
    }
    let mut image = vec![E::ZERO; plan.batch() * grid.height * grid.width * stride];
    let row = grid.width * stride;
    if row == 0 || grid.height == 0 {
        return image;
    }
    image
        .par_chunks_mut(grid.height * row) // one pose
        .enumerate()
        .for_each(|(b, pose)| {
            pose.par_chunks_mut(TILE_SIZE * row) // one band of tiles
                .enumerate()
                .for_each(|(ty, band)| {
                    let rows = band.len() / row;
                    for tx in 0..grid.tiles_x {
                        let w = work_of[b * grid.len() + ty * grid.tiles_x + tx];
                        let Some(tile) = tiles.get(w) else {
                            continue;
                        };
                        let x0 = tx * TILE_SIZE;
                        let columns = TILE_SIZE.min(grid.width - x0);
                        for y in 0..rows {
                            for x in 0..columns {
                                let p = y * TILE_SIZE + x;
                                let at = y * row + (x0 + x) * stride;
                                for k in 0..stride {
                                    band[at + k] = tile.planes[k * TILE_PIXELS + p];
                                }
                            }
                        }
                    }
                });
        });
    image
}

/// The output gradients of work tile `w`'s pixels, planar `[C + 1, 256]` (zero outside the
/// image, and alpha's zero where the plan drops it), from the gradient of the packed image
/// `[B, H, W, C + 1]` (or `[B, H, W, C]`).
fn tile_output_gradients<E: Real>(
    plan: &CompositePlan,
    channels: usize,
    v_image: &[E],
    w: usize,
) -> Vec<E> {
    let grid = plan.grid;
    let (tx0, ty0) = plan.tile_origin(plan.tiles[w]);
    let valid = valid_pixels(plan, plan.tiles[w]);
    let mut v_planes = vec![E::ZERO; (channels + 1) * TILE_PIXELS];
    let stride = plan.image_width(channels);
    for p in 0..TILE_PIXELS {
        if !valid[p] {
            continue;
        }
        let (x, y) = (tx0 + p % TILE_SIZE, ty0 + p / TILE_SIZE);
        let pixel = (plan.batches[w] * grid.height + y) * grid.width + x;
        for k in 0..stride {
            v_planes[k * TILE_PIXELS + p] = v_image[pixel * stride + k];
        }
    }
    v_planes
}

/// The backward's walk over a tile's list, back to front: which pixels take part at each entry
/// (pixel p from entry last[p] − 1 down, when its last contributor is reached).
struct Replay {
    /// (last, pixel) of the pixels that contributed, in the order they join: last descending.
    joining: Vec<(u32, usize)>,
    joined: usize,
    /// The pixels taking part.
    replaying: RowBits,
}

impl Replay {
    /// The replay of a tile whose pixels saved these counts (`[256]`), and the number of
    /// entries it walks (the largest count).
    fn new(last: &[u32]) -> (Self, usize) {
        let mut joining: Vec<(u32, usize)> = (0..TILE_PIXELS)
            .filter(|&p| last[p] > 0)
            .map(|p| (last[p], p))
            .collect();
        joining.sort_unstable_by(|a, b| b.cmp(a));
        let entries = joining.first().map_or(0, |&(count, _)| count as usize);
        let replay = Replay {
            joining,
            joined: 0,
            replaying: [0; TILE_SIZE],
        };
        (replay, entries)
    }

    /// The pixels taking part at entry `j` (called with j descending).
    fn at(&mut self, j: usize) -> RowBits {
        while let Some(&(count, p)) = self.joining.get(self.joined)
            && count as usize > j
        {
            self.replaying[p / TILE_SIZE] |= 1 << (p % TILE_SIZE);
            self.joined += 1;
        }
        self.replaying
    }
}

/// Per list entry of one tile: [v_mx, v_my, v_a, v_b, v_c, v_o, v_values…]. `[len, 6 + C]`
fn backward_tile<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    state: &ForwardState<E>,
    v_image: &[E],
    w: usize,
) -> Vec<E> {
    let channels = splats.channels;
    let stride = 6 + channels;
    let corner = Corner::new(plan.tile_origin(plan.tiles[w]));
    let min_alpha = E::of(MIN_ALPHA);
    let max_alpha = E::of(MAX_ALPHA);
    let half = E::of(0.5);

    let (final_t, last) = state.tile(w);
    let v_planes = tile_output_gradients(plan, channels, v_image, w);

    let list = plan.list(w);
    let mut slots = vec![E::ZERO; list.len() * stride];
    let mut t = final_t.to_vec();
    let mut behind = vec![E::ZERO; channels * TILE_PIXELS]; // Σ over later contributors of f·α·T
    let mut gathered = Gathered::new(&state.footprints, list, Walk::BackToFront);
    let (mut replay, entries) = Replay::new(last);
    for j in (0..entries).rev() {
        let replaying = replay.at(j);
        let row = list[j] as usize;
        let Some((splat, xs, ys)) = gathered.get(j).on_tile(corner) else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        let slot = &mut slots[j * stride..(j + 1) * stride];
        for p in pixels_of(replaying, xs, ys) {
            let Some((dx, dy, power, exp_power)) = splat.at(p) else {
                continue;
            };
            let raw = splat.opacity * exp_power;
            let alpha = clamp_alpha(raw);
            if alpha < min_alpha {
                continue;
            }
            let keep = E::ONE - alpha;
            let t_before = t[p] / keep;
            let weight = alpha * t_before;
            // dL/dα = Σ_k v_k (f_k T_i − S_k / (1 − α)) + v_A · T_final / (1 − α)
            let mut v_alpha = v_planes[channels * TILE_PIXELS + p] * final_t[p] / keep;
            for k in 0..channels {
                let v_k = v_planes[k * TILE_PIXELS + p];
                v_alpha += v_k * (values[k] * t_before - behind[k * TILE_PIXELS + p] / keep);
                slot[6 + k] += v_k * weight;
                behind[k * TILE_PIXELS + p] += values[k] * weight;
            }
            t[p] = t_before;
            if raw > max_alpha {
                continue;
            }
            slot[5] += v_alpha * exp_power;
            if power > E::ZERO {
                continue;
            }
            let v_power = v_alpha * raw;
            slot[0] += v_power * (splat.a * dx + splat.b * dy);
            slot[1] += v_power * (splat.b * dx + splat.c * dy);
            slot[2] += -(v_power * half * dx * dx);
            slot[3] += -(v_power * dx * dy);
            slot[4] += -(v_power * half * dy * dy);
        }
    }
    slots
}

/// Every work tile's backward in 8 lanes, where `kernels` asks for them, E is f32 and the
/// processor has them; `None` otherwise.
#[cfg(target_arch = "x86_64")]
fn backward_tiles_in_lanes<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    state: &ForwardState<E>,
    v_image: &[E],
    kernels: Kernels,
) -> Option<Vec<Vec<E>>> {
    let lanes = simd::Lanes::new().filter(|_| kernels == Kernels::Lanes8)?;
    let splats = cast_ref::<_, HostSplats<f32>>(splats)?;
    let state = cast_ref::<_, ForwardState<f32>>(state)?;
    let channels = splats.channels;
    let slots: Option<Vec<Vec<f32>>> = (0..plan.tiles.len())
        .into_par_iter()
        .with_max_len(TILES_PER_TASK)
        .map(|w| {
            let v_planes = cast(tile_output_gradients(plan, channels, v_image, w))?;
            Some(lanes.backward_tile(splats, plan, state, v_planes, w))
        })
        .collect();
    cast(slots?)
}

/// No 8-lane kernels off x86-64.
#[cfg(not(target_arch = "x86_64"))]
fn backward_tiles_in_lanes<E: Real>(
    _: &HostSplats<E>,
    _: &CompositePlan,
    _: &ForwardState<E>,
    _: &[E],
    _: Kernels,
) -> Option<Vec<Vec<E>>> {
    None
}

/// Backward pass with the fastest kernels this processor runs ([`Kernels::detect`]):
/// gradients of the inputs from the gradient of the packed image `[B, H, W, C + 1]`.
pub fn backward<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    state: &ForwardState<E>,
    v_image: &[E],
) -> HostGradients<E> {
    backward_with(splats, plan, state, v_image, Kernels::detect())
}

/// [`backward`] with the given kernels.
pub fn backward_with<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    state: &ForwardState<E>,
    v_image: &[E],
    kernels: Kernels,
) -> HostGradients<E> {
    let channels = splats.channels;
    let slots: Vec<Vec<E>> = backward_tiles_in_lanes(splats, plan, state, v_image, kernels)
        .unwrap_or_else(|| {
            (0..plan.tiles.len())
                .into_par_iter()
                .with_max_len(TILES_PER_TASK)
                .map(|w| backward_tile(splats, plan, state, v_image, w))
                .collect()
        });
    gradient_sums::sum_slots(plan, &slots, splats.opacities.len(), channels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_random::uniform;

    /// What the kernels decide at a tile pixel: whether α ≥ 1/255 there (the forward's test).
    fn live<E: Real>(splat: &Splat<E>, p: usize) -> bool {
        splat
            .at(p)
            .is_some_and(|(_, _, _, e)| clamp_alpha(splat.opacity * e) >= E::of(MIN_ALPHA))
    }

    /// Splats whose α ellipse has a pixel centre right at the edge of its box (the extreme
    /// point in x or y, moved by a few millionths of the distance either way), needles to
    /// discs, opacities from just above 1/255 to 1, on tiles far from the origin. Returns how
    /// many live pixels lay beyond the box of the exact ellipse (kept only by the rounding
    /// allowance) and how many live pixels were checked.
    fn boxes_hold_every_live_pixel<E: Real>(cases: usize) -> (usize, usize) {
        let mut next = uniform(0x5eed_0b0c);
        let (mut beyond, mut checked) = (0, 0);
        for case in 0..cases {
            // Σ = R diag(λ1, λ2) Rᵀ, the smaller at the low-pass floor (needles up to 1 : 10⁶).
            let big = 0.3 * 10f64.powf(6.0 * next());
            let small = 0.3 * 10f64.powf(next());
            let angle = std::f64::consts::PI * next();
            let (s, c) = angle.sin_cos();
            let sigma = [
                big * c * c + small * s * s,
                (big - small) * s * c,
                big * s * s + small * c * c,
            ];
            let det = sigma[0] * sigma[2] - sigma[1] * sigma[1];
            let conic = [sigma[2] / det, -sigma[1] / det, sigma[0] / det].map(E::of);
            let opacity = E::of(MIN_ALPHA * 255f64.powf(next().powi(3)) * (1.0 + 1e-7));
            // The ellipse of the stored values, exactly (f64 of the E numbers).
            let [a, b, c] = conic.map(E::to_f64);
            let t = (255.0 * opacity.to_f64()).ln();
            let det = a * c - b * b;
            let (sxx, sxy, syy) = (c / det, -b / det, a / det);
            let extreme = if case % 2 == 0 {
                [sxx, sxy].map(|v| v * (2.0 * t / sxx).sqrt())
            } else {
                [sxy, syy].map(|v| v * (2.0 * t / syy).sqrt())
            };
            let sign = if next() < 0.5 { -1.0 } else { 1.0 };
            let scale = sign * (1.0 + 4e-6 * (next() - 0.5));
            let pixel = [(next() * 16.0).floor() + 0.5, (next() * 16.0).floor() + 0.5];
            let corner = [
                16.0 * (next() * 120.0).floor(),
                16.0 * (next() * 70.0).floor(),
            ];
            let mean = [0, 1].map(|i| E::of(corner[i] + pixel[i] - scale * extreme[i]));
            let splats = HostSplats {
                means: mean.to_vec(),
                conics: conic.to_vec(),
                opacities: vec![opacity],
                values: vec![E::ONE],
                channels: 1,
            };
            let footprint = Footprint::new(&splats, 0);
            let corner = Corner::new((corner[0] as usize, corner[1] as usize));
            let placed = footprint.on_tile(corner);
            let splat = Splat {
                mx: mean[0] - corner.at[0],
                my: mean[1] - corner.at[1],
                ..footprint.splat
            };
            for p in (0..TILE_PIXELS).filter(|&p| live(&splat, p)) {
                checked += 1;
                let (x, y) = (p % TILE_SIZE, p / TILE_SIZE);
                let Some((_, xs, ys)) = &placed else {
                    panic!("case {case}: pixel {p} is live, the splat has no box on the tile");
                };
                assert!(
                    xs.contains(&x) && ys.contains(&y),
                    "case {case}: live pixel ({x}, {y}) outside the box {xs:?} × {ys:?} \
                     (conic {conic:?}, opacity {opacity:?}, mean {mean:?})"
                );
                let [dx, dy] =
                    [(x, splat.mx), (y, splat.my)].map(|(p, m)| p as f64 + 0.5 - m.to_f64());
                if dx * dx > 2.0 * t * sxx || dy * dy > 2.0 * t * syy {
                    beyond += 1;
                }
            }
        }
        (beyond, checked)
    }

    /// The box skips no pixel the kernels would find α ≥ 1/255 at, in f32 (where rounding
    /// makes some pixels just outside the exact ellipse live, and the box must hold them) and
    /// in f64.
    #[test]
    fn the_box_holds_every_pixel_the_kernels_find_live() {
        let (beyond, checked) = boxes_hold_every_live_pixel::<f32>(200_000);
        assert!(checked > 100_000, "{checked} live pixels checked");
        assert!(
            beyond > 0,
            "no live pixel beyond the exact ellipse's box: the cases miss the edge"
        );
        let (_, checked) = boxes_hold_every_live_pixel::<f64>(50_000);
        assert!(checked > 20_000, "{checked} live pixels checked in f64");
    }
}
