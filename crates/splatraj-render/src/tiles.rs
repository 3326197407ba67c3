//! Tile binning on the host: which Gaussians touch which 16×16 tile, front to back. A Gaussian
//! goes into the tiles of its 3σ square (the reference renderer's rule) that its α ≥ 1/255
//! ellipse meets (`alpha_reach`), which changes no pixel.
//!
//! This is integer data decided without gradient (docs/conventions.md): the cull decisions, the
//! tile lists and the depth order. It also applies the exact pruning of mask passes: a tile no
//! object Gaussian touches renders an all-zero mask, and in a tile the object does touch, Gaussians
//! behind the object's last one cannot change the mask or its gradient (they only add terms whose
//! mask value is 0, after every term that carries the object).

use std::ops::Range;

use rayon::prelude::*;

use crate::bitset::GaussianBits;
use crate::decide::{Decided, Decisions};
use crate::heaviest_first::map_heaviest_first;
pub use crate::tile_grid::{TILE_PIXELS, TILE_SIZE, TileGrid};

/// Which tiles and Gaussians a pass must visit.
#[derive(Debug, Clone, Copy)]
pub enum TileSelection<'a> {
    /// Every tile, every Gaussian that touches it (any channel).
    All,
    /// A mask pass for one object, its Gaussians by scene index. Only tiles the object
    /// touches, and in each only the Gaussians up to the object's last one.
    /// Exact for the mask channel (value and gradient); other channels are not rendered right.
    Object(&'a GaussianBits),
}

/// One tile of one image of the batch, with the Gaussians to composite there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TileWork {
    /// Index of the image in the batch.
    pub batch: usize,
    /// Tile index, row-major: ty · tiles_x + tx.
    pub tile: usize,
    /// Gaussian indices (into the scene's N) front to back by depth, ties by index.
    pub gaussians: Vec<u32>,
}

/// Bins the Gaussians every pose keeps into tiles and sorts each tile front to back.
///
/// Pose b visits the tiles and Gaussians of `selection[b]` (a pass of several objects' masks
/// selects per pose). Returns only non-empty tiles (after pruning), ordered by (batch, tile).
/// Panics if `selection` is not one per pose.
pub fn bin_tiles(
    decisions: &Decisions,
    grid: &TileGrid,
    selection: &[TileSelection],
) -> Vec<TileWork> {
    assert_eq!(
        selection.len(),
        decisions.kept.len(),
        "one selection per pose"
    );
    let poses = decisions.kept.len();
    // The poses that keep the most first.
    let by_pose = map_heaviest_first(
        (0..poses).collect(),
        |&b| decisions.kept[b].len(),
        |b| {
            let pose = PoseToBin {
                kept: &decisions.kept[b],
                b,
                selection: selection[b],
                // The cores the other poses leave: a frame's one pose gets all of them.
                bands: (rayon::current_num_threads() / poses).max(1),
            };
            bin_one_pose(pose, grid)
        },
    );
    by_pose.into_iter().flatten().collect()
}

/// One pose's share of [`bin_tiles`]: what it keeps, its index, what it visits, and how many
/// bands of tile rows may fill its lists in parallel.
struct PoseToBin<'a> {
    kept: &'a [Decided],
    b: usize,
    selection: TileSelection<'a>,
    bands: usize,
}

