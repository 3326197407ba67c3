//! PlayCanvas SOG ("spatially ordered Gaussians"): what SuperSplat exports by default.
//!
//! Written from the format's definition in playcanvas/splat-transform (the reader
//! `src/lib/readers/read-sog.ts` and `read-sog-v1.ts`, the writer `src/lib/writers/write-sog.ts`),
//! checked against the reference tool's own decoding of a real capture (`narcissus.sog`, see
//! `scripts/make_sog_fixture.py`).
//!
//! # Container
//!
//! A scene is a `meta.json` plus a few lossless WebP images, either bundled in a zip (`.sog`) or
//! side by side in a folder. Image names come from `meta.json` and are relative to it. Every
//! per-Gaussian image is `width × height ≥ count` texels read row by row: Gaussian `i` is texel
//! `i` (the writer has already put the Gaussians in Morton order; we keep its order).
//!
//! # Version 2 (`"version": 2`)
//!
//! - `means`: `means_l` and `means_u` hold the low and high bytes of a 16-bit value per axis
//!   (R, G, B = x, y, z). `v = mins + (maxs − mins) · n / 65535` is the position in the log
//!   space `sign(x)·ln(|x| + 1)`, so `x = sign(v)·(exp(|v|) − 1)`. A zero span counts as 1, as
//!   in the reference reader.
//! - `quats`: "smallest three". Alpha is `252 + k` where `k` indexes the largest component in
//!   `(w, x, y, z)` order; R, G, B are the other three in that order, each `(q·√2 · 0.5 + 0.5) ·
//!   255`, and the largest is recomputed, positive.
//! - `scales`: R, G, B index a shared codebook of log-scales (`scales.codebook`).
//! - `sh0`: R, G, B index a shared codebook of SH DC terms (`sh0.codebook`); A is the activated
//!   opacity × 255 (the writer applies the sigmoid before quantising).
//! - `shN` (optional, `bands` 1-3): a palette of SH vectors. `shN_labels` gives each Gaussian a
//!   16-bit palette index (R low byte, G high byte); `shN_centroids` stores palette entry `e` in
//!   row `e / 64`, texels `(e mod 64)·c … (e mod 64)·c + c − 1` for the `c` coefficients after
//!   the DC term, R, G, B being the colour channels, each byte indexing `shN.codebook`.
//!
//! # Version 1 (no `version`)
//!
//! The same images with per-channel linear ranges instead of codebooks: `count` is
//! `means.shape[0]`; scales are `mins + (maxs − mins)·b/255` (log-space); `sh0` R, G, B are DC
//! terms in `mins[0..3]`/`maxs[0..3]` and A is the opacity *logit* in `mins[3]`/`maxs[3]`; shN
//! bytes map to one scalar range `shN.mins`/`shN.maxs` and the band count follows from the
//! centroid image's width (192, 512, 960).
//!
//! SOG stores the PLY's own axes (splat-transform's `Transform.PLY`), so no axis change is made.

use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Result, SceneError};
use crate::scene::{Extras, Scene, sh_coeffs_for_degree, sigmoid};

/// The zip local-file-header signature that a `.sog` bundle starts with.
pub const ZIP_MAGIC: &[u8] = b"PK\x03\x04";
/// The name of the description file, in a bundle or a folder.
pub const META_NAME: &str = "meta.json";

/// Palette entries per row of the `shN_centroids` image.
const PALETTE_ROW: usize = 64;
/// No image entry of a real bundle comes near this; it bounds what a corrupt zip can make us
/// allocate.
const MAX_ENTRY_BYTES: u64 = 1 << 30;
/// The WebP format cannot be larger than 16383 × 16383, so no valid SOG holds more Gaussians.
const MAX_COUNT: usize = 16383 * 16383;

/// True when `bytes` are a zip archive that names a `meta.json` (a SOG bundle).
pub fn is_sog_bundle(bytes: &[u8]) -> bool {
    // The central directory at the end lists every entry's name; finding the name anywhere in
    // the file is a cheap test that the full zip parse then confirms.
    bytes.starts_with(ZIP_MAGIC)
        && bytes
            .windows(META_NAME.len())
            .any(|w| w == META_NAME.as_bytes())
}

