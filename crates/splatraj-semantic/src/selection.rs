//! From per-Gaussian relevancy to the object's 0/1 channel: thresholds, DBSCAN, statistics.
//!
//! Graded relevancy (the `features` route) keeps the Gaussians in the top `top_fraction` of
//! relevancy **and** above `floor`, then runs DBSCAN in 3D on their centres and keeps the main
//! cluster (or every cluster above a size fraction). Masks (labels, regions) skip the
//! thresholds and are clustered only when the source asks for it.
//!
//! DBSCAN's radius is derived from the kept points themselves: `eps = factor × quantile` of
//! each point's distance to its (`min_points` − 1)-th nearest neighbour (the classic "k-distance"
//! heuristic of Ester et al.), defaults `quantile = 0.9`, `factor = 2`. The median
//! nearest-neighbour distance (`neighbour = 1`, `quantile = 0.5`) is available through
//! [`EpsRule::Auto`] but is not the default: on the fruit_drops capture it split every
//! ground-truth object into 5-20 pieces (splats crowd in dense surface patches, so the typical
//! nearest neighbour is far closer than the gaps inside one object), whereas the default kept
//! each object in one cluster holding ≥ 98.5% of its Gaussians.

use std::collections::HashMap;
use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use ndarray::Array2;
use petal_clustering::{Dbscan, Fit};
use petal_neighbors::distance::Euclidean;
use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::error::{Result, SemanticError};
use crate::sources::{Relevancy, Scoring, TargetSource};

/// Default fraction of Gaussians kept by the relevancy percentile (top 2%).
pub const DEFAULT_TOP_FRACTION: f32 = 0.02;
/// Default absolute relevancy floor (0.5: no more like the query than like a negative).
pub const DEFAULT_FLOOR: f32 = 0.5;
/// Default DBSCAN minimum neighbourhood size (the point itself included).
pub const DEFAULT_MIN_POINTS: usize = 5;
/// Default quantile of the k-distances that sets eps.
pub const DEFAULT_EPS_QUANTILE: f32 = 0.9;
/// Default multiplier of that quantile.
pub const DEFAULT_EPS_FACTOR: f32 = 2.0;

/// How DBSCAN's neighbourhood radius is chosen.
///
/// In a config: `eps = { fixed = 0.05 }` or `eps = { auto = { quantile = 0.5, factor = 3 } }`
/// (missing fields of `auto` take their defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum EpsRule {
    /// `factor × quantile_q` over the kept points of the distance to their `neighbour`-th
    /// nearest other point; `neighbour = None` means `min_points − 1`.
    Auto {
        /// Which neighbour (1 = nearest); `None`: `min_points − 1`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        neighbour: Option<usize>,
        /// Quantile in [0, 1] of those distances.
        #[serde(default = "default_eps_quantile")]
        quantile: f32,
        /// Multiplier (> 0).
        #[serde(default = "default_eps_factor")]
        factor: f32,
    },
    /// A fixed radius in world units.
    Fixed(f32),
}

impl Default for EpsRule {
    fn default() -> Self {
        EpsRule::Auto {
            neighbour: None,
            quantile: DEFAULT_EPS_QUANTILE,
            factor: DEFAULT_EPS_FACTOR,
        }
    }
}

fn default_eps_quantile() -> f32 {
    DEFAULT_EPS_QUANTILE
}

fn default_eps_factor() -> f32 {
    DEFAULT_EPS_FACTOR
}

/// Which DBSCAN clusters make the object.
///
/// In a config: `keep = "largest"` or `keep = { above_fraction = 0.1 }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum KeepClusters {
    /// Only the largest cluster (the object; other clusters are look-alikes or noise).
    #[default]
    Largest,
    /// Every cluster holding at least this fraction of the Gaussians that passed the
    /// thresholds (for objects made of separate parts).
    AboveFraction(f32),
}

