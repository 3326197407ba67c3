//! `region` source: Gaussians whose centre lies in a box or a sphere in world coordinates, or
//! that a user selected in an editor and exported as a file ([`super::editor_selection`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::error::{Result, SemanticError};
use crate::names;
use crate::sources::editor_selection::{SelectionFile, match_selection};
use crate::sources::{Relevancy, Scoring, TargetSource};

/// A region of world space. Boundaries are inclusive.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "shape")]
pub enum Region {
    /// Axis-aligned box.
    Box {
        /// Smallest corner.
        min: [f32; 3],
        /// Largest corner.
        max: [f32; 3],
    },
    /// Ball.
    Sphere {
        /// Centre.
        centre: [f32; 3],
        /// Radius (> 0).
        radius: f32,
    },
}

impl Region {
    /// Whether point `p` lies in the region (boundary included).
    pub fn contains(&self, p: [f32; 3]) -> bool {
        match *self {
            Region::Box { min, max } => (0..3).all(|k| min[k] <= p[k] && p[k] <= max[k]),
            Region::Sphere { centre, radius } => {
                let d2: f32 = (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum();
                d2 <= radius * radius
            }
        }
    }

    /// Checks the region's numbers; `key` names it in errors.
    pub fn validate(&self, key: &str) -> Result<()> {
        match *self {
            Region::Box { min, max } => {
                if min.iter().chain(&max).any(|v| !v.is_finite()) {
                    return Err(SemanticError::option(key, "box corners must be finite"));
                }
                if let Some(k) = (0..3).find(|&k| min[k] > max[k]) {
                    return Err(SemanticError::option(
                        key,
                        format!("box min[{k}] = {} exceeds max[{k}] = {}", min[k], max[k]),
                    ));
                }
            }
            Region::Sphere { centre, radius } => {
                if centre.iter().any(|v| !v.is_finite()) {
                    return Err(SemanticError::option(key, "sphere centre must be finite"));
                }
                if !(radius.is_finite() && radius > 0.0) {
                    return Err(SemanticError::option(
                        key,
                        format!("sphere radius {radius} must be finite and > 0"),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Named regions and selection files; a query names one of them (case-insensitive).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionSource {
    /// Region by name.
    pub regions: BTreeMap<String, Region>,
    /// Selection file by name, read (matched to the scene when a query names it).
    #[serde(skip)]
    pub selections: BTreeMap<String, SelectionFile>,
}

impl RegionSource {
    /// A source holding one region under `name`.
    pub fn single(name: impl Into<String>, region: Region) -> Self {
        RegionSource {
            regions: BTreeMap::from([(name.into(), region)]),
            selections: BTreeMap::new(),
        }
    }
}

impl TargetSource for RegionSource {
    fn kind(&self) -> &'static str {
        "region"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let q = names::normalise(query);
        if let Some((name, selection)) = self
            .selections
            .iter()
            .find(|(n, _)| names::normalise(n) == q)
        {
            let matched = match_selection(scene, selection)?;
            let mut values = vec![0.0; scene.len()];
            for &i in &matched.indices {
                values[i] = 1.0;
            }
            return Ok(Relevancy {
                name: name.clone(),
                values,
                scoring: Scoring::Mask { cluster: false },
                notes: vec![matched.describe(&selection.path)],
            });
        }
        let Some((name, region)) = self.regions.iter().find(|(n, _)| names::normalise(n) == q)
        else {
            return Err(SemanticError::NoMatch {
                what: "region".to_string(),
                query: query.to_string(),
                closest: names::closest(
                    query,
                    self.regions
                        .keys()
                        .chain(self.selections.keys())
                        .map(String::as_str),
                    names::SUGGESTIONS,
                ),
            });
        };
        region.validate(&format!("regions.{name}"))?;
        let values = scene
            .means
            .iter()
            .map(|&m| if region.contains(m) { 1.0 } else { 0.0 })
            .collect();
        Ok(Relevancy {
            name: name.clone(),
            values,
            scoring: Scoring::Mask { cluster: false },
            notes: Vec::new(),
        })
    }
}
