//! The lifted language field: CLIP patch features of rendered views, lifted onto Gaussians.
//!
//! For each view: render RGB at the image tower's input size, take ClearCLIP's dense patch
//! features, and express them in a principal subspace shared by all views ([`Subspace`]). Then
//! for each view: upsample the patch coordinates to the lifting resolution (bilinear between
//! patch centres) and lift them through the rasterizer's backward
//! ([`splatraj_render::lift::lift_views`]): each Gaussian gets Σ w·z and Σ w over every pixel of
//! every view, w being its blending weight there, so a Gaussian hidden in a view gets no vote
//! from it. A Gaussian's feature is then `mean + basisᵀ·(Σ w·z / Σ w)`.
//!
//! Why compressed: the per-Gaussian memory is `components + 1` floats whatever the scene's size
//! (33 floats at the default 32 components: 20 MB for 150k Gaussians, 1.3 GB for 10 M, against
//! 2 KB per Gaussian for full 512-d features), a further query is a dot product per Gaussian,
//! and because lifting is linear the result equals lifting the full features and projecting,
//! up to the share of variance the subspace leaves out ([`LiftedField::explained`]).

use splatraj_render::camera::Intrinsics;
use splatraj_render::lift::{LiftSums, lift_views};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Rasterizer, RenderRequest, render_poses,
};
use splatraj_semantic::image_encoder::{DenseFeatures, ImageEncoder, RgbImage};

use crate::MIN_WEIGHT;
use crate::error::{LiftError, Result};
use crate::pca::Subspace;
use crate::progress::{LiftStage, Progress};
use crate::views::View;

/// How views are rendered and lifted.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldOptions {
    /// Side of the image tower's input for dense features: each view is rendered (or its
    /// photo shrunk) to about `render_size²` pixels with its own aspect ratio, on whole
    /// patches (448 with ViT-B/16: 28×28 patches).
    pub render_size: usize,
    /// Longer side of the renders the features are lifted through, pixels.
    pub lift_size: usize,
    /// Principal components kept per Gaussian.
    pub components: usize,
}

impl Default for FieldOptions {
    fn default() -> Self {
        FieldOptions {
            render_size: 448,
            lift_size: 224,
            components: 32,
        }
    }
}

impl FieldOptions {
    /// Checks the values; errors name the key under `prefix` (`targets.lifted`).
    pub fn check(&self, prefix: &str) -> Result<()> {
        for (key, value, range) in [
            ("render_size", self.render_size, 32..=2048),
            ("lift_size", self.lift_size, 16..=2048),
            ("components", self.components, 1..=1024),
        ] {
            if !range.contains(&value) {
                return Err(LiftError::option(
                    format!("{prefix}.{key}"),
                    format!("{value} must be in {}..={}", range.start(), range.end()),
                ));
            }
        }
        Ok(())
    }
}

/// Estimated peak bytes of building a field of `n` Gaussians from `views` views with
/// `options`, for an image tower whose weights file has `weights_bytes` bytes (loaded as f32,
/// so up to twice a half-precision file) and embeddings of `dim` values: the scene on the
/// lifting device, the tower and two passes' activations (views are encoded two at a time),
/// every view's dense features and their copy for the subspace, the lift sums (f64) beside the
/// gradient of one pass, and the field.
pub fn memory_bytes(
    n: usize,
    views: usize,
    options: &FieldOptions,
    weights_bytes: u64,
    dim: usize,
) -> f64 {
    let k = options.components as f64;
    let n = n as f64;
    let patches = (options.render_size as f64 / 16.0).powi(2);
    // Means, covariance factors, opacities and SH up to degree 3 on the device, and its
    // host geometry for the per-pass decisions.
    let scene = n * 250.0;
    let tower = 2.0 * weights_bytes as f64;
    // Activations of one ViT-B/16 pass: ~16 token buffers of width 768 and 12 attention maps.
    let tokens = patches + 1.0;
    let activations = 2.0 * 4.0 * (16.0 * tokens * 768.0 + 12.0 * tokens * tokens);
    let dense = 2.0 * views as f64 * patches * dim as f64 * 4.0;
    let lift_pixels = (options.lift_size as f64).powi(2);
    let lift_pass = lift_pixels * (k + 1.0) * 4.0 * 4.0 + n * (k + 1.0) * 4.0 * 3.0;
    let sums = n * (k + 1.0) * 8.0;
    let field = n * (k + 1.0) * 4.0;
    scene + tower + activations + dense + lift_pass + sums + field
}

