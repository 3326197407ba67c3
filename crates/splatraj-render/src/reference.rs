//! The independent reference renderer: brute force, per pixel, all in f64.
//!
//! This module is the project's yardstick. It is written directly from the "Conventions" and
//! "Rendering" rules of `docs/conventions.md` (the INRIA 3DGS rasterizer's rules) and shares no
//! code with the burn tensor rasterizer, so that the tensor path can be tested against it (max abs
//! difference ≤ 1e-5 in f64). It is also the CPU preview of a scene (see `examples/preview.rs`),
//! which is why the work is organised like INRIA's rasterizer: every Gaussian is projected once,
//! binned into the 16×16 tiles it touches, each tile's list is sorted front to back, and each pixel
//! walks only its tile's list. [`reference_weights`] exposes each pixel's blending weights
//! `α·T` from the same walk (the yardstick of [`crate::lift`]).
//!
//! # Rules, as implemented (cite these when comparing with another renderer)
//!
//! 1. **Camera** (OpenCV pinhole): `p_cam = R_cw p_world + t_cw`, x right, y down, z forward.
//!    Camera centre `c = −R_cwᵀ t_cw`. Pixel `(i, j)` (column `i`, row `j`) has its centre at
//!    `(i + 0.5, j + 0.5)` in the same continuous coordinates as `u = fx·x/z + cx`,
//!    `v = fy·y/z + cy`.
//! 2. **Cull** a Gaussian whose camera depth `z ≤ near` (not clamped).
//! 3. `Σ_world = R S Sᵀ Rᵀ`, R from the quaternion (w, x, y, z) *normalised again in f64*
//!    (the design says quaternions must be normalised; re-normalising removes the f32 rounding
//!    of the stored unit quaternion), `S = diag(scales)`.
//! 4. `Σ_cam = W Σ_world Wᵀ`, `W = R_cw`.
//! 5. Jacobian of `(x, y, z) ↦ (fx·x/z, fy·y/z)` at the mean, with `x/z` clamped to
//!    `±1.3·tan_x` and `y/z` to `±1.3·tan_y` first, where `tan_x = 0.5·width/fx`,
//!    `tan_y = 0.5·height/fy` (INRIA's `tan_fovx`, `tan_fovy`):
//!    `J = [[fx/z, 0, −fx·x̂/z], [0, fy/z, −fy·ŷ/z]]` with `x̂ = clamp(x/z)`, `ŷ = clamp(y/z)`.
//!    The projected mean `(u, v)` uses the unclamped `x/z`, `y/z`.
//! 6. `Σ_2D = J Σ_cam Jᵀ + 0.3·I`. Cull if `det(Σ_2D) ≤ 0` (or is not finite).
//!    `conic = Σ_2D⁻¹`.
//! 7. `radius = ceil(3·sqrt(λ_max(Σ_2D)))` with the exact largest eigenvalue
//!    `λ_max = m + sqrt(max(0, m² − det))`, `m = (a + c)/2`. *Choice:* INRIA uses
//!    `max(0.1, m² − det)` under the square root, which enlarges the radius of nearly
//!    isotropic splats by a hair; the design says `λ_max`, so we use the exact value.
//! 8. **Tile touch rule** (*choice*, INRIA's `getRect` in our pixel coordinates): tiles are
//!    16×16 pixels, tile `(tx, ty)` covers pixels `16·tx ≤ i < 16·tx + 16` (same for rows),
//!    `tiles_x = ceil(width/16)`, `tiles_y = ceil(height/16)`. A Gaussian touches the tiles
//!    `tx ∈ [floor((u − r)/16), ceil((u + r)/16))` and
//!    `ty ∈ [floor((v − r)/16), ceil((v + r)/16))` (lower bound inclusive, upper exclusive),
//!    each clipped to `[0, tiles_x]` / `[0, tiles_y]`. A Gaussian whose clipped range is empty
//!    touches nothing. Note that a square ending exactly on a tile boundary (`u + r = 16·k`)
//!    does not touch tile `k`. (INRIA computes the upper bound as `(int)((p + r + 15)/16)` with
//!    `p = u − 0.5`; that equals ceil only when `p + r` is an integer, which it is not in
//!    general. We keep the clean ceil form; a tensor renderer must use this same rule.)
//!    **A Gaussian contributes to a pixel only if it touches that pixel's tile**, even where
//!    its α there would be ≥ 1/255.
//! 9. Per pixel, with `d = (u, v) − (i + 0.5, j + 0.5)`:
//!    `power = −½ dᵀ conic d`; skip if `power > 0`;
//!    `α = min(0.99, o·exp(power))`; skip if `α < 1/255`.
//! 10. **Order**: front to back by camera depth `z`; ties (equal `z`) keep scene order
//!     (*choice*: INRIA's radix sort is stable over keys emitted in Gaussian order, so this is
//!     what it does too).
//! 11. **Transmittance**: `T` starts at 1. Before including a Gaussian, if
//!     `T·(1 − α) < 1e-4` the pixel stops and that Gaussian and all behind it are left out.
//!     Otherwise channel `k` accumulates `f_k·α·T` and `T ← T·(1 − α)`.
//! 12. **Channels**: RGB from SH at the scene's degree, view direction
//!     `(mean − camera centre)/‖mean − camera centre‖`, INRIA's real SH basis and constants,
//!     `colour = max(0, 0.5 + Σ SH)` per channel (no upper clamp, as INRIA); depth is the
//!     camera `z` of the mean; masks are the caller's per-Gaussian values. Background is black
//!     (0) for every channel; `alpha = 1 − final T`.
//!
//! Images are row-major: pixel `(i, j)` is element `j·width + i`.