fn bin_one_pose(pose: PoseToBin<'_>, grid: &TileGrid) -> Vec<TileWork> {
    let PoseToBin {
        kept,
        b,
        selection,
        bands,
    } = pose;
    // Tile rectangle [x0, x1) × [y0, y1) of every kept Gaussian's square, computed once
    // `[kept]`: here for a mask pass, whose object's rectangles mark its tiles, else beside
    // the filter below.
    let mut rects: Vec<[u16; 4]> = vec![[0; 4]; kept.len()];
    // A mask pass needs only the tiles its object touches.
    let (wanted, rects_found): (Vec<bool>, RectsFound) = match selection {
        TileSelection::All => (vec![true; grid.len()], RectsFound::NotYet),
        TileSelection::Object(in_object) => {
            let mark = |mut wanted: Vec<bool>, (kept, rects): (&[Decided], &mut [[u16; 4]])| {
                for (decided, rect) in kept.iter().zip(rects.iter_mut()) {
                    *rect = rect_of(decided, grid);
                    if in_object.contains(decided.gaussian as usize) {
                        tiles_until(decided, *rect, ALL_ROWS, grid.tiles_x, |tile| {
                            wanted[tile] = true;
                            false
                        });
                    }
                }
                wanted
            };
            let none = || vec![false; grid.len()];
            let wanted = if bands <= 1 {
                mark(none(), (kept, &mut rects))
            } else {
                // A pose with the cores to itself (a frame's mask, a single mask pass): this
                // loop was a serial quarter of its binning (biker at 128²: 1.9 of 7.5 ms).
                kept.par_chunks(RECT_CHUNK)
                    .zip(rects.par_chunks_mut(RECT_CHUNK))
                    .fold(none, mark)
                    .reduce(none, |mut wanted, more| {
                        wanted.iter_mut().zip(more).for_each(|(w, m)| *w |= m);
                        wanted
                    })
            };
            (wanted, RectsFound::Already)
        }
    };
    // The Gaussians that touch a wanted tile as (key, position in `kept`), where (depth,
    // index) as one u64 is unique within a pose and sorts them front to back, ties by scene
    // index: pushing them in that order leaves every list sorted.
    let mut order: Vec<(u64, u32)> = if bands <= 1 {
        // The pose has one core (the poses of a step share them): one loop, no tasks. With
        // the rectangles and the filter in one pass instead of two parallel ones, a first-try
        // guitar step's binning went 33.8 → 28.2 ms on one thread (a 720p frame's, banded,
        // 11.5 → 9.5 ms on 2 cores).
        let mut order = Vec::with_capacity(kept.len());
        rects_and_order(
            kept,
            0,
            grid,
            (&wanted, rects_found),
            &mut rects,
            &mut order,
        );
        order
    } else {
        let parts: Vec<Vec<(u64, u32)>> = kept
            .par_chunks(RECT_CHUNK)
            .zip(rects.par_chunks_mut(RECT_CHUNK))
            .enumerate()
            .map(|(c, (kept, rects))| {
                let mut order = Vec::with_capacity(kept.len());
                rects_and_order(
                    kept,
                    c * RECT_CHUNK,
                    grid,
                    (&wanted, rects_found),
                    rects,
                    &mut order,
                );
                order
            })
            .collect();
        parts.concat()
    };
    // The keys are unique, so either sort gives this order. Where the poses share the cores
    // (an optimisation step's tens of poses of 10 000–30 000 Gaussians each), each pose's
    // sort runs on one thread, and a radix sort (radsort, Bevy's; LSB by byte, skipping the
    // bytes all keys share) took the quarter of the binning the comparison sort was (perf,
    // first-try guitar step). A pose with the cores to itself (a frame, possibly of millions
    // of Gaussians) keeps the parallel sort, which a single-threaded one cannot match there.
    // Tried and not kept: keys of 8 bytes (depth, position) with equal depths put in scene
    // order afterwards, half the bytes a pass moves; the step's binning did not move.
    if bands <= 1 {
        radsort::sort_by_key(&mut order, |&(key, _)| key);
    } else {
        order.par_sort_unstable_by_key(|&(key, _)| key);
    }
    let bands = if order.len() < BANDED_ENTRIES {
        1
    } else {
        bands
    };
    let lists = fill_lists(&order, kept, &rects, &wanted, grid, bands);
    lists
        .into_iter()
        .enumerate()
        .filter_map(|(tile, mut gaussians)| {
            if let TileSelection::Object(in_object) = selection {
                let last = gaussians
                    .iter()
                    .rposition(|&g| in_object.contains(g as usize))?;
                gaussians.truncate(last + 1);
            }
            (!gaussians.is_empty()).then_some(TileWork {
                batch: b,
                tile,
                gaussians,
            })
        })
        .collect()
}

