//! A CLIP image encoder in burn: the image tower (ViT) of OpenAI's CLIP and open_clip
//! (ViT-B/16 as LangSplat pairs it; ViT-B/32 and ViT-L/14 share the layout), read from the
//! same file as the [text encoder](crate::text_encoder), with two outputs:
//!
//! - [`ImageEncoder::encode`]: unit global embeddings, open_clip's
//!   `CLIP.encode_image(normalize=True)` (patch convolution, class token, position
//!   embeddings, `ln_pre`, pre-norm transformer, `ln_post` on the class token, projection);
//! - [`ImageEncoder::dense`]: dense text-aligned patch features by **ClearCLIP** (Mengcheng
//!   Lan, Chaofeng Chen, Yiping Ke, Xinjiang Wang, Litong Feng, Wayne Zhang, "ClearCLIP:
//!   Decomposing CLIP Representations for Dense Vision-Language Inference", ECCV 2024,
//!   arXiv 2407.12442). Its three changes, all to the last block: the attention is
//!   self-self, `softmax(q·qᵀ/√d)·v` with `q`, `v` from that block's `ln_1(x)` and its
//!   trained projections; the residual connection is removed (the block's output is the
//!   attention branch alone, out projection included); the feed-forward network is
//!   dropped. Then `ln_post` and the projection on each patch token, L2-normalised. The
//!   patch features then compare with text embeddings by cosine, as the global one does.
//!   At an input other than the native one, the patch part of the position embeddings is
//!   resampled to the new grid as `F.interpolate(size=grid, mode="bicubic",
//!   align_corners=False)` (PyTorch's cubic kernel, A = −0.75, no antialias; the class
//!   token's unchanged). ClearCLIP's code calls the same interpolation with a scale factor
//!   of `(grid + 0.1) / native`, which maps sample positions slightly differently; the
//!   output size is given here, as open_clip's `resize_pos_embed` does.
//!
//! Resolution: `dense` runs the tower once on a larger input with interpolated position
//! embeddings (default [`DENSE_SIZE`] = 448 pixels, a 28×28 grid for patch 16), rather than
//! ClearCLIP's sliding 224-pixel windows. An object covering 2% of a view covers about 16
//! patches of that grid (4×4), against about 4 (2×2) at the native 224. The single pass
//! (785 tokens) costs about half the matrix products of the 9 windows (197 tokens each,
//! stride 112) that cover a 448 input, and needs no merging of overlaps. Measured on a
//! 2-core CPU with burn's flex backend and the ViT-B/16 shape (random weights): 2.1–2.6 s
//! per `dense` view at 448, against 0.49 s per 224 pass (so about 4.4 s for the 9 windows);
//! `time_dense_at_vit_b_16_size` in `tests/image_encoder.rs` prints these. Non-square views
//! keep their aspect ratio with about as many patches (see [`ImageEncoder::grid_for`]).
//!
//! What is read from where:
//! - the weights: [`StateDict`] (safetensors or a `torch.save`d state dict), keys under
//!   `visual.` (`visual.conv1.weight`, `visual.class_embedding`, `visual.positional_embedding`,
//!   `visual.ln_pre.*`, `visual.transformer.resblocks.{i}.*`, `visual.ln_post.*`,
//!   `visual.proj`), the text tower's keys ignored;
//! - width, layers, patch size, native grid, MLP and output widths: the tensors' shapes,
//!   every image tensor checked against them (a missing or mis-shaped tensor is an error
//!   naming the file and the tensor);
//! - heads and activation, which shapes cannot tell: [`ImageEncoderOptions`] when given,
//!   else `open_clip_config.json` beside the weights (`model_cfg.vision_cfg.width /
//!   head_width`, `model_cfg.quick_gelu`), else `width / 64` heads (open_clip's
//!   `CLIPVisionCfg.head_width` default and OpenAI's rule) and GELU.
//!
//! Preprocessing is CLIP's normalisation of pixels in [0, 1] by OpenAI's dataset mean and
//! standard deviation. Resizing is done here, by a small bilinear resampler of the whole
//! view ([`RgbImage::resized`], antialiased when shrinking): `encode` resizes to the
//! tower's native input (open_clip's own preprocessing instead resizes the shorter side
//! bicubically and crops the centre, so give square images of the native size for its exact
//! numbers), `dense` to its grid.

