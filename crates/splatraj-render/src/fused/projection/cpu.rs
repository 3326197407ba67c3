//! The fused projection's kernels in plain Rust: one row (pose, Gaussian) at a time, in
//! parallel over fixed chunks of rows with rayon, generic over f32 and f64; in f32 eight rows
//! at a time in lanes where the processor has AVX (`cpu/simd.rs`, the same bits).
//!
//! Every operation mirrors the tensor projection (`project.rs`) in the same order, with the same
//! clamps and the same gradient conventions at them (a clamp passes the gradient where the value
//! lies inside it or on its bound, as burn's `clamp_min`/`clamp` do), so that in f64 the two
//! agree to rounding (`tests/fused_projection.rs`). The backward is the reverse of those steps,
//! written out by hand; each row's pose gradient goes through the rotation's axes and the
//! camera centre, and the per-pose sums are taken in f64 in a fixed chunk order (the same
//! numbers on every thread count), then through Rodrigues' derivative once per pose.

#[cfg(target_arch = "x86_64")]
mod simd;

use rayon::prelude::*;

use super::{PackedColumn, ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS};
use crate::fused::real::Real;
use crate::project::{LOW_PASS, NORMALISED_DET_FLOOR};
use crate::rodrigues::Rotation;

/// Rows per parallel chunk: fixed, so that the sums do not depend on the thread count.
const ROWS_PER_CHUNK: usize = 2048;

/// One pose as the rows read it: the camera's axes and centre in the pass's float type.
#[derive(Debug, Clone, Copy)]
struct Frame<E> {
    /// `axes[k][e]`: camera axis k (column k of R_wc), world component e.
    axes: [[E; 3]; 3],
    centre: [E; 3],
}

impl<E: Real> Frame<E> {
    fn new(pose: &[f64], rotation: &Rotation) -> Self {
        Frame {
            axes: std::array::from_fn(|k| std::array::from_fn(|e| E::of(rotation.matrix[e][k]))),
            centre: std::array::from_fn(|e| E::of(pose[3 + e])),
        }
    }

    /// The same frame in f32 (exact where E is f32, the only case that asks).
    #[cfg(target_arch = "x86_64")]
    fn as_f32(&self) -> Frame<f32> {
        let f32_of = |v: E| v.to_f64() as f32;
        Frame {
            axes: self.axes.map(|axis| axis.map(f32_of)),
            centre: self.centre.map(f32_of),
        }
    }
}

/// One pose's camera constants in the pass's float type: the intrinsics zoomed by s.
#[derive(Debug, Clone, Copy)]
struct Lens<E> {
    /// The zoom s (focal lengths scale by it about the fixed principal point).
    zoom: E,
    /// Unzoomed focal lengths: d fx·s/ds = fx.
    fx0: E,
    fy0: E,
    /// Zoomed focal lengths fx·s, fy·s (the product in f64, as an `Intrinsics` with fx·s gives).
    fx: E,
    fy: E,
    cx: E,
    cy: E,
    /// The unzoomed clamp ±1.3·tan(half fov) of s·x/z, s·y/z: the zoomed bound on x/z is
    /// this over s (tan of half the field of view shrinks as 1/s).
    lim_x: E,
    lim_y: E,
    near: E,
}

impl<E: Real> Lens<E> {
    fn new(camera: &ProjectionCamera, zoom: f64) -> Self {
        let (lim_x, lim_y) = camera.limits();
        Lens {
            zoom: E::of(zoom),
            fx0: E::of(camera.fx),
            fy0: E::of(camera.fy),
            fx: E::of(camera.fx * zoom),
            fy: E::of(camera.fy * zoom),
            cx: E::of(camera.cx),
            cy: E::of(camera.cy),
            lim_x: E::of(lim_x),
            lim_y: E::of(lim_y),
            near: E::of(camera.near),
        }
    }

    /// The same lens in f32 (exact where E is f32, the only case that asks).
    #[cfg(target_arch = "x86_64")]
    fn as_f32(&self) -> Lens<f32> {
        let f32_of = |v: E| v.to_f64() as f32;
        Lens {
            zoom: f32_of(self.zoom),
            fx0: f32_of(self.fx0),
            fy0: f32_of(self.fy0),
            fx: f32_of(self.fx),
            fy: f32_of(self.fy),
            cx: f32_of(self.cx),
            cy: f32_of(self.cy),
            lim_x: f32_of(self.lim_x),
            lim_y: f32_of(self.lim_y),
            near: f32_of(self.near),
        }
    }
}