/// Each tile's list: the entries of `order` (key, position in `kept`) whose square `rects`
/// meets a `wanted` tile, in order. `[tiles]`
///
/// Bands of tile rows fill their own tiles' lists in parallel, each visiting every entry in
/// order: the same lists whatever `bands` is. A full frame's loop was three quarters of its
/// binning on one thread (720p guitar: 7.6 of 10 ms); an optimisation step's poses are binned
/// beside each other and take one band each (banded too, the guitar's step binned 18 → 21 ms
/// on 2 cores).
fn fill_lists(
    order: &[(u64, u32)],
    kept: &[Decided],
    rects: &[[u16; 4]],
    wanted: &[bool],
    grid: &TileGrid,
    bands: usize,
) -> Vec<Vec<u32>> {
    if bands <= 1 {
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); grid.len()];
        for &(key, k) in order {
            let g = key as u32; // the low 32 bits
            let k = k as usize;
            tiles_until(&kept[k], rects[k], ALL_ROWS, grid.tiles_x, |tile| {
                if wanted[tile] {
                    lists[tile].push(g);
                }
                false
            });
        }
        return lists;
    }
    let rows_per_band = grid.tiles_y.div_ceil(bands).max(1);
    (0..grid.tiles_y.div_ceil(rows_per_band))
        .into_par_iter()
        .flat_map_iter(|band| {
            let rows = band * rows_per_band..((band + 1) * rows_per_band).min(grid.tiles_y);
            let first = rows.start * grid.tiles_x;
            let mut lists: Vec<Vec<u32>> = vec![Vec::new(); rows.len() * grid.tiles_x];
            for &(key, k) in order {
                let k = k as usize;
                let [_, _, y0, y1] = rects[k].map(usize::from);
                if y1 <= rows.start || y0 >= rows.end {
                    continue;
                }
                let g = key as u32; // the low 32 bits
                // Only the band's rows: a square across bands was walked whole by each, and
                // every tile paid a division to find its row (a 720p frame's binning, where a
                // pose has the cores and its lists are filled by bands).
                tiles_until(&kept[k], rects[k], rows.clone(), grid.tiles_x, |tile| {
                    if wanted[tile] {
                        lists[tile - first].push(g);
                    }
                    false
                });
            }
            lists
        })
        .collect()
}

/// Kept Gaussians per task where a pose's rectangles are found in parallel.
const RECT_CHUNK: usize = 4096;

/// The tile rectangle [x0, x1, y0, y1] of a kept Gaussian's square.
fn rect_of(decided: &Decided, grid: &TileGrid) -> [u16; 4] {
    let [u, v] = decided.means_2d.map(f64::from);
    let (xs, ys) = grid.touched(u, v, f64::from(decided.radius));
    [xs.start, xs.end, ys.start, ys.end].map(|t| t as u16)
}

/// Whether a pose's tile rectangles are already in its `rects`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RectsFound {
    /// Found with the wanted tiles (a mask pass).
    Already,
    /// To be found with the filter ([`rects_and_order`]).
    NotYet,
}

/// Writes the rectangles of `kept` (positions `first..` of the pose's) into `rects` unless
/// they are found already, and pushes onto `order` the (key, position) of those that touch a
/// `wanted` tile, in `kept`'s order.
fn rects_and_order(
    kept: &[Decided],
    first: usize,
    grid: &TileGrid,
    (wanted, found): (&[bool], RectsFound),
    rects: &mut [[u16; 4]],
    order: &mut Vec<(u64, u32)>,
) {
    for (k, (decided, rect)) in kept.iter().zip(rects.iter_mut()).enumerate() {
        if found == RectsFound::NotYet {
            *rect = rect_of(decided, grid);
        }
        if tiles_until(decided, *rect, ALL_ROWS, grid.tiles_x, |tile| wanted[tile]) {
            let key = (u64::from(ordered_bits(decided.depth)) << 32) | u64::from(decided.gaussian);
            order.push((key, (first + k) as u32));
        }
    }
}

/// Entries of a pose from which its lists are filled by bands of tile rows in parallel.
const BANDED_ENTRIES: usize = 20_000;

