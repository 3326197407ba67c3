//! The fused compositing kernels on the GPU backend (`CubeBackend`: wgpu and any CubeCL runtime, under burn's fusion: [`super::fusion`]):
//! the same rules, saved state and back-to-front replay as the host kernels ([`super::cpu`]),
//! written as CubeCL kernels with one cube (workgroup) of 256 units per work tile, one unit
//! per pixel.
//!
//! - Forward: the tile's list is staged through shared memory 256 Gaussians at a time; each
//!   unit composites its pixel and keeps its final T and the count of list entries up to its
//!   last contributor. A tile stops once none of its pixels is open.
//! - Backward: every unit replays its pixel back to front from the saved state, the list's rows
//!   staged through shared memory 64 entries at a time; per list entry the tile's 256
//!   contributions are summed in a fixed order in shared memory (two levels, one or two
//!   barriers per entry: [`EntrySums`]) into that entry's gradient slot, and a second kernel
//!   sums each Gaussian's slots in plan order (the host built the map from Gaussian to its
//!   slots). No atomics, so the result is the same on every run.
//! - Long lists are cut into segments ([`super::segments`]), one cube each: the forward still
//!   composites a tile's whole list in the cube of its first segment and saves each segment's
//!   state on the way; the backward replays the segments in parallel.
//!
//! The tile lists are built on the host (binning is cheapest there: it is a per-pose sort the
//! host already does for its decisions) and uploaded each pass as three integer tensors. f64 is
//! not a GPU type on most devices: an f64 pass runs the host kernels instead.

use std::sync::Arc;

use burn::backend::TensorMetadata;
use burn::backend::tensor::FloatTensor;
use burn::tensor::{DType, IntDType, TensorData};
use burn_backend::cubecl::dtype_to_storage_type;
use burn_backend::ops::{FloatTensorOps, IntTensorOps};
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;
use burn_cubecl::{CubeDevice, cubecl};

use super::plan::CompositePlan;
use super::segments::{SEGMENT_COLUMNS, Segments};
use super::{CompositeKernels, ForwardUse, HostSaved, SplatPrimitives, host_backward};
use super::{host_pool, launch_grid};
use crate::rasterize::{AlphaChannel, MAX_ALPHA, MIN_ALPHA};
use crate::tiles::TILE_PIXELS;

/// Gradient slot width of one list entry: [v_mx, v_my, v_a, v_b, v_c, v_o, v_values…].
const fn slot_width(channels: usize) -> usize {
    6 + channels
}

/// Pixels summed by one unit in the first level of the backward's per-entry sum.
const GROUP_PIXELS: usize = 8;

/// Groups of [`GROUP_PIXELS`] in a tile: the second level's terms.
const GROUPS: usize = TILE_PIXELS / GROUP_PIXELS;

/// List entries the backward stages in shared memory at once: 64 keeps a pass of up to four
/// channels (rows, values, the per-entry sums, the replay's maximum) within WebGPU's default
/// 16 KiB of workgroup memory.
const STAGED_ENTRIES: usize = 64;

/// How the backward sums each list entry's contributions over the tile's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EntrySums {
    /// Contributions, group sums and the sum of the groups of one entry, then the next: two
    /// barriers per entry, one buffer.
    OneAtATime,
    /// The three steps of three consecutive entries between the same barriers: one barrier
    /// per entry, two buffers (more workgroup memory).
    Pipelined,
}

impl EntrySums {
    /// Buffers of contributions and of group sums held at once.
    pub const fn buffers(self) -> usize {
        match self {
            EntrySums::OneAtATime => 1,
            EntrySums::Pipelined => 2,
        }
    }

    /// Steps from an entry's contributions to its group sums (and again to their sum).
    pub const fn lag(self) -> usize {
        match self {
            EntrySums::OneAtATime => 0,
            EntrySums::Pipelined => 1,
        }
    }

    /// Workgroup memory the backward kernel declares for `channels` channels, bytes (f32):
    /// the staged rows and values, the contributions, the group sums, the replay's maximum.
    pub const fn shared_bytes(self, channels: usize) -> usize {
        let stride = channels + 6;
        4 * (STAGED_ENTRIES * stride
            + self.buffers() * (TILE_PIXELS + GROUPS) * stride
            + TILE_PIXELS)
    }

    /// Pipelined where the device's workgroup memory holds it, else one entry at a time;
    /// [`ENTRY_SUMS_VARIABLE`] may ask for one entry at a time everywhere.
    pub fn fitting(channels: usize, max_shared_bytes: usize) -> EntrySums {
        let asked = *ASKED_ENTRY_SUMS.get_or_init(asked_entry_sums);
        if asked == EntrySums::Pipelined
            && EntrySums::Pipelined.shared_bytes(channels) <= max_shared_bytes
        {
            EntrySums::Pipelined
        } else {
            EntrySums::OneAtATime
        }
    }
}

