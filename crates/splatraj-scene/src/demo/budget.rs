//! How many Gaussians each part gets: a share for floor, walls and table by area (the table
//! denser), a fixed minimum per object plus a share by area, split exactly (Hamilton's method).

use super::FIRST_OBJECT_ID;
use super::objects::{OBJECTS, Part};

/// Share of the budget for floor, walls and table; the rest goes to the objects.
const STRUCTURE_SHARE: f64 = 0.62;
/// Share every object gets whatever its area, so small objects still render solid.
const OBJECT_MIN_SHARE: f64 = 0.018;
/// Density multipliers of the structural labels (per unit area): the table is seen up close.
const STRUCTURE_DENSITY: [f64; 3] = [1.0, 0.6, 3.0];

/// Number of Gaussians per part, summing exactly to `total`.
pub(super) fn allocate(parts: &[Part], total: usize) -> Vec<usize> {
    let labels = OBJECTS.len();
    let mut area = vec![0.0; labels];
    for p in parts {
        area[p.label as usize] += p.area * p.weight;
    }
    let objects = labels - FIRST_OBJECT_ID as usize;
    let object_area: f64 = area[FIRST_OBJECT_ID as usize..].iter().sum();
    let structure: f64 = (0..FIRST_OBJECT_ID as usize)
        .map(|l| area[l] * STRUCTURE_DENSITY[l])
        .sum();
    let area_share = 1.0 - STRUCTURE_SHARE - objects as f64 * OBJECT_MIN_SHARE;
    let label_weight: Vec<f64> = (0..labels)
        .map(|l| {
            if l < FIRST_OBJECT_ID as usize {
                STRUCTURE_SHARE * area[l] * STRUCTURE_DENSITY[l] / structure
            } else {
                OBJECT_MIN_SHARE + area_share * area[l] / object_area
            }
        })
        .collect();
    let label_counts = largest_remainder(&label_weight, total);
    let mut counts = vec![0; parts.len()];
    for (l, &label_count) in label_counts.iter().enumerate() {
        let idx: Vec<usize> = (0..parts.len())
            .filter(|&i| parts[i].label as usize == l)
            .collect();
        let w: Vec<f64> = idx
            .iter()
            .map(|&i| parts[i].area * parts[i].weight)
            .collect();
        for (&i, c) in idx.iter().zip(largest_remainder(&w, label_count)) {
            counts[i] = c;
        }
    }
    counts
}

/// Splits `total` in proportion to `weights` into integers that sum to `total` exactly
/// (Hamilton's method: floors, then the largest fractional parts get one more).
fn largest_remainder(weights: &[f64], total: usize) -> Vec<usize> {
    let sum: f64 = weights.iter().sum();
    let exact: Vec<f64> = weights.iter().map(|w| w / sum * total as f64).collect();
    let mut counts: Vec<usize> = exact.iter().map(|e| e.floor() as usize).collect();
    let given: usize = counts.iter().sum();
    let mut order: Vec<usize> = (0..weights.len()).collect();
    // Stable sort with an index tie-break keeps the split deterministic.
    order.sort_by(|&a, &b| {
        let (fa, fb) = (exact[a] - exact[a].floor(), exact[b] - exact[b].floor());
        fb.total_cmp(&fa).then(a.cmp(&b))
    });
    for &i in order.iter().take(total - given) {
        counts[i] += 1;
    }
    counts
}
