//! `opengaussian` source: OpenGaussian scenes (Wu et al., NeurIPS 2024), whose Gaussians are
//! grouped into leaf clusters that each carry one CLIP feature.
//!
//! Layout, as checked in OpenGaussian's `train.py` (its copies in the code index): after the
//! 2D–3D association stage it writes `cluster_lang.npz` with `np.savez`, keys `leaf_feat`
//! (`[k1·k2, 512]`, the mean CLIP feature of the masks each leaf matched), `leaf_score`
//! (`[k1·k2]`), `occu_count` (`[k1·k2]`, how many views matched the leaf) and `leaf_ind`
//! (`[num_pts]` int64, each Gaussian's leaf). Its evaluation looks each Gaussian's feature up
//! as `leaf_feat[leaf_ind]` and zeroes leaves matched in too few views (`occu_count` below a
//! threshold). The `ins_feat_*` PLY properties (6-d instance features) are what the leaves
//! were clustered from; `leaf_ind` already holds the result, so they are not needed here.
//!
//! Relevancy is scored once per leaf (the `features` scoring: LERF softmax against canonical
//! negatives) and handed to the leaf's Gaussians; leaves with a zero feature or fewer than
//! `min_views` matching views get 0.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::embeddings::Matrix;
use crate::error::{Result, SemanticError};
use crate::sources::text_keys::{TextKeys, refuse_unknown_keys};
use crate::sources::{
    FeatureInput, FeaturesSource, Relevancy, Scoring, SourceConfig, SourceContext, TargetSource,
};

/// The name the source is registered under (`source = "custom.opengaussian"`).
pub const OPENGAUSSIAN: &str = "opengaussian";

/// Default least number of views a leaf must have been matched in to count.
pub const DEFAULT_MIN_VIEWS: u32 = 1;

/// The contents of OpenGaussian's `cluster_lang.npz` that queries need.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterLang {
    /// Per-leaf language features `[leaves, D]`.
    pub leaf_feat: Matrix,
    /// Number of views each leaf was matched in.
    pub occu_count: Vec<f64>,
    /// Each Gaussian's leaf.
    pub leaf_ind: Vec<usize>,
}

/// One `.npy` member of an `.npz` file: its shape and its values as f64.
type Array = (Vec<u64>, Vec<f64>);

/// The `.npy` members of an `.npz` file (stored or deflated), by name without `.npy`, each as
/// its shape and values converted to f64 (float32/64 and integer arrays).
fn read_npz(path: &Path) -> Result<BTreeMap<String, Array>> {
    let file = splatraj_scene::input::open(path)
        .map(|(file, _)| file)
        .map_err(|e| SemanticError::io(path, e))?;
    let mut archive = zip::ZipArchive::new(std::io::BufReader::new(file))
        .map_err(|e| SemanticError::file(path, format!("not a readable .npz (zip) file: {e}")))?;
    let mut arrays = BTreeMap::new();
    for i in 0..archive.len() {
        let mut entry = archive
            .by_index(i)
            .map_err(|e| SemanticError::file(path, format!("reading member {i}: {e}")))?;
        let name = entry
            .name()
            .map_err(|e| SemanticError::file(path, format!("member {i}'s name: {e}")))?
            .trim_end_matches(".npy")
            .to_string();
        let mut bytes = Vec::new();
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| SemanticError::file(path, format!("reading {name:?}: {e}")))?;
        let bad = |detail: String| SemanticError::file(path, format!("array {name:?}: {detail}"));
        crate::npy_size::check_shape_product(&bytes).map_err(bad)?;
        let npy = npyz::NpyFile::new(&bytes[..]).map_err(|e| bad(format!("not .npy: {e}")))?;
        crate::npy_size::check_npy_bytes(&bytes, npy.header()).map_err(bad)?;
        let shape = npy.shape().to_vec();
        let values: std::io::Result<Vec<f64>> = match npy.try_data::<f32>() {
            Ok(d) => d.map(|v| v.map(f64::from)).collect(),
            Err(npy) => match npy.try_data::<f64>() {
                Ok(d) => d.collect(),
                Err(npy) => match npy.try_data::<i64>() {
                    Ok(d) => d.map(|v| v.map(|x| x as f64)).collect(),
                    Err(npy) => match npy.try_data::<i32>() {
                        Ok(d) => d.map(|v| v.map(f64::from)).collect(),
                        // Other dtypes are kept empty: only the arrays the source reads are
                        // checked, and an empty one of non-zero shape is refused there.
                        Err(_) => Ok(Vec::new()),
                    },
                },
            },
        };
        arrays.insert(
            name.clone(),
            (shape, values.map_err(|e| bad(e.to_string()))?),
        );
    }
    Ok(arrays)
}