/// Environment variable that picks the backward's entry sums, `one-at-a-time` or `pipelined`
/// (the default): for measuring both on a GPU (`scripts/gpu_check.sh`), not for runs.
pub const ENTRY_SUMS_VARIABLE: &str = "SPLATRAJ_ENTRY_SUMS";

static ASKED_ENTRY_SUMS: std::sync::OnceLock<EntrySums> = std::sync::OnceLock::new();

fn asked_entry_sums() -> EntrySums {
    match std::env::var(ENTRY_SUMS_VARIABLE).as_deref() {
        Ok("one-at-a-time") => EntrySums::OneAtATime,
        Ok("pipelined") | Err(_) => EntrySums::Pipelined,
        Ok(other) => {
            tracing::warn!(
                "{ENTRY_SUMS_VARIABLE}={other:?} is neither `one-at-a-time` nor `pipelined`; \
                 the backward stays pipelined"
            );
            EntrySums::Pipelined
        }
    }
}

/// Whether the compositing kernels' global-memory indices are guarded at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IndexChecks {
    /// CubeCL's checked launch (the default): every index into a buffer is compared with its
    /// length (a read past it gives 0, a write is dropped), and on WGSL every loop is bounded.
    Guarded,
    /// CubeCL's unchecked launch: no guard. Every index of these kernels stays within its
    /// buffer by construction (tile pixels outside the image are skipped by `inside`, list
    /// entries by their segment's bounds); `tests/backend.rs` passes both ways on lavapipe.
    Trusted,
}

/// Environment variable that launches the compositing kernels unchecked (`trusted`; the
/// default is `guarded`): for measuring what the guards cost on a GPU (`scripts/gpu_check.sh`),
/// not for runs.
pub const INDEX_CHECKS_VARIABLE: &str = "SPLATRAJ_INDEX_CHECKS";

static ASKED_INDEX_CHECKS: std::sync::OnceLock<IndexChecks> = std::sync::OnceLock::new();

/// The index checks [`INDEX_CHECKS_VARIABLE`] asks for.
pub fn index_checks() -> IndexChecks {
    *ASKED_INDEX_CHECKS.get_or_init(|| match std::env::var(INDEX_CHECKS_VARIABLE).as_deref() {
        Ok("trusted") => IndexChecks::Trusted,
        Ok("guarded") | Err(_) => IndexChecks::Guarded,
        Ok(other) => {
            tracing::warn!(
                "{INDEX_CHECKS_VARIABLE}={other:?} is neither `trusted` nor `guarded`; the \
                 compositing kernels stay guarded"
            );
            IndexChecks::Guarded
        }
    })
}

/// Launches a compositing kernel checked or unchecked, as [`index_checks`] says.
macro_rules! launch_compositing {
    ($kernel:ident, $($arg:expr),* $(,)?) => {
        match index_checks() {
            IndexChecks::Guarded => $kernel::launch($($arg),*),
            // SAFETY: the kernels index only within their buffers (see `IndexChecks::Trusted`).
            IndexChecks::Trusted => unsafe { $kernel::launch_unchecked($($arg),*) },
        }
    };
}

/// The workgroup memory of `device` in bytes: None on the host backends.
fn max_shared_bytes(device: &burn::tensor::Device) -> Option<usize> {
    crate::backend::cube_device(device)
        .map(|cube| cube.client().properties().hardware.max_shared_memory_size)
}

/// How the backward sums entries on `device` (a GPU device of the wgpu backend; None on the
/// host backends) for `channels` channels.
pub fn entry_sums_on(device: &burn::tensor::Device, channels: usize) -> Option<EntrySums> {
    max_shared_bytes(device).map(|max| EntrySums::fitting(channels, max))
}

/// Workgroup memory the forward kernel declares for `channels` channels, bytes (f32): the
/// staged rows (six values) and channel values of 256 entries, and the tile's open flag.
pub const fn forward_shared_bytes(channels: usize) -> usize {
    4 * (TILE_PIXELS * (6 + channels) + 1)
}

/// The most channels one composite may take on `device` (None on the host backends, which
/// have no such limit): the forward and the backward (one entry at a time) of that many fit
/// its workgroup memory; at least 1. More channels are composited in groups
/// ([`super::composite_packed`]).
pub fn channels_per_composite(device: &burn::tensor::Device) -> Option<usize> {
    max_shared_bytes(device).map(channels_within)
}

/// The most channels whose forward and backward kernels fit `max_shared` bytes, at least 1.
fn channels_within(max_shared: usize) -> usize {
    (1..=4096)
        .take_while(|&c| {
            forward_shared_bytes(c) <= max_shared
                && EntrySums::OneAtATime.shared_bytes(c) <= max_shared
        })
        .last()
        .unwrap_or(1)
}

/// Work tile index of this cube (the launch grid is 2D past its per-axis cap:
/// [`super::launch_grid`]).
#[cube]
fn work_index() -> usize {
    CUBE_POS_Y as usize * CUBE_COUNT_X as usize + CUBE_POS_X as usize
}