/// Squares of at most this many tiles are kept whole: there the ellipse's test cost the binning
/// more than the few entries it saved the compositing (`bench step`, first-try guitar: binning
/// 16 → 20 ms a step, compositing 49 → 47 ms, when every square was tested).
const SMALL_SQUARE_TILES: usize = 4;

/// Every tile row, for [`tiles_until`].
const ALL_ROWS: Range<usize> = 0..usize::MAX;

/// Visits the tiles of a kept Gaussian's square `rect` ([x0, x1, y0, y1] in tiles) where its
/// α can reach 1/255 (`alpha_reach`: the same images and gradients from far shorter lists in
/// close-ups), row by row within the tile rows `rows`, until `visit` returns true; whether it
/// did. Whether the square is tested against the ellipse depends on the whole square, so a
/// row's tiles are the same whatever `rows` is.
fn tiles_until(
    decided: &Decided,
    rect: [u16; 4],
    rows: Range<usize>,
    tiles_x: usize,
    mut visit: impl FnMut(usize) -> bool,
) -> bool {
    let [x0, x1, y0, y1] = rect.map(usize::from);
    let mut visited = y0.max(rows.start)..y1.min(rows.end);
    if (x1 - x0) * (y1 - y0) <= SMALL_SQUARE_TILES {
        // The square whole, without the ellipse's set-up (most Gaussians at a step's size).
        return visited.any(|ty| (x0..x1).any(|tx| visit(ty * tiles_x + tx)));
    }
    let mean = decided.means_2d.map(f64::from);
    visited
        .clone()
        .zip(decided.reach.row_columns(mean, visited, x0..x1))
        .any(|(ty, columns)| columns.map(|tx| ty * tiles_x + tx).any(&mut visit))
}

