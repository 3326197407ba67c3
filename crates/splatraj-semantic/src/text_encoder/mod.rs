//! A CLIP text encoder in burn, so that queries can be any phrase: the text tower of OpenAI's
//! CLIP and open_clip (ViT-B/16 as LangSplat pairs it, `laion2b_s34b_b88k`; ViT-B/32, ViT-L/14
//! and the OpenAI towers share the layout), with weights from a file the user has.
//!
//! The tower (`open_clip.model.CLIP.encode_text(normalize=True)`): CLIP's tokenizer
//! ([`ClipTokenizer`]), token embedding plus position embedding, `layers` pre-norm residual
//! blocks (causal multi-head self-attention, then an MLP of width `4·width` with GELU or
//! QuickGELU), final layer norm, the features at the end-of-text token, the text projection
//! and L2 normalisation.
//!
//! What is read from where:
//! - the weights: [`StateDict`] (safetensors or a `torch.save`d state dict), text tower keys
//!   at the top level (`CLIP`) or under `text.` (`CustomTextCLIP`), the vision tower's keys
//!   ignored;
//! - vocabulary, context, width, layers, MLP and output widths: the tensors' shapes, every
//!   text tensor checked against them (a missing or mis-shaped tensor is an error naming the
//!   file and the tensor);
//! - heads and activation, which shapes cannot tell: [`TextEncoderOptions`] when given, else
//!   `open_clip_config.json` beside the weights (`model_cfg.text_cfg.heads`,
//!   `model_cfg.quick_gelu`, as open_clip saves models for the Hugging Face hub), else
//!   `width / 64` heads (the rule of every OpenAI and open_clip CLIP text tower) and GELU.

mod model;
pub mod phrase_file;
mod tokenizer;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::nn::Embedding;
use burn::tensor::Device;

use crate::clip::{
    Loader, block_shapes, check_known, choose, config_activation, config_count, count_layers,
};
use crate::embeddings::{Matrix, PhraseTable};
use crate::error::{Result, SemanticError};

pub use crate::clip::{Activation, HEAD_WIDTH, OPEN_CLIP_CONFIG};
pub use crate::weights::StateDict;
pub use tokenizer::{CONTEXT_LENGTH, ClipTokenizer, END_OF_TEXT, START_OF_TEXT, VOCAB_SIZE, clean};

use model::Tower;

/// Phrases encoded per forward pass: bounds the activations held at once.
const BATCH: usize = 64;

/// What the weight shapes cannot tell; `None` takes `open_clip_config.json` or the default.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TextEncoderOptions {
    /// The MLP activation.
    pub activation: Option<Activation>,
    /// Attention heads.
    pub heads: Option<usize>,
}

/// The shape of a text tower, as found in a checkpoint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TowerShape {
    /// Key prefix of the text tower (`""` or `"text."`).
    pub prefix: String,
    /// Rows of the token embedding.
    pub vocab: usize,
    /// Positions of the position embedding.
    pub context: usize,
    /// Transformer width.
    pub width: usize,
    /// Residual blocks.
    pub layers: usize,
    /// Hidden width of each block's MLP.
    pub mlp_width: usize,
    /// Length of the output embedding.
    pub embed_dim: usize,
}

