//! From per-Gaussian relevancy to the object's 0/1 channel: thresholds, density clustering,
//! statistics.
//!
//! Graded relevancy (the `features` route) keeps the Gaussians in the top `top_fraction` of
//! relevancy **and** above `floor` (the candidates), then clusters them by density in 3D and
//! keeps the cluster with the largest relevancy mass (sum of relevancy), or every cluster
//! above a share of the candidates' mass. Masks (labels, regions) skip the thresholds and are
//! clustered only when the source asks for it. The [`Target`] lists every cluster (kept or
//! runner-up, with its count, mass, centre and extent), the candidates dropped, and warnings.
//!
//! Clustering rules ([`EpsRule`]): by default a candidate's neighbourhood is its nearest
//! Gaussians of the whole scene ([`EpsRule::Scene`], see [`crate::cluster`] for the rule and
//! the figures that chose it), so the radius follows the scene's density and not the
//! candidates' spread. [`EpsRule::Auto`] is the rule before that: one DBSCAN radius
//! `factor × quantile` of the candidates' own distances to their (`min_points` − 1)-th
//! nearest candidate (Ester et al.'s "k-distance"); scattered look-alikes inflate it (1.84 m
//! on the 20 000-Gaussian scene of issue 16, where the object is 0.2 m across), which is why
//! it is no longer the default. [`EpsRule::Fixed`] is one radius in world units.
//!
//! The centre is the per-axis median of the kept Gaussians' means and the extent the span
//! between their 5% and 95% quantiles, so a few stray Gaussians move neither. A selection
//! whose extent is implausible for its count, because more than [`SPARSE_SHARE`] of its
//! Gaussians lie apart from the rest ([`isolated_share`]: far from other selected Gaussians
//! compared with the scene's density there), is scattered look-alikes rather than one object;
//! it gets a warning naming the query.

use serde::{Deserialize, Serialize};
use splatraj_scene::Scene;

use crate::cluster::{self, Clustering, PointIndex, kth_neighbour_distances};
use crate::error::{Result, SemanticError};
use crate::sources::{Relevancy, Scoring, TargetSource};

/// Default fraction of Gaussians kept by the relevancy percentile (top 2%).
pub const DEFAULT_TOP_FRACTION: f32 = 0.02;
/// Default absolute relevancy floor (0.5: no more like the query than like a negative).
pub const DEFAULT_FLOOR: f32 = 0.5;
/// Default DBSCAN minimum neighbourhood size (the point itself included).
pub const DEFAULT_MIN_POINTS: usize = 5;
/// Default nearest scene Gaussian whose distance sets a candidate's radius
/// ([`EpsRule::Scene`]).
pub const DEFAULT_SCENE_NEIGHBOURS: usize = 16;
/// Default multiplier of that distance ([`EpsRule::Scene`]).
pub const DEFAULT_SCENE_FACTOR: f32 = 2.0;
/// Default quantile of the k-distances that sets eps ([`EpsRule::Auto`]).
pub const DEFAULT_EPS_QUANTILE: f32 = 0.9;
/// Default multiplier of that quantile ([`EpsRule::Auto`]).
pub const DEFAULT_EPS_FACTOR: f32 = 2.0;
/// A selected Gaussian is isolated when its [`SPARSITY_NEIGHBOUR`]-th nearest selected
/// Gaussian is more than this many times farther than its [`SPARSITY_NEIGHBOUR`]-th nearest
/// Gaussian of the scene (the selection at least 27× sparser than the scene there).
pub const SPARSE_RATIO: f32 = 3.0;
/// Which neighbour the sparsity check compares (1 = nearest).
pub const SPARSITY_NEIGHBOUR: usize = 4;
/// A selection with more than this share of isolated Gaussians gets a warning.
pub const SPARSE_SHARE: f64 = 0.1;

/// How a candidate's neighbourhood is chosen for the density clustering.
///
/// In a config: `eps = { scene = {} }` (the default; `{ scene = { neighbours = 32, factor =
/// 1.5 } }`),
/// `eps = { fixed = 0.05 }` or `eps = { auto = { quantile = 0.5, factor = 3 } }` (missing
/// fields take their defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum EpsRule {
    /// One radius per candidate: `factor` × its distance to its `neighbours`-th nearest
    /// Gaussian of the whole scene, so it follows the scene's local density (see
    /// [`crate::cluster`]).
    Scene {
        /// Which nearest scene Gaussian sets the radius (the candidate itself counts as the
        /// 1st).
        #[serde(default = "default_scene_neighbours")]
        neighbours: usize,
        /// Multiplier of that distance (> 0).
        #[serde(default = "default_scene_factor")]
        factor: f32,
    },
    /// One radius for all: `factor × quantile_q` over the candidates of the distance to their
    /// `neighbour`-th nearest other candidate; `neighbour = None` means `min_points − 1`.
    /// Scattered look-alikes inflate it: the default before [`EpsRule::Scene`].
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
        EpsRule::Scene {
            neighbours: DEFAULT_SCENE_NEIGHBOURS,
            factor: DEFAULT_SCENE_FACTOR,
        }
    }
}

