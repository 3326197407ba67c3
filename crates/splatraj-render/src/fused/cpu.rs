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

use rayon::prelude::*;

use super::plan::CompositePlan;
use crate::rasterize::{MAX_ALPHA, MIN_ALPHA};
use crate::tiles::{TILE_PIXELS, TILE_SIZE, ceil_small, floor_small};

/// The float types the kernels run in.
pub trait Real:
    Copy
    + Send
    + Sync
    + PartialOrd
    + std::fmt::Debug
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::AddAssign
    + std::ops::Neg<Output = Self>
    + 'static
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The nearest value to `x`.
    fn of(x: f64) -> Self;
    /// e^self.
    fn exp(self) -> Self;
    /// The value as f64.
    fn to_f64(self) -> f64;
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn of(x: f64) -> Self {
        x as f32
    }
    fn exp(self) -> Self {
        f32::exp(self)
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn of(x: f64) -> Self {
        x
    }
    fn exp(self) -> Self {
        f64::exp(self)
    }
    fn to_f64(self) -> f64 {
        self
    }
}

/// Screen-space Gaussians on the host, rows b·U + u (as [`crate::rasterize::SplatInputs`]).
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
    /// T after the last contributing Gaussian, per work tile and pixel. `[work, 256]`
    pub final_t: Vec<E>,
    /// Number of list entries up to and including the last contributor. `[work, 256]`
    pub last: Vec<u32>,
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

/// One Gaussian of a list, loaded once per tile step.
#[derive(Clone, Copy)]
struct Splat<E> {
    mx: E,
    my: E,
    a: E,
    b: E,
    c: E,
    opacity: E,
    /// ln(255·o): α ≥ 1/255 needs ½dᵀ·conic·d ≤ this (NaN or negative: nowhere).
    reach: E,
    /// Below this power α < 1/255 for sure (−reach less a margin for rounding).
    skip_below: E,
}