impl ClusterLang {
    /// Reads `cluster_lang.npz`; a missing key, a wrong rank or a `leaf_ind` outside the
    /// leaves is an error naming the file and the key.
    pub fn read(path: &Path) -> Result<Self> {
        let arrays = read_npz(path)?;
        let get = |key: &str, rank: usize| -> Result<&Array> {
            let found = arrays.get(key).ok_or_else(|| {
                SemanticError::file(
                    path,
                    format!(
                        "no array {key:?}: not an OpenGaussian cluster_lang.npz (it holds {:?})",
                        arrays.keys().collect::<Vec<_>>()
                    ),
                )
            })?;
            if found.0.len() != rank || (found.1.is_empty() && found.0.iter().product::<u64>() > 0)
            {
                return Err(SemanticError::file(
                    path,
                    format!(
                        "array {key:?} has shape {:?}: expected {rank} dimension(s) of float or \
                         integer values",
                        found.0
                    ),
                ));
            }
            Ok(found)
        };
        let (feat_shape, feat) = get("leaf_feat", 2)?;
        let (leaves, dim) = (feat_shape[0] as usize, feat_shape[1] as usize);
        let (_, occu_count) = get("occu_count", 1)?;
        if occu_count.len() != leaves {
            return Err(SemanticError::file(
                path,
                format!(
                    "array \"occu_count\" has {} values for {leaves} leaves",
                    occu_count.len()
                ),
            ));
        }
        let (_, ind) = get("leaf_ind", 1)?;
        let leaf_ind = ind
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if v >= 0.0 && v.fract() == 0.0 && (v as usize) < leaves {
                    Ok(v as usize)
                } else {
                    Err(SemanticError::file(
                        path,
                        format!(
                            "array \"leaf_ind\": Gaussian {i} has leaf {v}, outside the \
                             {leaves} leaves of \"leaf_feat\""
                        ),
                    ))
                }
            })
            .collect::<Result<Vec<_>>>()?;
        if let Some(i) = feat.iter().position(|v| !v.is_finite()) {
            return Err(SemanticError::file(
                path,
                format!("array \"leaf_feat\": leaf {} holds {}", i / dim, feat[i]),
            ));
        }
        Ok(ClusterLang {
            leaf_feat: Matrix {
                source: format!("{} (leaf_feat)", path.display()),
                rows: leaves,
                dim,
                values: feat.iter().map(|&v| v as f32).collect(),
            },
            occu_count: occu_count.clone(),
            leaf_ind,
        })
    }
}

/// OpenGaussian's leaf language features, scored per leaf and looked up per Gaussian.
#[derive(Debug, Clone)]
pub struct OpenGaussianSource {
    /// The clusters read from `cluster_lang.npz`.
    pub clusters: ClusterLang,
    /// Leaves matched in fewer views than this score 0.
    pub min_views: u32,
    /// The scoring (phrase table, encoder, negatives, temperature); its input is unused.
    pub scoring: FeaturesSource,
}

impl TargetSource for OpenGaussianSource {
    fn kind(&self) -> &'static str {
        "opengaussian"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> Result<Relevancy> {
        let c = &self.clusters;
        if c.leaf_ind.len() != scene.len() {
            return Err(SemanticError::Mismatch(format!(
                "{}: leaf_ind has {} Gaussians but the scene has {}",
                c.leaf_feat.source,
                c.leaf_ind.len(),
                scene.len()
            )));
        }
        let usable: Vec<usize> = (0..c.leaf_feat.rows)
            .filter(|&k| {
                c.occu_count[k] >= f64::from(self.min_views)
                    && c.leaf_feat.row(k).iter().any(|&v| v != 0.0)
            })
            .collect();
        let values: Vec<f32> = usable
            .iter()
            .flat_map(|&k| c.leaf_feat.row(k).iter().copied())
            .collect();
        let scores = self.scoring.score_rows(
            query,
            &c.leaf_feat.source,
            "leaf",
            c.leaf_feat.dim,
            &values,
        )?;
        let mut leaf_relevancy = vec![0.0f32; c.leaf_feat.rows];
        for (&k, s) in usable.iter().zip(scores) {
            leaf_relevancy[k] = s;
        }
        Ok(Relevancy {
            name: query.trim().to_string(),
            values: c.leaf_ind.iter().map(|&k| leaf_relevancy[k]).collect(),
            scoring: Scoring::Graded,
            notes: Vec::new(),
        })
    }
}

/// `[targets.custom.opengaussian]`: `cluster_lang` (OpenGaussian's `cluster_lang.npz`,
/// required), `min_views` (default 1) and the [`TextKeys`].
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct OpenGaussianConfig {
    /// OpenGaussian's `cluster_lang.npz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster_lang: Option<PathBuf>,
    /// Leaves matched in fewer views than this score 0 (OpenGaussian's evaluation drops
    /// rarely matched leaves the same way).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min_views: Option<u32>,
    /// Text embeddings and scoring.
    #[serde(flatten)]
    pub text: TextKeys,
    /// Keys no one knows, refused by `init`.
    #[serde(flatten, skip_serializing)]
    pub unknown: BTreeMap<String, toml::Value>,
}

impl SourceConfig for OpenGaussianConfig {
    fn init(&self, context: &SourceContext) -> Result<Box<dyn TargetSource>> {
        refuse_unknown_keys(&self.unknown, OPENGAUSSIAN, &["cluster_lang", "min_views"])?;
        let path = self.cluster_lang.as_deref().ok_or_else(|| {
            SemanticError::option(
                "cluster_lang",
                "the opengaussian source needs the scene's cluster_lang.npz",
            )
        })?;
        let clusters =
            ClusterLang::read(&context.resolve(path)).map_err(|e| e.in_key("cluster_lang"))?;
        let scoring = self
            .text
            .features_source(FeatureInput::Sidecar(clusters.leaf_feat.clone()), context)?;
        if clusters.leaf_feat.dim != scoring.table.dim() {
            return Err(SemanticError::Mismatch(format!(
                "{} has vectors of length {} but the text embeddings have length {}: they \
                 must come from the same CLIP model",
                clusters.leaf_feat.source,
                clusters.leaf_feat.dim,
                scoring.table.dim()
            ))
            .in_key("cluster_lang"));
        }
        Ok(Box::new(OpenGaussianSource {
            clusters,
            min_views: self.min_views.unwrap_or(DEFAULT_MIN_VIEWS),
            scoring,
        }))
    }
}