use rayon::prelude::*;
use splatraj_scene::Scene;

use crate::camera::Intrinsics;

/// Side of a square screen tile in pixels (INRIA's `BLOCK_X = BLOCK_Y = 16`).
pub const TILE_SIZE: usize = 16;

/// Default near plane: Gaussians with camera depth `z ≤ 0.01` are culled.
pub const DEFAULT_NEAR: f64 = 0.01;

/// Constant added to the diagonal of every projected covariance (INRIA's low-pass filter).
const LOW_PASS: f64 = 0.3;
/// Largest α a single Gaussian may have.
const ALPHA_MAX: f64 = 0.99;
/// Smallest α that counts; weaker contributions are skipped.
const ALPHA_MIN: f64 = 1.0 / 255.0;
/// A pixel stops before the Gaussian that would bring T below this.
const T_MIN: f64 = 1e-4;
/// Jacobian clamp: x/z and y/z are limited to ±1.3·tan(half fov).
const FOV_CLAMP: f64 = 1.3;

/// Real SH constants as in INRIA's `forward.cu` (degree 0 to 3), in f64.
const SH_C0: f64 = 0.282_094_791_773_878_14;
const SH_C1: f64 = 0.488_602_511_902_919_9;
const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

type Mat3 = [[f64; 3]; 3];

/// A pinhole camera in OpenCV axes (x right, y down, z forward), all in f64.
#[derive(Debug, Clone, PartialEq)]
pub struct RefCamera {
    /// Focal lengths, principal point (pixel `i` has its centre at `i + 0.5`) and image size,
    /// in pixels.
    pub k: Intrinsics,
    /// World-to-camera rotation `R_cw`; its rows are the camera's x, y, z axes in world.
    pub rotation_cw: [[f64; 3]; 3],
    /// World-to-camera translation: `p_cam = R_cw p_world + t_cw`.
    pub translation_cw: [f64; 3],
    /// Near plane: Gaussians with camera depth `z ≤ near` are culled.
    pub near: f64,
}

impl RefCamera {
    /// The camera of pose Φ with `intrinsics` and near plane `near` (the tested renderer's
    /// conventions: `R_cw = R(ω)ᵀ`, `t_cw = −R_cw·c`).
    pub fn from_pose(pose: &crate::camera::Pose, k: &Intrinsics, near: f64) -> Self {
        let rows = splatraj_camera::pose::matrix_rows(&pose.world_to_camera());
        let row = |i: usize| [rows[i][0], rows[i][1], rows[i][2]];
        RefCamera {
            k: *k,
            rotation_cw: [row(0), row(1), row(2)],
            translation_cw: [rows[0][3], rows[1][3], rows[2][3]],
            near,
        }
    }