/// Where unit `p` of work tile `w` sits: its pose, its pixel and whether that pixel lies in
/// the image, and its centre relative to the tile corner (the host kernels' coordinates).
#[derive(CubeType)]
struct TilePixel<F: Float> {
    pose: u32,
    x: u32,
    y: u32,
    inside: bool,
    px: F,
    py: F,
    x0: F,
    y0: F,
}

#[cube]
fn tile_pixel<F: Float, I: Int>(
    work: &Tensor<I>,
    w: usize,
    p: usize,
    width: u32,
    height: u32,
) -> TilePixel<F> {
    let x0 = u32::cast_from(work[SEGMENT_COLUMNS * w + 1]);
    let y0 = u32::cast_from(work[SEGMENT_COLUMNS * w + 2]);
    let x = x0 + (p % 16) as u32;
    let y = y0 + (p / 16) as u32;
    TilePixel::<F> {
        pose: u32::cast_from(work[SEGMENT_COLUMNS * w]),
        x,
        y,
        inside: x < width && y < height,
        px: F::cast_from((p % 16) as u32) + F::new(0.5),
        py: F::cast_from((p / 16) as u32) + F::new(0.5),
        x0: F::cast_from(x0),
        y0: F::cast_from(y0),
    }
}

#[cube(launch, launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn forward_kernel<F: Float, I: Int>(
    splats: &Tensor<F>,      // [R, S]: u, v, conic a, b, c, opacity, …
    values: &Tensor<F>,      // [R, C]
    work: &Tensor<I>,        // [segments, 5]: pose, tile corner x, y, tile's first segment, count
    starts: &Tensor<I>,      // [segments + 1]
    rows: &Tensor<I>,        // [pairs]
    image: &mut Tensor<F>,   // [B, H, W, C + 1], or [B, H, W, C] where alpha is dropped
    final_t: &mut Tensor<F>, // [segments, 256]: T at each segment's end
    last: &mut Tensor<I>,    // [segments, 256]: entries up to the last contributor, per segment
    partial: &mut Tensor<F>, // [segments, 256, C] where tiles are cut, else [1]
    stop_t: f32,
    work_count: u32,
    width: u32,
    height: u32,
    columns: u32,
    segment_entries: u32,
    #[comptime] channels: usize,
    #[comptime] alpha: AlphaChannel,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    // One cube per segment, but a tile's list is composited whole, front to back, by the cube
    // of its first segment: the forward is cheap per entry, and what its segments' backwards
    // need (T at each segment's end, its last contributor, its sums) falls out on the way.
    let w = work_index();
    if w >= work_count as usize {
        terminate!();
    }
    let first_segment = u32::cast_from(work[SEGMENT_COLUMNS * w + 3]) as usize;
    let segment_count = u32::cast_from(work[SEGMENT_COLUMNS * w + 4]) as usize;
    if w != first_segment {
        terminate!();
    }
    let p = UNIT_POS as usize;
    let at = tile_pixel::<F, I>(work, w, p, width, height);
    let (pose, x, y, inside) = (at.pose, at.x, at.y, at.inside);
    let (px, py, x0f, y0f) = (at.px, at.py, at.x0, at.y0);

    let mut open = inside;
    let mut t = F::new(1.0);
    // Per segment: entries up to its last contributor, and its sums; `totals` the tile's.
    let mut last_entry = 0u32;
    let mut sums = Array::<F>::new(channels);
    let mut totals = Array::<F>::new(channels);
    for k in 0..channels {
        sums[k] = F::new(0.0);
        totals[k] = F::new(0.0);
    }
    let start = u32::cast_from(starts[w]) as usize;
    let end = u32::cast_from(starts[w + segment_count]) as usize;
    let mut segment = 0usize;
    let mut segment_start = start;
    let mut sh_mx = Shared::<[F]>::new_slice(256usize);
    let mut sh_my = Shared::<[F]>::new_slice(256usize);
    let mut sh_a = Shared::<[F]>::new_slice(256usize);
    let mut sh_b = Shared::<[F]>::new_slice(256usize);
    let mut sh_c = Shared::<[F]>::new_slice(256usize);
    let mut sh_o = Shared::<[F]>::new_slice(256usize);
    let mut sh_values = Shared::<[F]>::new_slice(comptime!(256usize * channels));
    let mut sh_open = Shared::<[u32]>::new_slice(1usize);

    let mut first = start;
    while first < end {
        // Stop the tile once no pixel is open (uniform across the cube: read after a barrier).
        if p == 0 {
            sh_open[0] = 0u32;
        }
        sync_cube();
        if open {
            sh_open[0] = 1u32;
        }
        sync_cube();
        if sh_open[0] == 0u32 {
            break;
        }
        let j = first + p;
        if j < end {
            let row = u32::cast_from(rows[j]) as usize;
            let at = row * columns as usize;
            sh_mx[p] = splats[at] - x0f;
            sh_my[p] = splats[at + 1] - y0f;
            sh_a[p] = splats[at + 2];
            sh_b[p] = splats[at + 3];
            sh_c[p] = splats[at + 4];
            sh_o[p] = splats[at + 5];
            for k in 0..channels {
                sh_values[k * 256 + p] = values[row * channels + k];
            }
        }
        sync_cube();
        let count = min(end - first, 256usize);
        for i in 0..count {
            if open {
                let dx = px - sh_mx[i];
                let dy = py - sh_my[i];
                let power = F::new(0.0)
                    - F::new(0.5) * (sh_a[i] * dx * dx + sh_c[i] * dy * dy)
                    - sh_b[i] * dx * dy;
                let alpha = min(
                    sh_o[i] * F::exp(min(power, F::new(0.0))),
                    F::new(MAX_ALPHA as f32),
                );
                if alpha >= F::new(MIN_ALPHA as f32) {
                    let t_next = t * (F::new(1.0) - alpha);
                    if t_next < F::cast_from(stop_t) {
                        open = false;
                    } else {
                        let weight = alpha * t;
                        for k in 0..channels {
                            sums[k] += sh_values[k * 256 + i] * weight;
                        }
                        t = t_next;
                        last_entry = (first - segment_start + i + 1) as u32;
                    }
                }
            }
        }
        sync_cube();
        first += 256;
        // A segment ends between stages (its length is whole stages, [`Segments::of`]).
        if first < end && first == segment_start + segment_entries as usize {
            let at = first_segment + segment;
            final_t[at * 256 + p] = t;
            last[at * 256 + p] = I::cast_from(last_entry);
            for k in 0..channels {
                partial[(at * 256 + p) * channels + k] = sums[k];
                totals[k] += sums[k];
                sums[k] = F::new(0.0);
            }
            last_entry = 0u32;
            segment += 1;
            segment_start = first;
        }
    }

    // The segment the loop ended in, and those after it (a tile whose pixels all stopped
    // ends early): they composited nothing past here, and T stays where it stopped.
    for j in segment..segment_count {
        let at = first_segment + j;
        final_t[at * 256 + p] = t;
        let mine = j == segment;
        last[at * 256 + p] = I::cast_from(if mine { last_entry } else { 0u32 });
        if segment_count > 1 {
            for k in 0..channels {
                partial[(at * 256 + p) * channels + k] = if mine { sums[k] } else { F::new(0.0) };
            }
        }
    }
    if inside {
        let pixel = ((pose * height + y) * width + x) as usize;
        let image_width = comptime!(alpha.image_width(channels));
        for k in 0..channels {
            image[pixel * image_width + k] = totals[k] + sums[k];
        }
        if comptime!(alpha == AlphaChannel::Returned) {
            image[pixel * image_width + channels] = F::new(1.0) - t;
        }
    }
}

