//! `gaussian_grouping` source: Gaussian Grouping scenes (Ye et al., ECCV 2024), whose
//! Gaussians carry an identity encoding that a small classifier turns into instance ids.
//!
//! Layout, as checked in lkeab/gaussian-grouping: `scene/gaussian_model.py` keeps
//! `_objects_dc` `[N, 1, num_objects]` (`num_objects = 16`) and `save_ply` writes it as float
//! properties `obj_dc_0..obj_dc_15` after `rot_*`. `train.py` trains `classifier =
//! torch.nn.Conv2d(num_objects, num_classes, kernel_size=1)` on the rendered identity map and
//! saves `classifier.pth` beside the PLY (`torch.save(classifier.state_dict())`: keys
//! `weight` `[num_classes, num_objects, 1, 1]` and `bias` `[num_classes]`). Its editing
//! scripts classify the Gaussians themselves: `softmax(classifier(_objects_dc), dim=0)` over
//! the classes, one probability per (class, Gaussian); `edit_object_removal.py` then takes
//! the Gaussians whose probability of the chosen ids exceeds `removal_thresh` (0.3 in its
//! configs). The class ids are the mask ids of the video segmentation the scene was trained
//! on (DEVA's; 0 is its "no object" region); Gaussian Grouping has no names for them.
//!
//! Here each Gaussian gets the class of largest probability (the argmax, as Gaussian
//! Grouping's renders label pixels) when that probability is at least `min_probability`
//! (default 0.3, Gaussian Grouping's own threshold), and no instance ([`UNASSIGNED`])
//! otherwise: a Gaussian the classifier is unsure of (a floater, a boundary Gaussian) joins no
//! object. With the argmax the instances are disjoint, unlike the removal rule, under which a
//! Gaussian with two classes above 0.3 belongs to both. Queries then work as with the
//! `labels` source: an instance id (`"34"`), or a name from the `label_names` table
//! (`{ "34" = "bear" }`) or its `synonyms`.
//!
//! The classifier runs once, at the first query, on the caller's burn device (as a one-layer
//! decoder, [`crate::sources::conv1x1`]), and the ids are kept.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};
use splatraj_scene::{Labels, Scene};

use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};
use crate::sources::conv1x1::read_conv1x1_layers;
use crate::sources::properties::numbered_properties;
use crate::sources::{
    LabelsSource, LangsplatDecoder, Relevancy, SourceConfig, SourceContext, TargetSource,
};

/// The name the source is registered under (`source = "custom.gaussian_grouping"`).
pub const GAUSSIAN_GROUPING: &str = "gaussian_grouping";

/// Prefix of the identity-encoding properties (`obj_dc_0`, `obj_dc_1`, ...).
pub const OBJ_DC_PREFIX: &str = "obj_dc_";

/// Default least softmax probability of a Gaussian's class (Gaussian Grouping's
/// `removal_thresh`).
pub const DEFAULT_MIN_PROBABILITY: f32 = 0.3;

/// The id of Gaussians whose largest class probability is below `min_probability`.
pub const UNASSIGNED: i32 = -1;

/// What the classifier file must be, for errors.
const CLASSIFIER: &str = "a Gaussian Grouping classifier.pth (torch.nn.Conv2d(num_objects, \
                          num_classes, kernel_size=1) state dict: weight and bias)";

/// Reads Gaussian Grouping's `classifier.pth` onto `device` as a one-layer decoder from the
/// identity encoding to class logits. A missing key or another shape is an error naming the
/// file and the key.
pub fn read_classifier(path: &Path, device: &Device) -> Result<LangsplatDecoder> {
    read_conv1x1_layers(path, &[""], CLASSIFIER, device)
}

/// The scene's identity encodings `[N, num_objects]` from its `obj_dc_0..` properties, in
/// index order; an error when there are none, an index is missing or a value is not finite.
pub fn identity_encodings(scene: &Scene) -> Result<Matrix> {
    numbered_properties(
        scene,
        OBJ_DC_PREFIX,
        GAUSSIAN_GROUPING,
        "Gaussian Grouping's identity encodings",
    )
}

/// Each Gaussian's most probable class and its softmax probability.
#[derive(Debug, Clone, PartialEq)]
pub struct Identities {
    /// Argmax of the class logits, per Gaussian.
    pub ids: Vec<usize>,
    /// Softmax probability of that class, per Gaussian.
    pub probability: Vec<f32>,
}

impl Identities {
    /// The instance ids as labels: the class, or [`UNASSIGNED`] below `min_probability`.
    pub fn labels(&self, min_probability: f32, source: String) -> Labels {
        Labels {
            source,
            ids: self
                .ids
                .iter()
                .zip(&self.probability)
                .map(|(&id, &p)| {
                    if p >= min_probability {
                        id as i32
                    } else {
                        UNASSIGNED
                    }
                })
                .collect(),
            names: BTreeMap::new(),
        }
    }
}

/// Classifies `encodings` with `classifier` (softmax over classes, then the largest), on the
/// classifier's device.
pub fn classify(classifier: &LangsplatDecoder, encodings: &Matrix) -> Result<Identities> {
    if encodings.dim != classifier.latent_dim() {
        return Err(SemanticError::Mismatch(format!(
            "{} takes identity encodings of width {} (weight [{}, {}, 1, 1]) but the scene has \
             {} {OBJ_DC_PREFIX}* properties: give the classifier.pth saved with this scene",
            classifier.source().display(),
            classifier.latent_dim(),
            classifier.output_dim(),
            classifier.latent_dim(),
            encodings.dim
        )));
    }
    // [rows, 2]: the largest probability and its class (exact in f32 below 2^24 classes).
    let best = classifier.map_rows(encodings, 2, "classified", &|x| {
        let probabilities = softmax(classifier.forward_raw(x), 1);
        let (p, class) = probabilities.max_dim_with_indices(1);
        Tensor::cat(vec![p, class.float()], 1)
    })?;
    let (probability, ids) = best
        .values
        .chunks_exact(2)
        .map(|row| (row[0], row[1] as usize))
        .unzip();
    Ok(Identities { ids, probability })
}

