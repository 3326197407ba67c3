//! `labels` source: per-Gaussian label ids with names; a query names a label.

use std::collections::{BTreeMap, BTreeSet};

use splatraj_scene::{Labels, Scene};

use crate::error::{Result, SemanticError};
use crate::names;
use crate::sources::{Relevancy, Scoring, TargetSource};

/// Selects the Gaussians of one label.
///
/// A query matches a label when, ignoring case and repeated spaces, it equals the label's name
/// or one of its synonyms, or when it is a label id written as an integer. Several ids sharing
/// one name (instances of one category) are selected together. The labels are ground truth, so
/// the selection is exactly the label's Gaussians unless `cluster` asks for DBSCAN.
#[derive(Debug, Clone, Default)]
pub struct LabelsSource {
    /// Names by id that add to or replace the names the scene carries (e.g. from the config
    /// when the label file has ids only).
    pub names: BTreeMap<i32, String>,
    /// Synonyms: label name → other words that mean it.
    pub synonyms: BTreeMap<String, Vec<String>>,
    /// Run DBSCAN on the label's Gaussians (off by default: ground truth needs no cleaning).
    pub cluster: bool,
}

impl TargetSource for LabelsSource {
    fn kind(&self) -> &'static str {
        "labels"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let labels = scene
            .extras
            .labels
            .as_ref()
            .ok_or_else(|| SemanticError::MissingData {
                source_kind: "labels",
                detail: "the scene has no per-Gaussian labels: give a label sidecar (e.g. a \
                     SuperSplat segments JSON) or a scene with a label property"
                    .to_string(),
            })?;
        self.match_labels(labels, scene.len(), query)
    }
}

impl LabelsSource {
    /// The 0/1 values of the Gaussians whose label `query` names (the rule of
    /// [`LabelsSource`]), for `labels` of a scene of `gaussians` Gaussians: the matching of
    /// every source whose per-Gaussian values are instance ids (e.g. Gaussian Grouping's
    /// classified identities).
    pub fn match_labels(
        &self,
        labels: &Labels,
        gaussians: usize,
        query: &str,
    ) -> Result<Relevancy> {
        if labels.ids.len() != gaussians {
            return Err(SemanticError::Mismatch(format!(
                "labels from {} hold {} ids for a scene of {gaussians} Gaussians",
                labels.source,
                labels.ids.len(),
            )));
        }
        let present: BTreeSet<i32> = labels.ids.iter().copied().collect();
        let mut all_names = labels.names.clone();
        all_names.extend(self.names.iter().map(|(k, v)| (*k, v.clone())));

        // Every synonym must name a known label: a typo in the config would otherwise make a
        // word silently match nothing.
        for name in self.synonyms.keys() {
            let n = names::normalise(name);
            if !all_names.values().any(|v| names::normalise(v) == n) {
                return Err(SemanticError::option(
                    format!("synonyms.{name:?}"),
                    format!(
                        "{name:?} is not a label name (known: {})",
                        all_names.values().cloned().collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }

        let q = names::normalise(query);
        let canonical: Option<String> = all_names
            .values()
            .find(|v| names::normalise(v) == q)
            .cloned()
            .or_else(|| {
                self.synonyms.iter().find_map(|(name, words)| {
                    words.iter().any(|w| names::normalise(w) == q).then(|| {
                        // The label's own spelling, not the config key's.
                        let n = names::normalise(name);
                        all_names
                            .values()
                            .find(|v| names::normalise(v) == n)
                            .cloned()
                            .unwrap_or_else(|| name.clone())
                    })
                })
            });

        let (name, ids): (String, BTreeSet<i32>) = if let Some(name) = canonical {
            let n = names::normalise(&name);
            let ids = all_names
                .iter()
                .filter(|(_, v)| names::normalise(v) == n)
                .map(|(k, _)| *k)
                .collect();
            (name, ids)
        } else if let Ok(id) = q.parse::<i32>()
            && present.contains(&id)
        {
            let name = all_names
                .get(&id)
                .cloned()
                .unwrap_or_else(|| format!("label {id}"));
            (name, BTreeSet::from([id]))
        } else {
            let mut candidates: Vec<&str> = all_names.values().map(String::as_str).collect();
            candidates.extend(self.synonyms.values().flatten().map(String::as_str));
            let mut closest = names::closest(query, candidates, names::SUGGESTIONS);
            // Point a suggested synonym at its label, so the user sees what it would select.
            for c in &mut closest {
                if let Some((name, _)) = self
                    .synonyms
                    .iter()
                    .find(|(_, words)| words.iter().any(|w| w == c))
                {
                    *c = format!("{c} (synonym of {name})");
                }
            }
            if closest.is_empty() {
                closest = present.iter().map(|id| id.to_string()).collect();
            }
            return Err(SemanticError::NoMatch {
                what: format!("label in {}", labels.source),
                query: query.to_string(),
                closest,
            });
        };

        if !ids.iter().any(|id| present.contains(id)) {
            return Err(SemanticError::NothingSelected {
                query: query.to_string(),
                detail: format!(
                    "label {name:?} (id {ids:?}) is named but no Gaussian carries it in {}",
                    labels.source
                ),
            });
        }
        let values = labels
            .ids
            .iter()
            .map(|id| if ids.contains(id) { 1.0 } else { 0.0 })
            .collect();
        Ok(Relevancy {
            name,
            values,
            scoring: Scoring::Mask {
                cluster: self.cluster,
            },
            notes: Vec::new(),
        })
    }
}

/// The 0/1 mask of the Gaussians a label query names, by the [`LabelsSource`] rule (name
/// ignoring case and repeated spaces, all ids sharing it, or an id). When nothing matches, the
/// error lists every label name, closest first.
pub fn label_mask(scene: &Scene, query: &str) -> Result<Vec<f32>> {
    match LabelsSource::default().relevancy(scene, query) {
        Ok(r) => Ok(r.values),
        Err(SemanticError::NoMatch { what, query, .. }) => {
            let labels = scene.extras.labels.as_ref();
            let all: Vec<&str> = labels
                .map(|l| l.names.values().map(String::as_str).collect())
                .unwrap_or_default();
            let mut closest = names::closest(&query, all, usize::MAX);
            if closest.is_empty() {
                closest = labels
                    .map(|l| l.counts().keys().map(|id| id.to_string()).collect())
                    .unwrap_or_default();
            }
            Err(SemanticError::NoMatch {
                what,
                query,
                closest,
            })
        }
        Err(e) => Err(e),
    }
}
