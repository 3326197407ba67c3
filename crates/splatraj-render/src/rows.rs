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
use crate::heaviest_first::map_heaviest_first;
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

/// A pass's rows laid out per pose by [`lay_out_rows`].
#[derive(Debug)]
pub struct LaidOutRows {
    /// Where each pose's rows sit.
    pub rows: PoseRows,
    /// Each row's Gaussian by scene index, each pose's in increasing order. `[R]`
    pub scene_of_row: Vec<u32>,
    /// The Gaussians some list of the pass reads (the union over its poses).
    pub used: GaussianBits,
}

/// Lays out a pass's rows per pose from its tile lists, whose entries are scene indices below
/// `n`: each pose gets one row per distinct Gaussian its lists read, in increasing scene index,
/// and each list entry is renumbered to its row within its pose (the row is
/// `rows.start(pose) + entry`).
///
/// One renumbering, scene index to row: the lists used to be renumbered to the pass's compact
/// set first and to rows second, two passes over a step's million entries (2.2 + 3.7 ms of one
/// thread a first-try guitar step, host work a GPU step waits on).
///
/// The lists are grouped by pose first when they are not already (a stable sort by pose: the
/// order of a pose's tiles is kept).
pub fn lay_out_rows(work: &mut [TileWork], batch: usize, n: usize) -> LaidOutRows {
    if !work.is_sorted_by_key(|list| list.batch) {
        work.sort_by_key(|list| list.batch);
    }
    // The poses with the most entries first; the results in pose order.
    let read: Vec<(usize, GaussianBits)> = map_heaviest_first(
        work.chunk_by_mut(|a, b| a.batch == b.batch).collect(),
        |lists| lists.iter().map(|l| l.gaussians.len()).sum(),
        |lists| (lists[0].batch, lay_out_pose(lists, n)),
    );
    let mut counts = vec![0; batch];
    for (pose, bits) in &read {
        counts[*pose] = bits.count();
    }
    // Each pose's part filled beside the others': on one thread this was a millisecond of a
    // first-try guitar step's 480 000 rows that a GPU step's host work waited on, whatever the
    // cores.
    let mut scene_of_row = vec![0u32; counts.iter().sum()];
    parts_mut(&mut scene_of_row, read.iter().map(|(_, bits)| bits.count()))
        .into_par_iter()
        .zip(&read)
        .for_each(|(part, (_, bits))| {
            for (row, g) in part.iter_mut().zip(bits.iter()) {
                *row = g as u32;
            }
        });
    let used = union_in_parallel(&read, n, 1, |used, (_, bits)| used.union_with(bits));
    LaidOutRows {
        rows: PoseRows::from_counts(counts),
        scene_of_row,
        used,
    }
}

/// The Gaussians one pose's `lists` read, the lists renumbered to their ranks among them.
///
/// Folded and renumbered in parallel over the lists: an output frame's one pose has thousands
/// of lists and every core, while a step's poses (tens of lists each) run beside each other.
fn lay_out_pose(lists: &mut [TileWork], n: usize) -> GaussianBits {
    let bits = union_in_parallel(lists, n, LISTS_PER_TASK, |bits, list| {
        for &g in &list.gaussians {
            bits.insert(g as usize);
        }
    });
    let ranks = bits.ranks();
    lists
        .par_iter_mut()
        .with_min_len(LISTS_PER_TASK)
        .for_each(|list| {
            for g in &mut list.gaussians {
                *g = ranks.rank(*g as usize);
            }
        });
    bits
}

/// Tile lists per rayon task where a pose's lists are read or renumbered.
const LISTS_PER_TASK: usize = 64;

