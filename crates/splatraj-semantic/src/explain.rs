//! Why a graded query found, or did not find, an object: the relevancy over all Gaussians,
//! the thresholds the selection applied, and where the most relevant Gaussians lie.
//!
//! A free-text query that selects nothing (or the wrong thing) leaves a user guessing: the
//! phrase may match nothing in the scene's language field, or match weakly everywhere, or
//! match two places. [`explain`] answers from the source's [`Relevancy`], before any
//! selection: quantiles of the relevancy over every Gaussian, how many Gaussians pass the
//! floor and the percentile, and the most relevant Gaussians grouped in space (each group's
//! size, centre, extent and relevancy), so the user sees whether the object is there but
//! below the floor, or elsewhere than expected.

use serde::Serialize;
use splatraj_scene::Scene;

use crate::cluster::{PointIndex, scene_density_clusters};
use crate::error::Result;
use crate::selection::{
    DEFAULT_SCENE_FACTOR, DEFAULT_SCENE_NEIGHBOURS, SelectionOptions, quantile_sorted, robust_box,
};
use crate::sources::{Relevancy, Scoring};

/// Fewest and most of the top Gaussians grouped into [`Explanation::top`].
const TOP_GAUSSIANS: (usize, usize) = (100, 2000);
/// Groups listed in [`Explanation::top`].
pub const LISTED_GROUPS: usize = 5;

/// Quantiles of the relevancy over all Gaussians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quantiles {
    /// Smallest.
    pub min: f32,
    /// Median.
    pub p50: f32,
    /// 90th percentile.
    pub p90: f32,
    /// 99th percentile.
    pub p99: f32,
    /// Largest.
    pub max: f32,
}

/// A group of the most relevant Gaussians that lie together.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MatchGroup {
    /// Gaussians in it.
    pub count: usize,
    /// Per-axis median of their means.
    pub centre: [f32; 3],
    /// Per-axis span between the 5% and 95% quantiles of their means.
    pub extent: [f32; 3],
    /// Their mean relevancy.
    pub mean_relevancy: f32,
    /// Their largest relevancy.
    pub max_relevancy: f32,
}

/// What [`explain`] found for one graded query.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Explanation {
    /// The query.
    pub query: String,
    /// Relevancy over all Gaussians.
    pub quantiles: Quantiles,
    /// The floor a Gaussian's relevancy must exceed (`selection.floor`).
    pub floor: f32,
    /// The relevancy at the `top_fraction` percentile (a candidate needs at least this).
    pub percentile_threshold: f32,
    /// The fraction of Gaussians the percentile keeps (`selection.top_fraction`).
    pub top_fraction: f32,
    /// Gaussians above the floor.
    pub above_floor: usize,
    /// Gaussians above the floor and at or above the percentile threshold (the candidates
    /// the clustering gets).
    pub candidates: usize,
    /// How many of the most relevant Gaussians were grouped.
    pub top_considered: usize,
    /// The largest groups (by relevancy mass) of the most relevant Gaussians, at most
    /// [`LISTED_GROUPS`], most relevant mass first.
    pub top: Vec<MatchGroup>,
    /// Groups found among the most relevant Gaussians (listed or not).
    pub groups: usize,
}

