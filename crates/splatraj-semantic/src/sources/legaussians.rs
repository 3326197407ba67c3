//! `legaussians` source: LEGaussians scenes (Shi et al., "Language Embedded 3D Gaussians for
//! Open-Vocabulary Scene Understanding", CVPR 2024), whose Gaussians carry a short vector that
//! a decoder turns into an index into a quantised codebook of CLIP features.
//!
//! Layout, as checked in buaavrcg/LEGaussians:
//! - `scene/gaussian_model.py` writes each Gaussian's `_semantic_features` (width
//!   `semantic_features_dim`, 8 in its configs) as float properties `clip_f_indices_0..`.
//!   (`save_lem_ply`, which `train.py` uses, writes the columns after them in another order
//!   than it names them: the data `opacity, scale_0..2, uncertainty` under the names `opacity,
//!   uncertainty, scale_0..2`; LEGaussians reads them back by name the same way, and so does
//!   splatraj's scene reader. The `clip_f_indices_*` columns are not affected.)
//! - `scene/index_decoder.py`'s `IndexDecoder`: 1×1 convolutions `conv1` (D→128), `conv2`
//!   (128→256), `conv3` (256→codebook size) with ReLU between, applied to the L2-normalised
//!   feature; `train.py` saves its `state_dict()` as `index_decoder_chkpnt<iteration>.pth`
//!   beside each `chkpnt<iteration>.pth`.
//! - the codebook, `<prefix>_codebook.pt` from `preprocess/quantize_features.py`: the
//!   `state_dict()` of its `VectorQuantizer`, key `embedding.weight` `[n_e, e_dim]`, the CLIP
//!   feature in the first 512 columns (DINO's 384 follow when both were quantised).
//! - `render_mask.py` turns the decoder's logits into a CLIP feature (`--com_type argmax`: the
//!   codebook row of the largest logit; `softmax`: the softmax-weighted sum of the rows) and
//!   scores it with LERF's relevancy against "object", "things", "stuff", "texture" at
//!   `--scale` 100 (`utils/lem_utils.py`, `CLIPRelevance.get_relevancy`).
//!
//! LEGaussians does this per pixel of a rendered feature map; here it is done per Gaussian
//! (each Gaussian's own vector normalised and decoded), as the other language fields are.
//! The CLIP columns are the first text-width columns of the codebook (512 for ViT-B/16).
//! With `combine = "argmax"` (the default) each codebook row is scored once per query and
//! looked up per Gaussian; with `"softmax"` every Gaussian's mixture is kept (text width
//! floats per Gaussian, as the `langsplat` source keeps its decoded vectors). The temperature
//! defaults to LEGaussians' scale, 100.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use burn::store::pytorch_reader::PytorchReader;
use burn::tensor::activation::softmax;
use burn::tensor::{DType, Tensor, TensorData};
use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};
use crate::sources::conv1x1::read_conv1x1_layers;
use crate::sources::langsplat::read_f32;
use crate::sources::properties::numbered_properties;
use crate::sources::text_keys::{TextKeys, refuse_unknown_keys};
use crate::sources::{
    FeatureInput, FeaturesSource, LangsplatDecoder, Relevancy, Scoring, SourceConfig,
    SourceContext, TargetSource,
};

/// The name the source is registered under (`source = "custom.legaussians"`).
pub const LEGAUSSIANS: &str = "legaussians";

/// Prefix of the per-Gaussian semantic-feature properties.
pub const FEATURE_PREFIX: &str = "clip_f_indices_";

/// Key of the codebook in the `VectorQuantizer` state dict.
pub const CODEBOOK_KEY: &str = "embedding.weight";

/// Default relevancy temperature: LEGaussians' `render_mask.py --scale` default.
pub const DEFAULT_SCALE: f32 = 100.0;

/// Norms below this count as zero when normalising a Gaussian's vector (`F.normalize`'s eps).
const NORMALIZE_EPS: f32 = 1e-12;

/// How the decoder's logits become a CLIP feature (`render_mask.py --com_type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Combine {
    /// The codebook row of the largest logit.
    #[default]
    Argmax,
    /// The rows weighted by the softmax of the logits.
    Softmax,
}

/// Reads LEGaussians' `IndexDecoder` checkpoint (`conv1`..`conv3`, 1×1 convolutions) onto
/// `device`; errors name the file and the key.
pub fn read_index_decoder(path: &Path, device: &burn::tensor::Device) -> Result<LangsplatDecoder> {
    read_conv1x1_layers(
        path,
        &["conv1.", "conv2.", "conv3."],
        "a LEGaussians index_decoder_chkpnt*.pth (IndexDecoder state dict: conv1, conv2, conv3, \
         1×1 convolutions)",
        device,
    )
}