    /// Camera at `eye` looking at `target`, rolled so that image up (−y) lies along `world_up`.
    ///
    /// The optical axis z is `target − eye`, x is `z × world_up` (image right) and y is
    /// `z × x` (image down), which makes the frame right-handed with −y as close to
    /// `world_up` as the view direction allows. If the view direction is parallel to
    /// `world_up` (roll undefined), the world axis least aligned with the view direction is
    /// used as up instead. `near` is [`DEFAULT_NEAR`].
    pub fn look_at(eye: [f64; 3], target: [f64; 3], world_up: [f64; 3], k: Intrinsics) -> Self {
        let z = normalize(sub(target, eye));
        let mut x = cross(z, normalize(world_up));
        if norm(x) < 1e-9 {
            // Looking straight along up: any roll is as good; pick a stable one.
            let k = (0..3)
                .min_by(|&a, &b| z[a].abs().total_cmp(&z[b].abs()))
                .unwrap_or(0);
            let mut alt = [0.0; 3];
            alt[k] = 1.0;
            x = cross(z, alt);
        }
        let x = normalize(x);
        let y = cross(z, x);
        let rotation_cw = [x, y, z];
        let r_eye = mat_vec(&rotation_cw, eye);
        Self {
            k,
            rotation_cw,
            translation_cw: [-r_eye[0], -r_eye[1], -r_eye[2]],
            near: DEFAULT_NEAR,
        }
    }

    /// Camera centre in world coordinates, `−R_cwᵀ t_cw`.
    pub fn center(&self) -> [f64; 3] {
        let rt = transpose(&self.rotation_cw);
        let c = mat_vec(&rt, self.translation_cw);
        [-c[0], -c[1], -c[2]]
    }
}

/// Which channels to render: only what is asked is computed.
#[derive(Debug, Clone, Default)]
pub struct RefChannels<'a> {
    /// Render the SH colour.
    pub rgb: bool,
    /// Render composited camera depth z.
    pub depth: bool,
    /// Per-Gaussian channel values (0/1 object masks), one slice of `scene.len()` per mask.
    pub masks: Vec<&'a [f32]>,
}

/// A rendered image; buffers are row-major, pixel `(i, j)` at `j·width + i`.
#[derive(Debug, Clone, PartialEq)]
pub struct RefImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Composited colour, if asked (not clamped to 1).
    pub rgb: Option<Vec<[f64; 3]>>,
    /// Composited camera depth z, if asked (not normalised by alpha).
    pub depth: Option<Vec<f64>>,
    /// Composited masks, in the order of [`RefChannels::masks`].
    pub masks: Vec<Vec<f64>>,
    /// Accumulated opacity, `1 − final T`.
    pub alpha: Vec<f64>,
}

impl RefImage {
    /// Index of pixel `(i, j)` (column, row) in the buffers.
    pub fn index(&self, i: usize, j: usize) -> usize {
        j * self.width + i
    }

    /// Colour as 8-bit RGB bytes (clamped to [0, 1], rounded), or `None` without colour.
    pub fn rgb8(&self) -> Option<Vec<u8>> {
        let to_u8 = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        self.rgb
            .as_ref()
            .map(|rgb| rgb.iter().flat_map(|p| p.map(to_u8)).collect())
    }

    /// Writes the colour channel as a PNG file (an error if colour was not rendered).
    pub fn save_png(&self, path: impl AsRef<std::path::Path>) -> image::ImageResult<()> {
        let bytes = self.rgb8().ok_or_else(|| {
            image::ImageError::Parameter(image::error::ParameterError::from_kind(
                image::error::ParameterErrorKind::Generic(
                    "the image has no RGB channel (render with rgb: true)".into(),
                ),
            ))
        })?;
        image::save_buffer(
            path,
            &bytes,
            self.width as u32,
            self.height as u32,
            image::ExtendedColorType::Rgb8,
        )
    }
}

/// A Gaussian after projection, with the per-Gaussian values of the channels asked for.
#[derive(Debug, Clone)]
struct Splat {
    /// Index in the scene (for mask values and tie-breaking).
    index: usize,
    /// Projected mean in pixel coordinates (pixel centres at +0.5).
    u: f64,
    v: f64,
    /// Camera depth of the mean: sort key and depth channel value.
    z: f64,
    /// Inverse of Σ_2D as (a, b, c) for [[a, b], [b, c]].
    conic: [f64; 3],
    /// Opacity in [0, 1].
    opacity: f64,
    /// SH colour (zero when colour is not asked).
    rgb: [f64; 3],
    /// Half side of the screen square, `ceil(3·sqrt(λ_max))`.
    radius: f64,
}