/// True when `bytes` look like a SOG `meta.json` (a JSON object naming means and quats).
pub fn is_sog_meta(bytes: &[u8]) -> bool {
    let contains = |needle: &[u8]| bytes.windows(needle.len()).any(|w| w == needle);
    // The codebooks come first and run to kilobytes, so the keys are looked for everywhere;
    // only files that start as a JSON object get that far.
    bytes.trim_ascii_start().starts_with(b"{") && contains(b"\"means\"") && contains(b"\"quats\"")
}

/// Decodes a SOG scene: `bytes` are either a `.sog` zip or the `meta.json` of an unbundled
/// folder at `path` (its images are read from the same folder).
pub fn decode_sog(bytes: &[u8], path: &Path) -> Result<Scene> {
    let mut source = if bytes.starts_with(ZIP_MAGIC) {
        Source::zip(bytes, path)?
    } else {
        Source::Folder {
            dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            meta: bytes.to_vec(),
        }
    };
    let meta_bytes = source.meta(path)?;
    let version: Versioned = parse_meta(&meta_bytes, path)?;
    match version.version {
        Some(2) => decode_v2(&parse_meta(&meta_bytes, path)?, &mut source, path),
        None => decode_v1(&parse_meta(&meta_bytes, path)?, &mut source, path),
        Some(v) => Err(SceneError::malformed(
            path,
            format!("SOG meta.json version {v} is not supported (1 and 2 are)"),
        )),
    }
}

/// Where the images are: entries of a zip, or files next to `meta.json`.
enum Source<'a> {
    Zip {
        archive: zip::ZipArchive<Cursor<&'a [u8]>>,
        /// Folder of `meta.json` inside the zip ("" at the root), images are relative to it.
        prefix: String,
    },
    Folder {
        dir: PathBuf,
        meta: Vec<u8>,
    },
}

impl<'a> Source<'a> {
    fn zip(bytes: &'a [u8], path: &Path) -> Result<Self> {
        let archive = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| {
            SceneError::malformed(path, format!("SOG bundle is not a readable zip: {e}"))
        })?;
        // SuperSplat puts meta.json at the root; a bundle zipped from a folder has it one
        // level down, which is as good.
        let meta_entry = archive
            .file_names()
            .filter_map(|name| name.ok())
            .filter(|name| name.as_ref() == META_NAME || name.ends_with("/meta.json"))
            .min_by_key(|name| name.len())
            .map(|name| name.into_owned())
            .ok_or_else(|| {
                SceneError::malformed(path, "SOG bundle without a meta.json entry".to_string())
            })?;
        let prefix = meta_entry[..meta_entry.len() - META_NAME.len()].to_string();
        Ok(Source::Zip { archive, prefix })
    }

    fn meta(&mut self, path: &Path) -> Result<Vec<u8>> {
        match self {
            Source::Zip { .. } => self.load(META_NAME, path),
            Source::Folder { meta, .. } => Ok(std::mem::take(meta)),
        }
    }

    /// The bytes of the file `name` (relative to `meta.json`).
    fn load(&mut self, name: &str, path: &Path) -> Result<Vec<u8>> {
        if name.contains("..") || name.starts_with('/') || name.contains('\\') {
            return Err(SceneError::malformed(
                path,
                format!("meta.json names the image {name:?}, which is not a plain file name"),
            ));
        }
        match self {
            Source::Zip { archive, prefix } => {
                let full = format!("{prefix}{name}");
                let entry = archive.by_name(&full).map_err(|e| match e {
                    zip::result::ZipError::FileNotFound => SceneError::malformed(
                        path,
                        format!("missing image '{full}' in the SOG bundle (meta.json lists it)"),
                    ),
                    e => SceneError::malformed(path, format!("cannot read '{full}': {e}")),
                })?;
                let mut out = Vec::new();
                entry
                    .take(MAX_ENTRY_BYTES)
                    .read_to_end(&mut out)
                    .map_err(|e| {
                        SceneError::malformed(path, format!("cannot read '{full}': {e}"))
                    })?;
                Ok(out)
            }
            Source::Folder { dir, .. } => {
                let file = dir.join(name);
                crate::input::read_bytes(&file).map_err(|e| {
                    if e.kind() == std::io::ErrorKind::NotFound {
                        SceneError::malformed(
                            path,
                            format!("missing image {} (meta.json lists it)", file.display()),
                        )
                    } else {
                        SceneError::io(&file, e)
                    }
                })
            }
        }
    }

    /// Decodes the image `name` to RGBA and checks it has a texel for each of `count` Gaussians
    /// (and, before decoding, not far more: see [`MAX_SPARE_TEXELS`]).
    fn texture(&mut self, name: &str, count: usize, path: &Path) -> Result<Texture> {
        let bytes = self.load(name, path)?;
        let texture = decode_webp(&bytes, name, 2 * count + MAX_SPARE_TEXELS, count, path)?;
        if texture.texels() < count {
            return Err(SceneError::malformed(
                path,
                format!(
                    "image '{name}' is {}×{} = {} texels, fewer than the {count} Gaussians",
                    texture.width,
                    texture.height,
                    texture.texels()
                ),
            ));
        }
        Ok(texture)
    }
}

