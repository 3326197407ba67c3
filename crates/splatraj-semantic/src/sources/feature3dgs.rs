//! `feature3dgs` source: Feature 3DGS scenes (Zhou et al., CVPR 2024), whose Gaussians carry a
//! distilled feature vector, scored against text as the `features` source.
//!
//! Layout, as checked in ShijieZhou-UCLA/feature-3dgs: `scene/gaussian_model.py`
//! (`construct_list_of_attributes`, `save_ply`) writes the per-Gaussian feature as float
//! properties `semantic_0..semantic_{D-1}` after `rot_*`; the scene reader already reads them
//! into `scene.extras.features`. With `--speedup` the features are a quarter of the teacher's
//! width and `train.py` saves `decoder_chkpnt<iteration>.pth`, the `state_dict()` of
//! `models/networks.py`'s `CNN_decoder`: one `nn.Conv2d(in, out, kernel_size=1)`, keys
//! `conv.weight` `[out, in, 1, 1]` and `conv.bias` `[out]`. A 1×1 convolution applied to a
//! feature map is the same Linear map applied to each pixel's vector, and rendering is linear
//! in the per-Gaussian features, so applying it to each Gaussian's vector gives the vectors
//! whose render the decoder would produce (up to the bias, scaled by the pixel's opacity):
//! the decoded vectors are then in the teacher's (text-aligned, for LSeg/CLIP) space.
//!
//! The decoder runs once, at the first query, on the caller's burn device (as LangSplat's
//! decoder, through the same Linear-layer module), and the decoded matrix is kept.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};
use crate::sources::conv1x1::read_conv1x1_layers;
use crate::sources::features::scene_features;
use crate::sources::text_keys::{TextKeys, refuse_unknown_keys};
use crate::sources::{
    FeatureInput, FeaturesSource, LangsplatDecoder, Relevancy, Scoring, SourceConfig,
    SourceContext, TargetSource,
};

/// The name the source is registered under (`source = "custom.feature3dgs"`).
pub const FEATURE3DGS: &str = "feature3dgs";

/// Reads Feature 3DGS's 1×1-convolution decoder (`decoder_chkpnt*.pth`, keys `conv.weight`
/// `[out, in, 1, 1]` and `conv.bias` `[out]`) onto `device`, as a one-layer Linear decoder. A
/// missing key or another shape is an error naming the file and the key.
pub fn read_decoder(path: &Path, device: &Device) -> Result<LangsplatDecoder> {
    read_conv1x1_layers(
        path,
        &["conv."],
        "a Feature 3DGS CNN_decoder state dict (one Conv2d with kernel_size=1 under `conv`)",
        device,
    )
}

/// Feature 3DGS's `semantic_*` features, decoded by its 1×1 convolution when there is one,
/// scored against text as the `features` source.
#[derive(Debug)]
pub struct Feature3dgsSource {
    /// The scoring (phrase table, encoder, negatives, temperature); its input is unused.
    pub scoring: FeaturesSource,
    /// The `CNN_decoder`, when the features are narrower than the text embeddings.
    pub decoder: Option<LangsplatDecoder>,
    decoded: OnceLock<Matrix>,
}

impl Feature3dgsSource {
    /// A source scoring the scene's features with `scoring`, decoded by `decoder` if any.
    pub fn new(scoring: FeaturesSource, decoder: Option<LangsplatDecoder>) -> Self {
        Feature3dgsSource {
            scoring,
            decoder,
            decoded: OnceLock::new(),
        }
    }

    /// The scene's features through the decoder, decoded at the first call.
    fn decoded(&self, scene: &Scene, decoder: &LangsplatDecoder) -> Result<&Matrix> {
        if let Some(m) = self.decoded.get() {
            return Ok(m);
        }
        let f = scene_features(scene, "feature3dgs")?;
        let input = Matrix {
            source: format!(
                "scene features ({}..)",
                f.names.first().map_or("", String::as_str)
            ),
            rows: f.values.len().checked_div(f.dim).unwrap_or(0),
            dim: f.dim,
            values: f.values.clone(),
        };
        if input.dim != decoder.latent_dim() {
            return Err(SemanticError::Mismatch(format!(
                "{}: features of width {} but the decoder {} takes {}: give the decoder saved \
                 with this scene",
                input.source,
                input.dim,
                decoder.source().display(),
                decoder.latent_dim()
            )));
        }
        let decoded = decoder.decode(&input)?;
        Ok(self.decoded.get_or_init(|| decoded))
    }
}

impl TargetSource for Feature3dgsSource {
    fn kind(&self) -> &'static str {
        "feature3dgs"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let Some(decoder) = &self.decoder else {
            return self.scoring.relevancy(scene, query);
        };
        let m = self.decoded(scene, decoder)?;
        if m.rows != scene.len() {
            return Err(SemanticError::Mismatch(format!(
                "{}: {} feature vectors for a scene of {} Gaussians",
                m.source,
                m.rows,
                scene.len()
            )));
        }
        Ok(Relevancy {
            name: query.trim().to_string(),
            values: self
                .scoring
                .score_rows(query, &m.source, "Gaussian", m.dim, &m.values)?,
            scoring: Scoring::Graded,
            notes: Vec::new(),
        })
    }
}

/// `[targets.custom.feature3dgs]`: `decoder` (optional, Feature 3DGS's
/// `decoder_chkpnt*.pth`, when the `semantic_*` width is not the text width) and the
/// [`TextKeys`] (`phrases`, `text_encoder`, `negatives`, `temperature`, ...).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Feature3dgsConfig {
    /// Feature 3DGS's `CNN_decoder` checkpoint; `None`: the features are used as they are.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decoder: Option<PathBuf>,
    /// Text embeddings and scoring.
    #[serde(flatten)]
    pub text: TextKeys,
    /// Keys no one knows, refused by `init`.
    #[serde(flatten, skip_serializing)]
    pub unknown: BTreeMap<String, toml::Value>,
}

impl SourceConfig for Feature3dgsConfig {
    fn init(&self, context: &SourceContext) -> Result<Box<dyn TargetSource>> {
        refuse_unknown_keys(&self.unknown, FEATURE3DGS, &["decoder"])?;
        let decoder = match &self.decoder {
            Some(p) => Some(
                read_decoder(&context.resolve(p), context.device)
                    .map_err(|e| e.in_key("decoder"))?,
            ),
            None => None,
        };
        let scoring = self.text.features_source(FeatureInput::Scene, context)?;
        if let Some(d) = &decoder
            && d.output_dim() != scoring.table.dim()
        {
            return Err(SemanticError::Mismatch(format!(
                "the decoder {} makes vectors of length {} but the text embeddings have length \
                 {}: they must come from the same model",
                d.source().display(),
                d.output_dim(),
                scoring.table.dim()
            ))
            .in_key("decoder"));
        }
        Ok(Box::new(Feature3dgsSource::new(scoring, decoder)))
    }
}
