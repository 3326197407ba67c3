//! Semantic targets: from a query to the Gaussians of an object.
//!
//! SplaTraj grounds each query in the scene as a 0/1 value per Gaussian (paper, "Semantic Map
//! Extraction"). This crate does that grounding. A [`TargetSource`] turns a query into one
//! value per Gaussian: [`LabelsSource`] matches label names (case-insensitive, synonyms, ids),
//! [`RegionSource`] takes a box or a sphere in world coordinates, and [`FeaturesSource`] scores
//! per-Gaussian language embeddings against a phrase's text embedding with the LERF relevancy
//! (softmax against canonical negatives, minimum over negatives). [`selection`] then keeps the
//! top relevancy percentile above a floor, cleans it with DBSCAN in 3D (petal-clustering, with
//! a radius from k-d tree neighbour distances via kiddo) and returns a [`Target`]: the 0/1
//! channel, a robust centre and extent for the trajectory prior, and counts for diagnostics.
//! [`embeddings`] reads the feature sidecars (`.npy`, `.safetensors`) and phrase tables (JSON,
//! `.npy` + phrases, `.safetensors`).
//!
//! It does not compute text embeddings (no CLIP model here: phrase tables are precomputed
//! files), decode LangSplat latents, render anything or read config files: those belong to
//! other parts of splatraj. It does not depend on burn.

#![warn(missing_docs)]

pub mod embeddings;
pub mod error;
pub mod names;
pub mod selection;
pub mod sources;
pub mod vectors;

pub use embeddings::{Matrix, PhraseTable, read_feature_sidecar};
pub use error::{Result, SemanticError};
pub use selection::{
    ClusterOptions, EpsRule, KeepClusters, SelectionOptions, Spread, Target, find_target, select,
};
pub use sources::{
    FeatureInput, FeaturesSource, LabelsSource, Region, RegionSource, Relevancy, Scoring,
    TargetSource,
};