/// DBSCAN settings (config keys `min_points`, `eps`, `keep`; missing ones take the defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, rename_all = "snake_case", deny_unknown_fields)]
pub struct ClusterOptions {
    /// Minimum neighbourhood size of a core point, the point itself included.
    pub min_points: usize,
    /// Radius rule.
    pub eps: EpsRule,
    /// Which clusters to keep.
    pub keep: KeepClusters,
}

impl Default for ClusterOptions {
    fn default() -> Self {
        ClusterOptions {
            min_points: DEFAULT_MIN_POINTS,
            eps: EpsRule::default(),
            keep: KeepClusters::default(),
        }
    }
}

/// Selection settings (config keys `top_fraction`, `floor`, `cluster`; missing ones take the
/// defaults). In a config `cluster` is `false` (no DBSCAN), `true` (default DBSCAN) or a table
/// of [`ClusterOptions`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, rename_all = "snake_case", deny_unknown_fields)]
pub struct SelectionOptions {
    /// Fraction (0, 1] of all Gaussians kept by the relevancy percentile (graded scores only).
    pub top_fraction: f32,
    /// Relevancy a Gaussian must exceed (graded scores only), in [0, 1).
    pub floor: f32,
    /// DBSCAN for graded scores (`None`: no clustering); also the settings used when a mask
    /// source asks for clustering (the defaults when `None`).
    #[serde(with = "cluster_setting")]
    pub cluster: Option<ClusterOptions>,
}

impl SelectionOptions {
    /// Checks every value's range; errors name the option by its config key
    /// (`top_fraction`, `cluster.min_points`, ...).
    pub fn validate(&self) -> Result<()> {
        self.validate_as("")
    }

    /// As [`SelectionOptions::validate`], with `prefix` put before each key in errors
    /// (`"targets.selection."` for a config file).
    pub fn validate_as(&self, prefix: &str) -> Result<()> {
        validate(self).map_err(|e| match e {
            SemanticError::InvalidOption { key, detail } => {
                SemanticError::option(format!("{prefix}{key}"), detail)
            }
            other => other,
        })
    }
}

/// `cluster = false | true | { ... }`: TOML has no null, so "no DBSCAN" is `false`.
mod cluster_setting {
    use std::fmt;

    use serde::de::{self, MapAccess, Visitor};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::ClusterOptions;

    pub fn serialize<S: Serializer>(
        value: &Option<ClusterOptions>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        match value {
            None => s.serialize_bool(false),
            Some(c) => c.serialize(s),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<ClusterOptions>, D::Error> {
        struct Setting;
        impl<'de> Visitor<'de> for Setting {
            type Value = Option<ClusterOptions>;

            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("true, false, or a table of DBSCAN options (min_points, eps, keep)")
            }

            fn visit_bool<E: de::Error>(self, v: bool) -> Result<Self::Value, E> {
                Ok(v.then(ClusterOptions::default))
            }

            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                // Straight into ClusterOptions, so its own messages (unknown key, bad value)
                // reach the user unchanged.
                ClusterOptions::deserialize(de::value::MapAccessDeserializer::new(map)).map(Some)
            }
        }
        d.deserialize_any(Setting)
    }
}

impl Default for SelectionOptions {
    fn default() -> Self {
        SelectionOptions {
            top_fraction: DEFAULT_TOP_FRACTION,
            floor: DEFAULT_FLOOR,
            cluster: Some(ClusterOptions::default()),
        }
    }
}

/// Minimum, median and maximum of the relevancies of the selected Gaussians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    /// Smallest.
    pub min: f32,
    /// Median.
    pub median: f32,
    /// Largest.
    pub max: f32,
}

