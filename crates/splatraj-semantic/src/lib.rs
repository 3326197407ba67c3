//! Semantic targets: from a query to the Gaussians of an object.
//!
//! SplaTraj grounds each query in the scene as a 0/1 value per Gaussian (paper, "Semantic Map
//! Extraction"). This crate does that grounding. A [`TargetSource`] turns a query into one
//! value per Gaussian: [`LabelsSource`] matches label names (case-insensitive, synonyms, ids),
//! [`RegionSource`] takes a box or a sphere in world coordinates or a file of splats selected in
//! an editor ([`match_selection`]), [`FeaturesSource`] scores
//! per-Gaussian language embeddings against a phrase's text embedding with the LERF relevancy
//! (softmax against canonical negatives, minimum over negatives), and [`LangsplatSource`]
//! decodes LangSplat's per-Gaussian 3-d latents to 512-d with the scene's autoencoder decoder
//! ([`LangsplatDecoder`]: a burn module on the caller's device, weights read from the PyTorch
//! checkpoint with burn-store's reader) and then scores them as `features`. [`selection`] then
//! keeps the top relevancy percentile above a floor, clusters it by density in 3D against
//! the scene's own density ([`cluster`]: each candidate's nearest scene Gaussians from a kiddo
//! k-d tree) and returns a [`Target`]: the 0/1 channel of the cluster with the largest
//! relevancy mass, a robust centre and extent for the trajectory prior, the runner-up clusters
//! and dropped candidates, and warnings. [`embeddings`] reads the feature sidecars (`.npy`,
//! `.safetensors`) and phrase tables (JSON, `.npy` + phrases, `.safetensors`). [`config`] is
//! the `[targets]` table of a config file ([`TargetsConfig`]): which source, its files and
//! options, and the selection settings, built into a source in one call.
//!
//! [`explain`] tells why a graded query found, or did not find, an object (relevancy
//! quantiles, thresholds, the most relevant Gaussians grouped in space).
//!
//! [`text_encoder`] is a CLIP text tower in burn (open_clip/OpenAI weights from a file the user
//! has) that makes `features` and `langsplat` queries free text. [`image_encoder`] is the
//! image tower of the same file: global image embeddings, and dense text-aligned patch
//! features by ClearCLIP (Lan et al., ECCV 2024).
//!
//! It does not render anything or read whole config files (the caller parses the file and hands
//! over its `[targets]` table): those belong to other parts of splatraj.

#![warn(missing_docs)]

mod clip;
pub mod cluster;
pub mod config;
pub mod embeddings;
pub mod error;
pub mod explain;
pub mod image_encoder;
pub mod mask_file;
pub mod names;
mod npy_size;
pub mod selection;
pub mod source_config;
mod source_kind;
pub mod sources;
mod struct_keys;
pub mod text_encoder;
pub mod vectors;
mod weights;

pub use config::{RegionSpec, SourceKind, TargetsConfig};
pub use embeddings::{Matrix, PhraseTable, read_feature_sidecar};
pub use error::{Result, SemanticError};
pub use explain::{Explanation, explain};
pub use image_encoder::{DenseFeatures, ImageEncoder, ImageEncoderOptions, RgbImage};
pub use mask_file::read_mask_file;
pub use selection::{
    Cluster, ClusterOptions, ClusteringSummary, EpsRule, KeepClusters, SelectionOptions, Spread,
    Target, find_target, select,
};
pub use source_config::{
    FeaturesConfig, LabelsConfig, LangsplatConfig, LiftedConfig, RegionConfig, TargetSourceConfig,
};
pub use sources::{
    FeatureInput, FeaturesSource, LabelsSource, LangsplatDecoder, LangsplatSource, Region,
    RegionSource, Relevancy, Scoring, SelectionFile, SelectionMatch, SourceConfig, SourceContext,
    SourceRegistry, TargetSource, TextKeys, label_mask, match_selection,
};
pub use text_encoder::{Activation, ClipTokenizer, TextEncoder, TextEncoderOptions};
