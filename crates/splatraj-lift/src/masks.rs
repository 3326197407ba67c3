//! 2D masks as a second input to the same lifting: per-Gaussian labels from label images.
//!
//! A user who segmented a few views or photos (SAM or any segmenter) gives each mask with its
//! camera; every pixel holds an object id, 0 where no object was segmented. Each id becomes a
//! one-hot channel, lifted like the features: a Gaussian's share of object c is
//! `Σ w·[mask = c] / Σ w` over every pixel of every mask, w its blending weight there (so a view
//! where it is hidden gives it no vote). A Gaussian takes the object with the largest share when
//! that share is at least [`MaskOptions::min_share`]; "no object" does not compete. Why not a
//! plain majority: a Gaussian of a thin or small object spreads much of its weight over the
//! pixels around the object (its footprint reaches 3σ). On fruit_drops a tenth of each
//! object's own Gaussians hold less than 0.09–0.37 of it, while 99.9 % of the other Gaussians
//! hold less than 0.03–0.12 of any object (more only where two objects touch); `tests/masks.rs`
//! prints these figures.
//!
//! Then one pass of neighbour consensus: a Gaussian left without an object (too weak a share,
//! or hidden in every view) takes the object that at least half of its
//! [`MaskOptions::neighbours`] nearest Gaussians (by centre) won by their own votes. Objects are
//! spatially compact, so this labels the faint and the hidden Gaussians inside an object
//! without reaching past its surface (there the neighbours are mostly unlabelled).

use std::collections::BTreeMap;

use rayon::prelude::*;
use splatraj_scene::Scene;
use splatraj_semantic::cluster::PointIndex;

use splatraj_render::lift::{LiftSums, lift_views};
use splatraj_render::render::{DeviceScene, Rasterizer};

use crate::MIN_WEIGHT;
use crate::error::{LiftError, Result};
use crate::progress::{LiftStage, Progress};
use crate::views::View;

/// Label channels lifted per pass: bounds the per-pixel buffer (`[H, W, channels]`).
const CHANNELS_PER_PASS: usize = 16;

/// One label image and the camera it was taken from.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskView {
    /// The camera; its intrinsics' size is the mask's size.
    pub view: View,
    /// Label id per pixel, row-major. `[H, W]`
    pub labels: Vec<i32>,
}

/// How votes become labels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaskOptions {
    /// The winning object's least share of a Gaussian's weight.
    pub min_share: f32,
    /// Nearest Gaussians asked by one left without an object (0: no consensus pass).
    pub neighbours: usize,
    /// Bytes the votes may take (12 per Gaussian and label); more labels than fit are
    /// refused before any work. `None`: no bound but [`MAX_LABELS`].
    pub max_bytes: Option<u64>,
}

/// The most labels masks may hold (a 16-bit grey mask's range): segmenters give tens to
/// hundreds of objects a view; far more means the images are not label masks (a photo, or a
/// depth map saved in colour, where every pixel is its own colour).
pub const MAX_LABELS: usize = 65_535;

/// Bytes per Gaussian and label while lifting: the votes (f64) and the shares (f32).
pub const BYTES_PER_GAUSSIAN_AND_LABEL: u64 = 12;

impl Default for MaskOptions {
    fn default() -> Self {
        MaskOptions {
            min_share: 0.15,
            neighbours: 8,
            max_bytes: None,
        }
    }
}

/// Per-Gaussian labels lifted from masks.
#[derive(Debug, Clone, PartialEq)]
pub struct LiftedLabels {
    /// Label id per Gaussian (0: unlabelled or never seen). `[N]`
    pub ids: Vec<i32>,
    /// The leading object's share of the Gaussian's weight (0 where unseen). `[N]`
    pub share: Vec<f32>,
    /// Σ w per Gaussian over all masks. `[N]`
    pub weights: Vec<f32>,
    /// The label ids the votes are for, ascending.
    pub labels: Vec<i32>,
    /// Each label's share of each Gaussian's weight. `[N, labels]`
    pub shares: Vec<f32>,
}