/// Reads the CLIP part (the first `clip_width` columns) of a LEGaussians codebook
/// (`*_codebook.pt`); a missing key, a wrong rank or a codebook narrower than `clip_width`
/// is an error naming the file and the key.
pub fn read_codebook(path: &Path, clip_width: usize) -> Result<Matrix> {
    let reader = PytorchReader::new(path).map_err(|e| {
        SemanticError::file(path, format!("not a readable PyTorch checkpoint: {e}"))
    })?;
    let tensors = reader.tensors();
    let tensor = tensors.get(CODEBOOK_KEY).ok_or_else(|| {
        let mut keys: Vec<&str> = tensors.keys().map(String::as_str).collect();
        keys.sort_unstable();
        keys.truncate(8);
        SemanticError::file(
            path,
            format!(
                "missing key {CODEBOOK_KEY:?}: not a LEGaussians codebook (the state dict of \
                 its VectorQuantizer; its keys: {keys:?})"
            ),
        )
    })?;
    let [codes, width] = tensor.shape()[..] else {
        return Err(SemanticError::file(
            path,
            format!(
                "key {CODEBOOK_KEY:?} has shape {:?}: a codebook is [codes, width]",
                tensor.shape()
            ),
        ));
    };
    if width < clip_width {
        return Err(SemanticError::file(
            path,
            format!(
                "key {CODEBOOK_KEY:?} has shape [{codes}, {width}]: narrower than the text \
                 embeddings ({clip_width}), whose width its first columns must have"
            ),
        ));
    }
    let all = read_f32(path, CODEBOOK_KEY, tensor)?;
    Ok(Matrix {
        source: format!("{} ({CODEBOOK_KEY})", path.display()),
        rows: codes,
        dim: clip_width,
        values: all
            .chunks_exact(width)
            .flat_map(|row| row[..clip_width].iter().copied())
            .collect(),
    })
}

/// The scene's vectors decoded: one code per Gaussian, or one mixture feature per Gaussian.
#[derive(Debug, Clone)]
enum Decoded {
    /// Index of each Gaussian's codebook row.
    Codes(Vec<usize>),
    /// `[N, clip_width]` softmax mixtures of the codebook rows.
    Mixtures(Matrix),
}

/// LEGaussians' semantic features, decoded to codebook CLIP features and scored as the
/// `features` source.
#[derive(Debug)]
pub struct LeGaussiansSource {
    /// The index decoder.
    pub decoder: LangsplatDecoder,
    /// The codebook's CLIP columns `[codes, text width]`.
    pub codebook: Matrix,
    /// How logits become a feature.
    pub combine: Combine,
    /// The scoring (phrase table, encoder, negatives, temperature); its input is unused.
    pub scoring: FeaturesSource,
    decoded: OnceLock<Decoded>,
}

impl LeGaussiansSource {
    /// A source decoding with `decoder` into `codebook`.
    pub fn new(
        decoder: LangsplatDecoder,
        codebook: Matrix,
        combine: Combine,
        scoring: FeaturesSource,
    ) -> Self {
        LeGaussiansSource {
            decoder,
            codebook,
            combine,
            scoring,
            decoded: OnceLock::new(),
        }
    }

    /// Each Gaussian's codebook row (argmax of the decoded logits), decoded on the decoder's
    /// device.
    pub fn codes(&self, scene: &Scene) -> Result<Vec<usize>> {
        let input = self.normalised_features(scene)?;
        let best = self.decoder.map_rows(&input, 1, "decoded", &|x| {
            self.decoder.forward_raw(x).argmax(1).float()
        })?;
        Ok(best.values.iter().map(|&v| v as usize).collect())
    }

    /// The scene's `clip_f_indices_*`, each row L2-normalised as LEGaussians normalises
    /// the feature before decoding.
    fn normalised_features(&self, scene: &Scene) -> Result<Matrix> {
        let mut m = numbered_properties(
            scene,
            FEATURE_PREFIX,
            LEGAUSSIANS,
            "LEGaussians' semantic features",
        )?;
        if m.dim != self.decoder.latent_dim() {
            return Err(SemanticError::Mismatch(format!(
                "{} has vectors of width {} but the index decoder {} takes {}: give the \
                 index_decoder_chkpnt*.pth saved with this scene",
                m.source,
                m.dim,
                self.decoder.source().display(),
                self.decoder.latent_dim()
            )));
        }
        for row in m.values.chunks_mut(m.dim) {
            let norm = row
                .iter()
                .map(|x| x * x)
                .sum::<f32>()
                .sqrt()
                .max(NORMALIZE_EPS);
            row.iter_mut().for_each(|x| *x /= norm);
        }
        Ok(m)
    }