/// The scene's rows on the host: component-major `[9, N]` (x, y, z, Σ xx, xy, xz, yy, yz, zz).
#[derive(Debug, Clone, Copy)]
pub struct SceneRows<'a, E> {
    /// `[9, N]`
    pub components: &'a [E],
    /// `[N]`
    pub opacities: &'a [E],
}

impl<E: Real> SceneRows<'_, E> {
    fn len(&self) -> usize {
        self.opacities.len()
    }

    fn centre(&self, g: usize) -> [E; 3] {
        let n = self.len();
        std::array::from_fn(|e| self.components[e * n + g])
    }

    fn covariance(&self, g: usize) -> [E; 6] {
        let n = self.len();
        std::array::from_fn(|k| self.components[(3 + k) * n + g])
    }

    /// Gaussian `g` seen from `frame`.
    fn project(&self, g: usize, frame: &Frame<E>, lens: &Lens<E>) -> Row<E> {
        project_row(
            self.centre(g),
            self.covariance(g),
            self.opacities[g],
            frame,
            lens,
        )
    }
}

fn max<E: Real>(a: E, b: E) -> E {
    if a < b { b } else { a }
}

fn min<E: Real>(a: E, b: E) -> E {
    if b < a { b } else { a }
}

fn dot<E: Real>(p: &[E; 3], q: &[E; 3]) -> E {
    p[0] * q[0] + p[1] * q[1] + p[2] * q[2]
}

/// Σ·t with Σ given as (xx, xy, xz, yy, yz, zz).
fn sigma_times<E: Real>(s: &[E; 6], t: &[E; 3]) -> [E; 3] {
    const ROWS: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
    ROWS.map(|row| s[row[0]] * t[0] + s[row[1]] * t[1] + s[row[2]] * t[2])
}

/// Every intermediate of one row's projection that its backward reads.
#[derive(Debug, Clone, Copy)]
struct Row<E> {
    d: [E; 3],
    x: E,
    y: E,
    z: E,
    inv_z: E,
    x_over_z: E,
    y_over_z: E,
    tx: E,
    ty: E,
    j00: E,
    j11: E,
    j02: E,
    j12: E,
    sigma_t1: [E; 3],
    sigma_t2: [E; 3],
    a: E,
    b: E,
    c: E,
    inv_trace: E,
    trace: E,
    an: E,
    bn: E,
    cn: E,
    det_n: E,
    det_kept: E,
    scale: E,
    /// (u, v, conic a, b, c, opacity, z): the packed output.
    out: [E; SPLAT_COLUMNS],
}