/// Texels an image may hold beyond two per Gaussian: the largest shN codebook (65 536 entries
/// of 15 coefficients, 983 040 texels) with room to spare. A writer lays a per-Gaussian image
/// out as a near-square of `count` texels, so anything much larger is not this scene's.
const MAX_SPARE_TEXELS: usize = 4 << 20;

/// A decoded image, always RGBA.
struct Texture {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

impl Texture {
    fn texels(&self) -> usize {
        self.width * self.height
    }

    /// Texel `i` in row-major order.
    fn at(&self, i: usize) -> [u8; 4] {
        let t = &self.rgba[4 * i..4 * i + 4];
        [t[0], t[1], t[2], t[3]]
    }
}

/// Decodes a WebP image to RGBA.
///
/// `image-webp` is the pure-Rust decoder maintained by image-rs (the `image` crate's own WebP
/// backend): lossless (VP8L) and lossy, no C library to build, and already in Cargo.lock. SOG
/// images are lossless, so the bytes come back exactly as the writer quantised them.
///
/// An image of more than `max_texels` texels is refused from its header, before anything is
/// allocated for it (`count`: the Gaussians meta.json declares, for the message).
fn decode_webp(
    bytes: &[u8],
    name: &str,
    max_texels: usize,
    count: usize,
    path: &Path,
) -> Result<Texture> {
    let bad = |e: &dyn std::fmt::Display| {
        SceneError::malformed(path, format!("image '{name}' is not a readable WebP: {e}"))
    };
    let mut decoder = image_webp::WebPDecoder::new(Cursor::new(bytes)).map_err(|e| bad(&e))?;
    let (width, height) = decoder.dimensions();
    let (width, height) = (width as usize, height as usize);
    if width * height > max_texels {
        return Err(SceneError::malformed(
            path,
            format!(
                "image '{name}' is {width}×{height} = {} texels, far more than meta.json's \
                 {count} Gaussians need (at most {max_texels}): it is not this scene's image",
                width * height
            ),
        ));
    }
    let size = decoder
        .output_buffer_size()
        .ok_or_else(|| bad(&"the image is too large"))?;
    let mut buf = vec![0u8; size];
    decoder.read_image(&mut buf).map_err(|e| bad(&e))?;
    // A lossless encoder drops an all-opaque alpha channel, so images whose alpha the writer
    // set to 255 (means, labels) come back as RGB.
    let rgba = if decoder.has_alpha() {
        buf
    } else {
        buf.chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect()
    };
    Ok(Texture {
        width,
        height,
        rgba,
    })
}

#[derive(Deserialize)]
struct Versioned {
    version: Option<u32>,
}

fn parse_meta<'de, T: Deserialize<'de>>(bytes: &'de [u8], path: &Path) -> Result<T> {
    serde_json::from_slice(bytes)
        .map_err(|e| SceneError::malformed(path, format!("meta.json: {e}")))
}

/// A meta entry that only lists its images.
#[derive(Deserialize)]
struct Files {
    files: Vec<String>,
}

/// A meta entry with per-channel linear ranges (version 1, and means in version 2).
#[derive(Deserialize)]
struct RangedFiles {
    mins: Vec<f64>,
    maxs: Vec<f64>,
    files: Vec<String>,
}

/// A meta entry whose bytes index a shared codebook (version 2).
#[derive(Deserialize)]
struct CodebookFiles {
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MetaV2 {
    count: usize,
    means: RangedFiles,
    scales: CodebookFiles,
    quats: Files,
    sh0: CodebookFiles,
    #[serde(rename = "shN")]
    sh_n: Option<PaletteV2>,
}

#[derive(Deserialize)]
struct PaletteV2 {
    count: usize,
    bands: u8,
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MeansV1 {
    shape: Vec<usize>,
    mins: Vec<f64>,
    maxs: Vec<f64>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MetaV1 {
    means: MeansV1,
    scales: RangedFiles,
    quats: Files,
    sh0: RangedFiles,
    #[serde(rename = "shN")]
    sh_n: Option<PaletteV1>,
}

#[derive(Deserialize)]
struct PaletteV1 {
    mins: f32,
    maxs: f32,
    files: Vec<String>,
}

/// The `k`-th file name of a meta entry, or an error naming the entry.
fn file<'m>(files: &'m [String], k: usize, entry: &str, path: &Path) -> Result<&'m str> {
    files.get(k).map(String::as_str).ok_or_else(|| {
        SceneError::malformed(
            path,
            format!(
                "meta.json: '{entry}.files' lists {} images, expected at least {}",
                files.len(),
                k + 1
            ),
        )
    })
}

/// `n` numbers of a meta range, or an error naming the entry.
fn range<'m>(values: &'m [f64], n: usize, entry: &str, path: &Path) -> Result<&'m [f64]> {
    values.get(..n).ok_or_else(|| {
        SceneError::malformed(
            path,
            format!(
                "meta.json: '{entry}' has {} values, expected {n}",
                values.len()
            ),
        )
    })
}