#[cube(launch, launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn backward_kernel<F: Float, I: Int>(
    splats: &Tensor<F>,    // [R, S]
    values: &Tensor<F>,    // [R, C]
    work: &Tensor<I>,      // [segments, 5]
    starts: &Tensor<I>,    // [segments + 1]
    rows: &Tensor<I>,      // [pairs]
    final_t: &Tensor<F>,   // [segments, 256]
    last: &Tensor<I>,      // [segments, 256]
    partial: &Tensor<F>,   // [segments, 256, C] where tiles are cut, else [1]
    v_image: &Tensor<F>,   // [B, H, W, C + 1], or [B, H, W, C] where alpha is dropped
    slots: &mut Tensor<F>, // [pairs, 6 + C]
    work_count: u32,
    width: u32,
    height: u32,
    columns: u32,
    #[comptime] channels: usize,
    #[comptime] alpha: AlphaChannel,
    #[comptime] schedule: EntrySums,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let w = work_index();
    if w >= work_count as usize {
        terminate!();
    }
    let stride = comptime!(channels + 6);
    let p = UNIT_POS as usize;
    let at = tile_pixel::<F, I>(work, w, p, width, height);
    let (pose, x, y, inside) = (at.pose, at.x, at.y, at.inside);
    let (px, py, x0f, y0f) = (at.px, at.py, at.x0, at.y0);

    // The pixel's output gradients (zero outside the image) and replay state.
    let mut v_out = Array::<F>::new(comptime!(channels + 1));
    let mut behind = Array::<F>::new(channels); // Σ over later contributors of f·α·T
    for k in 0..comptime!(channels + 1) {
        v_out[k] = F::new(0.0);
    }
    for k in 0..channels {
        behind[k] = F::new(0.0);
    }
    // Alpha's gradient stays zero where the output has no alpha.
    if inside {
        let pixel = ((pose * height + y) * width + x) as usize;
        let image_width = comptime!(alpha.image_width(channels));
        for k in 0..image_width {
            v_out[k] = v_image[pixel * image_width + k];
        }
    }
    // A segment replays from the transmittance at its own end, with the colour the later
    // segments of its tile composited behind it; alpha's gradient needs the pixel's final T.
    let first_segment = u32::cast_from(work[SEGMENT_COLUMNS * w + 3]) as usize;
    let segment_count = u32::cast_from(work[SEGMENT_COLUMNS * w + 4]) as usize;
    for j in w - first_segment + 1..segment_count {
        for k in 0..channels {
            behind[k] += partial[((first_segment + j) * 256 + p) * channels + k];
        }
    }
    let t_final = final_t[(first_segment + segment_count - 1) * 256 + p];
    let mut t = final_t[w * 256 + p];
    let my_last = u32::cast_from(last[w * 256 + p]) as usize;

    // The tile replays from its deepest last contributor: a max over the cube.
    let mut sh_last = Shared::<[u32]>::new_slice(256usize);
    sh_last[p] = my_last as u32;
    sync_cube();
    let mut half = 128usize;
    while half > 0 {
        if p < half {
            let other = sh_last[p + half];
            if other > sh_last[p] {
                sh_last[p] = other;
            }
        }
        sync_cube();
        half /= 2;
    }
    let replay = sh_last[0] as usize;
    let start = u32::cast_from(starts[w]) as usize;

    // Each list entry goes through three steps: every unit's contribution (the replay), the
    // sums of 8-pixel groups, the sums of the groups. One at a time, the three are separated
    // by two barriers per entry. Pipelined, step e computes entry e, sums the groups of entry
    // e − 1 and the group sums of entry e − 2, and ends at one barrier (one per entry): each
    // step reads the buffers the step before it wrote and writes the other ones.
    let pipelined = comptime!(schedule == EntrySums::Pipelined);
    let buffers = comptime!(schedule.buffers());
    let lag = comptime!(schedule.lag());

    // The replayed entries' rows, staged [`STAGED_ENTRIES`] at a time (as the forward stages
    // its lists): read per entry from global memory, a row index then the row it names were
    // two dependent loads on every entry's path, which every unit of the tile waits for.
    let mut sh_rows = Shared::<[F]>::new_slice(comptime!(STAGED_ENTRIES * 6));
    let mut sh_values = Shared::<[F]>::new_slice(comptime!(STAGED_ENTRIES * channels));
    let mut sh_sum = Shared::<[F]>::new_slice(comptime!(buffers * TILE_PIXELS * (channels + 6)));
    let mut sh_group = Shared::<[F]>::new_slice(comptime!(buffers * GROUPS * (channels + 6)));
    // One loop over steps, not a loop of stages around a loop of entries: llvmpipe (lavapipe)
    // ends every loop of an invocation once all its loops together have made 65 535
    // iterations (LP_MAX_TGSI_LOOP_ITERATIONS, one counter shared by every loop), so each
    // iteration spent here shortens the longest list it can replay.
    let mut e = 0usize;
    while e < replay + 2 * lag {
        if e < replay {
            let s = e % STAGED_ENTRIES;
            if s == 0 {
                // Safe without a barrier before it: every read of the previous stage came
                // before the barrier that ended its last entry's step.
                let count = min(replay - e, STAGED_ENTRIES);
                if p < count {
                    let row = u32::cast_from(rows[start + replay - 1 - (e + p)]) as usize;
                    let at = row * columns as usize;
                    sh_rows[p * 6] = splats[at] - x0f;
                    sh_rows[p * 6 + 1] = splats[at + 1] - y0f;
                    #[unroll]
                    for q in 2..6usize {
                        sh_rows[p * 6 + q] = splats[at + q];
                    }
                    for k in 0..channels {
                        sh_values[k * STAGED_ENTRIES + p] = values[row * channels + k];
                    }
                }
                sync_cube();
            }
            let j = replay - 1 - e;
            let sum_at = (e % buffers) * comptime!(TILE_PIXELS * (channels + 6));
            let mx = sh_rows[s * 6];
            let my = sh_rows[s * 6 + 1];
            let a = sh_rows[s * 6 + 2];
            let b = sh_rows[s * 6 + 3];
            let c = sh_rows[s * 6 + 4];
            let o = sh_rows[s * 6 + 5];
            for k in 0..stride {
                sh_sum[sum_at + k * 256 + p] = F::new(0.0);
            }
            if j < my_last {
                let dx = px - mx;
                let dy = py - my;
                let power = F::new(0.0) - F::new(0.5) * (a * dx * dx + c * dy * dy) - b * dx * dy;
                let exp_power = F::exp(min(power, F::new(0.0)));
                let raw = o * exp_power;
                let alpha = min(raw, F::new(MAX_ALPHA as f32));
                if alpha >= F::new(MIN_ALPHA as f32) {
                    let keep = F::new(1.0) - alpha;
                    let t_before = t / keep;
                    let weight = alpha * t_before;
                    // dL/dα = Σ_k v_k (f_k T_i − S_k / (1 − α)) + v_A · T_final / (1 − α)
                    let mut v_alpha = v_out[channels] * t_final / keep;
                    for k in 0..channels {
                        let value = sh_values[k * STAGED_ENTRIES + s];
                        v_alpha += v_out[k] * (value * t_before - behind[k] / keep);
                        sh_sum[sum_at + (6 + k) * 256 + p] = v_out[k] * weight;
                        behind[k] += value * weight;
                    }
                    t = t_before;
                    if raw <= F::new(MAX_ALPHA as f32) {
                        sh_sum[sum_at + 5usize * 256 + p] = v_alpha * exp_power;
                        if power <= F::new(0.0) {
                            let v_power = v_alpha * raw;
                            sh_sum[sum_at + p] = v_power * (a * dx + b * dy);
                            sh_sum[sum_at + 256 + p] = v_power * (b * dx + c * dy);
                            sh_sum[sum_at + 2usize * 256 + p] =
                                F::new(0.0) - v_power * F::new(0.5) * dx * dx;
                            sh_sum[sum_at + 3usize * 256 + p] = F::new(0.0) - v_power * dx * dy;
                            sh_sum[sum_at + 4usize * 256 + p] =
                                F::new(0.0) - v_power * F::new(0.5) * dy * dy;
                        }
                    }
                }
            }
        }
        if !pipelined {
            sync_cube();
        }
        // A fixed two-level sum over the tile's pixels (the same sum on every run): 32 groups
        // of 8 pixels per component, then the 32 groups. A binary tree took ten barriers; on
        // a GPU the barriers, not the adds, bound this loop. Both levels are unrolled at
        // compile time: the second level's 31 loads are then issued together instead of one
        // after another while the whole tile waits for them, and no loop iteration is spent.
        if e >= lag && e - lag < replay {
            let sum_at = ((e - lag) % buffers) * comptime!(TILE_PIXELS * (channels + 6));
            let group_at = ((e - lag) % buffers) * comptime!(GROUPS * (channels + 6));
            #[unroll]
            for r in 0..comptime!((GROUPS * (channels + 6)).div_ceil(256)) {
                // u = k·32 + g: component k, pixels 8g … 8g + 7.
                let u = p + r * 256;
                if u < comptime!(GROUPS * (channels + 6)) {
                    let base = sum_at + (u / GROUPS) * 256 + (u % GROUPS) * GROUP_PIXELS;
                    let mut sum = sh_sum[base];
                    #[unroll]
                    for q in 1..GROUP_PIXELS {
                        sum += sh_sum[base + q];
                    }
                    sh_group[group_at + u] = sum;
                }
            }
        }
        if !pipelined {
            sync_cube();
        }
        // Safe without a barrier after it, one at a time: the next entry writes `sh_group`
        // only after its own first barrier.
        if e >= 2 * lag && e - 2 * lag < replay && p < stride {
            let group_at = ((e - 2 * lag) % buffers) * comptime!(GROUPS * (channels + 6));
            let mut sum = sh_group[group_at + p * GROUPS];
            #[unroll]
            for g in 1..GROUPS {
                sum += sh_group[group_at + p * GROUPS + g];
            }
            slots[(start + replay - 1 - (e - 2 * lag)) * stride + p] = sum;
        }
        if pipelined {
            sync_cube();
        }
        e += 1;
    }
    // The entries past the replay contribute nothing: their slots are written as zeros here,
    // so that the slots are allocated empty (no fill launch) and every one is still written.
    let len = u32::cast_from(starts[w + 1]) as usize - start;
    let mut j = replay + p;
    while j < len {
        for k in 0..stride {
            slots[(start + j) * stride + k] = F::new(0.0);
        }
        j += TILE_PIXELS;
    }
}

