//! What CLIP's text and image towers share: the pre-norm residual attention block
//! (open_clip's `ResidualAttentionBlock`, OpenAI's layout and names), its attention, layer
//! norm and MLP activation, the reading of blocks from a checkpoint, and the settings in
//! `open_clip_config.json` that shapes cannot tell.
//!
//! Both towers hold their blocks as [`Block`]s read by [`Loader::block`], and check a
//! checkpoint's block tensors with [`block_shapes`], [`count_layers`] and [`check_known`]:
//! one implementation for both, so that a fix to one tower is a fix to the other.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::module::{Module, Param};
use burn::nn::{LayerNorm, LayerNormConfig, Linear};
use burn::tensor::activation::{gelu, sigmoid, softmax};
use burn::tensor::{DType, Device, Tensor, TensorData};

use crate::error::{Result, SemanticError};
use crate::weights::StateDict;

/// The MLP's activation: open_clip's laion towers use GELU (erf form), OpenAI's QuickGELU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Activation {
    /// `x·Φ(x)` (PyTorch `nn.GELU()`), as open_clip trains its own towers.
    Gelu,
    /// `x·σ(1.702·x)`, as OpenAI trained CLIP.
    QuickGelu,
}

impl Activation {
    /// The name configs use.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Gelu => "gelu",
            Activation::QuickGelu => "quick-gelu",
        }
    }

    fn apply(self, h: Tensor<3>) -> Tensor<3> {
        match self {
            Activation::Gelu => gelu(h),
            Activation::QuickGelu => h.clone() * sigmoid(h * 1.702),
        }
    }
}

impl std::str::FromStr for Activation {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "gelu" => Ok(Activation::Gelu),
            "quick-gelu" => Ok(Activation::QuickGelu),
            other => Err(format!(
                "unknown text activation {other:?}: use gelu (open_clip's towers) or quick-gelu \
                 (OpenAI's)"
            )),
        }
    }
}

/// LayerNorm epsilon of CLIP's towers (PyTorch's default).
pub const LAYER_NORM_EPS: f64 = 1e-5;

/// Width of one attention head in every OpenAI and open_clip CLIP tower (heads = width / 64;
/// open_clip's `CLIPVisionCfg.head_width`).
pub const HEAD_WIDTH: usize = 64;

/// open_clip's model config file, beside its weights on the Hugging Face hub.
pub const OPEN_CLIP_CONFIG: &str = "open_clip_config.json";

/// One residual attention block (pre-norm).
#[derive(Module, Debug)]
pub struct Block {
    pub ln_1: LayerNorm,
    /// Query, key and value in one projection, as PyTorch's `in_proj_weight` holds them.
    pub in_proj: Linear,
    pub out_proj: Linear,
    pub ln_2: LayerNorm,
    pub c_fc: Linear,
    pub c_proj: Linear,
}

/// Which similarity weighs the values in an attention.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Similarity {
    /// `softmax(q·kᵀ/√d)`: the attention CLIP was trained with.
    QueryKey,
    /// `softmax(q·qᵀ/√d)`: ClearCLIP's self-self attention.
    QueryQuery,
}

impl Block {
    /// The whole block on `x` `[B, L, W]`: `x + attn(ln_1 x)`, then `+ mlp(ln_2 x)`.
    pub fn forward(
        &self,
        x: Tensor<3>,
        mask: Option<&Tensor<4>>,
        heads: usize,
        activation: Activation,
    ) -> Tensor<3> {
        let x = x.clone() + self.attention(self.ln_1.forward(x), mask, heads, Similarity::QueryKey);
        let h = activation.apply(self.c_fc.forward(self.ln_2.forward(x.clone())));
        x + self.c_proj.forward(h)
    }

    /// Multi-head self-attention of PyTorch's `nn.MultiheadAttention` on `x` `[B, L, W]`
    /// (already layer-normed), out projection included; `mask` is added to the scores.
    pub fn attention(
        &self,
        x: Tensor<3>,
        mask: Option<&Tensor<4>>,
        heads: usize,
        similarity: Similarity,
    ) -> Tensor<3> {
        let [batch, len, width] = x.dims();
        let head = width / heads;
        let qkv = self.in_proj.forward(x); // [B, L, 3W]
        let split = |k: usize| {
            qkv.clone()
                .slice([0..batch, 0..len, k * width..(k + 1) * width])
                .reshape([batch, len, heads, head])
                .swap_dims(1, 2) // [B, H, L, head]
        };
        let q = split(0);
        let v = split(2);
        let other = match similarity {
            Similarity::QueryKey => split(1),
            Similarity::QueryQuery => q.clone(),
        };
        let mut scores = q.matmul(other.swap_dims(2, 3)) / (head as f64).sqrt(); // [B, H, L, L]
        if let Some(mask) = mask {
            scores = scores + mask.clone();
        }
        let out = softmax(scores, 3)
            .matmul(v) // [B, H, L, head]
            .swap_dims(1, 2)
            .reshape([batch, len, width]);
        self.out_proj.forward(out)
    }
}