fn check_count(count: usize, path: &Path) -> Result<()> {
    if count > MAX_COUNT {
        return Err(SceneError::malformed(
            path,
            format!(
                "meta.json claims {count} Gaussians, more than WebP images of at most \
                 16383×16383 texels can hold"
            ),
        ));
    }
    Ok(())
}

/// Codebook entry `byte`, or an error naming the Gaussian and the codebook.
fn lookup(codebook: &[f32], byte: u8, gaussian: usize, entry: &str, path: &Path) -> Result<f32> {
    codebook.get(byte as usize).copied().ok_or_else(|| {
        SceneError::malformed(
            path,
            format!(
                "Gaussian {gaussian}: {entry} index {byte} is beyond its codebook of {} values",
                codebook.len()
            ),
        )
    })
}

/// Inverse of the writer's `sign(x)·ln(|x| + 1)`.
fn inv_log_transform(v: f64) -> f64 {
    v.signum() * (v.abs().exp() - 1.0)
}

/// Positions from the two 16-bit halves and the log-space ranges (both versions).
fn decode_means(
    low: &Texture,
    high: &Texture,
    mins: &[f64],
    maxs: &[f64],
    count: usize,
) -> Vec<[f32; 3]> {
    let spans: [f64; 3] = std::array::from_fn(|k| {
        let span = maxs[k] - mins[k];
        if span == 0.0 { 1.0 } else { span }
    });
    (0..count)
        .map(|i| {
            let (l, u) = (low.at(i), high.at(i));
            std::array::from_fn(|k| {
                let n = f64::from(u16::from(l[k]) | (u16::from(u[k]) << 8)) / 65535.0;
                inv_log_transform(mins[k] + spans[k] * n) as f32
            })
        })
        .collect()
}

/// Quaternions (w, x, y, z) from the smallest-three texels (both versions).
fn decode_quats(quats: &Texture, count: usize, path: &Path) -> Result<Vec<[f32; 4]>> {
    let half_sqrt2 = std::f32::consts::FRAC_1_SQRT_2;
    (0..count)
        .map(|i| {
            let t = quats.at(i);
            let Some(largest) = t[3].checked_sub(252).filter(|&k| k < 4) else {
                return Err(SceneError::malformed(
                    path,
                    format!(
                        "Gaussian {i}: quats alpha is {} (expected 252-255, naming the \
                         largest quaternion component)",
                        t[3]
                    ),
                ));
            };
            let largest = largest as usize;
            let mut q = [0.0f32; 4];
            let mut sum = 0.0;
            let others = (0..4).filter(|&c| c != largest);
            for (byte, c) in t[..3].iter().zip(others) {
                q[c] = (f32::from(*byte) / 255.0 * 2.0 - 1.0) * half_sqrt2;
                sum += q[c] * q[c];
            }
            q[largest] = (1.0 - sum).max(0.0).sqrt();
            Ok(q)
        })
        .collect()
}