/// Renders `scene` from `camera`, computing only the requested `channels` (plus alpha).
///
/// Panics if a mask slice does not have one value per Gaussian (a caller bug).
pub fn render_reference(scene: &Scene, camera: &RefCamera, channels: &RefChannels) -> RefImage {
    for (k, m) in channels.masks.iter().enumerate() {
        assert_eq!(
            m.len(),
            scene.len(),
            "mask {k} has {} values but the scene has {} Gaussians",
            m.len(),
            scene.len()
        );
    }
    let (width, height) = (camera.k.width, camera.k.height);
    let binned = Binned::new(scene, camera, channels.rgb);

    // Rules 9 and 11, one pixel at a time; rows in parallel.
    let n_masks = channels.masks.len();
    let rows: Vec<Vec<PixelOut>> = (0..height)
        .into_par_iter()
        .map(|j| {
            (0..width)
                .map(|i| shade_pixel(i, j, &binned, channels, n_masks))
                .collect()
        })
        .collect();

    let pixels = rows.into_iter().flatten();
    let n = width * height;
    let mut rgb = channels.rgb.then(|| Vec::with_capacity(n));
    let mut depth = channels.depth.then(|| Vec::with_capacity(n));
    let mut masks = vec![Vec::with_capacity(n); n_masks];
    let mut alpha = Vec::with_capacity(n);
    for p in pixels {
        if let Some(rgb) = &mut rgb {
            rgb.push(p.rgb);
        }
        if let Some(depth) = &mut depth {
            depth.push(p.depth);
        }
        for (out, value) in masks.iter_mut().zip(p.masks) {
            out.push(value);
        }
        alpha.push(1.0 - p.transmittance);
    }
    RefImage {
        width,
        height,
        rgb,
        depth,
        masks,
        alpha,
    }
}

/// Composited values of one pixel.
struct PixelOut {
    rgb: [f64; 3],
    depth: f64,
    masks: Vec<f64>,
    transmittance: f64,
}

/// The blending weights of every pixel: for pixel `j·width + i`, the pairs (scene index of a
/// Gaussian, `α·T`) in front-to-back order, i.e. the weight with which that Gaussian's channel
/// value enters the pixel (rule 11). Gaussians skipped by rules 8–11 are absent.
pub fn reference_weights(scene: &Scene, camera: &RefCamera) -> Vec<Vec<(usize, f64)>> {
    let binned = Binned::new(scene, camera, false);
    (0..camera.k.height)
        .into_par_iter()
        .flat_map_iter(|j| {
            let binned = &binned;
            (0..camera.k.width).map(move |i| {
                let mut weights = Vec::new();
                walk_pixel(i, j, binned, |g, w| weights.push((g.index, w)));
                weights
            })
        })
        .collect()
}

/// Projected splats binned into tiles, each tile's list sorted front to back.
struct Binned {
    splats: Vec<Splat>,
    /// Per tile (row-major), indices into `splats`.
    tiles: Vec<Vec<u32>>,
    tiles_x: usize,
}

impl Binned {
    fn new(scene: &Scene, camera: &RefCamera, want_rgb: bool) -> Self {
        let tiles_x = camera.k.width.div_ceil(TILE_SIZE);
        let tiles_y = camera.k.height.div_ceil(TILE_SIZE);

        // Rules 2–7 and 12 (per-Gaussian values): once per Gaussian, independent of the pixel.
        let center = camera.center();
        let splats: Vec<Splat> = (0..scene.len())
            .into_par_iter()
            .filter_map(|i| project(scene, camera, center, i, want_rgb))
            .collect();

        // Rule 8: bin each splat into the tiles its square touches.
        let mut tiles: Vec<Vec<u32>> = vec![Vec::new(); tiles_x * tiles_y];
        for (s, splat) in splats.iter().enumerate() {
            let (x0, x1) = tile_span(splat.u, splat.radius, tiles_x);
            let (y0, y1) = tile_span(splat.v, splat.radius, tiles_y);
            for ty in y0..y1 {
                for tx in x0..x1 {
                    tiles[ty * tiles_x + tx].push(s as u32);
                }
            }
        }
        // Rule 10: front to back by z, ties by scene index.
        tiles.par_iter_mut().for_each(|list| {
            list.sort_by(|&a, &b| {
                let (a, b) = (&splats[a as usize], &splats[b as usize]);
                a.z.total_cmp(&b.z).then(a.index.cmp(&b.index))
            });
        });
        Binned {
            splats,
            tiles,
            tiles_x,
        }
    }
}