impl TowerShape {
    /// Finds the text tower among `shapes` (a checkpoint's tensor names and shapes) and
    /// checks every one of its tensors; errors name `path` and the tensor.
    pub fn find(shapes: &BTreeMap<String, Vec<usize>>, path: &Path) -> Result<Self> {
        let token_keys: Vec<&String> = shapes
            .keys()
            .filter(|k| k.ends_with("token_embedding.weight") && !k.starts_with("visual."))
            .collect();
        let prefix = match token_keys[..] {
            [key] => key.trim_end_matches("token_embedding.weight").to_string(),
            [] => {
                let first: Vec<&str> = shapes.keys().take(6).map(String::as_str).collect();
                return Err(SemanticError::file(
                    path,
                    format!(
                        "no tensor \"token_embedding.weight\": not a CLIP text tower (its first \
                         tensors: {first:?})"
                    ),
                ));
            }
            _ => {
                return Err(SemanticError::file(
                    path,
                    format!("several text towers ({token_keys:?}): give a file with one"),
                ));
            }
        };
        let shape = |name: &str| -> Result<&Vec<usize>> {
            shapes.get(&format!("{prefix}{name}")).ok_or_else(|| {
                SemanticError::file(path, format!("missing tensor \"{prefix}{name}\""))
            })
        };
        let [vocab, width] = shape("token_embedding.weight")?[..] else {
            return Err(bad_rank(path, &prefix, "token_embedding.weight", 2));
        };
        let [context, _] = shape("positional_embedding")?[..] else {
            return Err(bad_rank(path, &prefix, "positional_embedding", 2));
        };
        let [_, embed_dim] = shape("text_projection")?[..] else {
            return Err(bad_rank(path, &prefix, "text_projection", 2));
        };
        let [mlp_width, _] = shape("transformer.resblocks.0.mlp.c_fc.weight")?[..] else {
            return Err(bad_rank(
                path,
                &prefix,
                "transformer.resblocks.0.mlp.c_fc.weight",
                2,
            ));
        };
        let blocks = format!("{prefix}transformer.resblocks.");
        let layers = count_layers(shapes, &blocks, path, "text")?;
        let tower = TowerShape {
            prefix,
            vocab,
            context,
            width,
            layers,
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
                        "tensor {name:?} has shape {got:?}, expected {want:?} for a text tower of \
                         width {width}, {} layers, vocabulary {vocab}, context {context}",
                        tower.layers
                    ),
                ));
            }
        }
        check_known(shapes, &blocks, &expected, path, "text")?;
        if vocab != VOCAB_SIZE {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor \"{}token_embedding.weight\" has {vocab} rows but CLIP's tokenizer \
                     has {VOCAB_SIZE} tokens",
                    tower.prefix
                ),
            ));
        }
        if context < 2 {
            return Err(SemanticError::file(
                path,
                format!(
                    "tensor \"{}positional_embedding\" has {context} positions",
                    tower.prefix
                ),
            ));
        }
        Ok(tower)
    }

    /// Every text-tower tensor with the shape it must have.
    pub fn expected_shapes(&self) -> BTreeMap<String, Vec<usize>> {
        let p = &self.prefix;
        let (w, m) = (self.width, self.mlp_width);
        let mut out = BTreeMap::new();
        out.insert(format!("{p}token_embedding.weight"), vec![self.vocab, w]);
        out.insert(format!("{p}positional_embedding"), vec![self.context, w]);
        out.insert(format!("{p}ln_final.weight"), vec![w]);
        out.insert(format!("{p}ln_final.bias"), vec![w]);
        out.insert(format!("{p}text_projection"), vec![w, self.embed_dim]);
        for i in 0..self.layers {
            out.extend(block_shapes(&format!("{p}transformer.resblocks."), i, w, m));
        }
        out
    }
}

fn bad_rank(path: &Path, prefix: &str, name: &str, rank: usize) -> SemanticError {
    SemanticError::file(
        path,
        format!("tensor \"{prefix}{name}\" must have {rank} dimensions"),
    )
}

/// Heads and activation from `open_clip_config.json` beside the weights, when there is one.
fn open_clip_config(
    weights: &Path,
) -> Result<(Option<usize>, Option<Activation>, Option<PathBuf>)> {
    let Some((model, path)) = crate::clip::open_clip_config(weights)? else {
        return Ok((None, None, None));
    };
    let heads = config_count(&model, "/text_cfg/heads", &path)?;
    let activation = config_activation(&model, &path)?;
    Ok((heads, activation, Some(path)))
}

/// A CLIP text encoder with its weights on a burn device.
#[derive(Debug)]
pub struct TextEncoder {
    tower: Tower,
    tokenizer: ClipTokenizer,
    shape: TowerShape,
    heads: usize,
    activation: Activation,
    source: PathBuf,
    settings_from: String,
}