/// The SH rest of each Gaussian from a palette: `labels` index entries of `centroids`, whose
/// bytes go through `dequantise`; the result is written into `scene.sh` after each DC term.
fn decode_palette(
    scene: &mut Scene,
    centroids: &Texture,
    labels: &Texture,
    palette_count: usize,
    dequantise: impl Fn(u8, usize) -> Result<f32>,
    path: &Path,
) -> Result<()> {
    let rest = sh_coeffs_for_degree(scene.sh_degree) - 1;
    let stride = 3 * (rest + 1);
    for i in 0..scene.len() {
        let l = labels.at(i);
        let entry = usize::from(l[0]) | (usize::from(l[1]) << 8);
        let row = entry / PALETTE_ROW;
        let first = (entry % PALETTE_ROW) * rest;
        if entry >= palette_count || row >= centroids.height {
            return Err(SceneError::malformed(
                path,
                format!(
                    "Gaussian {i}: shN label {entry} is beyond the palette ({palette_count} \
                     entries, {} rows of the centroids image)",
                    centroids.height
                ),
            ));
        }
        for j in 0..rest {
            let texel = centroids.at(row * centroids.width + first + j);
            for (c, &byte) in texel[..3].iter().enumerate() {
                scene.sh[i * stride + (1 + j) * 3 + c] = dequantise(byte, i)?;
            }
        }
    }
    Ok(())
}

/// An empty scene of `count` Gaussians with room for SH of `sh_degree`.
fn scene_with(count: usize, sh_degree: u8) -> Scene {
    Scene {
        means: Vec::new(),
        scales: Vec::with_capacity(count),
        rotations: Vec::new(),
        opacities: Vec::with_capacity(count),
        sh_degree,
        sh: vec![0.0; count * 3 * sh_coeffs_for_degree(sh_degree)],
        extras: Extras::default(),
    }
}

fn decode_v2(meta: &MetaV2, source: &mut Source<'_>, path: &Path) -> Result<Scene> {
    let n = meta.count;
    check_count(n, path)?;
    let palette = match &meta.sh_n {
        Some(p) if p.bands > 0 => {
            if p.bands > 3 {
                return Err(SceneError::malformed(
                    path,
                    format!("meta.json: shN.bands is {}, expected 0-3", p.bands),
                ));
            }
            Some(p)
        }
        _ => None,
    };
    let mut scene = scene_with(n, palette.map_or(0, |p| p.bands));
    let (mins, maxs) = (
        range(&meta.means.mins, 3, "means.mins", path)?,
        range(&meta.means.maxs, 3, "means.maxs", path)?,
    );
    let low = source.texture(file(&meta.means.files, 0, "means", path)?, n, path)?;
    let high = source.texture(file(&meta.means.files, 1, "means", path)?, n, path)?;
    scene.means = decode_means(&low, &high, mins, maxs, n);
    drop((low, high));

    let quats = source.texture(file(&meta.quats.files, 0, "quats", path)?, n, path)?;
    scene.rotations = decode_quats(&quats, n, path)?;
    drop(quats);

    let scales = source.texture(file(&meta.scales.files, 0, "scales", path)?, n, path)?;
    let book = &meta.scales.codebook;
    for i in 0..n {
        let t = scales.at(i);
        let mut s = [0.0; 3];
        for k in 0..3 {
            s[k] = lookup(book, t[k], i, "scales", path)?.exp();
        }
        scene.scales.push(s);
    }
    drop(scales);

    let sh0 = source.texture(file(&meta.sh0.files, 0, "sh0", path)?, n, path)?;
    let stride = 3 * scene.sh_coeffs();
    for i in 0..n {
        let t = sh0.at(i);
        for (c, &byte) in t[..3].iter().enumerate() {
            scene.sh[i * stride + c] = lookup(&meta.sh0.codebook, byte, i, "sh0", path)?;
        }
        scene.opacities.push(f32::from(t[3]) / 255.0);
    }
    drop(sh0);

    if let Some(p) = palette {
        let centroids = source.texture(file(&p.files, 0, "shN", path)?, 0, path)?;
        let rest = sh_coeffs_for_degree(p.bands) - 1;
        if centroids.width != PALETTE_ROW * rest {
            return Err(SceneError::malformed(
                path,
                format!(
                    "image '{}' is {} texels wide; {} SH bands need {}",
                    p.files[0],
                    centroids.width,
                    p.bands,
                    PALETTE_ROW * rest
                ),
            ));
        }
        let labels = source.texture(file(&p.files, 1, "shN", path)?, n, path)?;
        let book = &p.codebook;
        decode_palette(
            &mut scene,
            &centroids,
            &labels,
            p.count,
            |b, i| lookup(book, b, i, "shN", path),
            path,
        )?;
    }
    Ok(scene)
}