/// The Gaussians of one object, ready for the trajectory costs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Target {
    /// The query as given.
    pub query: String,
    /// What it matched (label name, phrase, region name).
    pub name: String,
    /// 0/1 per Gaussian.
    pub mask: Vec<f32>,
    /// Number of selected Gaussians.
    pub count: usize,
    /// Gaussians that passed the thresholds, before DBSCAN.
    pub candidates: usize,
    /// Robust centre: per-axis median of the selected centres.
    pub centre: [f32; 3],
    /// Robust extent: per-axis span between the 5% and 95% quantiles of the selected centres.
    pub extent: [f32; 3],
    /// Sizes of all DBSCAN clusters found, largest first (one entry, the count, without DBSCAN).
    pub clusters: Vec<usize>,
    /// Candidates DBSCAN marked as noise.
    pub noise: usize,
    /// DBSCAN radius used, if DBSCAN ran.
    pub eps: Option<f32>,
    /// Relevancy threshold the percentile set (graded scores only).
    pub percentile_threshold: Option<f32>,
    /// Relevancies of the selected Gaussians.
    pub relevancy_spread: Spread,
}

impl Target {
    /// Indices of the selected Gaussians.
    pub fn indices(&self) -> Vec<usize> {
        self.mask
            .iter()
            .enumerate()
            .filter(|(_, m)| **m > 0.5)
            .map(|(i, _)| i)
            .collect()
    }
}

/// Asks `source` for the relevancy of `query` and selects the object.
pub fn find_target(
    source: &dyn TargetSource,
    scene: &Scene,
    query: &str,
    options: &SelectionOptions,
) -> Result<Target> {
    if scene.is_empty() {
        return Err(SemanticError::EmptyScene);
    }
    let relevancy = source.relevancy(scene, query)?;
    select(scene, query, &relevancy, options)
}