/// Gaussian Grouping's classified identities, queried as labels.
#[derive(Debug)]
pub struct GaussianGroupingSource {
    /// The identity classifier.
    pub classifier: LangsplatDecoder,
    /// Least softmax probability of a Gaussian's class for it to join that instance.
    pub min_probability: f32,
    /// Names of instance ids and their synonyms.
    pub names: LabelsSource,
    identities: OnceLock<Identities>,
}

impl GaussianGroupingSource {
    /// A source classifying with `classifier`, naming instances with `names`.
    pub fn new(classifier: LangsplatDecoder, min_probability: f32, names: LabelsSource) -> Self {
        GaussianGroupingSource {
            classifier,
            min_probability,
            names,
            identities: OnceLock::new(),
        }
    }

    /// Every Gaussian's class and probability, classified at the first call.
    pub fn identities(&self, scene: &Scene) -> Result<&Identities> {
        if let Some(found) = self.identities.get() {
            return Ok(found);
        }
        let found = classify(&self.classifier, &identity_encodings(scene)?)?;
        Ok(self.identities.get_or_init(|| found))
    }
}

impl TargetSource for GaussianGroupingSource {
    fn kind(&self) -> &'static str {
        GAUSSIAN_GROUPING
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let identities = self.identities(scene)?;
        if identities.ids.len() != scene.len() {
            return Err(SemanticError::Mismatch(format!(
                "{} classified {} Gaussians but the scene has {}",
                self.classifier.source().display(),
                identities.ids.len(),
                scene.len()
            )));
        }
        let labels = |min_probability: f32| {
            identities.labels(
                min_probability,
                format!(
                    "the Gaussian Grouping identities ({} at probability ≥ {min_probability})",
                    self.classifier.source().display(),
                ),
            )
        };
        match self
            .names
            .match_labels(&labels(self.min_probability), scene.len(), query)
        {
            Err(SemanticError::NoMatch {
                what,
                query,
                mut closest,
            }) => {
                // The instance may exist with every Gaussian below min_probability: say so.
                if let Ok(unsure) = self.names.match_labels(&labels(0.0), scene.len(), &query) {
                    let highest = (unsure.values.iter().zip(&identities.probability))
                        .filter(|(v, _)| **v > 0.5)
                        .map(|(_, &p)| p)
                        .fold(0.0f32, f32::max);
                    return Err(SemanticError::NothingSelected {
                        query,
                        detail: format!(
                            "instance {:?} is the most probable class of some Gaussians, but \
                             none reaches min_probability = {} (highest: {highest:.3}); lower \
                             min_probability",
                            unsure.name, self.min_probability
                        ),
                    });
                }
                // Instances often have no names: list the ids there are, largest first.
                let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
                for &id in &labels(self.min_probability).ids {
                    *counts.entry(id).or_default() += 1;
                }
                let mut by_size: Vec<(i32, usize)> = counts
                    .into_iter()
                    .filter(|(id, _)| *id != UNASSIGNED)
                    .collect();
                by_size.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
                closest.extend(
                    by_size
                        .iter()
                        .map(|(id, count)| format!("{id} ({count} Gaussians)")),
                );
                Err(SemanticError::NoMatch {
                    what,
                    query,
                    closest,
                })
            }
            other => other,
        }
    }
}

/// `[targets.custom.gaussian_grouping]`: `classifier` (Gaussian Grouping's `classifier.pth`,
/// required), `min_probability` (default 0.3), `label_names` (id → name) and `synonyms`
/// (name → other words).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaussianGroupingConfig {
    /// Gaussian Grouping's `classifier.pth`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub classifier: Option<PathBuf>,
    /// Least softmax probability of a Gaussian's class, in [0, 1].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_probability: Option<f32>,
    /// Instance id (written as a string key) → name.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub label_names: BTreeMap<String, String>,
    /// Instance name → other words that mean it.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub synonyms: BTreeMap<String, Vec<String>>,
}

impl SourceConfig for GaussianGroupingConfig {
    fn init(&self, context: &SourceContext) -> Result<Box<dyn TargetSource>> {
        let min_probability = self.min_probability.unwrap_or(DEFAULT_MIN_PROBABILITY);
        if !(0.0..=1.0).contains(&min_probability) {
            return Err(SemanticError::option(
                "min_probability",
                format!("{min_probability} must lie in [0, 1]"),
            ));
        }
        let mut names = BTreeMap::new();
        for (id, name) in &self.label_names {
            let parsed = id.trim().parse::<i32>().map_err(|_| {
                SemanticError::option(
                    format!("label_names.{id:?}"),
                    format!("{id:?} is not an instance id (an integer)"),
                )
            })?;
            names.insert(parsed, name.clone());
        }
        let path = self.classifier.as_deref().ok_or_else(|| {
            SemanticError::option(
                "classifier",
                "the gaussian_grouping source needs the scene's classifier.pth (saved by \
                 Gaussian Grouping's train.py beside point_cloud.ply)",
            )
        })?;
        let classifier = read_classifier(&context.resolve(path), context.device)
            .map_err(|e| e.in_key("classifier"))?;
        Ok(Box::new(GaussianGroupingSource::new(
            classifier,
            min_probability,
            LabelsSource {
                names,
                synonyms: self.synonyms.clone(),
                cluster: false,
            },
        )))
    }
}