mod model;
mod resample;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::Device;

use crate::clip::{
    HEAD_WIDTH, Loader, block_shapes, check_known, choose, config_activation, config_count,
    count_layers,
};
use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};
use crate::weights::StateDict;

pub use crate::clip::Activation;
pub use resample::{MEAN, STD};

use model::VisionTower;

/// Default input size of [`ImageEncoder::dense`] (pixels of a square view; 28×28 patches
/// for patch 16).
pub const DENSE_SIZE: usize = 448;

/// Images encoded per forward pass by [`ImageEncoder::encode`]: bounds the activations.
const BATCH: usize = 8;

/// Key prefix of the image tower.
const PREFIX: &str = "visual.";

/// An RGB image.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `[H, W, 3]` in [0, 1], row-major.
    pub pixels: Vec<f32>,
}

impl RgbImage {
    /// Checks the size and values; `what` names the image in errors.
    pub fn check(&self, what: &str) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(SemanticError::Mismatch(format!(
                "{what} is {}×{}: an image needs at least one pixel",
                self.width, self.height
            )));
        }
        let want = self.width * self.height * 3;
        if self.pixels.len() != want {
            return Err(SemanticError::Mismatch(format!(
                "{what} is {}×{} but holds {} values, expected {want} ([H, W, 3])",
                self.width,
                self.height,
                self.pixels.len()
            )));
        }
        if let Some(&value) = self.pixels.iter().find(|v| !v.is_finite()) {
            return Err(SemanticError::NonFinite {
                what: what.to_string(),
                value,
            });
        }
        Ok(())
    }

    /// The whole view resampled to `width`×`height` (bilinear on pixel centres,
    /// antialiased when shrinking; the same size is returned unchanged).
    pub fn resized(&self, width: usize, height: usize) -> RgbImage {
        RgbImage {
            width,
            height,
            pixels: resample::resize_bilinear(&self.pixels, self.width, self.height, width, height),
        }
    }
}

/// What the weight shapes cannot tell, and the dense input size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageEncoderOptions {
    /// The MLP activation; `None` takes `open_clip_config.json` or GELU.
    pub activation: Option<Activation>,
    /// Attention heads; `None` takes `open_clip_config.json` or `width / 64`.
    pub heads: Option<usize>,
    /// Side in pixels of the square input [`ImageEncoder::dense`] runs at (a non-square view
    /// gets about as many patches); at least one patch.
    pub dense_size: usize,
}

impl Default for ImageEncoderOptions {
    fn default() -> Self {
        ImageEncoderOptions {
            activation: None,
            heads: None,
            dense_size: DENSE_SIZE,
        }
    }
}

/// The shape of an image tower, as found in a checkpoint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VisionShape {
    /// Transformer width.
    pub width: usize,
    /// Residual blocks.
    pub layers: usize,
    /// Patch side in pixels.
    pub patch: usize,
    /// Patches per side of the native input (the position embeddings' grid).
    pub grid: usize,
    /// Hidden width of each block's MLP.
    pub mlp_width: usize,
    /// Length of the output embedding.
    pub embed_dim: usize,
}

impl VisionShape {
    /// Side of the native input in pixels.
    pub fn input_size(&self) -> usize {
        self.grid * self.patch
    }