/// The Gaussians `insert` puts in a set from each of `items` (scene indices below `n`), the
/// items shared among rayon tasks of at least `min_len` each and the tasks' sets joined.
fn union_in_parallel<T: Sync>(
    items: &[T],
    n: usize,
    min_len: usize,
    insert: impl Fn(&mut GaussianBits, &T) + Sync + Send,
) -> GaussianBits {
    items
        .par_iter()
        .with_min_len(min_len)
        .fold(
            || GaussianBits::new(n),
            |mut bits, item| {
                insert(&mut bits, item);
                bits
            },
        )
        .reduce_with(|mut a, b| {
            a.union_with(&b);
            a
        })
        .unwrap_or_else(|| GaussianBits::new(n))
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
    /// are its distinct Gaussians in increasing order, each entry names the row holding the
    /// Gaussian it named, and the pass uses the union.
    #[test]
    fn rows_hold_each_pose_s_own_gaussians_and_entries_point_at_them() {
        let original = vec![
            list(2, 0, &[7, 3]),
            list(0, 1, &[5, 1, 5]),
            list(2, 4, &[3, 9]),
            list(0, 0, &[1]),
        ];
        let mut work = original.clone();
        let laid = lay_out_rows(&mut work, 3, 10);
        let rows = &laid.rows;
        assert_eq!(rows.starts(), &[0, 2, 2, 5]);
        assert_eq!((rows.batch(), rows.total(), rows.largest()), (3, 5, 3));
        assert_eq!(laid.scene_of_row, vec![1, 5, 3, 7, 9]);
        assert_eq!(laid.used.iter().collect::<Vec<_>>(), vec![1, 3, 5, 7, 9]);
        // The stable grouping keeps each pose's tiles in their order.
        let tiles: Vec<(usize, usize)> = work.iter().map(|w| (w.batch, w.tile)).collect();
        assert_eq!(tiles, vec![(0, 1), (0, 0), (2, 0), (2, 4)]);
        assert_entries_name_their_rows(&original, &work, &laid);
    }

    /// Each entry of `renumbered` is a row of its pose holding the Gaussian the same entry of
    /// `original` named.
    fn assert_entries_name_their_rows(
        original: &[TileWork],
        renumbered: &[TileWork],
        laid: &LaidOutRows,
    ) {
        for list in renumbered {
            let before = original
                .iter()
                .find(|w| (w.batch, w.tile) == (list.batch, list.tile))
                .unwrap();
            assert_eq!(list.gaussians.len(), before.gaussians.len());
            for (&entry, &g) in list.gaussians.iter().zip(&before.gaussians) {
                assert!(entry < laid.rows.count(list.batch) as u32);
                assert_eq!(
                    laid.scene_of_row[laid.rows.start(list.batch) + entry as usize],
                    g
                );
            }
        }
    }

    /// One pose (an output frame's pass): rows are its Gaussians in increasing scene index,
    /// entries their ranks.
    #[test]
    fn one_pose_gets_a_row_for_each_gaussian_it_reads() {
        let original = vec![list(0, 0, &[7, 0]), list(0, 3, &[3, 7, 9])];
        let mut work = original.clone();
        let laid = lay_out_rows(&mut work, 1, 12);
        assert_eq!(laid.rows.starts(), &[0, 4]);
        assert_eq!(laid.scene_of_row, vec![0, 3, 7, 9]);
        assert_eq!(work, vec![list(0, 0, &[2, 0]), list(0, 3, &[1, 2, 3])]);
    }

    /// Poses with hundreds of lists (folded and renumbered in parallel tasks) and with a few,
    /// on one thread and on four: every pose's rows are the sorted distinct scene indices of
    /// its lists (found here by sorting), and the union is every index some list names.
    #[test]
    fn parallel_layout_matches_a_sort_of_each_pose_s_entries() {
        let n = 5000;
        let mut next = crate::test_random::uniform(0x5eed_f00d_u64);
        let mut original = Vec::new();
        for (batch, lists) in [(0, 300), (1, 3), (3, 150)] {
            for tile in 0..lists {
                let len = (next() * 40.0) as usize;
                // Pose 1 reads the top of the universe only, so that its rows and the union
                // differ from the other poses'.
                let low = if batch == 1 { n - 50 } else { 0 };
                let gaussians = (0..len)
                    .map(|_| (low as f64 + next() * (n - low) as f64) as u32)
                    .collect::<Vec<u32>>();
                original.push(list(batch, tile, &gaussians));
            }
        }
        // Out of pose order: pose 3's lists first.
        original.rotate_left(303);
        for threads in [1, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut work = original.clone();
            let laid = pool.install(|| lay_out_rows(&mut work, 4, n));
            let mut union = Vec::new();
            for pose in 0..4 {
                let mut read: Vec<u32> = original
                    .iter()
                    .filter(|w| w.batch == pose)
                    .flat_map(|w| w.gaussians.iter().copied())
                    .collect();
                read.sort_unstable();
                read.dedup();
                let start = laid.rows.start(pose);
                assert_eq!(
                    &laid.scene_of_row[start..start + laid.rows.count(pose)],
                    &read[..],
                    "pose {pose}, {threads} threads"
                );
                union.extend(read);
            }
            union.sort_unstable();
            union.dedup();
            let used: Vec<u32> = laid.used.iter().map(|g| g as u32).collect();
            assert_eq!(used, union, "{threads} threads");
            assert_entries_name_their_rows(&original, &work, &laid);
        }
    }

    #[test]
    fn dense_rows_are_pose_times_count_plus_index() {
        let rows = PoseRows::dense(3, 4);
        assert_eq!(rows.starts(), &[0, 4, 8, 12]);
        assert_eq!((rows.start(2), rows.count(1), rows.largest()), (8, 4, 4));
        assert_eq!(PoseRows::dense(0, 4).largest(), 0);
    }
}