/// Selects the object from a source's relevancy (see the module docs).
pub fn select(
    scene: &Scene,
    query: &str,
    relevancy: &Relevancy,
    options: &SelectionOptions,
) -> Result<Target> {
    validate(options)?;
    let n = scene.len();
    if n == 0 {
        return Err(SemanticError::EmptyScene);
    }
    let r = &relevancy.values;
    if r.len() != n {
        return Err(SemanticError::Mismatch(format!(
            "query {query:?}: {} relevancy values for a scene of {n} Gaussians",
            r.len()
        )));
    }
    if let Some(i) = r.iter().position(|v| !v.is_finite()) {
        return Err(SemanticError::NonFinite {
            what: format!("the relevancy of Gaussian {i} for query {query:?}"),
            value: r[i],
        });
    }
    let nothing = |detail: String| SemanticError::NothingSelected {
        query: query.to_string(),
        detail,
    };

    let (candidates, percentile_threshold, cluster) = match relevancy.scoring {
        Scoring::Mask { cluster } => {
            let kept: Vec<usize> = (0..n).filter(|&i| r[i] > 0.5).collect();
            if kept.is_empty() {
                return Err(nothing(format!(
                    "{:?} contains none of the {n} Gaussians",
                    relevancy.name
                )));
            }
            let cluster = cluster.then(|| options.cluster.unwrap_or_default());
            (kept, None, cluster)
        }
        Scoring::Graded => {
            let (lo, hi) = r
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                });
            if lo == hi {
                return Err(SemanticError::Degenerate {
                    query: query.to_string(),
                    detail: format!(
                        "all {n} Gaussians have the same relevancy {lo}: the query does not tell \
                         any Gaussian apart (are the features all equal?)"
                    ),
                });
            }
            // The k-th largest value: ties at the threshold are all kept.
            let k = ((options.top_fraction as f64 * n as f64).ceil() as usize).clamp(1, n);
            let mut sorted = r.clone();
            let (_, kth, _) = sorted.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
            let threshold = *kth;
            let kept: Vec<usize> = (0..n)
                .filter(|&i| r[i] >= threshold && r[i] > options.floor)
                .collect();
            if kept.is_empty() {
                return Err(nothing(format!(
                    "no Gaussian has relevancy above the floor {} (highest: {hi}); lower `floor` \
                     or check the query and the features",
                    options.floor
                )));
            }
            (kept, Some(threshold), options.cluster)
        }
    };

    let (selected, clusters, noise, eps) = match cluster {
        None => (candidates.clone(), vec![candidates.len()], 0, None),
        Some(c) => {
            let points: Vec<[f32; 3]> = candidates.iter().map(|&i| scene.means[i]).collect();
            if points.len() < c.min_points {
                return Err(nothing(format!(
                    "only {} Gaussians passed the thresholds, fewer than DBSCAN's min_points = \
                     {}: lower min_points, or raise top_fraction / lower floor",
                    points.len(),
                    c.min_points
                )));
            }
            let eps = dbscan_eps(&points, &c)?;
            let (groups, noise) = dbscan(&points, eps, c.min_points);
            if groups.is_empty() {
                return Err(nothing(format!(
                    "DBSCAN (eps {eps}, min_points {}) found no cluster among the {} candidate \
                     Gaussians: they are too scattered; raise the eps factor",
                    c.min_points,
                    points.len()
                )));
            }
            let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
            let kept_groups: Vec<&Vec<usize>> = match c.keep {
                KeepClusters::Largest => vec![&groups[0]],
                KeepClusters::AboveFraction(f) => {
                    let min = f as f64 * points.len() as f64;
                    let above: Vec<_> = groups.iter().filter(|g| g.len() as f64 >= min).collect();
                    if above.is_empty() {
                        // The largest cluster is always kept: an empty target helps no one.
                        vec![&groups[0]]
                    } else {
                        above
                    }
                }
            };
            let mut selected: Vec<usize> = kept_groups
                .into_iter()
                .flatten()
                .map(|&j| candidates[j])
                .collect();
            selected.sort_unstable();
            (selected, sizes, noise, Some(eps))
        }
    };

    let mut mask = vec![0.0f32; n];
    for &i in &selected {
        mask[i] = 1.0;
    }
    let axis = |k: usize| -> Vec<f32> {
        let mut v: Vec<f32> = selected.iter().map(|&i| scene.means[i][k]).collect();
        v.sort_by(f32::total_cmp);
        v
    };
    let mut centre = [0.0; 3];
    let mut extent = [0.0; 3];
    for k in 0..3 {
        let v = axis(k);
        centre[k] = quantile_sorted(&v, 0.5);
        extent[k] = quantile_sorted(&v, 0.95) - quantile_sorted(&v, 0.05);
    }
    let mut rel: Vec<f32> = selected.iter().map(|&i| r[i]).collect();
    rel.sort_by(f32::total_cmp);
    Ok(Target {
        query: query.to_string(),
        name: relevancy.name.clone(),
        count: selected.len(),
        mask,
        candidates: candidates.len(),
        centre,
        extent,
        clusters,
        noise,
        eps,
        percentile_threshold,
        relevancy_spread: Spread {
            min: rel[0],
            median: quantile_sorted(&rel, 0.5),
            max: rel[rel.len() - 1],
        },
    })
}

fn validate(o: &SelectionOptions) -> Result<()> {
    if !(o.top_fraction > 0.0 && o.top_fraction <= 1.0) {
        return Err(SemanticError::option(
            "top_fraction",
            format!(
                "{} must be in (0, 1] (0.02 keeps the top 2%)",
                o.top_fraction
            ),
        ));
    }
    if !(o.floor >= 0.0 && o.floor < 1.0) {
        return Err(SemanticError::option(
            "floor",
            format!("{} must be in [0, 1): relevancies lie in (0, 1)", o.floor),
        ));
    }
    if let Some(c) = &o.cluster {
        if c.min_points == 0 {
            return Err(SemanticError::option(
                "cluster.min_points",
                "must be at least 1",
            ));
        }
        match c.eps {
            EpsRule::Auto {
                neighbour,
                quantile,
                factor,
            } => {
                if neighbour == Some(0) {
                    return Err(SemanticError::option(
                        "cluster.eps.auto.neighbour",
                        "must be at least 1 (1 = nearest)",
                    ));
                }
                if !(0.0..=1.0).contains(&quantile) {
                    return Err(SemanticError::option(
                        "cluster.eps.auto.quantile",
                        format!("{quantile} must be in [0, 1]"),
                    ));
                }
                if !(factor.is_finite() && factor > 0.0) {
                    return Err(SemanticError::option(
                        "cluster.eps.auto.factor",
                        format!("{factor} must be finite and > 0"),
                    ));
                }
            }
            EpsRule::Fixed(e) => {
                if !(e.is_finite() && e > 0.0) {
                    return Err(SemanticError::option(
                        "cluster.eps.fixed",
                        format!("{e} must be finite and > 0"),
                    ));
                }
            }
        }
        if let KeepClusters::AboveFraction(f) = c.keep
            && !(0.0..=1.0).contains(&f)
        {
            return Err(SemanticError::option(
                "cluster.keep.above_fraction",
                format!("{f} must be in [0, 1]"),
            ));
        }
    }
    Ok(())
}