#[cube(launch, launch_unchecked)]
#[allow(clippy::too_many_arguments)]
fn gather_kernel<F: Float, I: Int>(
    slots: &Tensor<F>,        // [pairs, 6 + C]
    slot_order: &Tensor<I>,   // [pairs]: slots grouped by row, in plan order within a row
    slot_starts: &Tensor<I>,  // [R + 1]
    v_splats: &mut Tensor<F>, // [R, S]; columns past the sixth 0
    v_values: &mut Tensor<F>, // [R, C]
    row_count: u32,
    columns: u32,
    #[comptime] channels: usize,
    #[define(F, I)] _dtypes: [ElemType; 2],
) {
    let row = ABSOLUTE_POS;
    if row >= row_count as usize {
        terminate!();
    }
    let stride = comptime!(channels + 6);
    let mut sums = Array::<F>::new(comptime!(channels + 6));
    for k in 0..stride {
        sums[k] = F::new(0.0);
    }
    let from = u32::cast_from(slot_starts[row]) as usize;
    let to = u32::cast_from(slot_starts[row + 1]) as usize;
    for i in from..to {
        let slot = u32::cast_from(slot_order[i]) as usize;
        for k in 0..stride {
            sums[k] += slots[slot * stride + k];
        }
    }
    // Slots hold [v_mx, v_my, v_a, v_b, v_c, v_o, …]: the splat row's first six columns.
    let at = row * columns as usize;
    for k in 0..6usize {
        v_splats[at + k] = sums[k];
    }
    // Every element written: the buffer is allocated empty, with no fill launch.
    for k in 6..columns as usize {
        v_splats[at + k] = F::new(0.0);
    }
    for k in 0..channels {
        v_values[row * channels + k] = sums[6 + k];
    }
}

