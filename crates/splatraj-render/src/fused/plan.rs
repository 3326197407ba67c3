//! The integer side of a fused compositing pass: which rows each (pose, tile) composites.

use rayon::prelude::*;

use crate::rasterize::{AlphaChannel, MIN_TRANSMITTANCE};
use crate::rows::{PoseRows, parts_mut};
use crate::tiles::{TILE_SIZE, TileGrid, TileWork};

/// The longest segment when nothing else is asked: ~20× shorter than a guitar step's longest
/// list, and long enough that a segment's fixed costs (the replay's maximum over the tile,
/// the colour behind it, its saved state) stay small beside its entries.
pub const DEFAULT_SEGMENT_ENTRIES: usize = 1024;

/// Environment variable that sets the longest segment (0: lists are never cut), for measuring
/// on a GPU (`scripts/gpu_check.sh`), not for runs.
pub const SEGMENT_ENTRIES_VARIABLE: &str = "SPLATRAJ_SEGMENT_ENTRIES";

static ASKED_SEGMENT_ENTRIES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();

/// The longest segment a plan asks for: [`SEGMENT_ENTRIES_VARIABLE`] where set to a number,
/// else [`DEFAULT_SEGMENT_ENTRIES`].
pub fn asked_segment_entries() -> usize {
    *ASKED_SEGMENT_ENTRIES.get_or_init(|| match std::env::var(SEGMENT_ENTRIES_VARIABLE) {
        Err(_) => DEFAULT_SEGMENT_ENTRIES,
        Ok(text) => text.trim().parse().unwrap_or_else(|_| {
            tracing::warn!(
                "{SEGMENT_ENTRIES_VARIABLE}={text:?} is not a number of entries; segments \
                 stay at {DEFAULT_SEGMENT_ENTRIES}"
            );
            DEFAULT_SEGMENT_ENTRIES
        }),
    })
}

/// Tile lists of a batch, flattened: work tile `w` composites rows
/// `rows[starts[w]..starts[w + 1]]` front to back.
#[derive(Debug, Clone, PartialEq)]
pub struct CompositePlan {
    /// The image tiling.
    pub grid: TileGrid,
    /// Which input rows each pose owns (and so the poses in the batch).
    pub pose_rows: PoseRows,
    /// Pose of each work tile. `[work]`
    pub batches: Vec<usize>,
    /// Tile index (row-major) of each work tile. `[work]`
    pub tiles: Vec<usize>,
    /// Offsets into `rows`. `[work + 1]`
    pub starts: Vec<usize>,
    /// Input rows, list after list. `[pairs]`
    pub rows: Vec<u32>,
    /// A pixel stops before T would fall below this (the exact rule: [`MIN_TRANSMITTANCE`]).
    pub stop_transmittance: f64,
    /// Whether the output holds alpha after the channels (`[B, H, W, C + 1]`) or the channels
    /// alone (`[B, H, W, C]`, whose backward takes alpha's gradient as zero).
    pub alpha: AlphaChannel,
    /// The longest run of a list one GPU workgroup composites: longer lists are cut into
    /// segments composited in parallel ([`super::segments`]; 0: never cut). The host kernels
    /// take whole lists.
    pub segment_entries: usize,
}

impl CompositePlan {
    /// Flattens `work`, whose entries are each pose's own rows, into input rows
    /// `rows.start(pose) + entry` (every list keeps to its pose's rows).
    pub fn new(work: &[TileWork], rows: &PoseRows, grid: TileGrid) -> Self {
        let starts: Vec<usize> = std::iter::once(0)
            .chain(work.iter().scan(0, |end, w| {
                *end += w.gaussians.len();
                Some(*end)
            }))
            .collect();
        // Each list's part filled beside the others': one thread over a first-try guitar
        // step's million entries was a third of a millisecond that a GPU step waited on.
        let mut flat = vec![0u32; starts[work.len()]];
        parts_mut(&mut flat, work.iter().map(|w| w.gaussians.len()))
            .into_par_iter()
            .zip(work)
            .for_each(|(part, w)| {
                let base = rows.start(w.batch) as u32;
                for (entry, &g) in part.iter_mut().zip(&w.gaussians) {
                    *entry = base + g;
                }
            });
        CompositePlan {
            grid,
            pose_rows: rows.clone(),
            batches: work.iter().map(|w| w.batch).collect(),
            tiles: work.iter().map(|w| w.tile).collect(),
            starts,
            rows: flat,
            stop_transmittance: MIN_TRANSMITTANCE,
            alpha: AlphaChannel::Returned,
            segment_entries: asked_segment_entries(),
        }
    }

    /// The same plan with another stopping transmittance (an approximation when larger).
    pub fn with_stop_transmittance(self, stop_transmittance: f64) -> Self {
        CompositePlan {
            stop_transmittance,
            ..self
        }
    }

    /// The same plan with alpha returned or dropped.
    pub fn with_alpha(self, alpha: AlphaChannel) -> Self {
        CompositePlan { alpha, ..self }
    }

    /// Values per pixel of the output for `channels` channel values.
    pub fn image_width(&self, channels: usize) -> usize {
        self.alpha.image_width(channels)
    }

    /// The same plan with another longest segment for the GPU kernels (0: lists stay whole).
    pub fn with_segment_entries(self, segment_entries: usize) -> Self {
        CompositePlan {
            segment_entries,
            ..self
        }
    }

    /// Poses in the batch.
    pub fn batch(&self) -> usize {
        self.pose_rows.batch()
    }

    /// The rows work tile `w` composites, front to back.
    pub fn list(&self, w: usize) -> &[u32] {
        &self.rows[self.starts[w]..self.starts[w + 1]]
    }

