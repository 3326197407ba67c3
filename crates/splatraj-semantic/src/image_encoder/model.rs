//! The CLIP image tower (ViT) as a burn module: patch embedding, class and position
//! embeddings, `ln_pre`, the pre-norm transformer ([`Block`]s shared with the text tower),
//! `ln_post` and the projection; the global embedding (open_clip's
//! `encode_image(normalize=True)`) and ClearCLIP's dense patch features.

use burn::module::{Module, Param};
use burn::nn::LayerNorm;
use burn::tensor::{DType, Tensor, TensorData};

use crate::clip::{Activation, Block, Similarity, normalize_rows};

/// The whole tower's weights.
#[derive(Module, Debug)]
pub struct VisionTower {
    /// The patch convolution as a matrix `[3·patch·patch, width]` (stride = kernel, no bias,
    /// so the convolution is this product on flattened patches).
    pub patch_embed: Param<Tensor<2>>,
    /// `[1, width]`.
    pub class_embedding: Param<Tensor<2>>,
    pub ln_pre: LayerNorm,
    pub blocks: Vec<Block>,
    pub ln_post: LayerNorm,
    /// `[width, embed]`, applied as `x · P`.
    pub projection: Param<Tensor<2>>,
}

impl VisionTower {
    /// Tokens `[B, 1 + N, W]` after `ln_pre`: the class token then the patches, plus the
    /// position embeddings `positions` (`[1 + N, W]`, already at this grid).
    pub fn embed(&self, patches: Vec<f32>, batch: usize, positions: Vec<f32>) -> Tensor<3> {
        let device = self.patch_embed.val().device();
        let [len, width] = self.patch_embed.val().dims();
        let n = patches.len() / (batch * len);
        let patches = Tensor::<2>::from_data(
            TensorData::new(patches, [batch * n, len]),
            (&device, DType::F32),
        );
        let x = patches
            .matmul(self.patch_embed.val())
            .reshape([batch, n, width]); // [B, N, W]
        let class = self
            .class_embedding
            .val()
            .unsqueeze::<3>()
            .expand([batch, 1, width]); // [B, 1, W]
        let positions = Tensor::<2>::from_data(
            TensorData::new(positions, [n + 1, width]),
            (&device, DType::F32),
        )
        .unsqueeze::<3>(); // [1, 1 + N, W]
        self.ln_pre
            .forward(Tensor::cat(vec![class, x], 1) + positions)
    }

    /// Unit global embeddings `[B, embed]` of tokens `x` `[B, 1 + N, W]`: every block, then
    /// `ln_post` on the class token and the projection.
    pub fn global(&self, mut x: Tensor<3>, heads: usize, activation: Activation) -> Tensor<2> {
        for block in &self.blocks {
            x = block.forward(x, None, heads, activation);
        }
        let [batch, _, width] = x.dims();
        let class = x.narrow(1, 0, 1).reshape([batch, width]); // [B, W]
        normalize_rows(self.ln_post.forward(class).matmul(self.projection.val()))
    }

    /// ClearCLIP's dense features `[N, embed]` (unit rows) of one image's tokens `x`
    /// `[1, 1 + N, W]`: every block but the last as trained; in the last, only the attention
    /// branch, with query-query similarity (no residual, no feed-forward); then `ln_post`
    /// and the projection on the patch tokens.
    pub fn dense(&self, mut x: Tensor<3>, heads: usize, activation: Activation) -> Tensor<2> {
        let (last, first) = self.blocks.split_last().expect("a tower has a block");
        for block in first {
            x = block.forward(x, None, heads, activation);
        }
        let x = last.attention(last.ln_1.forward(x), None, heads, Similarity::QueryQuery); // [1, 1 + N, W]
        let [_, tokens, width] = x.dims();
        let patches = x.narrow(1, 1, tokens - 1).reshape([tokens - 1, width]); // [N, W]
        normalize_rows(self.ln_post.forward(patches).matmul(self.projection.val()))
    }
}