    /// Finds the image tower among `shapes` (a checkpoint's tensor names and shapes) and
    /// checks every one of its tensors; errors name `path` and the tensor.
    pub fn find(shapes: &BTreeMap<String, Vec<usize>>, path: &Path) -> Result<Self> {
        let conv = format!("{PREFIX}conv1.weight");
        let Some(conv_shape) = shapes.get(&conv) else {
            let first: Vec<&str> = shapes.keys().take(6).map(String::as_str).collect();
            return Err(SemanticError::file(
                path,
                format!(
                    "no tensor {conv:?}: not a CLIP ViT image tower (its first tensors: \
                     {first:?})"
                ),
            ));
        };
        let shape = |name: &str| -> Result<&Vec<usize>> {
            shapes.get(&format!("{PREFIX}{name}")).ok_or_else(|| {
                SemanticError::file(path, format!("missing tensor \"{PREFIX}{name}\""))
            })
        };
        let [width, 3, patch, patch_x] = conv_shape[..] else {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor {conv:?} has shape {conv_shape:?}: expected [width, 3, patch, \
                     patch] (a ResNet CLIP image tower is not supported)"
                ),
            ));
        };
        if patch != patch_x || patch == 0 {
            return Err(SemanticError::file(
                path,
                format!("tensor {conv:?} has shape {conv_shape:?}: patches must be square"),
            ));
        }
        let [positions, _] = shape("positional_embedding")?[..] else {
            return Err(bad_rank(path, "positional_embedding", 2));
        };
        let grid = (positions.saturating_sub(1) as f64).sqrt().round() as usize;
        if grid == 0 || grid * grid + 1 != positions {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor \"{PREFIX}positional_embedding\" has {positions} rows: expected a \
                     class token plus a square grid of patches"
                ),
            ));
        }
        let [_, embed_dim] = shape("proj")?[..] else {
            return Err(bad_rank(path, "proj", 2));
        };
        let [mlp_width, _] = shape("transformer.resblocks.0.mlp.c_fc.weight")?[..] else {
            return Err(bad_rank(path, "transformer.resblocks.0.mlp.c_fc.weight", 2));
        };
        let blocks = format!("{PREFIX}transformer.resblocks.");
        let layers = count_layers(shapes, &blocks, path, "image")?;
        let tower = VisionShape {
            width,
            layers,
            patch,
            grid,
            mlp_width,
            embed_dim,
        };
        let expected = tower.expected_shapes();
        for (name, want) in &expected {
            let got = shapes
                .get(name)
                .ok_or_else(|| SemanticError::file(path, format!("missing tensor {name:?}")))?;
            if got != want {
                return Err(SemanticError::file(
                    path,
                    format!(
                        "tensor {name:?} has shape {got:?}, expected {want:?} for an image \
                         tower of width {width}, {layers} layers, patch {patch}, grid \
                         {grid}×{grid}"
                    ),
                ));
            }
        }
        check_known(shapes, &blocks, &expected, path, "image")?;
        // Anything else under `visual.` (an attention pooler, a head) changes the output.
        if let Some(key) = shapes
            .keys()
            .find(|k| k.starts_with(PREFIX) && !expected.contains_key(*k))
        {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor {key:?} belongs to an image-tower variant splatraj does not \
                     implement (it knows conv1, class_embedding, positional_embedding, ln_pre, \
                     transformer, ln_post, proj)"
                ),
            ));
        }
        Ok(tower)
    }

    /// Every image-tower tensor with the shape it must have.
    pub fn expected_shapes(&self) -> BTreeMap<String, Vec<usize>> {
        let p = PREFIX;
        let w = self.width;
        let mut out = BTreeMap::new();
        out.insert(
            format!("{p}conv1.weight"),
            vec![w, 3, self.patch, self.patch],
        );
        out.insert(format!("{p}class_embedding"), vec![w]);
        out.insert(
            format!("{p}positional_embedding"),
            vec![self.grid * self.grid + 1, w],
        );
        for norm in ["ln_pre", "ln_post"] {
            out.insert(format!("{p}{norm}.weight"), vec![w]);
            out.insert(format!("{p}{norm}.bias"), vec![w]);
        }
        out.insert(format!("{p}proj"), vec![w, self.embed_dim]);
        for i in 0..self.layers {
            out.extend(block_shapes(
                &format!("{p}transformer.resblocks."),
                i,
                w,
                self.mlp_width,
            ));
        }
        out
    }
}

