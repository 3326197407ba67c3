//! Where each (pose, Gaussian) of a render pass sits among the pass's rows: pose after pose,
//! each pose only the Gaussians its own tile lists read.
//!
//! **Why per pose.** A pass of several windows (a shared optimisation step, a start view's
//! batch) uses the union U of all its poses' Gaussians, but each pose reads only its own part
//! of it. Laid out as `[B, U]` (row b·U + u), every pose projected, stored and differentiated
//! every Gaussian of the union: on the first-try guitar's shared step 2.0 M rows where the
//! tile lists read 0.6 M (`bench step`'s `k rows`). Laid out per pose, the projection, the
//! channel values, the compositing's footprints and every gradient of them have exactly the
//! rows some list reads; the dense layout stays for callers that want every pose to project
//! every Gaussian ([`PoseRows::dense`]).

use rayon::prelude::*;

use crate::bitset::GaussianBits;
use crate::tiles::TileWork;

/// Rows of a pass, pose after pose: pose b owns rows `starts[b]..starts[b + 1]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PoseRows {
    /// First row of each pose, then the total. `[B + 1]`
    starts: Vec<usize>,
}

impl PoseRows {
    /// Pose b owns `counts[b]` rows.
    pub fn from_counts(counts: impl IntoIterator<Item = usize>) -> Self {
        let mut starts = vec![0];
        let mut total = 0;
        for count in counts {
            total += count;
            starts.push(total);
        }
        PoseRows { starts }
    }

    /// Every one of `batch` poses owns `per_pose` rows: row b·per_pose + u (the layout of a
    /// pass in which every pose projects every Gaussian).
    pub fn dense(batch: usize, per_pose: usize) -> Self {
        Self::from_counts(std::iter::repeat_n(per_pose, batch))
    }

    /// Poses.
    pub fn batch(&self) -> usize {
        self.starts.len() - 1
    }

    /// Rows of all poses.
    pub fn total(&self) -> usize {
        self.starts[self.batch()]
    }

    /// First row of `pose`.
    pub fn start(&self, pose: usize) -> usize {
        self.starts[pose]
    }

    /// Rows of `pose`.
    pub fn count(&self, pose: usize) -> usize {
        self.starts[pose + 1] - self.starts[pose]
    }

    /// The most rows one pose owns (0 for an empty batch).
    pub fn largest(&self) -> usize {
        (0..self.batch()).map(|b| self.count(b)).max().unwrap_or(0)
    }

    /// First row of each pose, then the total. `[B + 1]`
    pub fn starts(&self) -> &[usize] {
        &self.starts
    }
}

/// `values` cut into consecutive parts of `lengths` (which must not add up to more), so that
/// each pose's part can be filled on its own thread.
pub(crate) fn parts_mut<T>(
    values: &mut [T],
    lengths: impl IntoIterator<Item = usize>,
) -> Vec<&mut [T]> {
    let mut rest = values;
    lengths
        .into_iter()
        .map(|length| {
            let (part, after) = std::mem::take(&mut rest).split_at_mut(length);
            rest = after;
            part
        })
        .collect()
}