/// The projection of one Gaussian from one pose, step by step as `project.rs` does it.
fn project_row<E: Real>(
    p: [E; 3],
    s: [E; 6],
    opacity: E,
    frame: &Frame<E>,
    lens: &Lens<E>,
) -> Row<E> {
    let [r0, r1, r2] = frame.axes;
    let d: [E; 3] = std::array::from_fn(|e| p[e] - frame.centre[e]);
    let (x, y, z) = (dot(&r0, &d), dot(&r1, &d), dot(&r2, &d));
    let inv_z = E::ONE / max(z, lens.near);
    let x_over_z = x * inv_z;
    let y_over_z = y * inv_z;
    let u = x_over_z * lens.fx + lens.cx;
    let v = y_over_z * lens.fy + lens.cy;
    // clamp(x/z, ±lim/s) written as clamp(s·x/z, ±lim)/s: the same value and gradient (also
    // through the bound), and the same bits as the unzoomed rule at s = 1.
    let tx = max(min(x_over_z * lens.zoom, lens.lim_x), -lens.lim_x) / lens.zoom;
    let ty = max(min(y_over_z * lens.zoom, lens.lim_y), -lens.lim_y) / lens.zoom;
    let j00 = inv_z * lens.fx;
    let j11 = inv_z * lens.fy;
    let j02 = tx * inv_z * -lens.fx;
    let j12 = ty * inv_z * -lens.fy;
    let t1: [E; 3] = std::array::from_fn(|e| j00 * r0[e] + j02 * r2[e]);
    let t2: [E; 3] = std::array::from_fn(|e| j11 * r1[e] + j12 * r2[e]);
    let sigma_t1 = sigma_times(&s, &t1);
    let sigma_t2 = sigma_times(&s, &t2);
    let low_pass = E::of(LOW_PASS);
    let a = dot(&t1, &sigma_t1) + low_pass;
    let b = dot(&t2, &sigma_t1);
    let c = dot(&t2, &sigma_t2) + low_pass;
    let trace = a + c;
    let inv_trace = E::ONE / trace;
    let (an, bn, cn) = (a * inv_trace, b * inv_trace, c * inv_trace);
    let det_n = an * cn - bn * bn;
    let det_kept = max(det_n, E::of(NORMALISED_DET_FLOOR));
    let scale = E::ONE / (det_kept * trace);
    let out = [u, v, cn * scale, -(bn * scale), an * scale, opacity, z];
    Row {
        d,
        x,
        y,
        z,
        inv_z,
        x_over_z,
        y_over_z,
        tx,
        ty,
        j00,
        j11,
        j02,
        j12,
        sigma_t1,
        sigma_t2,
        a,
        b,
        c,
        inv_trace,
        trace,
        an,
        bn,
        cn,
        det_n,
        det_kept,
        scale,
        out,
    }
}

