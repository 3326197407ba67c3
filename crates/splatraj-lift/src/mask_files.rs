//! Label masks from files: a segmenter's PNGs (SAM or any) matched to the capture's cameras.
//!
//! Conventions ([`read_masks`]):
//!
//! - a mask is `DIR/<stem>.png` where `<stem>` is its camera's image name without folder and
//!   extension ([`crate::cameras::image_stem`]: `frame_0001.png` for `images/frame_0001.jpg`);
//!   a camera without a mask is skipped, a mask without a camera is an error, other files are
//!   ignored (but a JPEG or WebP mask is refused: lossy compression blends label colours);
//! - grey PNGs (8 or 16 bit) hold label ids, 0 = no object; colour PNGs (RGB, RGBA, palette)
//!   code labels by colour: black is 0 and every other colour, over all masks, a label
//!   numbered from 1 in ascending (R, G, B) order, so the same colours give the same ids
//!   whatever the file order ([`MaskFiles::legend`]); a pixel with alpha 0 is 0. All masks are
//!   grey or all colour;
//! - a mask is its camera's size, or smaller or larger with the same aspect ratio to within
//!   [`ASPECT_TOLERANCE`] (a rescaled image, each side rounded): the camera is rescaled to it.
//!   Any other size is refused, naming the mask, its size and the camera's.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use burn::tensor::{DType, Device, Tensor};
use image::DynamicImage;
use rayon::prelude::*;
use splatraj_render::render::{Channel, DeviceScene, RenderError, RenderRequest, render};
use splatraj_scene::{Labels, Scene};

use crate::cameras::{NamedView, read_views};
use crate::error::{LiftError, Result};
use crate::masks::{LiftedLabels, MaskOptions, MaskView, lift_masks};
use crate::progress::Progress;
use crate::views::View;

/// Extensions of lossy image formats, refused as masks.
const LOSSY: [&str; 3] = ["jpg", "jpeg", "webp"];

/// How far (relative) a mask's aspect ratio may be from its camera's: rounding each side of a
/// rescaled image to whole pixels moves it by at most 1/side, under 1 % for masks of 100
/// pixels a side or more; a few pixels' mask of a larger image is not told apart from a crop.
pub const ASPECT_TOLERANCE: f64 = 0.01;

/// How many names an error lists before "and N more".
const LISTED: usize = 8;

/// How the masks of a folder code their labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskCoding {
    /// Grey values are label ids.
    Grey,
    /// Colours are labels ([`MaskFiles::legend`]).
    Colour,
}

/// One colour of colour-coded masks and the label id it became.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LegendEntry {
    /// The colour, RGB.
    pub colour: [u8; 3],
    /// Its label id (from 1).
    pub id: i32,
}

impl LegendEntry {
    /// The colour as `#rrggbb`, the label's name in the sidecar.
    pub fn name(&self) -> String {
        let [r, g, b] = self.colour;
        format!("#{r:02x}{g:02x}{b:02x}")
    }
}

/// The masks of a folder, matched to their cameras.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskFiles {
    /// One per mask file, the camera rescaled to the mask's size.
    pub masks: Vec<MaskView>,
    /// The camera name of each mask.
    pub names: Vec<String>,
    /// Cameras without a mask (skipped).
    pub unmasked: Vec<String>,
    /// How the labels are coded.
    pub coding: MaskCoding,
    /// Colour → label id of colour-coded masks, by id (empty for grey masks).
    pub legend: Vec<LegendEntry>,
}

/// A decoded mask before colours are numbered.
enum Decoded {
    /// Label ids.
    Grey(Vec<i32>),
    /// Packed `0xRRGGBB` per pixel, `None` for no object (black or transparent).
    Colour(Vec<Option<u32>>),
}