/// Walks pixel `(i, j)`'s tile list front to back (rules 9 and 11), calling `visit` with each
/// Gaussian that contributes and its weight `α·T`. Returns the final transmittance.
fn walk_pixel(i: usize, j: usize, binned: &Binned, mut visit: impl FnMut(&Splat, f64)) -> f64 {
    // Rule 1: the pixel's centre.
    let (px, py) = (i as f64 + 0.5, j as f64 + 0.5);
    let list = &binned.tiles[(j / TILE_SIZE) * binned.tiles_x + i / TILE_SIZE];
    let mut transmittance = 1.0;
    for &s in list {
        let g = &binned.splats[s as usize];
        // Rule 9: Gaussian falloff at the pixel centre.
        let (dx, dy) = (g.u - px, g.v - py);
        let [a, b, c] = g.conic;
        let power = -0.5 * (a * dx * dx + 2.0 * b * dx * dy + c * dy * dy);
        if power > 0.0 {
            continue; // only possible through rounding for a positive-definite conic
        }
        let alpha = (g.opacity * power.exp()).min(ALPHA_MAX);
        if alpha < ALPHA_MIN {
            continue;
        }
        // Rule 11: stop before the Gaussian that would bring T below 1e-4.
        let next_t = transmittance * (1.0 - alpha);
        if next_t < T_MIN {
            break;
        }
        visit(g, alpha * transmittance);
        transmittance = next_t;
    }
    transmittance
}

/// Composites pixel `(i, j)` (rules 9, 11 and 12).
fn shade_pixel(
    i: usize,
    j: usize,
    binned: &Binned,
    channels: &RefChannels,
    n_masks: usize,
) -> PixelOut {
    let mut out = PixelOut {
        rgb: [0.0; 3],
        depth: 0.0,
        masks: vec![0.0; n_masks],
        transmittance: 1.0,
    };
    let transmittance = walk_pixel(i, j, binned, |g, w| {
        if channels.rgb {
            for k in 0..3 {
                out.rgb[k] += g.rgb[k] * w;
            }
        }
        if channels.depth {
            out.depth += g.z * w;
        }
        for (acc, mask) in out.masks.iter_mut().zip(&channels.masks) {
            *acc += f64::from(mask[g.index]) * w;
        }
    });
    out.transmittance = transmittance;
    out
}

/// Projects Gaussian `i` (rules 2–7) and evaluates its colour if asked (rule 12).
/// `None` when it is culled.
fn project(
    scene: &Scene,
    cam: &RefCamera,
    cam_center: [f64; 3],
    i: usize,
    want_rgb: bool,
) -> Option<Splat> {
    let mean = scene.means[i].map(f64::from);
    // Rule 1: world to camera.
    let rm = mat_vec(&cam.rotation_cw, mean);
    let t = [
        rm[0] + cam.translation_cw[0],
        rm[1] + cam.translation_cw[1],
        rm[2] + cam.translation_cw[2],
    ];
    let z = t[2];
    // Rule 2: cull at the near plane (also catches NaN depth).
    if z.is_nan() || z <= cam.near {
        return None;
    }

    // Rule 3: Σ_world = R S Sᵀ Rᵀ = M Mᵀ with M = R S.
    let r = quat_to_mat(scene.rotations[i].map(f64::from));
    let s = scene.scales[i].map(f64::from);
    let m: Mat3 = std::array::from_fn(|row| std::array::from_fn(|col| r[row][col] * s[col]));
    let sigma_world = mat_mul(&m, &transpose(&m));

    // Rule 4: Σ_cam = W Σ Wᵀ, W = R_cw.
    let w = &cam.rotation_cw;
    let sigma_cam = mat_mul(&mat_mul(w, &sigma_world), &transpose(w));

    // Rule 5: Jacobian at the mean with clamped x/z, y/z.
    let lim_x = FOV_CLAMP * 0.5 * cam.k.width as f64 / cam.k.fx;
    let lim_y = FOV_CLAMP * 0.5 * cam.k.height as f64 / cam.k.fy;
    let xz = (t[0] / z).clamp(-lim_x, lim_x);
    let yz = (t[1] / z).clamp(-lim_y, lim_y);
    let jac = [
        [cam.k.fx / z, 0.0, -cam.k.fx * xz / z],
        [0.0, cam.k.fy / z, -cam.k.fy * yz / z],
    ];

    // Rule 6: Σ_2D = J Σ_cam Jᵀ + 0.3 I.
    let mut cov = [[0.0; 2]; 2];
    for (a, row) in cov.iter_mut().enumerate() {
        for (b, out) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for k in 0..3 {
                for l in 0..3 {
                    acc += jac[a][k] * sigma_cam[k][l] * jac[b][l];
                }
            }
            *out = acc;
        }
    }
    // Symmetric by construction up to rounding; use the average off-diagonal.
    let (a, b, c) = (
        cov[0][0] + LOW_PASS,
        0.5 * (cov[0][1] + cov[1][0]),
        cov[1][1] + LOW_PASS,
    );
    let det = a * c - b * b;
    // Cull det ≤ 0, and NaN/inf from degenerate input.
    if !det.is_finite() || det <= 0.0 {
        return None;
    }
    let conic = [c / det, -b / det, a / det];

    // Rule 7: radius from the exact largest eigenvalue.
    let mid = 0.5 * (a + c);
    let lambda_max = mid + (mid * mid - det).max(0.0).sqrt();
    let radius = (3.0 * lambda_max.sqrt()).ceil();

    // Projected mean, not clamped.
    let u = cam.k.fx * t[0] / z + cam.k.cx;
    let v = cam.k.fy * t[1] / z + cam.k.cy;

    let rgb = if want_rgb {
        let dir = normalize(sub(mean, cam_center));
        sh_color(scene.sh_of(i), scene.sh_degree, dir)
    } else {
        [0.0; 3]
    };
    Some(Splat {
        index: i,
        u,
        v,
        z,
        conic,
        opacity: f64::from(scene.opacities[i]),
        rgb,
        radius,
    })
}