/// Gradient of one row's output `v` (the packed columns; opacity's is ignored: it is a scene
/// constant) with respect to the pose's axes `[k][e]`, centre and zoom.
fn backward_row<E: Real>(
    row: &Row<E>,
    v: &[E],
    frame: &Frame<E>,
    lens: &Lens<E>,
) -> ([[E; 3]; 3], [E; 3], E) {
    let [r0, r1, r2] = frame.axes;
    let zero = E::ZERO;
    let [vu, vv, va_out, vb_out, vc_out] = std::array::from_fn(|k| v[k]);
    let v_depth = v[PackedColumn::Depth as usize];

    // conic = (cn, −bn, an) · scale, scale = 1 / (max(det_n, floor) · trace)
    let v_scale = va_out * row.cn - vb_out * row.bn + vc_out * row.an;
    let mut v_cn = va_out * row.scale;
    let mut v_bn = -(vb_out * row.scale);
    let mut v_an = vc_out * row.scale;
    let q = row.det_kept * row.trace;
    let v_q = -(v_scale / (q * q));
    let v_det_kept = v_q * row.trace;
    let mut v_trace = v_q * row.det_kept;
    let floor = E::of(NORMALISED_DET_FLOOR);
    let v_det = if row.det_n < floor { zero } else { v_det_kept };
    v_an += v_det * row.cn;
    v_cn += v_det * row.an;
    v_bn += -(E::of(2.0) * row.bn * v_det);
    let v_inv_trace = v_an * row.a + v_bn * row.b + v_cn * row.c;
    v_trace += -(v_inv_trace * row.inv_trace * row.inv_trace);
    let v_a = v_an * row.inv_trace + v_trace;
    let v_b = v_bn * row.inv_trace;
    let v_c = v_cn * row.inv_trace + v_trace;

    // a = t1ᵀΣt1, b = t2ᵀΣt1, c = t2ᵀΣt2 (Σ symmetric)
    let two = E::of(2.0);
    let v_t1: [E; 3] = std::array::from_fn(|e| two * v_a * row.sigma_t1[e] + v_b * row.sigma_t2[e]);
    let v_t2: [E; 3] = std::array::from_fn(|e| v_b * row.sigma_t1[e] + two * v_c * row.sigma_t2[e]);

    // t1 = j00·r0 + j02·r2, t2 = j11·r1 + j12·r2
    let v_j00 = dot(&v_t1, &r0);
    let v_j02 = dot(&v_t1, &r2);
    let v_j11 = dot(&v_t2, &r1);
    let v_j12 = dot(&v_t2, &r2);
    let mut v_axes = [[zero; 3]; 3];
    for e in 0..3 {
        v_axes[0][e] = row.j00 * v_t1[e];
        v_axes[1][e] = row.j11 * v_t2[e];
        v_axes[2][e] = row.j02 * v_t1[e] + row.j12 * v_t2[e];
    }

    // j00 = fx/z, j11 = fy/z, j02 = −fx·tx/z, j12 = −fy·ty/z (fx, fy zoomed); tx, ty the
    // clamped x/z, y/z: tx = clamp(s·x/z, ±lim)/s
    let mut v_inv_z =
        lens.fx * v_j00 + lens.fy * v_j11 - lens.fx * row.tx * v_j02 - lens.fy * row.ty * v_j12;
    let v_tx = -(lens.fx * row.inv_z * v_j02);
    let v_ty = -(lens.fy * row.inv_z * v_j12);
    // d L/d(fx·s), d L/d(fy·s): through u, v and the Jacobian.
    let v_fx = vu * row.x_over_z + v_j00 * row.inv_z - v_j02 * row.tx * row.inv_z;
    let v_fy = vv * row.y_over_z + v_j11 * row.inv_z - v_j12 * row.ty * row.inv_z;
    let mut v_zoom = v_fx * lens.fx0 + v_fy * lens.fy0;
    let inside = |t: E, lim: E| !(t > lim || t < -lim);
    let s = lens.zoom;
    // tx = k/s with k = clamp(s·x/z): d tx/d k = 1/s, d tx/ds (at fixed k) = −tx/s.
    let v_kx = v_tx / s;
    let v_ky = v_ty / s;
    v_zoom += -(v_tx * row.tx / s) - v_ty * row.ty / s;
    let mut v_x_over_z = lens.fx * vu;
    let x_zoomed = row.x_over_z * s;
    if inside(x_zoomed, lens.lim_x) {
        v_x_over_z += v_kx * s;
        v_zoom += v_kx * row.x_over_z;
    }
    let mut v_y_over_z = lens.fy * vv;
    let y_zoomed = row.y_over_z * s;
    if inside(y_zoomed, lens.lim_y) {
        v_y_over_z += v_ky * s;
        v_zoom += v_ky * row.y_over_z;
    }
    let v_x = v_x_over_z * row.inv_z;
    let v_y = v_y_over_z * row.inv_z;
    v_inv_z += v_x_over_z * row.x + v_y_over_z * row.y;
    let mut v_z = v_depth;
    if row.z >= lens.near {
        v_z += -(v_inv_z * row.inv_z * row.inv_z);
    }

    // (x, y, z) = (r0·d, r1·d, r2·d), d = p − c
    for (v_axis, v_coordinate) in v_axes.iter_mut().zip([v_x, v_y, v_z]) {
        for (v, d) in v_axis.iter_mut().zip(row.d) {
            *v += v_coordinate * d;
        }
    }
    let v_centre = std::array::from_fn(|e| -(v_x * r0[e] + v_y * r1[e] + v_z * r2[e]));
    (v_axes, v_centre, v_zoom)
}