/// Refuses `labels` label channels (0 included) on `gaussians` Gaussians when there are more
/// than [`MAX_LABELS`] or their votes would take more than `max_bytes`.
pub fn check_label_count(labels: usize, gaussians: usize, max_bytes: Option<u64>) -> Result<()> {
    if labels > MAX_LABELS + 1 {
        return Err(LiftError::Scene(format!(
            "the masks hold {} labels (distinct ids or colours), more than the {MAX_LABELS} \
             label masks can: are they label images (not photos or depth maps)?",
            labels - 1
        )));
    }
    let bytes = labels as u64 * gaussians as u64 * BYTES_PER_GAUSSIAN_AND_LABEL;
    if let Some(limit) = max_bytes
        && bytes > limit
    {
        return Err(LiftError::Scene(format!(
            "the masks hold {} labels: lifting them onto {gaussians} Gaussians needs {:.1} GB \
             ({BYTES_PER_GAUSSIAN_AND_LABEL} bytes per Gaussian and label), above the memory \
             limit of {:.1} GB; merge labels, or give fewer masks",
            labels - 1,
            bytes as f64 / 1e9,
            limit as f64 / 1e9
        )));
    }
    Ok(())
}

/// Labels smaller than this many pixels (over all masks) are specks, not objects.
pub const MIN_LABEL_PIXELS: usize = 4;

/// How many speck labels ([`MIN_LABEL_PIXELS`]) masks may hold before they are judged not to be
/// label masks: a segmenter's stray specks are a few, a photo's or depth map's colours are
/// thousands, each on a pixel or two.
pub const MAX_SPECK_LABELS: usize = 256;

/// Refuses masks whose labels (0 excluded) are mostly specks: more than
/// [`MAX_SPECK_LABELS`] labels cover fewer than [`MIN_LABEL_PIXELS`] pixels each, and they are
/// the majority. Lifting each label is a render pass per mask, so such images would take
/// minutes and gigabytes to give nothing (two 128×96 images of distinct colours: 24 576 labels,
/// 28 s, 2.3 GB before this check).
pub fn check_label_areas(areas: &BTreeMap<i32, usize>) -> Result<()> {
    let labels = areas.iter().filter(|&(&id, _)| id != 0).count();
    let specks = areas
        .iter()
        .filter(|&(&id, &area)| id != 0 && area < MIN_LABEL_PIXELS)
        .count();
    if specks > MAX_SPECK_LABELS && 2 * specks > labels {
        return Err(LiftError::Scene(format!(
            "the masks hold {labels} labels, {specks} of them on fewer than {MIN_LABEL_PIXELS} \
             pixels each: label masks give each object a region, so these look like photos or \
             depth maps (every pixel its own colour), not label images"
        )));
    }
    Ok(())
}

/// Lifts `masks` onto `scene` (see the module docs).
pub fn lift_masks(
    scene: &Scene,
    device_scene: &DeviceScene,
    masks: &[MaskView],
    options: &MaskOptions,
    progress: &Progress,
) -> Result<LiftedLabels> {
    if masks.is_empty() {
        return Err(LiftError::Scene("no masks to lift".into()));
    }
    if scene.len() != device_scene.len() {
        return Err(LiftError::Scene(format!(
            "the scene has {} Gaussians but its uploaded copy {}",
            scene.len(),
            device_scene.len()
        )));
    }
    for (m, mask) in masks.iter().enumerate() {
        let expected = mask.view.intrinsics.width * mask.view.intrinsics.height;
        if mask.labels.len() != expected {
            return Err(LiftError::option(
                format!("masks[{m}]"),
                format!(
                    "{} labels for a {}×{} camera",
                    mask.labels.len(),
                    mask.view.intrinsics.width,
                    mask.view.intrinsics.height
                ),
            ));
        }
    }
    let mut areas: BTreeMap<i32, usize> = BTreeMap::new();
    for &id in masks.iter().flat_map(|m| m.labels.iter()) {
        *areas.entry(id).or_default() += 1;
    }
    let ids: Vec<i32> = areas.keys().copied().collect();
    let n = device_scene.len();
    check_label_count(ids.len(), n, options.max_bytes)?;
    check_label_areas(&areas)?;
    let mut votes = vec![0f64; n * ids.len()]; // [N, labels]
    let mut weights = vec![0f64; n];
    for (group_index, group) in ids.chunks(CHANNELS_PER_PASS).enumerate() {
        let mut sums = LiftSums::zeros(n, group.len());
        for (m, mask) in masks.iter().enumerate() {
            progress(
                LiftStage::Lift,
                group_index * masks.len() + m,
                masks.len() * ids.len().div_ceil(CHANNELS_PER_PASS),
            );
            let pixels: Vec<f32> = mask
                .labels
                .iter()
                .flat_map(|&id| group.iter().map(move |&c| f32::from(u8::from(c == id))))
                .collect();
            let view_sums = lift_views(
                device_scene,
                &[mask.view.pose],
                &mask.view.intrinsics,
                &pixels,
                group.len(),
                Rasterizer::Fused,
            )?;
            sums.add(&view_sums);
        }
        let offset = group_index * CHANNELS_PER_PASS;
        for i in 0..n {
            for (c, _) in group.iter().enumerate() {
                votes[i * ids.len() + offset + c] = sums.weighted[i * group.len() + c];
            }
        }
        weights.copy_from_slice(&sums.weights);
    }
    let mut labels = LiftedLabels {
        ids: vec![0; n],
        share: vec![0.0; n],
        weights: weights.iter().map(|&w| w as f32).collect(),
        labels: ids.clone(),
        shares: votes
            .chunks_exact(ids.len())
            .zip(&weights)
            .flat_map(|(row, &w)| {
                row.iter()
                    .map(move |&v| if w > 0.0 { (v / w) as f32 } else { 0.0 })
            })
            .collect(),
    };
    for i in 0..n {
        if (weights[i] as f32) < MIN_WEIGHT {
            continue;
        }
        let row = &votes[i * ids.len()..(i + 1) * ids.len()];
        let best = ids
            .iter()
            .zip(row)
            .filter(|(id, _)| **id != 0)
            .max_by(|a, b| a.1.total_cmp(b.1));
        if let Some((&id, &v)) = best {
            let share = (v / weights[i]) as f32;
            labels.share[i] = share;
            if share >= options.min_share {
                labels.ids[i] = id;
            }
        }
    }
    if options.neighbours > 0 {
        labels.ids = neighbour_consensus(&scene.means, &labels.ids, options.neighbours)?;
    }
    Ok(labels)
}