/// What the GPU forward pass keeps for its backward.
#[derive(Debug, Clone)]
pub struct DeviceSaved {
    /// Splat rows and channel values.
    inputs: [CubeTensor; 2],
    plan: Arc<CompositePlan>,
    lists: PlanTensors,
    final_t: CubeTensor,
    last: CubeTensor,
    /// Each segment's sums where tiles were cut (else a placeholder).
    partial: CubeTensor,
}

/// The backward state: on the device, or on the host for f64 passes.
#[derive(Debug, Clone)]
pub enum CubeSaved {
    /// f32 (and f16/bf16) passes: state on the device.
    Device(Box<DeviceSaved>),
    /// f64 passes: the host kernels' state.
    Host(HostSaved),
}

/// The tile lists of a plan, cut into segments, as device tensors.
#[derive(Debug, Clone)]
struct PlanTensors {
    work: CubeTensor,
    starts: CubeTensor,
    rows: CubeTensor,
    /// Segments ([`Segments::len`]).
    count: usize,
    /// Whether any tile was cut.
    cut: bool,
    /// Entries of a segment (its tile's last may hold fewer).
    segment_entries: usize,
}

/// An i32 device tensor (never empty: a kernel argument needs a buffer).
pub(crate) fn int_tensor(values: Vec<i32>, device: &CubeDevice) -> CubeTensor {
    let values = if values.is_empty() { vec![0] } else { values };
    let len = values.len();
    crate::counters::upload(4 * len);
    CubeBackend::int_from_data(TensorData::new(values, [len]), device)
}