/// Reads the masks in `dir` for `cameras` (see the module docs for the conventions).
pub fn read_masks(cameras: &[NamedView], dir: &Path) -> Result<MaskFiles> {
    let mut by_stem: HashMap<&str, usize> = HashMap::new();
    for (c, camera) in cameras.iter().enumerate() {
        if let Some(other) = by_stem.insert(camera.stem(), c) {
            return Err(LiftError::file(
                dir,
                format!(
                    "cameras {:?} and {:?} share the stem {:?}: a mask cannot say which it is",
                    cameras[other].name,
                    camera.name,
                    camera.stem()
                ),
            ));
        }
    }
    let mut files: Vec<(usize, PathBuf)> = Vec::new();
    let mut strangers: Vec<String> = Vec::new();
    for path in mask_candidates(dir)? {
        let file_name = path.file_name().unwrap_or_default().to_string_lossy();
        let (stem, ext) = file_name
            .rsplit_once('.')
            .map_or((file_name.as_ref(), ""), |(s, e)| (s, e));
        if LOSSY.iter().any(|l| ext.eq_ignore_ascii_case(l)) {
            return Err(LiftError::file(
                &path,
                "masks must be PNG: lossy compression blends label colours at every edge",
            ));
        }
        if !ext.eq_ignore_ascii_case("png") {
            continue;
        }
        match by_stem.get(stem) {
            Some(&c) => files.push((c, path.clone())),
            None => strangers.push(file_name.into_owned()),
        }
    }
    if !strangers.is_empty() {
        return Err(LiftError::file(
            dir,
            format!(
                "{} mask(s) match no camera: {} (masks are named after the cameras' images, \
                 e.g. {}.png)",
                strangers.len(),
                listed(&strangers),
                cameras.first().map_or("frame_0000", NamedView::stem)
            ),
        ));
    }
    if files.is_empty() {
        return Err(LiftError::file(
            dir,
            format!(
                "no PNG mask named after any of the {} cameras (e.g. {}.png)",
                cameras.len(),
                cameras.first().map_or("frame_0000", NamedView::stem)
            ),
        ));
    }
    files.sort_by_key(|(c, _)| *c);

    let decoded = files
        .par_iter()
        .map(|(c, path)| {
            let (width, height, pixels) = decode(path)?;
            let view = fitted_view(&cameras[*c], width, height, path)?;
            Ok((view, pixels))
        })
        .collect::<Result<Vec<_>>>()?;

    let grey = decoded
        .iter()
        .position(|(_, d)| matches!(d, Decoded::Grey(_)));
    let colour = decoded
        .iter()
        .position(|(_, d)| matches!(d, Decoded::Colour(_)));
    let coding = match (grey, colour) {
        (Some(g), Some(c)) => {
            return Err(LiftError::file(
                dir,
                format!(
                    "{} is grey (label ids) but {} is colour-coded: all masks must code labels \
                     the same way",
                    files[g].1.display(),
                    files[c].1.display()
                ),
            ));
        }
        (Some(_), None) => MaskCoding::Grey,
        _ => MaskCoding::Colour,
    };
    let colours: BTreeSet<u32> = decoded
        .iter()
        .filter_map(|(_, d)| match d {
            Decoded::Colour(px) => Some(px.iter().flatten().copied()),
            Decoded::Grey(_) => None,
        })
        .flatten()
        .collect();
    let ids: BTreeMap<u32, i32> = colours.iter().zip(1..).map(|(&c, id)| (c, id)).collect();
    let masks: Vec<MaskView> = decoded
        .into_iter()
        .map(|(view, d)| MaskView {
            view,
            labels: match d {
                Decoded::Grey(labels) => labels,
                Decoded::Colour(px) => px.iter().map(|p| p.map_or(0, |c| ids[&c])).collect(),
            },
        })
        .collect();
    if masks.iter().all(|m| m.labels.iter().all(|&l| l == 0)) {
        return Err(LiftError::file(
            dir,
            format!(
                "none of the {} masks labels any pixel (all 0 or black)",
                masks.len()
            ),
        ));
    }
    let masked: BTreeSet<usize> = files.iter().map(|(c, _)| *c).collect();
    Ok(MaskFiles {
        masks,
        names: files
            .iter()
            .map(|(c, _)| cameras[*c].name.clone())
            .collect(),
        unmasked: (0..cameras.len())
            .filter(|c| !masked.contains(c))
            .map(|c| cameras[c].name.clone())
            .collect(),
        coding,
        legend: ids
            .iter()
            .map(|(&c, &id)| LegendEntry {
                colour: [(c >> 16) as u8, (c >> 8) as u8, c as u8],
                id,
            })
            .collect(),
    })
}