/// Per-Gaussian compressed features and how much each Gaussian was seen.
#[derive(Debug, Clone, PartialEq)]
pub struct LiftedField {
    /// The subspace the codes live in (embedding length, mean, basis, explained variance).
    pub subspace: Subspace,
    /// Lifted coordinates per Gaussian (zeros where unseen). `[N, k]`
    pub codes: Vec<f32>,
    /// Σ w over all views and pixels per Gaussian: 0 for a Gaussian no view shows. `[N]`
    pub weights: Vec<f32>,
}

impl LiftedField {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// True for a field of no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// Share of the features' variance the stored components keep.
    pub fn explained(&self) -> f64 {
        self.subspace.explained
    }

    /// Cosine between each Gaussian's feature and the unit vector `t`; `None` for a Gaussian no
    /// view showed. Uses `|mean + Bᵀz|² = |mean|² + 2·(B·mean)·z + |z|²` (B orthonormal), so
    /// no full feature is ever built.
    pub fn cosines(&self, t: &[f32]) -> Vec<Option<f32>> {
        let sub = &self.subspace;
        let k = sub.components();
        let mean_t: f64 = sub
            .mean
            .iter()
            .zip(t)
            .map(|(&m, &x)| f64::from(m * x))
            .sum();
        let mean_sq: f64 = sub.mean.iter().map(|&m| f64::from(m * m)).sum();
        let t_coords = sub.coordinates(t);
        let mean_coords = sub.coordinates(&sub.mean);
        self.codes
            .chunks_exact(k)
            .zip(&self.weights)
            .map(|(z, &w)| {
                if w < MIN_WEIGHT {
                    return None;
                }
                let mut dot_t = mean_t;
                let mut norm_sq = mean_sq;
                for j in 0..k {
                    let zj = f64::from(z[j]);
                    dot_t += zj * f64::from(t_coords[j]);
                    norm_sq += zj * (2.0 * f64::from(mean_coords[j]) + zj);
                }
                // |mean + Bᵀz|² comes from cancelling f32 terms: below a millionth of |mean|² it
                // is rounding, and a direction from it would be noise.
                (norm_sq > 1e-6 * mean_sq.max(1e-12))
                    .then(|| (dot_t / norm_sq.sqrt()).clamp(-1.0, 1.0) as f32)
            })
            .collect()
    }

    /// Renders `views`, encodes them with `encoder` and lifts their features onto the scene.
    pub fn build(
        scene: &DeviceScene,
        views: &[View],
        encoder: &ImageEncoder,
        options: &FieldOptions,
        progress: &Progress,
    ) -> Result<LiftedField> {
        let dense = encode_views(scene, views, encoder, options, progress)?;
        LiftedField::lift(scene, views, &dense, options, progress)
    }

    /// Lifts the dense features `dense` of `views` (one per view) onto the scene: the subspace
    /// of all their patch features, then each view's patch coordinates upsampled and lifted.
    pub fn lift(
        scene: &DeviceScene,
        views: &[View],
        dense: &[DenseFeatures],
        options: &FieldOptions,
        progress: &Progress,
    ) -> Result<LiftedField> {
        options.check("lifted.field")?;
        if views.is_empty() || views.len() != dense.len() {
            return Err(LiftError::Scene(format!(
                "{} views with {} feature grids: need one grid per view, at least one",
                views.len(),
                dense.len()
            )));
        }
        let dim = dense[0].dim;
        if let Some(d) = dense.iter().find(|d| d.dim != dim) {
            return Err(LiftError::Scene(format!(
                "feature grids of lengths {dim} and {} cannot share a field",
                d.dim
            )));
        }
        let samples: Vec<f32> = dense
            .iter()
            .flat_map(|d| d.values.iter().copied())
            .collect();
        let subspace = Subspace::fit(&samples, dim, options.components);
        let k = subspace.components();
        let mut sums = LiftSums::zeros(scene.len(), k);
        for (v, (view, features)) in views.iter().zip(dense).enumerate() {
            progress(LiftStage::Lift, v, views.len());
            let intrinsics = sized(&view.intrinsics, options.lift_size)?;
            let codes: Vec<f32> = features
                .values
                .chunks_exact(dim)
                .flat_map(|f| subspace.project(f))
                .collect();
            let pixels = upsample(&codes, features.rows, features.cols, k, &intrinsics);
            let view_sums = lift_views(
                scene,
                &[view.pose],
                &intrinsics,
                &pixels,
                k,
                Rasterizer::Fused,
            )?;
            sums.add(&view_sums);
        }
        progress(LiftStage::Lift, views.len(), views.len());
        Ok(from_sums(subspace, &sums))
    }
}