impl EpsRule {
    /// The rule that was the default before [`EpsRule::Scene`], with its defaults: its default parameters: one radius from the candidates' own
    /// k-distances.
    pub fn candidate_k_distance() -> Self {
        EpsRule::Auto {
            neighbour: None,
            quantile: DEFAULT_EPS_QUANTILE,
            factor: DEFAULT_EPS_FACTOR,
        }
    }
}

fn default_scene_neighbours() -> usize {
    DEFAULT_SCENE_NEIGHBOURS
}

fn default_scene_factor() -> f32 {
    DEFAULT_SCENE_FACTOR
}

fn default_eps_quantile() -> f32 {
    DEFAULT_EPS_QUANTILE
}

fn default_eps_factor() -> f32 {
    DEFAULT_EPS_FACTOR
}

/// Which clusters make the object.
///
/// In a config: `keep = "largest"` or `keep = { above_fraction = 0.1 }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum KeepClusters {
    /// Only the cluster with the largest relevancy mass (the object; other clusters are
    /// look-alikes).
    #[default]
    Largest,
    /// Every cluster holding at least this fraction of the candidates' relevancy mass (for
    /// objects made of separate parts); the largest is always kept.
    AboveFraction(f32),
}

/// Density clustering settings (config keys `min_points`, `eps`, `keep`; missing ones take
/// the defaults).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, rename_all = "snake_case", deny_unknown_fields)]
pub struct ClusterOptions {
    /// Candidates a core point's neighbourhood must hold, the point itself included.
    pub min_points: usize,
    /// Neighbourhood rule.
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
        self.validate_named(&|key| format!("{prefix}{key}"))
    }

    /// As [`SelectionOptions::validate`], with each key (`top_fraction`, ...) named in errors
    /// as `name` gives it (a command-line flag, `--top-fraction`).
    pub fn validate_named(&self, name: &dyn Fn(&str) -> String) -> Result<()> {
        validate(self).map_err(|e| match e {
            SemanticError::InvalidOption(e) => SemanticError::option(name(&e.key), e.reason),
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

/// One cluster of candidates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cluster {
    /// Gaussians in it.
    pub count: usize,
    /// Sum of their relevancies.
    pub relevancy_mass: f64,
    /// Per-axis median of their means.
    pub centre: [f32; 3],
    /// Per-axis span between the 5% and 95% quantiles of their means.
    pub extent: [f32; 3],
    /// Whether it is part of the target (else a runner-up).
    pub kept: bool,
}

/// How the candidates were clustered.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClusteringSummary {
    /// The rule, in words ("scene density (16 nearest Gaussians)", "candidate k-distance",
    /// "fixed radius").
    pub method: String,
    /// Candidates a core point's neighbourhood held at least.
    pub min_points: usize,
    /// The neighbourhood radius: the one radius of the global rules, the median of the
    /// candidates' radii under [`EpsRule::Scene`].
    pub eps: f32,
    /// Smallest and largest radius over the candidates (equal for the global rules).
    pub eps_range: [f32; 2],
}

/// The Gaussians of one object, ready for the trajectory costs, and how they were found.
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
    /// Gaussians that passed the thresholds, before clustering.
    pub candidates: usize,
    /// Robust centre: per-axis median of the selected centres.
    pub centre: [f32; 3],
    /// Robust extent: per-axis span between the 5% and 95% quantiles of the selected centres.
    pub extent: [f32; 3],
    /// Every cluster found, largest relevancy mass first (without clustering: one, of all
    /// candidates).
    pub clusters: Vec<Cluster>,
    /// Candidates in no cluster.
    pub noise: usize,
    /// Candidates left out of the target (runner-up clusters and noise), as sorted indices.
    #[serde(skip)]
    pub rejected: Vec<usize>,
    /// How the candidates were clustered; `None`: they were not.
    pub clustering: Option<ClusteringSummary>,
    /// Relevancy threshold the percentile set (graded scores only).
    pub percentile_threshold: Option<f32>,
    /// Relevancies of the selected Gaussians.
    pub relevancy_spread: Spread,
    /// Doubts about the selection, each naming the query (for the caller to show).
    pub warnings: Vec<String>,
    /// What the source said about how it matched (a selection file's matched share), for the
    /// caller to show.
    pub notes: Vec<String>,
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

    /// Sizes of the clusters, largest relevancy mass first.
    pub fn cluster_sizes(&self) -> Vec<usize> {
        self.clusters.iter().map(|c| c.count).collect()
    }

    /// The 0/1 channel of the rejected candidates.
    pub fn rejected_mask(&self) -> Vec<f32> {
        let mut mask = vec![0.0; self.mask.len()];
        for &i in &self.rejected {
            mask[i] = 1.0;
        }
        mask
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
                // A soft mask renders (as weights), but membership needs a value above 0.5:
                // say so, with the largest value found, rather than only "none".
                let largest = r.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                return Err(nothing(format!(
                    "{:?} contains none of the {n} Gaussians: a mask marks the object with \
                     values above 0.5 (1 = object, 0 = not), and its largest value is {largest}",
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

    // The scene's k-d tree serves the scene-density rule and the sparsity check.
    let scene_index = PointIndex::new(&scene.means)?;
    let (groups, noise, clustering) = match cluster {
        None => (vec![candidates.clone()], Vec::new(), None),
        Some(c) => {
            if candidates.len() < c.min_points {
                return Err(nothing(format!(
                    "only {} Gaussians passed the thresholds, fewer than the clustering's \
                     min_points = {}: lower min_points, or raise top_fraction / lower floor",
                    candidates.len(),
                    c.min_points
                )));
            }
            let (found, summary) = cluster_candidates(scene, &scene_index, &candidates, &c)?;
            let to_scene =
                |v: Vec<usize>| -> Vec<usize> { v.into_iter().map(|j| candidates[j]).collect() };
            let groups: Vec<Vec<usize>> = found.clusters.into_iter().map(to_scene).collect();
            if groups.is_empty() {
                return Err(nothing(format!(
                    "{} (min_points {}) found no cluster among the {} candidate Gaussians: they \
                     are too scattered for one object; check the query, or raise top_fraction so \
                     that more of the object passes",
                    summary.method,
                    c.min_points,
                    candidates.len()
                )));
            }
            (groups, to_scene(found.noise), Some(summary))
        }
    };

    let mass = |g: &[usize]| -> f64 { g.iter().map(|&i| r[i] as f64).sum() };
    let mut groups: Vec<(f64, Vec<usize>)> = groups.into_iter().map(|g| (mass(&g), g)).collect();
    // Largest mass first; ties by size, then by the smallest index, for a deterministic order.
    groups.sort_by(|a, b| {
        b.0.total_cmp(&a.0)
            .then(b.1.len().cmp(&a.1.len()))
            .then(a.1[0].cmp(&b.1[0]))
    });
    let keep_above = match cluster.map(|c| c.keep) {
        Some(KeepClusters::AboveFraction(f)) => f as f64 * mass(&candidates),
        _ => f64::INFINITY,
    };
    let kept: Vec<bool> = (0..groups.len())
        .map(|k| k == 0 || groups[k].0 >= keep_above)
        .collect();
    let clusters: Vec<Cluster> = groups
        .iter()
        .zip(&kept)
        .map(|((m, g), &kept)| {
            let (centre, extent) = robust_box(scene, g);
            Cluster {
                count: g.len(),
                relevancy_mass: *m,
                centre,
                extent,
                kept,
            }
        })
        .collect();
    let mut selected: Vec<usize> = groups
        .iter()
        .zip(&kept)
        .filter(|(_, k)| **k)
        .flat_map(|((_, g), _)| g.iter().copied())
        .collect();
    selected.sort_unstable();
    let mut rejected: Vec<usize> = groups
        .iter()
        .zip(&kept)
        .filter(|(_, k)| !**k)
        .flat_map(|((_, g), _)| g.iter().copied())
        .chain(noise.iter().copied())
        .collect();
    rejected.sort_unstable();

    let mut mask = vec![0.0f32; n];
    for &i in &selected {
        mask[i] = 1.0;
    }
    let (centre, extent) = robust_box(scene, &selected);
    let mut warnings = Vec::new();
    if let Some(share) = isolated_share(scene, &scene_index, &selected)?
        && share > SPARSE_SHARE
    {
        warnings.push(format!(
            "query {query:?}: the extent {:.3} × {:.3} × {:.3} is implausible for {} Gaussians: \
             {:.0}% of them lie apart from the rest (scattered look-alikes, not one object), so \
             the centre and the framing may miss the object; check the query, the relevancy \
             (top_fraction, floor) and the clustering (cluster)",
            extent[0],
            extent[1],
            extent[2],
            selected.len(),
            100.0 * share
        ));
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
        noise: noise.len(),
        rejected,
        clustering,
        percentile_threshold,
        relevancy_spread: Spread {
            min: rel[0],
            median: quantile_sorted(&rel, 0.5),
            max: rel[rel.len() - 1],
        },
        warnings,
        notes: relevancy.notes.clone(),
    })
}

/// Clusters the `candidates` (scene indices) under `c`'s rule; the clusters and noise are
/// positions in `candidates`.
fn cluster_candidates(
    scene: &Scene,
    scene_index: &PointIndex,
    candidates: &[usize],
    c: &ClusterOptions,
) -> Result<(Clustering, ClusteringSummary)> {
    let points: Vec<[f32; 3]> = candidates.iter().map(|&i| scene.means[i]).collect();
    match c.eps {
        EpsRule::Scene { neighbours, factor } => {
            let (found, mut radii) = cluster::scene_density_clusters(
                scene_index,
                &scene.means,
                candidates,
                neighbours,
                factor,
                c.min_points,
            )?;
            radii.sort_by(f32::total_cmp);
            let summary = ClusteringSummary {
                method: format!(
                    "scene density (radius {factor} × distance to the {neighbours}th nearest \
                     Gaussian)"
                ),
                min_points: c.min_points,
                eps: quantile_sorted(&radii, 0.5),
                eps_range: [radii[0], radii[radii.len() - 1]],
            };
            Ok((found, summary))
        }
        EpsRule::Auto { .. } | EpsRule::Fixed(_) => {
            let eps = dbscan_eps(&points, c)?;
            let method = match c.eps {
                EpsRule::Fixed(_) => "DBSCAN, fixed radius",
                _ => "DBSCAN, radius from the candidates' k-distances",
            };
            let summary = ClusteringSummary {
                method: method.to_string(),
                min_points: c.min_points,
                eps,
                eps_range: [eps, eps],
            };
            Ok((cluster::dbscan(&points, eps, c.min_points), summary))
        }
    }
}

/// Per-axis median and 5-95% span of the means of `indices`.
pub(crate) fn robust_box(scene: &Scene, indices: &[usize]) -> ([f32; 3], [f32; 3]) {
    let mut centre = [0.0; 3];
    let mut extent = [0.0; 3];
    for k in 0..3 {
        let mut v: Vec<f32> = indices.iter().map(|&i| scene.means[i][k]).collect();
        v.sort_by(f32::total_cmp);
        centre[k] = quantile_sorted(&v, 0.5);
        extent[k] = quantile_sorted(&v, 0.95) - quantile_sorted(&v, 0.05);
    }
    (centre, extent)
}

/// Share of the `selected` Gaussians that are isolated within the selection: whose distance
/// to their [`SPARSITY_NEIGHBOUR`]-th nearest selected Gaussian is more than [`SPARSE_RATIO`]
/// times their distance to their [`SPARSITY_NEIGHBOUR`]-th nearest Gaussian of the scene.
/// An object's Gaussians are as close to each other as the scene's are there (share near 0);
/// scattered look-alikes are far from each other among dense scene Gaussians. `None` when
/// too few are selected to tell.
pub fn isolated_share(
    scene: &Scene,
    scene_index: &PointIndex,
    selected: &[usize],
) -> Result<Option<f64>> {
    if selected.len() <= SPARSITY_NEIGHBOUR {
        return Ok(None);
    }
    let points: Vec<[f32; 3]> = selected.iter().map(|&i| scene.means[i]).collect();
    let own = kth_neighbour_distances(&points, SPARSITY_NEIGHBOUR)?;
    let isolated = points
        .iter()
        .zip(&own)
        .filter(|(p, d)| **d > SPARSE_RATIO * scene_index.kth_other_distance(p, SPARSITY_NEIGHBOUR))
        .count();
    Ok(Some(isolated as f64 / points.len() as f64))
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
            EpsRule::Scene { neighbours, factor } => {
                if neighbours < 2 {
                    return Err(SemanticError::option(
                        "cluster.eps.scene.neighbours",
                        format!(
                            "{neighbours} must be at least 2 (the 1st nearest Gaussian is the \
                             candidate itself)"
                        ),
                    ));
                }
                if !(factor.is_finite() && factor > 0.0) {
                    return Err(SemanticError::option(
                        "cluster.eps.scene.factor",
                        format!("{factor} must be finite and > 0"),
                    ));
                }
            }
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

/// The one DBSCAN radius for `points` under a global rule (`Auto`, `Fixed`; see the module
/// docs); an error under [`EpsRule::Scene`], whose radius differs per candidate.
pub fn dbscan_eps(points: &[[f32; 3]], c: &ClusterOptions) -> Result<f32> {
    let (neighbour, quantile, factor) = match c.eps {
        EpsRule::Fixed(e) => return Ok(e),
        EpsRule::Scene { .. } => {
            return Err(SemanticError::option(
                "cluster.eps",
                "the scene rule has one radius per candidate, not one for all",
            ));
        }
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

/// Nearest-rank quantile of sorted values (`q` in [0, 1]); 0 for an empty slice.
pub fn quantile_sorted(sorted: &[f32], q: f32) -> f32 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f32 * q).round() as usize]
}