/// Σ over the rows `rows` (in order) of their gradients d L/d axes (9), d L/d centre (3) and
/// d L/ds (1), each added in f64 row after row: eight rows' gradients at a time in lanes where
/// E is f32 and the processor has AVX ([`simd`], the same bits), the rest one by one.
fn row_gradients<E: Real>(
    scene: SceneRows<'_, E>,
    plan: &ProjectionPlan,
    v_out: &[E],
    rows: impl Iterator<Item = usize>,
    frame: &Frame<E>,
    lens: &Lens<E>,
) -> [f64; 13] {
    let mut sums = [0.0f64; 13];
    let one_row = |r: usize, sums: &mut [f64; 13]| {
        let v = &v_out[r * SPLAT_COLUMNS..(r + 1) * SPLAT_COLUMNS];
        let row = scene.project(plan.gaussians[r] as usize, frame, lens);
        let (v_axes, v_centre, v_zoom) = backward_row(&row, v, frame, lens);
        for k in 0..3 {
            for e in 0..3 {
                sums[3 * k + e] += v_axes[k][e].to_f64();
            }
            sums[9 + k] += v_centre[k].to_f64();
        }
        sums[12] += v_zoom.to_f64();
    };
    #[cfg(target_arch = "x86_64")]
    if let (Some((lanes, scene, frame, lens)), Some(v_out)) =
        (in_lanes(scene, frame, lens), E::as_f32(v_out))
    {
        let mut group = [0usize; simd::LANES];
        let mut filled = 0;
        for r in rows {
            group[filled] = r;
            filled += 1;
            if filled < simd::LANES {
                continue;
            }
            filled = 0;
            let gaussians = group.map(|r| plan.gaussians[r] as usize);
            let v_rows = group.map(|r| {
                let v = &v_out[r * SPLAT_COLUMNS..(r + 1) * SPLAT_COLUMNS];
                <[f32; SPLAT_COLUMNS]>::try_from(v).expect("7 columns")
            });
            let terms = lanes.backward(scene, gaussians, &v_rows, &frame, &lens);
            for lane in 0..simd::LANES {
                for (sum, term) in sums.iter_mut().zip(&terms) {
                    *sum += f64::from(term[lane]);
                }
            }
        }
        for &r in &group[..filled] {
            one_row(r, &mut sums);
        }
        return sums;
    }
    for r in rows {
        one_row(r, &mut sums);
    }
    sums
}

fn frames<E: Real>(poses: &[f64]) -> (Vec<Rotation>, Vec<Frame<E>>) {
    let rotations: Vec<Rotation> = poses
        .chunks_exact(6)
        .map(|p| Rotation::new([p[0], p[1], p[2]]))
        .collect();
    let frames = poses
        .chunks_exact(6)
        .zip(&rotations)
        .map(|(p, r)| Frame::new(p, r))
        .collect();
    (rotations, frames)
}

/// The pose's lenses: `camera` zoomed by `zoom` `[B]`.
fn lenses<E: Real>(camera: &ProjectionCamera, zoom: &[f64]) -> Vec<Lens<E>> {
    zoom.iter().map(|&s| Lens::new(camera, s)).collect()
}

/// The packed rows `[R, 7]` of `plan`'s rows seen from `poses` (`[B, 6]`, Φ = ω, c) through
/// the plan's camera zoomed by `zoom` (`[B]`, s > 0).
pub fn forward<E: Real>(
    poses: &[f64],
    zoom: &[f64],
    scene: SceneRows<'_, E>,
    plan: &ProjectionPlan,
) -> Vec<E> {
    let (_, frames) = frames::<E>(poses);
    let lenses = lenses::<E>(&plan.camera, zoom);
    let rows = &plan.rows;
    let mut out = vec![E::ZERO; rows.total() * SPLAT_COLUMNS];
    // One job per chunk of a pose's rows, each writing its own slice of the output.
    let mut jobs = Vec::new();
    let mut rest = out.as_mut_slice();
    for b in 0..rows.batch() {
        let (own, tail) = rest.split_at_mut(rows.count(b) * SPLAT_COLUMNS);
        rest = tail;
        let chunks = own.chunks_mut(ROWS_PER_CHUNK * SPLAT_COLUMNS).enumerate();
        jobs.extend(chunks.map(|(c, out)| (b, rows.start(b) + c * ROWS_PER_CHUNK, out)));
    }
    jobs.into_par_iter().for_each(|(b, first, out)| {
        let gaussians = &plan.gaussians[first..first + out.len() / SPLAT_COLUMNS];
        project_rows(scene, gaussians, &frames[b], &lenses[b], out);
    });
    out
}

/// The lanes with what they read: the scene's rows, one pose's frame and its lens, in f32.
#[cfg(target_arch = "x86_64")]
type InLanes<'a> = (simd::Lanes, SceneRows<'a, f32>, Frame<f32>, Lens<f32>);

/// [`InLanes`] where E is f32 and the processor has AVX.
#[cfg(target_arch = "x86_64")]
fn in_lanes<'a, E: Real>(
    scene: SceneRows<'a, E>,
    frame: &Frame<E>,
    lens: &Lens<E>,
) -> Option<InLanes<'a>> {
    let scene = SceneRows {
        components: E::as_f32(scene.components)?,
        opacities: E::as_f32(scene.opacities)?,
    };
    Some((simd::Lanes::new()?, scene, frame.as_f32(), lens.as_f32()))
}