fn upload_plan(plan: &CompositePlan, used: ForwardUse, device: &CubeDevice) -> PlanTensors {
    let segments = Segments::for_forward(plan, used);
    let (count, cut, segment_entries) = (segments.len(), segments.cut, segments.entries);
    crate::counters::segments(count);
    PlanTensors {
        work: int_tensor(segments.work, device),
        starts: int_tensor(segments.starts, device),
        rows: int_tensor(host_pool::i32s(&plan.rows), device),
        count,
        cut,
        segment_entries,
    }
}

fn zeros(shape: Vec<usize>, device: &CubeDevice, dtype: DType) -> CubeTensor {
    CubeBackend::float_zeros(shape.into(), device, dtype.into())
}

fn device_forward(
    inputs: SplatPrimitives<CubeBackend>,
    plan: Arc<CompositePlan>,
    used: ForwardUse,
) -> (CubeTensor, DeviceSaved) {
    let inputs = [inputs.splats, inputs.values].map(into_contiguous);
    let device = inputs[0].device.clone();
    let client = inputs[0].client.clone();
    let dtype = inputs[0].dtype;
    let columns = inputs[0].shape().dims::<2>()[1];
    let channels = inputs[1].shape().dims::<2>()[1];
    let grid = plan.grid;
    let lists = upload_plan(&plan, used, &device);
    let work_count = lists.count;
    let image = zeros(
        vec![
            plan.batch(),
            grid.height,
            grid.width,
            plan.image_width(channels),
        ],
        &device,
        dtype,
    );
    // The kernel writes both for every pixel of every work tile: neither a fill launch nor an
    // upload of zeros (4 bytes a pixel of every work tile) is needed.
    let final_t = CubeBackend::float_empty(
        vec![work_count.max(1), TILE_PIXELS].into(),
        &device,
        dtype.into(),
    );
    let last = CubeBackend::int_empty(
        vec![work_count.max(1) * TILE_PIXELS].into(),
        &device,
        IntDType::I32,
    );
    // Where tiles are cut: each segment's sums, written by the forward for every pixel.
    let partial = CubeBackend::float_empty(
        vec![
            if lists.cut {
                work_count * TILE_PIXELS * channels
            } else {
                1
            }
            .max(1),
        ]
        .into(),
        &device,
        dtype.into(),
    );
    if work_count > 0 {
        launch_compositing!(
            forward_kernel,
            &client,
            launch_grid::linear(work_count),
            CubeDim::new_1d(TILE_PIXELS as u32),
            inputs[0].clone().into_tensor_arg(),
            inputs[1].clone().into_tensor_arg(),
            lists.work.clone().into_tensor_arg(),
            lists.starts.clone().into_tensor_arg(),
            lists.rows.clone().into_tensor_arg(),
            image.clone().into_tensor_arg(),
            final_t.clone().into_tensor_arg(),
            last.clone().into_tensor_arg(),
            partial.clone().into_tensor_arg(),
            plan.stop_transmittance as f32,
            work_count as u32,
            grid.width as u32,
            grid.height as u32,
            columns as u32,
            lists.segment_entries as u32,
            channels,
            plan.alpha,
            [
                dtype_to_storage_type(dtype),
                dtype_to_storage_type(last.dtype),
            ],
        );
    }
    let saved = DeviceSaved {
        inputs,
        plan,
        lists,
        final_t,
        last,
        partial,
    };
    (image, saved)
}

