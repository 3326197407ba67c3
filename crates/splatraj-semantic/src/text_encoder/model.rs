//! The CLIP text tower as a burn module: token and position embeddings, a causal
//! pre-norm transformer, final layer norm, the end-of-text token's features, text
//! projection, L2 norm (open_clip's `CLIP.encode_text(normalize=True)`).

use burn::module::{Module, Param};
use burn::nn::{Embedding, LayerNorm, LayerNormConfig, Linear};
use burn::tensor::activation::{gelu, sigmoid, softmax};
use burn::tensor::{DType, Device, Int, Tensor, TensorData};

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
}

impl std::str::FromStr for Activation {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
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

/// LayerNorm epsilon of CLIP's text towers (PyTorch's default).
pub const LAYER_NORM_EPS: f64 = 1e-5;

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

/// The whole tower's weights.
#[derive(Module, Debug)]
pub struct Tower {
    pub token_embedding: Embedding,
    /// `[context, width]`.
    pub positional: Param<Tensor<2>>,
    pub blocks: Vec<Block>,
    pub ln_final: LayerNorm,
    /// `[width, embed]`, applied as `x · P`.
    pub projection: Param<Tensor<2>>,
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

impl Tower {
    /// Unit text embeddings `[B, embed]` of token rows `ids` (each starting with
    /// `<start_of_text>` and ending with `<end_of_text>`, no padding needed).
    ///
    /// Only the first `max(len)` positions are run: the mask is causal, so the features at a
    /// row's end-of-text token never depend on the positions after it, and running the
    /// padding (up to 77) would change nothing but the time.
    pub fn forward(&self, ids: &[Vec<u32>], heads: usize, activation: Activation) -> Tensor<2> {
        let device = self.positional.val().device();
        let batch = ids.len();
        let len = ids.iter().map(Vec::len).max().unwrap_or(1).max(1);
        let mut flat = vec![0i64; batch * len];
        for (b, row) in ids.iter().enumerate() {
            for (t, &id) in row.iter().enumerate() {
                flat[b * len + t] = i64::from(id);
            }
        }
        let tokens = Tensor::<2, Int>::from_data(TensorData::new(flat, [batch, len]), &device);
        let positions = self.positional.val().narrow(0, 0, len); // [len, width]
        let mut x = self.token_embedding.forward(tokens) + positions.unsqueeze::<3>(); // [B, len, W]

        let mut mask = vec![0.0f32; len * len];
        for i in 0..len {
            for j in i + 1..len {
                mask[i * len + j] = f32::NEG_INFINITY;
            }
        }
        let mask = Tensor::<2>::from_data(TensorData::new(mask, [len, len]), (&device, DType::F32))
            .unsqueeze::<4>(); // [1, 1, len, len]

        for block in &self.blocks {
            x = x.clone() + attention(block, block.ln_1.forward(x), &mask, heads);
            let h = block.c_fc.forward(block.ln_2.forward(x.clone()));
            let h = match activation {
                Activation::Gelu => gelu(h),
                Activation::QuickGelu => h.clone() * sigmoid(h * 1.702),
            };
            x = x + block.c_proj.forward(h);
        }
        let x = self.ln_final.forward(x);
        let [_, _, width] = x.dims();
        // The end-of-text token has the largest id, so its position is each row's argmax
        // (open_clip's `text_global_pool(..., "argmax")`).
        let eot: Vec<i64> =
            ids.iter()
                .enumerate()
                .map(|(b, row)| {
                    let (t, _) = row.iter().enumerate().fold((0, 0), |best, (t, &id)| {
                        if id > best.1 { (t, id) } else { best }
                    });
                    (b * len + t) as i64
                })
                .collect();
        let eot = Tensor::<1, Int>::from_data(TensorData::new(eot, [batch]), &device);
        let pooled = x.reshape([batch * len, width]).select(0, eot); // [B, W]
        let projected = pooled.matmul(self.projection.val()); // [B, embed]
        let norm = (projected.clone() * projected.clone())
            .sum_dim(1)
            .sqrt()
            .clamp_min(1e-12);
        projected / norm
    }
}

/// Causal multi-head self-attention of PyTorch's `nn.MultiheadAttention` on `x` `[B, L, W]`.
fn attention(block: &Block, x: Tensor<3>, mask: &Tensor<4>, heads: usize) -> Tensor<3> {
    let [batch, len, width] = x.dims();
    let head = width / heads;
    let qkv = block.in_proj.forward(x); // [B, L, 3W]
    let split = |k: usize| {
        qkv.clone()
            .slice([0..batch, 0..len, k * width..(k + 1) * width])
            .reshape([batch, len, heads, head])
            .swap_dims(1, 2) // [B, H, L, head]
    };
    let (q, k, v) = (split(0), split(1), split(2));
    let scores = q.matmul(k.swap_dims(2, 3)) / (head as f64).sqrt() + mask.clone(); // [B, H, L, L]
    let weights = softmax(scores, 3);
    let out = weights
        .matmul(v)
        .swap_dims(1, 2)
        .reshape([batch, len, width]);
    block.out_proj.forward(out)
}