impl<E: Real> Splat<E> {
    fn load(splats: &HostSplats<E>, row: usize, x0: E, y0: E) -> Self {
        // One logarithm per list entry, shared by the pixel box and the per-pixel skip: this
        // runs once per tile–Gaussian pair, which on real captures is about as often as pixels.
        // In f64 like the bound it feeds: α at exactly 1/255 must not round out of the box.
        let reach = E::of((255.0 * splats.opacities[row].to_f64()).ln());
        // Coordinates relative to the tile's corner keep dx, dy small (as the tensor path does
        // with its tile centre), so f32 loses nothing to cancellation.
        Splat {
            mx: splats.means[2 * row] - x0,
            my: splats.means[2 * row + 1] - y0,
            a: splats.conics[3 * row],
            b: splats.conics[3 * row + 1],
            c: splats.conics[3 * row + 2],
            opacity: splats.opacities[row],
            reach,
            skip_below: -reach - E::of(1e-3),
        }
    }

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

impl<E: Real> Splat<E> {
    /// Tile pixels `(xs, ys)` whose centre can reach α ≥ 1/255, with a pixel of margin; the
    /// rest of the tile is skipped (it would be skipped by the 1/255 rule anyway, so this
    /// changes no value and no decision). The whole tile when the bound is not finite.
    fn pixel_box(&self) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
        let [mx, my, a, b, c, t] =
            [self.mx, self.my, self.a, self.b, self.c, self.reach].map(E::to_f64);
        // ½dᵀ·conic·d ≤ t with t = ln(255·o); the ellipse's half-widths are sqrt(2t·Σ_xx),
        // sqrt(2t·Σ_yy) with Σ = conic⁻¹ (Σ_xx = c/det, Σ_yy = a/det).
        if t.is_nan() || t < 0.0 {
            return None; // o < 1/255: α < 1/255 everywhere
        }
        let det = a * c - b * b;
        let full = Some((0..TILE_SIZE, 0..TILE_SIZE));
        if det.is_nan() || det <= 0.0 {
            return full;
        }
        let half_x = (2.0 * t * c / det).sqrt();
        let half_y = (2.0 * t * a / det).sqrt();
        if !(half_x.is_finite() && half_y.is_finite() && mx.is_finite() && my.is_finite()) {
            return full;
        }
        // Pixel i's centre is i + 0.5: keep i with |i + 0.5 − m| ≤ half + 1. Clamping to the
        // tile first (integer bounds commute with floor and ceil) keeps the values small, so
        // the rounding is a cast: the baseline x86-64 target has no rounding instruction and
        // calls into libm for f64::floor/ceil, once per tile–Gaussian pair.
        let span = |m: f64, half: f64| {
            let lo = ceil_small((m - half - 1.5).clamp(0.0, TILE_SIZE as f64)) as usize;
            let hi = floor_small((m + half + 0.5).clamp(-1.0, TILE_SIZE as f64 - 1.0)) + 1;
            lo..(hi.max(lo as i64) as usize)
        };
        let (xs, ys) = (span(mx, half_x), span(my, half_y));
        (!xs.is_empty() && !ys.is_empty()).then_some((xs, ys))
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

/// Pixels of tile `tile` that lie inside the image (partial tiles at the right/bottom edge).
fn valid_pixels(plan: &CompositePlan, tile: usize) -> [bool; TILE_PIXELS] {
    let (x0, y0) = plan.tile_origin(tile);
    let mut valid = [false; TILE_PIXELS];
    for (p, v) in valid.iter_mut().enumerate() {
        *v = x0 + p % TILE_SIZE < plan.grid.width && y0 + p / TILE_SIZE < plan.grid.height;
    }
    valid
}

fn forward_tile<E: Real>(splats: &HostSplats<E>, plan: &CompositePlan, w: usize) -> TileForward<E> {
    let channels = splats.channels;
    let (x0, y0) = plan.tile_origin(plan.tiles[w]);
    let (x0, y0) = (E::of(x0 as f64), E::of(y0 as f64));
    let min_alpha = E::of(MIN_ALPHA);
    let min_t = E::of(plan.stop_transmittance);

    let mut open = valid_pixels(plan, plan.tiles[w]);
    let mut t = vec![E::ONE; TILE_PIXELS];
    let mut last = vec![0u32; TILE_PIXELS];
    let mut planes = vec![E::ZERO; (channels + 1) * TILE_PIXELS];
    let mut open_count = open.iter().filter(|&&o| o).count();
    for (j, &row) in plan.list(w).iter().enumerate() {
        if open_count == 0 {
            break;
        }
        let row = row as usize;
        let splat = Splat::load(splats, row, x0, y0);
        let Some((xs, ys)) = splat.pixel_box() else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        for p in ys.flat_map(|y| xs.clone().map(move |x| y * TILE_SIZE + x)) {
            if !open[p] {
                continue;
            }
            let Some((_, _, _, exp_power)) = splat.at(p) else {
                continue;
            };
            let alpha = clamp_alpha(splat.opacity * exp_power);
            if alpha < min_alpha {
                continue;
            }
            let t_next = t[p] * (E::ONE - alpha);
            if t_next < min_t {
                open[p] = false;
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

/// Forward pass of every work tile. Returns the packed image `[B, H, W, C + 1]` and the state.
pub fn forward<E: Real>(splats: &HostSplats<E>, plan: &CompositePlan) -> (Vec<E>, ForwardState<E>) {
    let tiles: Vec<TileForward<E>> = (0..plan.tiles.len())
        .into_par_iter()
        .map(|w| forward_tile(splats, plan, w))
        .collect();
    let channels = splats.channels;
    let grid = plan.grid;
    let mut image = vec![E::ZERO; plan.batch * grid.height * grid.width * (channels + 1)];
    let mut state = ForwardState {
        final_t: Vec::with_capacity(tiles.len() * TILE_PIXELS),
        last: Vec::with_capacity(tiles.len() * TILE_PIXELS),
    };
    for (w, tile) in tiles.into_iter().enumerate() {
        let (x0, y0) = plan.tile_origin(plan.tiles[w]);
        for p in 0..TILE_PIXELS {
            let (x, y) = (x0 + p % TILE_SIZE, y0 + p / TILE_SIZE);
            if x >= grid.width || y >= grid.height {
                continue;
            }
            let pixel = (plan.batches[w] * grid.height + y) * grid.width + x;
            for k in 0..=channels {
                image[pixel * (channels + 1) + k] = tile.planes[k * TILE_PIXELS + p];
            }
        }
        state.final_t.extend(tile.final_t);
        state.last.extend(tile.last);
    }
    (image, state)
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
    let grid = plan.grid;
    let (tx0, ty0) = plan.tile_origin(plan.tiles[w]);
    let (x0, y0) = (E::of(tx0 as f64), E::of(ty0 as f64));
    let min_alpha = E::of(MIN_ALPHA);
    let max_alpha = E::of(MAX_ALPHA);
    let half = E::of(0.5);
    let valid = valid_pixels(plan, plan.tiles[w]);

    let last = &state.last[w * TILE_PIXELS..(w + 1) * TILE_PIXELS];
    let final_t = &state.final_t[w * TILE_PIXELS..(w + 1) * TILE_PIXELS];
    // Output gradients of this tile's pixels, planar `[C + 1, 256]` (zero outside the image).
    let mut v_planes = vec![E::ZERO; (channels + 1) * TILE_PIXELS];
    for p in 0..TILE_PIXELS {
        if !valid[p] {
            continue;
        }
        let (x, y) = (tx0 + p % TILE_SIZE, ty0 + p / TILE_SIZE);
        let pixel = (plan.batches[w] * grid.height + y) * grid.width + x;
        for k in 0..=channels {
            v_planes[k * TILE_PIXELS + p] = v_image[pixel * (channels + 1) + k];
        }
    }

    let list = plan.list(w);
    let replay = last.iter().copied().max().unwrap_or(0) as usize;
    let mut slots = vec![E::ZERO; list.len() * stride];
    let mut t = final_t.to_vec();
    let mut behind = vec![E::ZERO; channels * TILE_PIXELS]; // Σ over later contributors of f·α·T
    for j in (0..replay).rev() {
        let row = list[j] as usize;
        let splat = Splat::load(splats, row, x0, y0);
        let Some((xs, ys)) = splat.pixel_box() else {
            continue;
        };
        let values = &splats.values[row * channels..(row + 1) * channels];
        let slot = &mut slots[j * stride..(j + 1) * stride];
        for p in ys.flat_map(|y| xs.clone().map(move |x| y * TILE_SIZE + x)) {
            if j as u32 >= last[p] {
                continue;
            }
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

/// Backward pass: gradients of the inputs from the gradient of the packed image `[B, H, W, C + 1]`.
pub fn backward<E: Real>(
    splats: &HostSplats<E>,
    plan: &CompositePlan,
    state: &ForwardState<E>,
    v_image: &[E],
) -> HostGradients<E> {
    let channels = splats.channels;
    let stride = 6 + channels;
    let slots: Vec<Vec<E>> = (0..plan.tiles.len())
        .into_par_iter()
        .map(|w| backward_tile(splats, plan, state, v_image, w))
        .collect();
    let rows = splats.opacities.len();
    let mut v = HostGradients {
        means: vec![E::ZERO; 2 * rows],
        conics: vec![E::ZERO; 3 * rows],
        opacities: vec![E::ZERO; rows],
        values: vec![E::ZERO; channels * rows],
    };
    // Fixed order (work tiles in plan order, list entries front to back): deterministic sums.
    for (w, tile_slots) in slots.iter().enumerate() {
        for (j, &row) in plan.list(w).iter().enumerate() {
            let row = row as usize;
            let slot = &tile_slots[j * stride..(j + 1) * stride];
            v.means[2 * row] += slot[0];
            v.means[2 * row + 1] += slot[1];
            v.conics[3 * row] += slot[2];
            v.conics[3 * row + 1] += slot[3];
            v.conics[3 * row + 2] += slot[4];
            v.opacities[row] += slot[5];
            for k in 0..channels {
                v.values[channels * row + k] += slot[6 + k];
            }
        }
    }
    v
}