/// The visible regular files of `dir`, sorted by name.
fn mask_candidates(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| LiftError::file(dir, format!("cannot list the mask folder: {e}")))?;
    let mut paths = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| LiftError::file(dir, e))?;
        let path = entry.path();
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if !hidden && path.is_file() {
            paths.push(path);
        }
    }
    paths.sort();
    Ok(paths)
}

/// `names` for a message, the first few and how many more.
fn listed(names: &[String]) -> String {
    let mut text = names
        .iter()
        .take(LISTED)
        .map(String::as_str)
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > LISTED {
        text += &format!(" and {} more", names.len() - LISTED);
    }
    text
}

/// Width, height and pixels of the PNG at `path`.
fn decode(path: &Path) -> Result<(usize, usize, Decoded)> {
    let reader = splatraj_scene::input::open(path)
        .map(|(file, _)| std::io::BufReader::new(file))
        .map_err(|e| LiftError::file(path, e))?;
    let image = image::load(reader, image::ImageFormat::Png)
        .map_err(|e| LiftError::file(path, format!("not a readable PNG: {e}")))?;
    let (width, height) = (image.width() as usize, image.height() as usize);
    let decoded = match &image {
        // The values themselves, not scaled to another depth (to_luma16 would make 3 → 771).
        DynamicImage::ImageLuma8(g) => {
            Decoded::Grey(g.pixels().map(|p| i32::from(p.0[0])).collect())
        }
        DynamicImage::ImageLuma16(g) => {
            Decoded::Grey(g.pixels().map(|p| i32::from(p.0[0])).collect())
        }
        DynamicImage::ImageLumaA8(g) => Decoded::Grey(
            g.pixels()
                .map(|p| if p.0[1] == 0 { 0 } else { i32::from(p.0[0]) })
                .collect(),
        ),
        DynamicImage::ImageLumaA16(g) => Decoded::Grey(
            g.pixels()
                .map(|p| if p.0[1] == 0 { 0 } else { i32::from(p.0[0]) })
                .collect(),
        ),
        DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgba8(_)
        | DynamicImage::ImageRgb16(_)
        | DynamicImage::ImageRgba16(_) => Decoded::Colour(
            image
                .to_rgba8()
                .pixels()
                .map(|p| {
                    let [r, g, b, a] = p.0;
                    let packed = u32::from(r) << 16 | u32::from(g) << 8 | u32::from(b);
                    (a != 0 && packed != 0).then_some(packed)
                })
                .collect(),
        ),
        other => {
            return Err(LiftError::file(
                path,
                format!(
                    "{:?} pixels: a mask is grey (label ids) or 8/16-bit colour",
                    other.color()
                ),
            ));
        }
    };
    Ok((width, height, decoded))
}

/// `camera`'s view at the mask's size, or why the mask cannot be from it.
fn fitted_view(camera: &NamedView, width: usize, height: usize, path: &Path) -> Result<View> {
    let k = camera.view.intrinsics;
    if (k.width, k.height) == (width, height) {
        return Ok(camera.view);
    }
    // Aspect ratios compared as w·H against h·W (no division by a side).
    let cross = (width * k.height).abs_diff(height * k.width) as f64;
    if cross > ASPECT_TOLERANCE * (height * k.width) as f64 {
        return Err(LiftError::file(
            path,
            format!(
                "the mask's size {width}×{height} is not the size of camera {:?}, {}×{}, nor \
                 a rescale of it (aspect ratios {:.4} and {:.4} differ by more than {} %)",
                camera.name,
                k.width,
                k.height,
                width as f64 / height as f64,
                k.width as f64 / k.height as f64,
                100.0 * ASPECT_TOLERANCE
            ),
        ));
    }
    Ok(View {
        pose: camera.view.pose,
        intrinsics: k
            .rescaled(width, height)
            .map_err(|e| LiftError::file(path, e))?,
    })
}