fn bad_rank(path: &Path, name: &str, rank: usize) -> SemanticError {
    SemanticError::file(
        path,
        format!("tensor \"{PREFIX}{name}\" must have {rank} dimensions"),
    )
}

/// Heads and activation from `open_clip_config.json` beside the weights, when there is one.
fn open_clip_config(
    weights: &Path,
) -> Result<(Option<usize>, Option<Activation>, Option<PathBuf>)> {
    let Some((model, path)) = crate::clip::open_clip_config(weights)? else {
        return Ok((None, None, None));
    };
    // open_clip's VisionTransformer has width / head_width heads (head_width 64 unless set).
    let width = config_count(&model, "/vision_cfg/width", &path)?;
    let head_width = config_count(&model, "/vision_cfg/head_width", &path)?;
    let heads = match (width, head_width) {
        (Some(w), h) => Some(w / h.unwrap_or(HEAD_WIDTH)),
        (None, _) => None,
    };
    let activation = config_activation(&model, &path)?;
    Ok((heads, activation, Some(path)))
}

/// Dense features: one unit vector per patch of the grid `dense` ran on.
///
/// Patch `(row, col)` covers the pixels `[col·W/cols, (col+1)·W/cols) × [row·H/rows,
/// (row+1)·H/rows)` of the `W`×`H` image given to [`ImageEncoder::dense`] (the whole view
/// is resized to the grid), centred on [`DenseFeatures::centre`].
#[derive(Debug, Clone, PartialEq)]
pub struct DenseFeatures {
    /// Patch rows.
    pub rows: usize,
    /// Patch columns.
    pub cols: usize,
    /// Feature length (the tower's embedding width).
    pub dim: usize,
    /// `[rows, cols, dim]`, unit vectors.
    pub values: Vec<f32>,
}

impl DenseFeatures {
    /// The feature of patch `(row, col)`.
    pub fn at(&self, row: usize, col: usize) -> &[f32] {
        let i = (row * self.cols + col) * self.dim;
        &self.values[i..i + self.dim]
    }

    /// Centre `[x, y]` of patch `(row, col)` in pixel coordinates of a `width`×`height`
    /// image (pixel `(i, j)` spans `[j, j+1) × [i, i+1)`, so its centre is `(j+0.5, i+0.5)`).
    pub fn centre(&self, row: usize, col: usize, width: usize, height: usize) -> [f32; 2] {
        [
            (col as f32 + 0.5) * width as f32 / self.cols as f32,
            (row as f32 + 0.5) * height as f32 / self.rows as f32,
        ]
    }

    /// The patch `(row, col)` holding pixel coordinates `[x, y]` of a `width`×`height`
    /// image, clamped to the grid.
    pub fn patch_at(&self, x: f32, y: f32, width: usize, height: usize) -> (usize, usize) {
        let col = (x * self.cols as f32 / width as f32).floor().max(0.0) as usize;
        let row = (y * self.rows as f32 / height as f32).floor().max(0.0) as usize;
        (row.min(self.rows - 1), col.min(self.cols - 1))
    }
}

/// A CLIP image encoder with its weights on a burn device.
#[derive(Debug)]
pub struct ImageEncoder {
    tower: VisionTower,
    /// Position embeddings `[1 + grid², width]` on the host, resampled per input grid.
    positions: Vec<f32>,
    shape: VisionShape,
    heads: usize,
    activation: Activation,
    dense_size: usize,
    source: PathBuf,
    settings_from: String,
}