/// Renders each view in RGB at exactly the tower's patch grid for that view
/// ([`ImageEncoder::grid_for`]: about `(render_size / patch)²` patches with the view's aspect)
/// and takes its dense ClearCLIP features.
pub fn encode_views(
    scene: &DeviceScene,
    views: &[View],
    encoder: &ImageEncoder,
    options: &FieldOptions,
    progress: &Progress,
) -> Result<Vec<DenseFeatures>> {
    options.check("targets.lifted.field")?;
    let mut images = Vec::with_capacity(views.len());
    for (v, view) in views.iter().enumerate() {
        progress(LiftStage::Render, v, views.len());
        let (rows, cols) = encoder.grid_for(view.intrinsics.width, view.intrinsics.height);
        let patch = encoder.shape().patch;
        let intrinsics = view.intrinsics.rescaled(cols * patch, rows * patch)?;
        images.push(render_rgb_with(scene, view, &intrinsics)?);
    }
    progress(LiftStage::Render, views.len(), views.len());
    encode_images(images.len(), |i| Ok(images[i].clone()), encoder, progress)
}

/// Dense features of `count` images made by `image(i)`, in order. Two are made and encoded at a
/// time: one ViT pass keeps about one core busy (its matrix products are too small for burn's
/// CPU backend to split well), and two bound the images and activations held at once.
fn encode_images(
    count: usize,
    image: impl Fn(usize) -> Result<RgbImage> + Sync,
    encoder: &ImageEncoder,
    progress: &Progress,
) -> Result<Vec<DenseFeatures>> {
    let encode = |i: usize| -> Result<DenseFeatures> { Ok(encoder.dense(&image(i)?)?) };
    let mut dense = Vec::with_capacity(count);
    for first in (0..count).step_by(2) {
        progress(LiftStage::Encode, first, count);
        if first + 1 < count {
            let (a, b) = rayon::join(|| encode(first), || encode(first + 1));
            dense.push(a?);
            dense.push(b?);
        } else {
            dense.push(encode(first)?);
        }
    }
    progress(LiftStage::Encode, count, count);
    Ok(dense)
}

/// The field of lifted sums: codes are the weighted means (zeros where nothing was seen).
fn from_sums(subspace: Subspace, sums: &LiftSums) -> LiftedField {
    let k = sums.dim;
    let mut codes = vec![0f32; sums.weights.len() * k];
    for (i, &w) in sums.weights.iter().enumerate() {
        if w as f32 >= MIN_WEIGHT {
            for j in 0..k {
                codes[i * k + j] = (sums.weighted[i * k + j] / w) as f32;
            }
        }
    }
    LiftedField {
        subspace,
        codes,
        weights: sums.weights.iter().map(|&w| w as f32).collect(),
    }
}

/// `intrinsics` rescaled so that the longer side has `size` pixels.
pub fn sized(intrinsics: &Intrinsics, size: usize) -> Result<Intrinsics> {
    let long = intrinsics.width.max(intrinsics.height) as f64;
    let scale = size as f64 / long;
    let width = ((intrinsics.width as f64 * scale).round() as usize).max(1);
    let height = ((intrinsics.height as f64 * scale).round() as usize).max(1);
    Ok(intrinsics.rescaled(width, height)?)
}