/// `ids` with each 0 replaced by the object that at least half of its `k` nearest neighbours
/// carry in `ids` (one pass: a filled label does not vote for others).
fn neighbour_consensus(means: &[[f32; 3]], ids: &[i32], k: usize) -> Result<Vec<i32>> {
    let index = PointIndex::new(means)?;
    Ok(ids
        .par_iter()
        .enumerate()
        .map(|(i, &id)| {
            if id != 0 {
                return id;
            }
            let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
            for (j, _) in index.nearest(&means[i], k + 1) {
                if j != i && ids[j] != 0 {
                    *counts.entry(ids[j]).or_insert(0) += 1;
                }
            }
            counts
                .into_iter()
                .max_by_key(|&(_, c)| c)
                .filter(|&(_, c)| 2 * c >= k)
                .map_or(0, |(id, _)| id)
        })
        .collect())
}

#[cfg(test)]
mod label_bounds {
    use super::*;

    #[test]
    fn masks_of_specks_are_refused_and_a_few_specks_pass() {
        // Every pixel of two 128×96 images its own colour: 24 576 labels of one pixel.
        let photo: BTreeMap<i32, usize> = (1..=24_576).map(|id| (id, 1)).collect();
        let e = check_label_areas(&photo).unwrap_err().to_string();
        assert!(e.contains("24576 labels") && e.contains("photos"), "{e}");
        // Forty objects of hundreds of pixels and 100 stray specks: a segmenter's output.
        let mut masks: BTreeMap<i32, usize> = (1..=40).map(|id| (id, 500)).collect();
        masks.extend((41..=140).map(|id| (id, 1)));
        masks.insert(0, 10_000);
        assert!(check_label_areas(&masks).is_ok());
        // At the bound: 256 specks alone pass (more than 256 are needed, and a majority).
        let edge: BTreeMap<i32, usize> = (1..=256).map(|id| (id, 1)).collect();
        assert!(check_label_areas(&edge).is_ok());
    }

    #[test]
    fn labels_beyond_a_label_mask_or_the_memory_limit_are_refused_before_work() {
        // Every pixel of two 400×300 masks its own colour: 240 000 labels.
        let e = check_label_count(240_001, 1000, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("240000 labels") && e.contains("65535"), "{e}");
        // 24 576 labels (two 128×96 masks) on 50 000 Gaussians: 14.7 GB of votes.
        let e = check_label_count(24_577, 50_000, Some(8_000_000_000))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("24576 labels") && e.contains("14.7 GB") && e.contains("8.0 GB"),
            "{e}"
        );
        // A real segmentation: 40 objects.
        assert!(check_label_count(41, 2_000_000, Some(8_000_000_000)).is_ok());
    }
}