/// The packed rows `[rows, 7]` of `gaussians` seen from one pose, into `out`: eight at a time
/// in lanes where E is f32 and the processor has AVX ([`simd`], the same bits), the rest one
/// by one.
fn project_rows<E: Real>(
    scene: SceneRows<'_, E>,
    gaussians: &[u32],
    frame: &Frame<E>,
    lens: &Lens<E>,
    out: &mut [E],
) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if let (Some((lanes, scene, frame, lens)), Some(out)) =
        (in_lanes(scene, frame, lens), E::as_f32_mut(out))
    {
        let groups = gaussians.chunks_exact(simd::LANES);
        let packed = out.chunks_exact_mut(simd::LANES * SPLAT_COLUMNS);
        for (group, packed) in groups.zip(packed) {
            let group = std::array::from_fn(|i| group[i] as usize);
            let packed = packed.try_into().expect("8 packed rows");
            lanes.project(scene, group, &frame, &lens, packed);
            done += simd::LANES;
        }
    }
    let rest = out[done * SPLAT_COLUMNS..].chunks_exact_mut(SPLAT_COLUMNS);
    for (packed, &g) in rest.zip(&gaussians[done..]) {
        packed.copy_from_slice(&scene.project(g as usize, frame, lens).out);
    }
}

/// d L/dΦ `[B, 6]` and d L/ds `[B]` from the gradient of the packed rows `v_out` `[R, 7]`.
pub fn backward<E: Real>(
    poses: &[f64],
    zoom: &[f64],
    scene: SceneRows<'_, E>,
    plan: &ProjectionPlan,
    v_out: &[E],
) -> (Vec<f64>, Vec<f64>) {
    let (rotations, frames) = frames::<E>(poses);
    let lenses = lenses::<E>(&plan.camera, zoom);
    let rows = &plan.rows;
    let batch = frames.len();
    // (pose, its rows' range) per job: each pose's rows in chunks, in order.
    let jobs: Vec<(usize, std::ops::Range<usize>)> = (0..batch)
        .flat_map(|b| {
            let (start, count) = (rows.start(b), rows.count(b));
            (0..count.div_ceil(ROWS_PER_CHUNK)).map(move |c| {
                let first = c * ROWS_PER_CHUNK;
                (
                    b,
                    start + first..start + (first + ROWS_PER_CHUNK).min(count),
                )
            })
        })
        .collect();
    // Per job: Σ d L/d axes (9), d L/d centre (3) and d L/ds (1), in f64.
    let partial: Vec<(usize, [f64; 13])> = jobs
        .into_par_iter()
        .map(|(b, range)| {
            // Rows no pixel and no cost read (behind where every pixel stopped) contribute
            // nothing: skip their arithmetic.
            let read = range.filter(|&r| {
                let v = &v_out[r * SPLAT_COLUMNS..(r + 1) * SPLAT_COLUMNS];
                !v.iter().all(|g| g.to_f64() == 0.0)
            });
            (
                b,
                row_gradients(scene, plan, v_out, read, &frames[b], &lenses[b]),
            )
        })
        .collect();
    // Each pose's chunks summed in order (the same numbers on every thread count).
    let mut totals = vec![[0.0f64; 13]; batch];
    for (b, sums) in &partial {
        for (t, s) in totals[*b].iter_mut().zip(sums) {
            *t += s;
        }
    }
    let mut v_poses = vec![0.0; batch * 6];
    let mut v_zoom = vec![0.0; batch];
    for (b, (rotation, total)) in rotations.iter().zip(&totals).enumerate() {
        // Axis k is column k of R: d L/dR[e][k] = d L/d axes[k][e].
        let v_matrix: [[f64; 3]; 3] =
            std::array::from_fn(|e| std::array::from_fn(|k| total[3 * k + e]));
        let v_omega = rotation.omega_gradient(&v_matrix);
        v_poses[b * 6..b * 6 + 3].copy_from_slice(&v_omega);
        v_poses[b * 6 + 3..b * 6 + 6].copy_from_slice(&total[9..12]);
        v_zoom[b] = total[12];
    }
    (v_poses, v_zoom)
}