/// Reads each camera's photo (PNG or JPEG, turned upright by its EXIF orientation), checks
/// it shows that camera's view (same aspect ratio, a pixel of rounding allowed), shrinks it to
/// the tower's patch grid right away (a capture's 16-megapixel photos are never all held), and
/// takes its dense ClearCLIP features.
pub fn encode_photos(
    photos: &[(std::path::PathBuf, View)],
    encoder: &ImageEncoder,
    progress: &Progress,
) -> Result<Vec<DenseFeatures>> {
    let patch = encoder.shape().patch;
    let read = |i: usize| -> Result<RgbImage> {
        let (path, view) = &photos[i];
        let bad = |e: &dyn std::fmt::Display| LiftError::file(path, e);
        let mut decoder = image::ImageReader::open(path)
            .map_err(|e| bad(&e))?
            .with_guessed_format()
            .map_err(|e| bad(&e))?
            .into_decoder()
            .map_err(|e| bad(&e))?;
        let orientation = image::ImageDecoder::orientation(&mut decoder).map_err(|e| bad(&e))?;
        let mut photo = image::DynamicImage::from_decoder(decoder).map_err(|e| bad(&e))?;
        photo.apply_orientation(orientation);
        let (width, height) = (photo.width() as usize, photo.height() as usize);
        let k = view.intrinsics;
        if (width * k.height).abs_diff(height * k.width) > k.width + k.height {
            return Err(LiftError::file(
                path,
                format!(
                    "the photo is {width}×{height} (upright) but its camera is {}×{}: not the \
                     same aspect ratio, so not this camera's image (cropped, undistorted to \
                     another size, or from another image set?)",
                    k.width, k.height
                ),
            ));
        }
        let (rows, cols) = encoder.grid_for(k.width, k.height);
        let small = photo
            .resize_exact(
                (cols * patch) as u32,
                (rows * patch) as u32,
                image::imageops::FilterType::Triangle,
            )
            .to_rgb32f();
        Ok(RgbImage {
            width: small.width() as usize,
            height: small.height() as usize,
            pixels: small.into_raw(),
        })
    };
    encode_images(photos.len(), read, encoder, progress)
}

/// An RGB render of `view` at `size` pixels on its longer side, clamped to [0, 1].
pub fn render_rgb(scene: &DeviceScene, view: &View, size: usize) -> Result<RgbImage> {
    render_rgb_with(scene, view, &sized(&view.intrinsics, size)?)
}

/// An RGB render of `view`'s pose through `intrinsics`, clamped to [0, 1]. Rendered on the
/// scene's device without a gradient (the image is only read).
fn render_rgb_with(scene: &DeviceScene, view: &View, intrinsics: &Intrinsics) -> Result<RgbImage> {
    let request = RenderRequest {
        alpha: AlphaChannel::Dropped,
        ..RenderRequest::new(*intrinsics, vec![Channel::Rgb])
    };
    let out = render_poses(scene, &[view.pose], &request)?;
    let pixels: Vec<f32> = out
        .images
        .without_autodiff()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| LiftError::Scene(format!("reading a render back: {e:?}")))?;
    Ok(RgbImage {
        width: intrinsics.width,
        height: intrinsics.height,
        pixels: pixels.into_iter().map(|v| v.clamp(0.0, 1.0)).collect(),
    })
}

/// Per-pixel values `[H, W, k]` bilinearly interpolated between patch centres of a
/// `rows × cols` grid (`[rows, cols, k]`) that covers the whole image; pixels beyond the outer
/// centres take the edge values.
pub fn upsample(
    patches: &[f32],
    rows: usize,
    cols: usize,
    k: usize,
    intrinsics: &Intrinsics,
) -> Vec<f32> {
    let (w, h) = (intrinsics.width, intrinsics.height);
    let mut out = vec![0f32; w * h * k];
    // Pixel centre x + 0.5 in grid units, minus 0.5 to index patch centres.
    let coord = |p: usize, pixels: usize, cells: usize| -> (usize, usize, f32) {
        let g =
            ((p as f32 + 0.5) / pixels as f32 * cells as f32 - 0.5).clamp(0.0, (cells - 1) as f32);
        let lo = g.floor() as usize;
        let hi = (lo + 1).min(cells - 1);
        (lo, hi, g - lo as f32)
    };
    for y in 0..h {
        let (r0, r1, fy) = coord(y, h, rows);
        for x in 0..w {
            let (c0, c1, fx) = coord(x, w, cols);
            let at = |r: usize, c: usize| &patches[(r * cols + c) * k..(r * cols + c + 1) * k];
            let (a, b, c, d) = (at(r0, c0), at(r0, c1), at(r1, c0), at(r1, c1));
            let o = &mut out[(y * w + x) * k..(y * w + x + 1) * k];
            for j in 0..k {
                let top = a[j] + fx * (b[j] - a[j]);
                let bottom = c[j] + fx * (d[j] - c[j]);
                o[j] = top + fy * (bottom - top);
            }
        }
    }
    out
}