/// A LayerNorm of `width` with the given scale and shift.
pub fn layer_norm(gamma: Tensor<1>, beta: Tensor<1>, device: &Device) -> LayerNorm {
    let [width] = gamma.dims();
    let mut ln = LayerNormConfig::new(width)
        .with_epsilon(LAYER_NORM_EPS)
        .init(device);
    ln.gamma = Param::from_tensor(gamma);
    ln.beta = Some(Param::from_tensor(beta));
    ln
}

/// L2-normalises the rows of `x` `[N, D]` (open_clip's `F.normalize`, eps 1e-12).
pub fn normalize_rows(x: Tensor<2>) -> Tensor<2> {
    let norm = (x.clone() * x.clone()).sum_dim(1).sqrt().clamp_min(1e-12); // [N, 1]
    x / norm
}

/// The tensors of block `i` under `blocks` (`"visual.transformer.resblocks."`) with their
/// shapes, for width `w` and MLP width `m`.
pub fn block_shapes(blocks: &str, i: usize, w: usize, m: usize) -> Vec<(String, Vec<usize>)> {
    [
        ("ln_1.weight", vec![w]),
        ("ln_1.bias", vec![w]),
        ("attn.in_proj_weight", vec![3 * w, w]),
        ("attn.in_proj_bias", vec![3 * w]),
        ("attn.out_proj.weight", vec![w, w]),
        ("attn.out_proj.bias", vec![w]),
        ("ln_2.weight", vec![w]),
        ("ln_2.bias", vec![w]),
        ("mlp.c_fc.weight", vec![m, w]),
        ("mlp.c_fc.bias", vec![m]),
        ("mlp.c_proj.weight", vec![w, m]),
        ("mlp.c_proj.bias", vec![w]),
    ]
    .into_iter()
    .map(|(name, shape)| (format!("{blocks}{i}.{name}"), shape))
    .collect()
}

/// Number of blocks under `blocks` (one more than the largest index); `tower` ("text",
/// "image") names the tower in errors.
pub fn count_layers(
    shapes: &BTreeMap<String, Vec<usize>>,
    blocks: &str,
    path: &Path,
    tower: &str,
) -> Result<usize> {
    let mut layers = 0;
    for key in shapes.keys() {
        let Some(rest) = key.strip_prefix(blocks) else {
            continue;
        };
        match rest.split('.').next().and_then(|i| i.parse::<usize>().ok()) {
            Some(i) => layers = layers.max(i + 1),
            None => {
                return Err(SemanticError::file(
                    path,
                    format!("unexpected tensor {key:?} in the {tower} transformer"),
                ));
            }
        }
    }
    Ok(layers)
}

/// Errors on a block tensor not in `expected`: a tensor this code does not know (layer
/// scale, qk norm) would be ignored, and the embeddings silently wrong.
pub fn check_known(
    shapes: &BTreeMap<String, Vec<usize>>,
    blocks: &str,
    expected: &BTreeMap<String, Vec<usize>>,
    path: &Path,
    tower: &str,
) -> Result<()> {
    let article = if tower.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    };
    for key in shapes.keys().filter(|k| k.starts_with(blocks)) {
        if !expected.contains_key(key) {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor {key:?} belongs to {article} {tower}-tower variant splatraj does not \
                     implement (it knows ln_1, attn.in_proj, attn.out_proj, ln_2, mlp.c_fc, \
                     mlp.c_proj)"
                ),
            ));
        }
    }
    Ok(())
}

/// Reads tensors of a [`StateDict`] onto a device as f32.
pub struct Loader<'a> {
    /// The checkpoint.
    pub dict: &'a StateDict,
    /// Where the tensors go.
    pub device: &'a Device,
}