    /// Each row's slots (positions in `rows`, the lists' entries), grouped by row in
    /// increasing slot order: `(order, starts)`, row r's slots being
    /// `order[starts[r]..starts[r + 1]]`. The GPU backward sums each row's gradient over its
    /// slots in this fixed order (the same sums every run, no atomics).
    ///
    /// Each pose's lists name only its own rows, so the poses fill their own parts in
    /// parallel: on a GPU host this waits before the backward launches, and one thread over a
    /// first-try guitar step's million entries took 2.5–6.5 ms.
    pub fn slots_by_row(&self) -> (Vec<i32>, Vec<i32>) {
        let poses = self.batch();
        let mut items: Vec<Vec<usize>> = vec![Vec::new(); poses];
        for (w, &b) in self.batches.iter().enumerate() {
            items[b].push(w);
        }
        let total_rows = self.pose_rows.total();
        let mut order = vec![0i32; self.rows.len()];
        let mut starts = vec![0i32; total_rows + 1];
        starts[total_rows] = self.rows.len() as i32;
        // Pose after pose: its slots' part of `order` and its rows' part of `starts`.
        let slots: Vec<usize> = items
            .iter()
            .map(|pose_items| pose_items.iter().map(|&w| self.list(w).len()).sum())
            .collect();
        let first_slots = slots.iter().scan(0, |next, &count| {
            let first = *next;
            *next += count;
            Some(first)
        });
        let row_counts = (0..poses).map(|b| self.pose_rows.count(b));
        let order_parts = parts_mut(&mut order, slots.iter().copied());
        let starts_parts = parts_mut(&mut starts[..total_rows], row_counts);
        let parts: Vec<_> = first_slots.zip(order_parts).zip(starts_parts).collect();
        parts.into_par_iter().enumerate().for_each(
            |(b, ((first_slot, pose_order), pose_starts))| {
                let first_row = self.pose_rows.start(b);
                // Slots of each row, then where each row's slots begin.
                let mut next = vec![0usize; pose_starts.len()];
                for &w in &items[b] {
                    for &r in self.list(w) {
                        next[r as usize - first_row] += 1;
                    }
                }
                let mut at = 0;
                for (start, next) in pose_starts.iter_mut().zip(&mut next) {
                    *start = (first_slot + at) as i32;
                    let count = *next;
                    *next = at;
                    at += count;
                }
                for &w in &items[b] {
                    for (k, &r) in self.list(w).iter().enumerate() {
                        let next = &mut next[r as usize - first_row];
                        pose_order[*next] = (self.starts[w] + k) as i32;
                        *next += 1;
                    }
                }
            },
        );
        (order, starts)
    }

    /// Pixel coordinates of the top-left corner of `tile`.
    pub fn tile_origin(&self, tile: usize) -> (usize, usize) {
        (
            (tile % self.grid.tiles_x) * TILE_SIZE,
            (tile / self.grid.tiles_x) * TILE_SIZE,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`CompositePlan::slots_by_row`] the plain way: one counting sort over all slots.
    fn slots_by_row_in_one_loop(plan: &CompositePlan) -> (Vec<i32>, Vec<i32>) {
        let rows = plan.pose_rows.total();
        let mut starts = vec![0i32; rows + 1];
        for &r in &plan.rows {
            starts[r as usize + 1] += 1;
        }
        for r in 0..rows {
            starts[r + 1] += starts[r];
        }
        let mut next = starts.clone();
        let mut order = vec![0i32; plan.rows.len()];
        for (slot, &r) in plan.rows.iter().enumerate() {
            order[next[r as usize] as usize] = slot as i32;
            next[r as usize] += 1;
        }
        (order, starts)
    }

    #[test]
    fn slots_are_grouped_by_row_in_plan_order() {
        let grid = TileGrid::new(32, 16);
        let work = [
            TileWork {
                batch: 0,
                tile: 0,
                gaussians: vec![2, 0],
            },
            TileWork {
                batch: 0,
                tile: 1,
                gaussians: vec![0, 1, 2],
            },
        ];
        let plan = CompositePlan::new(&work, &PoseRows::dense(1, 3), grid);
        // Slots: 0→row 2, 1→row 0, 2→row 0, 3→row 1, 4→row 2.
        assert_eq!(plan.slots_by_row(), (vec![1, 2, 3, 0, 4], vec![0, 2, 3, 5]));
    }

    #[test]
    fn poses_filled_apart_give_the_slots_of_one_loop() {
        // Uneven poses (one with no rows, one with rows no list reads), lists out of pose
        // order, the same tile twice for different poses.
        let grid = TileGrid::new(64, 32);
        let rows = PoseRows::from_counts([3, 0, 5, 2]);
        let mut random = crate::test_random::uniform(11);
        let mut below = |n: usize| ((random() * n as f64) as usize).min(n - 1);
        let mut work = Vec::new();
        for (batch, tile) in [(2, 0), (0, 1), (3, 4), (2, 5), (0, 0), (2, 7), (3, 1)] {
            let count = rows.count(batch);
            let length = 1 + below(7);
            let gaussians = (0..length).map(|_| below(count) as u32).collect();
            work.push(TileWork {
                batch,
                tile,
                gaussians,
            });
        }
        let plan = CompositePlan::new(&work, &rows, grid);
        assert_eq!(plan.slots_by_row(), slots_by_row_in_one_loop(&plan));
        // Every slot once.
        let (mut order, starts) = plan.slots_by_row();
        assert_eq!(*starts.last().unwrap() as usize, plan.rows.len());
        order.sort();
        assert_eq!(order, (0..plan.rows.len() as i32).collect::<Vec<_>>());
    }
}