impl ImageEncoder {
    /// Reads the image tower of the checkpoint at `path` onto `device` (see the module docs
    /// for what is read from where).
    pub fn from_file(path: &Path, options: ImageEncoderOptions, device: &Device) -> Result<Self> {
        let dict = StateDict::open(path)?;
        let shape = VisionShape::find(dict.shapes(), path)?;
        if options.dense_size < shape.patch {
            return Err(SemanticError::option(
                "dense_size",
                format!(
                    "{} pixels is less than one patch ({} pixels) of the image tower in {}",
                    options.dense_size,
                    shape.patch,
                    path.display()
                ),
            ));
        }
        let (config_heads, config_activation, config_path) = open_clip_config(path)?;
        let (heads, heads_from) = choose(
            "heads",
            options.heads,
            config_heads,
            config_path.as_deref(),
            (shape.width / HEAD_WIDTH, "width / 64"),
        );
        let (activation, activation_from) = choose(
            "activation",
            options.activation,
            config_activation,
            config_path.as_deref(),
            (Activation::Gelu, "default"),
        );
        if heads == 0 || shape.width % heads != 0 {
            return Err(SemanticError::file(
                path,
                format!(
                    "{heads} attention heads do not divide the image width {} ({heads_from})",
                    shape.width
                ),
            ));
        }
        let load = Loader {
            dict: &dict,
            device,
        };
        let (w, p) = (shape.width, shape.patch);
        let blocks = (0..shape.layers)
            .map(|i| {
                load.block(
                    &format!("{PREFIX}transformer.resblocks."),
                    i,
                    w,
                    shape.mlp_width,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let tower = VisionTower {
            // [W, 3, p, p] → [W, 3·p·p] → [3·p·p, W].
            patch_embed: burn::module::Param::from_tensor(
                load.tensor(&format!("{PREFIX}conv1.weight"), [w, 3 * p * p])?
                    .transpose(),
            ),
            class_embedding: load.param(&format!("{PREFIX}class_embedding"), [1, w])?,
            ln_pre: load.layer_norm(&format!("{PREFIX}ln_pre."), w)?,
            blocks,
            ln_post: load.layer_norm(&format!("{PREFIX}ln_post."), w)?,
            projection: load.param(&format!("{PREFIX}proj"), [w, shape.embed_dim])?,
        };
        Ok(ImageEncoder {
            tower,
            positions: dict.f32(&format!("{PREFIX}positional_embedding"))?,
            heads,
            activation,
            dense_size: options.dense_size,
            source: path.to_path_buf(),
            settings_from: format!("{heads_from}; {activation_from}"),
            shape,
        })
    }

    /// The tower's shape.
    pub fn shape(&self) -> &VisionShape {
        &self.shape
    }

    /// Attention heads.
    pub fn heads(&self) -> usize {
        self.heads
    }

    /// The MLP activation.
    pub fn activation(&self) -> Activation {
        self.activation
    }

    /// Length of the embeddings (512 for ViT-B/16).
    pub fn dim(&self) -> usize {
        self.shape.embed_dim
    }

    /// The weights file.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// One line: layers, width, patch, input sizes, file, and where heads and activation came
    /// from.
    pub fn describe(&self) -> String {
        let s = &self.shape;
        let dense = self.dense_size / s.patch;
        format!(
            "{}: CLIP image tower (ViT), {} layers, width {}, {} heads, patch {}, input {}×{} \
             ({g}×{g} patches), dense input {}×{} ({dense}×{dense} patches, ClearCLIP), {}, \
             {}-d output ({})",
            self.source.display(),
            s.layers,
            s.width,
            self.heads,
            s.patch,
            s.input_size(),
            s.input_size(),
            dense * s.patch,
            dense * s.patch,
            self.activation.name(),
            s.embed_dim,
            self.settings_from,
            g = s.grid,
        )
    }

    /// Position embeddings `[1 + rows·cols, width]` for a `rows`×`cols` patch grid: the
    /// native ones, or their patch part resampled bicubically (class token unchanged).
    fn positions(&self, rows: usize, cols: usize) -> Vec<f32> {
        let (g, w) = (self.shape.grid, self.shape.width);
        if (rows, cols) == (g, g) {
            return self.positions.clone();
        }
        let mut out = self.positions[..w].to_vec();
        out.extend(resample::resize_bicubic(
            &self.positions[w..],
            g,
            g,
            w,
            rows,
            cols,
        ));
        out
    }

    /// Unit global embeddings of `images`, one row each (each resized to the native input
    /// first when it is not of that size).
    pub fn encode(&self, images: &[RgbImage]) -> Result<Matrix> {
        let size = self.shape.input_size();
        let (g, p) = (self.shape.grid, self.shape.patch);
        let mut values = Vec::with_capacity(images.len() * self.dim());
        for (c, chunk) in images.chunks(BATCH).enumerate() {
            let mut patches = Vec::with_capacity(chunk.len() * size * size * 3);
            for (i, image) in chunk.iter().enumerate() {
                image.check(&format!("image {}", c * BATCH + i))?;
                let pixels = if (image.width, image.height) == (size, size) {
                    resample::patches(&image.pixels, g, g, p)
                } else {
                    resample::patches(&image.resized(size, size).pixels, g, g, p)
                };
                patches.extend(pixels);
            }
            let x = self.tower.embed(patches, chunk.len(), self.positions(g, g));
            let out = self.tower.global(x, self.heads, self.activation);
            values.extend(read_back(out, "image embeddings")?);
        }
        Ok(Matrix {
            source: format!("image embeddings by {}", self.source.display()),
            rows: images.len(),
            dim: self.dim(),
            values,
        })
    }

    /// The patch grid `(rows, cols)` [`ImageEncoder::dense`] uses for a `width`×`height`
    /// view: about `(dense_size / patch)²` patches with the view's aspect ratio (square views
    /// get exactly `dense_size / patch` per side).
    pub fn grid_for(&self, width: usize, height: usize) -> (usize, usize) {
        let side = (self.dense_size / self.shape.patch) as f64;
        let aspect = width as f64 / height as f64;
        let rows = (side / aspect.sqrt()).round().max(1.0) as usize;
        let cols = (side * aspect.sqrt()).round().max(1.0) as usize;
        (rows, cols)
    }

    /// ClearCLIP dense features of `image` (any size): the whole view resized to the grid of
    /// [`ImageEncoder::grid_for`], position embeddings interpolated to it (see the module docs
    /// for the recipe and [`DenseFeatures`] for how patches map to pixels).
    pub fn dense(&self, image: &RgbImage) -> Result<DenseFeatures> {
        image.check("image")?;
        let (rows, cols) = self.grid_for(image.width, image.height);
        self.dense_grid(image, rows, cols)
    }

    /// ClearCLIP dense features of `image` on a `rows`×`cols` patch grid: the image is
    /// resized to `cols·patch`×`rows·patch` pixels (unchanged when already that size).
    pub fn dense_grid(&self, image: &RgbImage, rows: usize, cols: usize) -> Result<DenseFeatures> {
        image.check("image")?;
        if rows == 0 || cols == 0 {
            return Err(SemanticError::option(
                "grid",
                format!("{rows}×{cols} patches: a grid needs at least one patch"),
            ));
        }
        let p = self.shape.patch;
        let resized;
        let pixels = if (image.width, image.height) == (cols * p, rows * p) {
            &image.pixels
        } else {
            resized = image.resized(cols * p, rows * p);
            &resized.pixels
        };
        let x = self.tower.embed(
            resample::patches(pixels, rows, cols, p),
            1,
            self.positions(rows, cols),
        );
        let out = self.tower.dense(x, self.heads, self.activation);
        Ok(DenseFeatures {
            rows,
            cols,
            dim: self.dim(),
            values: read_back(out, "dense features")?,
        })
    }
}

/// The values of `t` on the host.
fn read_back(t: burn::tensor::Tensor<2>, what: &str) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| SemanticError::Mismatch(format!("reading {what} back from the device: {e:?}")))
}