    /// The scene's vectors decoded as `combine` asks, at the first call.
    fn decoded(&self, scene: &Scene) -> Result<&Decoded> {
        if let Some(d) = self.decoded.get() {
            return Ok(d);
        }
        let decoded = match self.combine {
            Combine::Argmax => Decoded::Codes(self.codes(scene)?),
            Combine::Softmax => {
                let input = self.normalised_features(scene)?;
                let c = &self.codebook;
                let mixtures = self.decoder.map_rows(&input, c.dim, "mixed", &|x| {
                    let rows = Tensor::<2>::from_data(
                        TensorData::new(c.values.clone(), [c.rows, c.dim]),
                        (&x.device(), DType::F32),
                    );
                    softmax(self.decoder.forward_raw(x), 1).matmul(rows)
                })?;
                Decoded::Mixtures(mixtures)
            }
        };
        Ok(self.decoded.get_or_init(|| decoded))
    }
}

impl TargetSource for LeGaussiansSource {
    fn kind(&self) -> &'static str {
        LEGAUSSIANS
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let values = match self.decoded(scene)? {
            Decoded::Codes(codes) => {
                let c = &self.codebook;
                let per_code =
                    self.scoring
                        .score_rows(query, &c.source, "codebook row", c.dim, &c.values)?;
                codes.iter().map(|&k| per_code[k]).collect()
            }
            Decoded::Mixtures(m) => self
                .scoring
                .score_rows(query, &m.source, "Gaussian", m.dim, &m.values)?,
        };
        Ok(Relevancy {
            name: query.trim().to_string(),
            values,
            scoring: Scoring::Graded,
            notes: Vec::new(),
        })
    }
}

/// `[targets.custom.legaussians]`: `index_decoder` (`index_decoder_chkpnt*.pth`, required),
/// `codebook` (`*_codebook.pt`, required), `combine` (`"argmax"`, default, or `"softmax"`)
/// and the [`TextKeys`] (temperature default 100).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct LeGaussiansConfig {
    /// LEGaussians' `index_decoder_chkpnt*.pth`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub index_decoder: Option<PathBuf>,
    /// LEGaussians' `*_codebook.pt`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub codebook: Option<PathBuf>,
    /// How logits become a CLIP feature.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub combine: Option<Combine>,
    /// Text embeddings and scoring.
    #[serde(flatten)]
    pub text: TextKeys,
    /// Keys no one knows, refused by `init`.
    #[serde(flatten, skip_serializing)]
    pub unknown: BTreeMap<String, toml::Value>,
}

impl SourceConfig for LeGaussiansConfig {
    fn init(&self, context: &SourceContext) -> Result<Box<dyn TargetSource>> {
        refuse_unknown_keys(
            &self.unknown,
            LEGAUSSIANS,
            &["index_decoder", "codebook", "combine"],
        )?;
        let required = |key: &str, value: &Option<PathBuf>, what: &str| {
            value.as_deref().map(|p| context.resolve(p)).ok_or_else(|| {
                SemanticError::option(key, format!("the legaussians source needs {what}"))
            })
        };
        let decoder_path = required(
            "index_decoder",
            &self.index_decoder,
            "the scene's index_decoder_chkpnt*.pth",
        )?;
        let codebook_path = required(
            "codebook",
            &self.codebook,
            "the scene's codebook (*_codebook.pt from preprocess/quantize_features.py)",
        )?;
        let mut text = self.text.clone();
        text.temperature.get_or_insert(DEFAULT_SCALE);
        // The scoring's input is unused: the source scores codebook rows or mixtures.
        let scoring = text.features_source(FeatureInput::Scene, context)?;
        let decoder = read_index_decoder(&decoder_path, context.device)
            .map_err(|e| e.in_key("index_decoder"))?;
        let codebook =
            read_codebook(&codebook_path, scoring.table.dim()).map_err(|e| e.in_key("codebook"))?;
        if decoder.output_dim() != codebook.rows {
            return Err(SemanticError::Mismatch(format!(
                "the index decoder {} makes logits over {} codes but the codebook {} has {} rows: \
                 they must come from the same scene",
                decoder.source().display(),
                decoder.output_dim(),
                codebook.source,
                codebook.rows
            ))
            .in_key("codebook"));
        }
        Ok(Box::new(LeGaussiansSource::new(
            decoder,
            codebook,
            self.combine.unwrap_or_default(),
            scoring,
        )))
    }
}