fn decode_v1(meta: &MetaV1, source: &mut Source<'_>, path: &Path) -> Result<Scene> {
    let n = *meta.means.shape.first().ok_or_else(|| {
        SceneError::malformed(
            path,
            "meta.json: 'means.shape' is empty (version 1 gives the count there)",
        )
    })?;
    check_count(n, path)?;
    let lerp = |lo: f64, hi: f64, b: u8| (lo + (hi - lo) * f64::from(b) / 255.0) as f32;

    // The band count comes from the centroid image (version 1 does not state it), so that image
    // is decoded first.
    let palette = match &meta.sh_n {
        Some(p) => {
            let centroids = source.texture(file(&p.files, 0, "shN", path)?, 0, path)?;
            let bands = match centroids.width {
                192 => 1,
                512 => 2,
                960 => 3,
                w => {
                    return Err(SceneError::malformed(
                        path,
                        format!(
                            "image '{}' is {w} texels wide, expected 192, 512 or 960 (64 \
                             palette entries of 3, 8 or 15 coefficients)",
                            p.files[0]
                        ),
                    ));
                }
            };
            Some((p, centroids, bands))
        }
        None => None,
    };
    let mut scene = scene_with(n, palette.as_ref().map_or(0, |(_, _, b)| *b));

    let (mins, maxs) = (
        range(&meta.means.mins, 3, "means.mins", path)?,
        range(&meta.means.maxs, 3, "means.maxs", path)?,
    );
    let low = source.texture(file(&meta.means.files, 0, "means", path)?, n, path)?;
    let high = source.texture(file(&meta.means.files, 1, "means", path)?, n, path)?;
    scene.means = decode_means(&low, &high, mins, maxs, n);
    drop((low, high));

    let quats = source.texture(file(&meta.quats.files, 0, "quats", path)?, n, path)?;
    scene.rotations = decode_quats(&quats, n, path)?;
    drop(quats);

    let (smin, smax) = (
        range(&meta.scales.mins, 3, "scales.mins", path)?,
        range(&meta.scales.maxs, 3, "scales.maxs", path)?,
    );
    let scales = source.texture(file(&meta.scales.files, 0, "scales", path)?, n, path)?;
    for i in 0..n {
        let t = scales.at(i);
        scene
            .scales
            .push(std::array::from_fn(|k| lerp(smin[k], smax[k], t[k]).exp()));
    }
    drop(scales);

    let (cmin, cmax) = (
        range(&meta.sh0.mins, 4, "sh0.mins", path)?,
        range(&meta.sh0.maxs, 4, "sh0.maxs", path)?,
    );
    let sh0 = source.texture(file(&meta.sh0.files, 0, "sh0", path)?, n, path)?;
    let stride = 3 * scene.sh_coeffs();
    for i in 0..n {
        let t = sh0.at(i);
        for c in 0..3 {
            scene.sh[i * stride + c] = lerp(cmin[c], cmax[c], t[c]);
        }
        // Version 1 stores the opacity logit, not the activated value.
        scene.opacities.push(sigmoid(lerp(cmin[3], cmax[3], t[3])));
    }
    drop(sh0);

    if let Some((p, centroids, bands)) = palette {
        let labels = source.texture(file(&p.files, 1, "shN", path)?, n, path)?;
        let rest = sh_coeffs_for_degree(bands) - 1;
        // Version 1 states no palette size: every entry the centroid image holds is valid.
        let palette_count = centroids.width / rest * centroids.height;
        let (lo, hi) = (f64::from(p.mins), f64::from(p.maxs));
        decode_palette(
            &mut scene,
            &centroids,
            &labels,
            palette_count,
            |b, _| Ok(lerp(lo, hi, b)),
            path,
        )?;
    }
    Ok(scene)
}