/// Lays out a pass's rows per pose from its tile lists, whose entries are compact Gaussian
/// indices u < `used`, every u read by some list (as a render numbers them): each pose gets
/// one row per distinct u its lists read, in increasing u,
/// and each list entry is renumbered to its row within its pose (the row is
/// `rows.start(pose) + entry`). Returns the layout and each row's u. `[R]`
///
/// The lists are grouped by pose first when they are not already (a stable sort by pose: the
/// order of a pose's tiles is kept).
pub fn lay_out_rows(work: &mut [TileWork], batch: usize, used: usize) -> (PoseRows, Vec<u32>) {
    if batch == 1 {
        // One pose reads every Gaussian of the pass (`used` counts what its lists read): its
        // rows are 0..used as they stand, and no entry changes (an output frame's pass).
        return (PoseRows::dense(1, used), (0..used as u32).collect());
    }
    if !work.is_sorted_by_key(|list| list.batch) {
        work.sort_by_key(|list| list.batch);
    }
    // Each pose's distinct u in increasing order, its lists renumbered, in parallel over poses.
    let mut read: Vec<(usize, Vec<u32>)> = work
        .chunk_by_mut(|a, b| a.batch == b.batch)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|lists| {
            let mut bits = GaussianBits::new(used);
            for list in lists.iter() {
                for &u in &list.gaussians {
                    bits.insert(u as usize);
                }
            }
            let ranks = bits.ranks();
            for list in lists.iter_mut() {
                for u in &mut list.gaussians {
                    *u = ranks.rank(*u as usize);
                }
            }
            (lists[0].batch, bits.iter().map(|u| u as u32).collect())
        })
        .collect();
    read.sort_by_key(|(pose, _)| *pose);
    let mut counts = vec![0; batch];
    for (pose, rows) in &read {
        counts[*pose] = rows.len();
    }
    let gaussians = read.into_iter().flat_map(|(_, rows)| rows).collect();
    (PoseRows::from_counts(counts), gaussians)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(batch: usize, tile: usize, gaussians: &[u32]) -> TileWork {
        TileWork {
            batch,
            tile,
            gaussians: gaussians.to_vec(),
        }
    }

    /// Three poses (the middle one reads nothing), lists out of pose order: each pose's rows
    /// are its distinct Gaussians in increasing order, and each entry names the row holding
    /// the Gaussian it named.
    #[test]
    fn rows_hold_each_pose_s_own_gaussians_and_entries_point_at_them() {
        let original = vec![
            list(2, 0, &[7, 3]),
            list(0, 1, &[5, 1, 5]),
            list(2, 4, &[3, 9]),
            list(0, 0, &[1]),
        ];
        let mut work = original.clone();
        let (rows, gaussians) = lay_out_rows(&mut work, 3, 10);
        assert_eq!(rows.starts(), &[0, 2, 2, 5]);
        assert_eq!((rows.batch(), rows.total(), rows.largest()), (3, 5, 3));
        assert_eq!(gaussians, vec![1, 5, 3, 7, 9]);
        // The stable grouping keeps each pose's tiles in their order.
        let tiles: Vec<(usize, usize)> = work.iter().map(|w| (w.batch, w.tile)).collect();
        assert_eq!(tiles, vec![(0, 1), (0, 0), (2, 0), (2, 4)]);
        for renumbered in &work {
            let before = original
                .iter()
                .find(|w| (w.batch, w.tile) == (renumbered.batch, renumbered.tile))
                .unwrap();
            for (&entry, &u) in renumbered.gaussians.iter().zip(&before.gaussians) {
                let row = rows.start(renumbered.batch) + entry as usize;
                assert!(entry < rows.count(renumbered.batch) as u32);
                assert_eq!(gaussians[row], u);
            }
        }
    }

    /// One pose reads every u: its rows are 0..used and its entries stay as they are.
    #[test]
    fn one_pose_keeps_its_compact_numbering() {
        let original = vec![list(0, 0, &[2, 0]), list(0, 3, &[1, 2, 3])];
        let mut work = original.clone();
        let (rows, gaussians) = lay_out_rows(&mut work, 1, 4);
        assert_eq!(rows.starts(), &[0, 4]);
        assert_eq!(gaussians, vec![0, 1, 2, 3]);
        assert_eq!(work, original);
    }

    #[test]
    fn dense_rows_are_pose_times_count_plus_index() {
        let rows = PoseRows::dense(3, 4);
        assert_eq!(rows.starts(), &[0, 4, 8, 12]);
        assert_eq!((rows.start(2), rows.count(1), rows.largest()), (8, 4, 4));
        assert_eq!(PoseRows::dense(0, 4).largest(), 0);
    }
}
