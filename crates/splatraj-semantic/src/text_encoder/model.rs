//! The CLIP text tower as a burn module: token and position embeddings, a causal
//! pre-norm transformer, final layer norm, the end-of-text token's features, text
//! projection, L2 norm (open_clip's `CLIP.encode_text(normalize=True)`).

use burn::module::{Module, Param};
use burn::nn::{Embedding, LayerNorm};
use burn::tensor::{DType, Int, Tensor, TensorData};

use crate::clip::{Activation, Block, normalize_rows};

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
            x = block.forward(x, Some(&mask), heads, activation);
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
        normalize_rows(projected)
    }
}