/// The bits of `x` as a u32 that orders like the float itself (negative values included).
fn ordered_bits(x: f32) -> u32 {
    let bits = x.to_bits();
    if bits >> 31 == 1 {
        !bits
    } else {
        bits | 0x8000_0000
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alpha_reach::AlphaReach;

    /// Bands of tile rows give the lists of one loop over all tiles, whatever their number
    /// (more bands than tile rows included), with some tiles not wanted.
    #[test]
    fn lists_filled_by_bands_are_the_lists_of_one_loop() {
        let grid = TileGrid::new(320, 232); // 20 × 15 tiles, the last row partial
        let mut next = crate::test_random::uniform(0x9e37_79b9_u64);
        let kept: Vec<Decided> = (0..3000u32)
            .map(|g| {
                let (sx, sy) = (1.0 + 400.0 * next().powi(3), 1.0 + 400.0 * next().powi(3));
                let covariance = [sx, (next() - 0.5) * sx.min(sy), sy];
                Decided {
                    gaussian: g,
                    means_2d: [
                        (next() * 360.0 - 20.0) as f32,
                        (next() * 270.0 - 20.0) as f32,
                    ],
                    depth: (next() * 10.0) as f32,
                    radius: (3.0 * sx.max(sy).sqrt()).ceil() as f32,
                    reach: AlphaReach::new(covariance, 0.05 + 0.9 * next()),
                }
            })
            .collect();
        let rects: Vec<[u16; 4]> = kept.iter().map(|d| rect_of(d, &grid)).collect();
        let mut order: Vec<(u64, u32)> = kept
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let key = (u64::from(ordered_bits(d.depth)) << 32) | u64::from(d.gaussian);
                (key, k as u32)
            })
            .collect();
        order.sort_unstable();
        let wanted: Vec<bool> = (0..grid.len()).map(|t| t % 7 != 3).collect();
        let one = fill_lists(&order, &kept, &rects, &wanted, &grid, 1);
        assert_eq!(one.len(), grid.len());
        assert!(one.iter().filter(|l| !l.is_empty()).count() > grid.len() / 2);
        for bands in [2, 4, 7, 15, 40] {
            assert_eq!(
                fill_lists(&order, &kept, &rects, &wanted, &grid, bands),
                one,
                "{bands} bands"
            );
        }
    }

    /// Every list holds the Gaussians that reach its tile front to back, equal depths by scene
    /// index, whatever order `kept` has them in (the positions follow spatial blocks, not the
    /// scene), on one thread (the radix sort, one loop) and on several (the parallel sort, the
    /// rectangles in chunks); and a mask pass keeps the tiles its object reaches, each list cut
    /// after the object's last Gaussian.
    #[test]
    fn lists_run_front_to_back_with_ties_by_scene_index() {
        let grid = TileGrid::new(160, 96);
        let mut next = crate::test_random::uniform(0x5eed_0042_u64);
        // More than two chunks of rectangles; scene indices shuffled against the positions,
        // depths from eight values: many ties.
        let count = 2 * RECT_CHUNK as u32 + 800;
        let mut scene: Vec<u32> = (0..count).collect();
        for i in (1..scene.len()).rev() {
            scene.swap(i, (next() * (i + 1) as f64) as usize);
        }
        let kept: Vec<Decided> = scene
            .iter()
            .map(|&g| {
                let s = 1.0 + 60.0 * next().powi(2);
                Decided {
                    gaussian: g,
                    means_2d: [(next() * 170.0 - 5.0) as f32, (next() * 100.0 - 2.0) as f32],
                    depth: 0.5 + (next() * 8.0).floor() as f32,
                    radius: (3.0 * s.sqrt()).ceil() as f32,
                    reach: AlphaReach::new([s, 0.0, s], 0.9),
                }
            })
            .collect();
        // The object: a small cluster of scene indices, so that some tiles are not wanted.
        let mut position_of = vec![0; scene.len()];
        for (k, &g) in scene.iter().enumerate() {
            position_of[g as usize] = k;
        }
        let in_object = GaussianBits::from_fn(count as usize, |g| {
            let [u, v] = kept[position_of[g]].means_2d;
            g % 3 == 0 && u < 60.0 && v < 40.0
        });
        // The references: each tile's Gaussians, sorted by (depth, scene index); for the mask
        // pass only the tiles an object Gaussian reaches, each cut after its last one.
        let mut all: Vec<Vec<(f32, u32)>> = vec![Vec::new(); grid.len()];
        for d in &kept {
            tiles_until(d, rect_of(d, &grid), ALL_ROWS, grid.tiles_x, |tile| {
                all[tile].push((d.depth, d.gaussian));
                false
            });
        }
        for list in &mut all {
            list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
        let ties = all
            .iter()
            .flat_map(|list| list.windows(2))
            .filter(|pair| pair[0].0 == pair[1].0)
            .count();
        assert!(ties > 1000, "{ties} ties");
        let object: Vec<Vec<(f32, u32)>> = all
            .iter()
            .map(|list| {
                match list
                    .iter()
                    .rposition(|&(_, g)| in_object.contains(g as usize))
                {
                    Some(last) => list[..=last].to_vec(),
                    None => Vec::new(),
                }
            })
            .collect();
        let object_tiles = object.iter().filter(|l| !l.is_empty()).count();
        assert!(
            object_tiles > 4 && object_tiles < grid.len() / 2,
            "{object_tiles} object tiles"
        );
        let decisions = Decisions { kept: vec![kept] };
        for (pass, selection, expected) in [
            ("all tiles", TileSelection::All, &all),
            ("mask pass", TileSelection::Object(&in_object), &object),
        ] {
            for threads in [1, 4] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("a pool");
                let work = pool.install(|| bin_tiles(&decisions, &grid, &[selection]));
                let listed: Vec<usize> = work.iter().map(|w| w.tile).collect();
                let non_empty: Vec<usize> = (0..grid.len())
                    .filter(|&t| !expected[t].is_empty())
                    .collect();
                assert_eq!(listed, non_empty, "{pass}, {threads} threads");
                for w in &work {
                    let want: Vec<u32> = expected[w.tile].iter().map(|&(_, g)| g).collect();
                    assert_eq!(
                        w.gaussians, want,
                        "tile {}, {pass}, {threads} threads",
                        w.tile
                    );
                }
            }
        }
    }
}