/// Labels lifted from mask files, with what was read.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskLift {
    /// The per-Gaussian labels.
    pub labels: LiftedLabels,
    /// The camera name of each mask used.
    pub masked: Vec<String>,
    /// Cameras without a mask (skipped).
    pub unmasked: Vec<String>,
    /// How the masks coded labels.
    pub coding: MaskCoding,
    /// Colour → label id of colour-coded masks (empty for grey masks).
    pub legend: Vec<LegendEntry>,
}

impl MaskLift {
    /// The labels as a scene's labels (`source` says where they came from); colour labels are
    /// named by their colour (`#rrggbb`).
    pub fn scene_labels(&self, source: impl Into<String>) -> Labels {
        Labels {
            source: source.into(),
            ids: self.labels.ids.clone(),
            names: self.legend.iter().map(|e| (e.id, e.name())).collect(),
        }
    }

    /// Share of the Gaussians no mask's camera showed.
    pub fn unseen_share(&self) -> f64 {
        let unseen = self
            .labels
            .weights
            .iter()
            .filter(|&&w| w < crate::MIN_WEIGHT)
            .count();
        unseen as f64 / self.labels.weights.len().max(1) as f64
    }
}

/// Reads the cameras of `cameras` and the masks in `masks` ([`read_masks`]) and lifts them onto
/// `scene` on `device` ([`lift_masks`]).
pub fn lift_mask_files(
    scene: &Scene,
    cameras: &Path,
    masks: &Path,
    options: &MaskOptions,
    device: &Device,
    progress: &Progress,
) -> Result<MaskLift> {
    let views = read_views(cameras)?;
    let files = read_masks(&views, masks)?;
    let device_scene = DeviceScene::new(scene, &device.clone().autodiff(), DType::F32);
    let labels = lift_masks(scene, &device_scene, &files.masks, options, progress)?;
    Ok(MaskLift {
        labels,
        masked: files.names,
        unmasked: files.unmasked,
        coding: files.coding,
        legend: files.legend,
    })
}

/// Per pixel of `view`, the label of `labels` (one per Gaussian) with the most blending weight,
/// where the render covers at least half the pixel (`None` elsewhere): the mask a segmenter
/// would draw for a scene whose Gaussians are already labelled (to check the mask route, or
/// to make masks of a labelled scene).
pub fn render_label_mask(
    device_scene: &DeviceScene,
    labels: &[i32],
    view: &View,
) -> Result<Vec<Option<i32>>> {
    let ids: Vec<i32> = labels
        .iter()
        .copied()
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let dim = ids.len().max(1);
    let values: Vec<f32> = labels
        .iter()
        .flat_map(|l| ids.iter().map(move |id| f32::from(u8::from(id == l))))
        .collect();
    let device = device_scene.geometry.means.device();
    let pose = splatraj_render::host::poses_tensor(&[view.pose], &device, DType::F32);
    let request = RenderRequest::new(view.intrinsics, vec![Channel::Features { dim, values }]);
    let out = render(device_scene, pose, &request)?;
    let read = |t: Tensor<4>| -> Result<Vec<f32>> {
        t.into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .map_err(|e| RenderError::ReadBack(format!("{e:?}")).into())
    };
    let alpha = out
        .alpha()
        .ok_or(RenderError::AlphaDropped)?
        .unsqueeze_dim(3);
    let image = read(out.images)?;
    let alpha = read(alpha)?;
    Ok(image
        .chunks_exact(dim)
        .zip(&alpha)
        .map(|(px, &a)| {
            let best = px
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(y.1))
                .map(|(i, _)| i);
            best.filter(|_| a >= 0.5 && !ids.is_empty()).map(|i| ids[i])
        })
        .collect())
}
