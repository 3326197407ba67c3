//! Long tile lists cut into segments, so that no GPU workgroup walks a whole long list alone.
//!
//! One workgroup composites one work tile, entry after entry. A first-try guitar step
//! composites 320 work tiles whose lists run from a median of 1 364 entries to 20 137, so on a
//! GPU of ~130 multiprocessors both compositing kernels last as long as the longest tile's
//! serial chain (in the backward a barrier and two levels of sums an entry), while most of the
//! device idles. Cut into segments of at most [`CompositePlan::segment_entries`] entries, each
//! its own workgroup, the chain is one segment long.
//!
//! Only the backward is cut. It costs about nine times the forward per entry (lavapipe, and
//! the H200's first measurement: forward 0.1–0.9 ms, backward 0.1–10 ms), and it is what a
//! segment can do alone: replaying a segment back to front needs only the transmittance at its
//! end, its last contributor, the pixel's final transmittance and the colour the later
//! segments put behind it. The forward still composites each list whole, front to back (a
//! pixel's stop depends on everything before it), and saves those per segment on its way:
//! segments are whole 256-entry stages of the forward, so a segment ends between two stages.
//! The host kernels take whole lists and do not use segments.

use super::ForwardUse;
use super::plan::CompositePlan;
use crate::tiles::TILE_PIXELS;

/// The longest segment that leaves every list whole.
pub const WHOLE_LISTS: usize = 0;

/// Entries the forward kernel stages at once, one a unit of its workgroup (a unit a tile
/// pixel): segments are whole stages.
pub const STAGE_ENTRIES: usize = TILE_PIXELS;

/// A plan's work tiles cut into segments, in the layout the GPU kernels read.
#[derive(Debug, Clone, PartialEq)]
pub struct Segments {
    /// Per segment: pose, tile corner x, tile corner y, its tile's first segment, its tile's
    /// segment count. `[segments, 5]`
    pub work: Vec<i32>,
    /// Offsets into the plan's `rows`: segment `s` composites `rows[starts[s]..starts[s + 1]]`.
    /// The segments of a tile follow each other, so these are the plan's own offsets with
    /// more cuts. `[segments + 1]`
    pub starts: Vec<i32>,
    /// Whether any tile was cut (else each segment is a whole work tile).
    pub cut: bool,
    /// Entries of every segment but a tile's last (which holds the rest): whole stages, and
    /// where nothing is cut at least the longest list. Never 0.
    pub entries: usize,
}

/// Columns of [`Segments::work`].
pub const SEGMENT_COLUMNS: usize = 5;

impl Segments {
    /// Cuts each list of `plan` into segments of `segment_entries` rounded up to whole
    /// stages, the last holding the rest ([`WHOLE_LISTS`]: lists stay whole).
    pub fn of(plan: &CompositePlan, segment_entries: usize) -> Self {
        let longest_list = (0..plan.tiles.len())
            .map(|w| plan.starts[w + 1] - plan.starts[w])
            .max()
            .unwrap_or(0);
        // Never longer than the longest list: a segment as long cuts nothing, and the kernels
        // take the length as a u32.
        let asked = match segment_entries {
            WHOLE_LISTS => longest_list,
            asked => asked.min(longest_list),
        };
        let entries = asked.max(1).next_multiple_of(STAGE_ENTRIES);
        let mut work = Vec::with_capacity(SEGMENT_COLUMNS * plan.tiles.len());
        let mut starts = vec![0i32];
        let mut cut = false;
        for w in 0..plan.tiles.len() {
            let (from, to) = (plan.starts[w], plan.starts[w + 1]);
            let count = (to - from).div_ceil(entries).max(1);
            cut |= count > 1;
            let (x0, y0) = plan.tile_origin(plan.tiles[w]);
            let first = (starts.len() - 1) as i32;
            for s in 1..=count {
                work.extend([
                    plan.batches[w] as i32,
                    x0 as i32,
                    y0 as i32,
                    first,
                    count as i32,
                ]);
                starts.push((from + entries * s).min(to) as i32);
            }
        }
        Segments {
            work,
            starts,
            cut,
            entries,
        }
    }