impl TextEncoder {
    /// Reads the text tower of the checkpoint at `path` onto `device` (see the module docs
    /// for what is read from where).
    pub fn from_file(path: &Path, options: TextEncoderOptions, device: &Device) -> Result<Self> {
        let dict = StateDict::open(path)?;
        let shape = TowerShape::find(dict.shapes(), path)?;
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
                    "{heads} attention heads do not divide the width {} ({heads_from})",
                    shape.width
                ),
            ));
        }

        let p = &shape.prefix;
        let load = Loader {
            dict: &dict,
            device,
        };
        let (w, m) = (shape.width, shape.mlp_width);
        let blocks = (0..shape.layers)
            .map(|i| load.block(&format!("{p}transformer.resblocks."), i, w, m))
            .collect::<Result<Vec<_>>>()?;
        let tower = Tower {
            token_embedding: Embedding {
                weight: load.param(&format!("{p}token_embedding.weight"), [shape.vocab, w])?,
            },
            positional: load.param(&format!("{p}positional_embedding"), [shape.context, w])?,
            blocks,
            ln_final: load.layer_norm(&format!("{p}ln_final."), w)?,
            projection: load.param(&format!("{p}text_projection"), [w, shape.embed_dim])?,
        };
        Ok(TextEncoder {
            tower,
            tokenizer: ClipTokenizer::new(),
            heads,
            activation,
            source: path.to_path_buf(),
            settings_from: format!("{heads_from}; {activation_from}"),
            shape,
        })
    }

    /// The tower's shape.
    pub fn shape(&self) -> &TowerShape {
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

    /// Length of the embeddings.
    pub fn dim(&self) -> usize {
        self.shape.embed_dim
    }

    /// The weights file.
    pub fn source(&self) -> &Path {
        &self.source
    }

    /// One line: the file, the shape, and where heads and activation came from.
    pub fn describe(&self) -> String {
        let s = &self.shape;
        format!(
            "{}: CLIP text tower, width {}, {} layers, {} heads, {}, {}-d output ({})",
            self.source.display(),
            s.width,
            s.layers,
            self.heads,
            self.activation.name(),
            s.embed_dim,
            self.settings_from
        )
    }

    /// The tokenizer.
    pub fn tokenizer(&self) -> &ClipTokenizer {
        &self.tokenizer
    }

    /// Unit embeddings of `texts`, one row each.
    pub fn encode(&self, texts: &[&str]) -> Result<Matrix> {
        let mut values = Vec::with_capacity(texts.len() * self.dim());
        for chunk in texts.chunks(BATCH) {
            let mut ids: Vec<Vec<u32>> = Vec::with_capacity(chunk.len());
            for text in chunk {
                let row = self.tokenizer.ids(text);
                if row.len() > self.shape.context {
                    return Err(SemanticError::Mismatch(format!(
                        "{:?} has {} tokens but the text tower of {} holds {} positions",
                        text,
                        row.len(),
                        self.source.display(),
                        self.shape.context
                    )));
                }
                ids.push(row);
            }
            let out = self.tower.forward(&ids, self.heads, self.activation);
            let rows = out
                .into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .map_err(|e| {
                    SemanticError::Mismatch(format!(
                        "reading text embeddings back from the device: {e:?}"
                    ))
                })?;
            values.extend(rows);
        }
        Ok(Matrix {
            source: format!("text embeddings by {}", self.source.display()),
            rows: texts.len(),
            dim: self.dim(),
            values,
        })
    }

    /// A phrase table of `phrases` encoded now (what `splatraj encode-text` writes).
    pub fn table(&self, phrases: &[String]) -> Result<PhraseTable> {
        let refs: Vec<&str> = phrases.iter().map(String::as_str).collect();
        let vectors = self.encode(&refs)?;
        PhraseTable::new(
            format!("phrases encoded by {}", self.source.display()),
            phrases.to_vec(),
            vectors,
        )
    }
}