/// The explanation of `relevancy` (for `query` on `scene`) under `options`; `None` for a
/// source whose values are a mask (labels, regions, instance ids), which needs none.
pub fn explain(
    scene: &Scene,
    query: &str,
    relevancy: &Relevancy,
    options: &SelectionOptions,
) -> Result<Option<Explanation>> {
    let r = &relevancy.values;
    let n = r.len();
    if relevancy.scoring != Scoring::Graded || n == 0 || n != scene.len() {
        return Ok(None);
    }
    let mut sorted = r.clone();
    sorted.sort_by(f32::total_cmp);
    let q = |p: f32| quantile_sorted(&sorted, p);
    let k = ((options.top_fraction as f64 * n as f64).ceil() as usize).clamp(1, n);
    let percentile_threshold = sorted[n - k];
    let above_floor = r.iter().filter(|&&v| v > options.floor).count();
    let candidates = r
        .iter()
        .filter(|&&v| v > options.floor && v >= percentile_threshold)
        .count();

    // The most relevant Gaussians, grouped by the scene-density rule of the selection with
    // every Gaussian a core point (so that nothing is noise: a lone match is a group of one).
    let considered = k.clamp(TOP_GAUSSIANS.0, TOP_GAUSSIANS.1).min(n);
    let mut order: Vec<usize> = (0..n).collect();
    order.select_nth_unstable_by(considered - 1, |&a, &b| r[b].total_cmp(&r[a]));
    order.truncate(considered);
    let index = PointIndex::new(&scene.means)?;
    let (found, _) = scene_density_clusters(
        &index,
        &scene.means,
        &order,
        DEFAULT_SCENE_NEIGHBOURS.min(n),
        DEFAULT_SCENE_FACTOR,
        1,
    )?;
    let mut groups: Vec<(f64, MatchGroup)> = found
        .clusters
        .iter()
        .map(|members| {
            let indices: Vec<usize> = members.iter().map(|&m| order[m]).collect();
            let mass: f64 = indices.iter().map(|&i| f64::from(r[i])).sum();
            let (centre, extent) = robust_box(scene, &indices);
            let group = MatchGroup {
                count: indices.len(),
                centre,
                extent,
                mean_relevancy: (mass / indices.len() as f64) as f32,
                max_relevancy: indices.iter().map(|&i| r[i]).fold(f32::MIN, f32::max),
            };
            (mass, group)
        })
        .collect();
    groups.sort_by(|a, b| {
        b.0.total_cmp(&a.0)
            .then(b.1.max_relevancy.total_cmp(&a.1.max_relevancy))
    });
    let total = groups.len();
    Ok(Some(Explanation {
        query: query.to_string(),
        quantiles: Quantiles {
            min: sorted[0],
            p50: q(0.5),
            p90: q(0.9),
            p99: q(0.99),
            max: sorted[n - 1],
        },
        floor: options.floor,
        percentile_threshold,
        top_fraction: options.top_fraction,
        above_floor,
        candidates,
        top_considered: considered,
        top: groups
            .into_iter()
            .take(LISTED_GROUPS)
            .map(|(_, g)| g)
            .collect(),
        groups: total,
    }))
}

fn fmt3(v: [f32; 3]) -> String {
    format!("({:.3}, {:.3}, {:.3})", v[0], v[1], v[2])
}

impl Explanation {
    /// The explanation in lines of text, for a terminal.
    pub fn text(&self) -> String {
        let q = &self.quantiles;
        let mut s = format!(
            "relevancy of {:?} over all Gaussians: min {:.4}, p50 {:.4}, p90 {:.4}, p99 {:.4}, \
             max {:.4}\n",
            self.query, q.min, q.p50, q.p90, q.p99, q.max
        );
        s.push_str(&format!(
            "thresholds: floor {:.4} ({} Gaussians above), top {} percentile {:.4}; {} \
             candidates pass both\n",
            self.floor,
            self.above_floor,
            percent(self.top_fraction),
            self.percentile_threshold,
            self.candidates
        ));
        if self.above_floor == 0 {
            s.push_str(&format!(
                "no Gaussian is more like {:?} than like the canonical negatives by the floor's \
                 margin: the phrase is not in this language field, or the floor {} is too high\n",
                self.query, self.floor
            ));
        }
        s.push_str(&format!(
            "most relevant {} Gaussians, in {} group(s) in space{}:\n",
            self.top_considered,
            self.groups,
            if self.groups > self.top.len() {
                format!(", the {} largest", self.top.len())
            } else {
                String::new()
            }
        ));
        for g in &self.top {
            s.push_str(&format!(
                "  {} Gaussians, relevancy mean {:.4} max {:.4}, centre {}, extent {}\n",
                g.count,
                g.mean_relevancy,
                g.max_relevancy,
                fmt3(g.centre),
                fmt3(g.extent)
            ));
        }
        s
    }
}

fn percent(fraction: f32) -> String {
    format!("{}%", (f64::from(fraction) * 1e4).round() / 100.0)
}