/// Rule 8 on one axis: tiles `[floor((p − r)/16), ceil((p + r)/16))` clipped to `[0, n]`.
fn tile_span(p: f64, r: f64, n: usize) -> (usize, usize) {
    let ts = TILE_SIZE as f64;
    // Clamp in f64 before converting so far-off splats cannot overflow an integer.
    let lo = ((p - r) / ts).floor().clamp(0.0, n as f64) as usize;
    let hi = ((p + r) / ts).ceil().clamp(0.0, n as f64) as usize;
    (lo, hi.max(lo))
}

/// Colour from SH (rule 12): INRIA's `computeColorFromSH` in f64.
///
/// `sh` is `[coefficient][channel]` flat, `dir` the unit view direction (mean − camera).
fn sh_color(sh: &[f32], degree: u8, dir: [f64; 3]) -> [f64; 3] {
    let coef = |k: usize, ch: usize| f64::from(sh[3 * k + ch]);
    let [x, y, z] = dir;
    std::array::from_fn(|ch| {
        let sh = |k| coef(k, ch);
        let mut result = SH_C0 * sh(0);
        if degree > 0 {
            result += -SH_C1 * y * sh(1) + SH_C1 * z * sh(2) - SH_C1 * x * sh(3);
            if degree > 1 {
                let (xx, yy, zz) = (x * x, y * y, z * z);
                let (xy, yz, xz) = (x * y, y * z, x * z);
                result += SH_C2[0] * xy * sh(4)
                    + SH_C2[1] * yz * sh(5)
                    + SH_C2[2] * (2.0 * zz - xx - yy) * sh(6)
                    + SH_C2[3] * xz * sh(7)
                    + SH_C2[4] * (xx - yy) * sh(8);
                if degree > 2 {
                    result += SH_C3[0] * y * (3.0 * xx - yy) * sh(9)
                        + SH_C3[1] * xy * z * sh(10)
                        + SH_C3[2] * y * (4.0 * zz - xx - yy) * sh(11)
                        + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh(12)
                        + SH_C3[4] * x * (4.0 * zz - xx - yy) * sh(13)
                        + SH_C3[5] * z * (xx - yy) * sh(14)
                        + SH_C3[6] * x * (xx - 3.0 * yy) * sh(15);
                }
            }
        }
        (result + 0.5).max(0.0)
    })
}

/// Rotation matrix of the quaternion (w, x, y, z), normalised first.
fn quat_to_mat(q: [f64; 4]) -> Mat3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|r| std::array::from_fn(|c| a[c][r]))
}

fn mat_vec(a: &Mat3, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| a[r][0] * v[0] + a[r][1] * v[1] + a[r][2] * v[2])
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}
