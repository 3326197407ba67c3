//! Target sources: each turns a query into one value per Gaussian.
//!
//! One file per source, each implementing [`TargetSource`]. A crate outside splatraj adds its
//! own the same way (a [`SourceConfig`] whose `init` builds its [`TargetSource`]) and registers
//! it in a [`SourceRegistry`]; a config then names it `source = "custom.<name>"`. Selection (thresholds, DBSCAN) is not the sources' job: it lives in
//! [`crate::selection`] and reads the [`Scoring`] a source declares.

pub mod conv1x1;
pub mod editor_selection;
pub mod feature3dgs;
pub mod features;
pub mod gaussian_grouping;
pub mod labels;
pub mod langsplat;
pub mod legaussians;
pub mod opengaussian;
pub mod properties;
pub mod region;
pub mod registry;
pub mod text_keys;

use serde::Serialize;
use splatraj_scene::Scene;

use crate::error::Result;

pub use editor_selection::{SelectionFile, SelectionMatch, match_selection};
pub use feature3dgs::{Feature3dgsConfig, Feature3dgsSource};
pub use features::{FeatureInput, FeaturesSource};
pub use gaussian_grouping::{GaussianGroupingConfig, GaussianGroupingSource};
pub use labels::{LabelsSource, label_mask};
pub use langsplat::{LangsplatDecoder, LangsplatSource};
pub use legaussians::{LeGaussiansConfig, LeGaussiansSource};
pub use opengaussian::{OpenGaussianConfig, OpenGaussianSource};
pub use region::{Region, RegionSource};
pub use registry::{SourceConfig, SourceContext, SourceRegistry};
pub use text_keys::TextKeys;

/// How the values of a [`Relevancy`] are to be read by the selection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scoring {
    /// Values are already a 0/1 selection (labels, regions): thresholds do not apply.
    /// `cluster` asks for DBSCAN on the selected Gaussians all the same.
    Mask {
        /// Run DBSCAN on the selected Gaussians.
        cluster: bool,
    },
    /// Graded scores (relevancy in [0, 1]): percentile and floor, then DBSCAN.
    Graded,
}

/// What a source says about every Gaussian for one query.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Relevancy {
    /// Canonical name of what the query matched (label name, phrase, region name).
    pub name: String,
    /// One value per Gaussian.
    pub values: Vec<f32>,
    /// How the values are to be read.
    pub scoring: Scoring,
    /// What the source says about how it matched, for the caller to show (a selection
    /// file's matched share); not doubts, which the selection's warnings carry.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// A way to turn a text query into per-Gaussian relevancy or selection. `Debug` so that a
/// boxed source can sit in a config or a report; `Send + Sync` so that queries can run on
/// worker threads.
pub trait TargetSource: std::fmt::Debug + Send + Sync {
    /// Short name of the source kind, for messages ("labels", "region", "features",
    /// "langsplat").
    fn kind(&self) -> &'static str;

    /// One value per Gaussian of `scene` for `query`, or an error when the query matches
    /// nothing (listing the closest names) or the scene lacks the data the source needs.
    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy>;
}