/// DBSCAN radius for `points` under `c.eps` (see the module docs).
pub fn dbscan_eps(points: &[[f32; 3]], c: &ClusterOptions) -> Result<f32> {
    let (neighbour, quantile, factor) = match c.eps {
        EpsRule::Fixed(e) => return Ok(e),
        EpsRule::Auto {
            neighbour,
            quantile,
            factor,
        } => (
            neighbour.unwrap_or(c.min_points.saturating_sub(1)).max(1),
            quantile,
            factor,
        ),
    };
    let mut d = kth_neighbour_distances(points, neighbour)?;
    d.sort_by(f32::total_cmp);
    let eps = factor * quantile_sorted(&d, quantile);
    // All candidates at one spot give eps = 0, with which no point would be anyone's
    // neighbour; a tiny radius keeps coincident points together instead.
    let scale = points
        .iter()
        .flat_map(|p| p.iter().map(|v| v.abs()))
        .fold(0.0f32, f32::max);
    Ok(eps.max(scale * 1e-6).max(1e-12))
}

/// Distance from each point to its `k`-th nearest other point (`k` ≥ 1), through a k-d tree.
/// With fewer than `k + 1` points the farthest other point is used.
pub fn kth_neighbour_distances(points: &[[f32; 3]], k: usize) -> Result<Vec<f32>> {
    if points.len() < 2 {
        return Ok(vec![0.0; points.len()]);
    }
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(points).map_err(|e| {
        SemanticError::Mismatch(format!("cannot build a k-d tree of the candidates: {e}"))
    })?;
    // The query point is in the tree at distance 0, hence k + 1 results.
    let want = (k + 1).min(points.len());
    let want = NonZeroUsize::new(want).expect("at least 2 points");
    Ok(points
        .iter()
        .map(|p| {
            let found = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(want)
                .execute();
            found.last().map_or(0.0, |r| r.distance.max(0.0).sqrt())
        })
        .collect())
}

/// DBSCAN clusters (indices into `points`, largest first, ties by smallest index) and the
/// number of noise points.
pub fn dbscan(points: &[[f32; 3]], eps: f32, min_points: usize) -> (Vec<Vec<usize>>, usize) {
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    let array = Array2::from_shape_vec((points.len(), 3), flat).expect("3 columns");
    let (clusters, noise): (HashMap<usize, Vec<usize>>, Vec<usize>) =
        Dbscan::new(eps, min_points, Euclidean::default()).fit(&array, None);
    let mut groups: Vec<Vec<usize>> = clusters
        .into_values()
        .map(|mut g| {
            g.sort_unstable();
            g
        })
        .collect();
    // HashMap order is random: sort for a deterministic "largest".
    groups.sort_by(|a, b| b.len().cmp(&a.len()).then(a[0].cmp(&b[0])));
    (groups, noise.len())
}

/// Nearest-rank quantile of sorted values (`q` in [0, 1]); 0 for an empty slice.
pub fn quantile_sorted(sorted: &[f32], q: f32) -> f32 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f32 * q).round() as usize]
}