    /// The segments a compositing forward of `plan` works in: cut only where a backward
    /// follows (it alone gains; a forward alone would only save more).
    pub fn for_forward(plan: &CompositePlan, used: ForwardUse) -> Self {
        match used {
            ForwardUse::ForBackward => Segments::of(plan, plan.segment_entries),
            ForwardUse::ImageOnly => Segments::of(plan, WHOLE_LISTS),
        }
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.starts.len() - 1
    }

    /// Whether there are none (a plan without work tiles).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rows::PoseRows;
    use crate::tiles::{TileGrid, TileWork};

    fn plan(lengths: &[usize], segment_entries: usize) -> CompositePlan {
        let grid = TileGrid::new(64, 16);
        let work: Vec<TileWork> = lengths
            .iter()
            .enumerate()
            .map(|(tile, &n)| TileWork {
                batch: tile % 2,
                tile,
                gaussians: (0..n as u32).collect(),
            })
            .collect();
        let most = lengths.iter().copied().max().unwrap_or(0);
        CompositePlan::new(&work, &PoseRows::dense(2, most), grid)
            .with_segment_entries(segment_entries)
    }

    #[test]
    fn long_lists_are_cut_into_whole_stages_in_order() {
        // 300 entries a segment, rounded up to two stages: 512.
        let plan = plan(&[3, 1100, 0, 1024], 300);
        let segments = Segments::of(&plan, plan.segment_entries);
        assert_eq!(segments.entries, 512);
        // Tile 0: 3 entries, one segment. Tile 1: 1100 → 512, 512, 76. Tile 2: an empty list
        // stays one (empty) segment. Tile 3: 1024 → two full segments.
        assert_eq!(
            segments.starts,
            vec![0, 3, 515, 1027, 1103, 1103, 1615, 2127]
        );
        assert!(segments.cut);
        let firsts_and_counts: Vec<(i32, i32)> = segments
            .work
            .chunks(SEGMENT_COLUMNS)
            .map(|s| (s[3], s[4]))
            .collect();
        assert_eq!(
            firsts_and_counts,
            vec![(0, 1), (1, 3), (1, 3), (1, 3), (4, 1), (5, 2), (5, 2)]
        );
        // Each segment keeps its tile's pose and corner.
        let tile_1: Vec<&[i32]> = segments
            .work
            .chunks(SEGMENT_COLUMNS)
            .skip(1)
            .take(3)
            .collect();
        assert!(tile_1.iter().all(|s| s[..3] == [1, 16, 0]));
    }

    #[test]
    fn only_a_forward_a_backward_follows_is_cut() {
        let plan = plan(&[3, 1100], 256);
        assert!(Segments::for_forward(&plan, ForwardUse::ForBackward).cut);
        let whole = Segments::for_forward(&plan, ForwardUse::ImageOnly);
        assert!(!whole.cut);
        assert_eq!(whole.len(), 2);
    }

    #[test]
    fn an_absurd_length_is_held_to_the_longest_list() {
        let segments = Segments::of(&plan(&[3, 1100], usize::MAX), usize::MAX);
        assert!(!segments.cut);
        assert_eq!(segments.entries, 1280);
    }

    #[test]
    fn lists_within_the_length_or_a_zero_length_stay_whole() {
        for (lengths, longest) in [(&[3usize, 256, 1][..], 4), (&[300, 5000][..], WHOLE_LISTS)] {
            let plan = plan(lengths, longest);
            let segments = Segments::of(&plan, plan.segment_entries);
            assert!(!segments.cut);
            assert!(segments.entries >= lengths.iter().copied().max().unwrap());
            let offsets: Vec<i32> = plan.starts.iter().map(|&s| s as i32).collect();
            assert_eq!(segments.starts, offsets);
        }
    }
}