fn device_backward(saved: DeviceSaved, v_image: CubeTensor) -> SplatPrimitives<CubeBackend> {
    let v_image = into_contiguous(v_image);
    let DeviceSaved {
        inputs,
        plan,
        lists,
        final_t,
        last,
        partial,
    } = saved;
    let device = inputs[0].device.clone();
    let client = inputs[0].client.clone();
    let dtype = inputs[0].dtype;
    let [rows, columns] = inputs[0].shape().dims::<2>();
    let channels = inputs[1].shape().dims::<2>()[1];
    let grid = plan.grid;
    let work_count = lists.count;
    let pairs = plan.rows.len();
    // Written whole by the backward kernel (every list entry's slot, replayed or not).
    let slots = CubeBackend::float_empty(
        vec![pairs.max(1), slot_width(channels)].into(),
        &device,
        dtype.into(),
    );
    let int_dtype = dtype_to_storage_type(last.dtype);
    if work_count > 0 {
        launch_compositing!(
            backward_kernel,
            &client,
            launch_grid::linear(work_count),
            CubeDim::new_1d(TILE_PIXELS as u32),
            inputs[0].clone().into_tensor_arg(),
            inputs[1].clone().into_tensor_arg(),
            lists.work.into_tensor_arg(),
            lists.starts.into_tensor_arg(),
            lists.rows.into_tensor_arg(),
            final_t.into_tensor_arg(),
            last.into_tensor_arg(),
            partial.into_tensor_arg(),
            v_image.into_tensor_arg(),
            slots.clone().into_tensor_arg(),
            work_count as u32,
            grid.width as u32,
            grid.height as u32,
            columns as u32,
            channels,
            plan.alpha,
            EntrySums::fitting(
                channels,
                client.properties().hardware.max_shared_memory_size,
            ),
            [dtype_to_storage_type(dtype), int_dtype],
        );
    }
    // Written whole by the gather kernel (every row, every column).
    let v_splats = CubeBackend::float_empty(vec![rows, columns].into(), &device, dtype.into());
    let v_values = CubeBackend::float_empty(vec![rows, channels].into(), &device, dtype.into());
    if rows > 0 {
        let (order, starts) = host_pool::run(|| plan.slots_by_row());
        let order = int_tensor(order, &device);
        let starts = int_tensor(starts, &device);
        let cube_dim = CubeDim::new_1d(256);
        let cube_count = launch_grid::linear(rows.div_ceil(256));
        launch_compositing!(
            gather_kernel,
            &client,
            cube_count,
            cube_dim,
            slots.into_tensor_arg(),
            order.into_tensor_arg(),
            starts.into_tensor_arg(),
            v_splats.clone().into_tensor_arg(),
            v_values.clone().into_tensor_arg(),
            rows as u32,
            columns as u32,
            channels,
            [dtype_to_storage_type(dtype), int_dtype],
        );
    }
    SplatPrimitives {
        splats: v_splats,
        values: v_values,
    }
}

impl CompositeKernels for CubeBackend {
    type Saved = CubeSaved;

    fn composite_forward(
        inputs: SplatPrimitives<Self>,
        plan: Arc<CompositePlan>,
        used: ForwardUse,
    ) -> (FloatTensor<Self>, CubeSaved) {
        if inputs.splats.dtype() == DType::F64 {
            // The host kernels run on every core: on the pool that never waits on the device.
            let (image, saved) = host_pool::run(|| super::host_forward::<Self>(inputs, plan));
            return (image, CubeSaved::Host(saved));
        }
        let (image, saved) = device_forward(inputs, plan, used);
        (image, CubeSaved::Device(Box::new(saved)))
    }

    fn composite_backward(saved: CubeSaved, v_image: FloatTensor<Self>) -> SplatPrimitives<Self> {
        match saved {
            CubeSaved::Host(saved) => host_pool::run(|| host_backward::<Self>(saved, v_image)),
            CubeSaved::Device(saved) => device_backward(*saved, v_image),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_a_composite_may_take_follow_the_workgroup_memory() {
        // By hand from the kernels' declarations (f32): the backward one entry at a time
        // needs 4·(352·(6 + C) + 256) bytes, the forward 4·(256·(6 + C) + 1); the backward is
        // the tighter. 32 KiB (lavapipe): 352·22 + 256 = 8 000 ≤ 8 192 < 352·23 + 256.
        assert_eq!(channels_within(32 * 1024), 16);
        // 48 KiB (NVIDIA's Vulkan): 352·34 + 256 = 12 224 ≤ 12 288.
        assert_eq!(channels_within(48 * 1024), 28);
        // WebGPU's default 16 KiB: 352·10 + 256 = 3 776 ≤ 4 096 < 352·11 + 256.
        assert_eq!(channels_within(16 * 1024), 4);
        // Nothing fits: still one channel a composite (the device's error, named, follows).
        assert_eq!(channels_within(1024), 1);
    }

    #[test]
    fn the_kernels_tile_rows_are_the_binnings() {
        assert_eq!(
            crate::tiles::TILE_SIZE,
            16,
            "the kernels hard-code 16-pixel tile rows"
        );
    }
}