impl Loader<'_> {
    /// Tensor `name` with the given (already checked) shape.
    pub fn tensor<const D: usize>(&self, name: &str, dims: [usize; D]) -> Result<Tensor<D>> {
        let values = self.dict.f32(name)?;
        Ok(Tensor::<D>::from_data(
            TensorData::new(values, dims.to_vec()),
            (self.device, DType::F32),
        ))
    }

    /// A parameter from tensor `name`.
    pub fn param<const D: usize>(&self, name: &str, dims: [usize; D]) -> Result<Param<Tensor<D>>> {
        Ok(Param::from_tensor(self.tensor(name, dims)?))
    }

    /// A LayerNorm from `{name}weight` and `{name}bias`.
    pub fn layer_norm(&self, name: &str, width: usize) -> Result<LayerNorm> {
        Ok(layer_norm(
            self.tensor(&format!("{name}weight"), [width])?,
            self.tensor(&format!("{name}bias"), [width])?,
            self.device,
        ))
    }

    /// A Linear from PyTorch's `[out, in]` `weight_key` and `bias_key`; burn computes
    /// `x·W` with `W` as `[in, out]`, hence the transpose.
    pub fn linear(
        &self,
        weight_key: &str,
        bias_key: &str,
        out: usize,
        input: usize,
    ) -> Result<Linear> {
        Ok(Linear {
            weight: Param::from_tensor(self.tensor(weight_key, [out, input])?.transpose()),
            bias: Some(self.param(bias_key, [out])?),
        })
    }

    /// Block `i` under `blocks`, of width `w` and MLP width `m`.
    pub fn block(&self, blocks: &str, i: usize, w: usize, m: usize) -> Result<Block> {
        let b = format!("{blocks}{i}.");
        let linear = |name: &str, out: usize, input: usize| {
            self.linear(
                &format!("{b}{name}.weight"),
                &format!("{b}{name}.bias"),
                out,
                input,
            )
        };
        Ok(Block {
            ln_1: self.layer_norm(&format!("{b}ln_1."), w)?,
            in_proj: self.linear(
                &format!("{b}attn.in_proj_weight"),
                &format!("{b}attn.in_proj_bias"),
                3 * w,
                w,
            )?,
            out_proj: linear("attn.out_proj", w, w)?,
            ln_2: self.layer_norm(&format!("{b}ln_2."), w)?,
            c_fc: linear("mlp.c_fc", m, w)?,
            c_proj: linear("mlp.c_proj", w, m)?,
        })
    }
}

/// `open_clip_config.json` beside `weights`, when there is one: its `model_cfg` (or the
/// whole file when it has none) and its path.
pub fn open_clip_config(weights: &Path) -> Result<Option<(serde_json::Value, PathBuf)>> {
    let path = weights
        .parent()
        .unwrap_or(Path::new(""))
        .join(OPEN_CLIP_CONFIG);
    if !path.is_file() {
        return Ok(None);
    }
    let text = splatraj_scene::input::read_text(&path).map_err(|e| SemanticError::io(&path, e))?;
    let mut json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| SemanticError::file(&path, format!("not valid JSON: {e}")))?;
    let model = match json.get_mut("model_cfg") {
        Some(model) => model.take(),
        None => json,
    };
    Ok(Some((model, path)))
}

/// A positive integer at `pointer` (`/text_cfg/heads`) of a model config, if present.
pub fn config_count(
    model: &serde_json::Value,
    pointer: &str,
    path: &Path,
) -> Result<Option<usize>> {
    match model.pointer(pointer) {
        None => Ok(None),
        Some(v) => Ok(Some(v.as_u64().filter(|&h| h > 0).ok_or_else(|| {
            SemanticError::file(
                path,
                format!(
                    "model_cfg{} is {v}: expected a positive integer",
                    pointer.replace('/', ".")
                ),
            )
        })? as usize)),
    }
}

/// The activation `model_cfg.quick_gelu` names, if present.
pub fn config_activation(model: &serde_json::Value, path: &Path) -> Result<Option<Activation>> {
    match model.get("quick_gelu") {
        None => Ok(None),
        Some(serde_json::Value::Bool(true)) => Ok(Some(Activation::QuickGelu)),
        Some(serde_json::Value::Bool(false)) => Ok(Some(Activation::Gelu)),
        Some(v) => Err(SemanticError::file(
            path,
            format!("model_cfg.quick_gelu is {v}: expected true or false"),
        )),
    }
}

/// A setting taken from the options, else the config file, else a default, with a note of
/// where it came from (`"heads: given"`).
pub fn choose<T>(
    what: &str,
    given: Option<T>,
    config: Option<T>,
    config_path: Option<&Path>,
    default: (T, &str),
) -> (T, String) {
    match (given, config, config_path) {
        (Some(v), _, _) => (v, format!("{what}: given")),
        (None, Some(v), Some(p)) => (v, format!("{what}: {}", p.display())),
        (None, Some(v), None) => (v, format!("{what}: default")),
        (None, None, _) => (default.0, format!("{what}: {}", default.1)),
    }
}
