//! The compositing backward's last step: each work tile's per-entry gradient slots summed into
//! per-row gradients, in one fixed order (work tiles in plan order, list entries front to
//! back), so the sums have the same bits on any number of threads.
//!
//! Where every list keeps to its own pose's rows (as `CompositePlan::new` makes them: the
//! plan's `pose_rows`), each pose's rows are summed by a task of their own from that pose's
//! tiles, which visits each row's terms in the same order; on one thread this loop was a
//! twentieth of an optimisation step while the other cores waited.

use rayon::prelude::*;

use super::{HostGradients, Real};
use crate::fused::plan::CompositePlan;

/// The per-row gradients `[rows]` of the slots of every work tile (`slots[w]`: `[list, 6 + C]`,
/// v_mx, v_my, v_a, v_b, v_c, v_o, then the C channel values').
pub(super) fn sum_slots<E: Real>(
    plan: &CompositePlan,
    slots: &[Vec<E>],
    rows: usize,
    channels: usize,
) -> HostGradients<E> {
    let mut v = HostGradients {
        means: vec![E::ZERO; 2 * rows],
        conics: vec![E::ZERO; 3 * rows],
        opacities: vec![E::ZERO; rows],
        values: vec![E::ZERO; channels * rows],
    };
    let sum = |rows: GradientRows<'_, E>, first: usize, tiles: &[usize]| {
        add_slots(rows, first, tiles, plan, slots, channels)
    };
    if lists_keep_to_their_poses(plan, rows, channels) {
        let mut tiles_of_pose: Vec<Vec<usize>> = vec![Vec::new(); plan.batch()];
        for (w, &b) in plan.batches.iter().enumerate() {
            tiles_of_pose[b].push(w);
        }
        // Each pose's block of gradient rows, split off in turn.
        let mut blocks = Vec::with_capacity(plan.batch());
        let mut rest = GradientRows::of(&mut v);
        for b in 0..plan.batch() {
            let (own, tail) = rest.split_at(plan.pose_rows.count(b), channels);
            blocks.push((b, own));
            rest = tail;
        }
        blocks.into_par_iter().for_each(|(b, rows)| {
            sum(rows, plan.pose_rows.start(b), &tiles_of_pose[b]);
        });
    } else {
        let all: Vec<usize> = (0..plan.tiles.len()).collect();
        sum(GradientRows::of(&mut v), 0, &all);
    }
    v
}

/// The gradient rows of a range of input rows, from its first.
struct GradientRows<'a, E> {
    means: &'a mut [E],
    conics: &'a mut [E],
    opacities: &'a mut [E],
    values: &'a mut [E],
}

impl<'a, E> GradientRows<'a, E> {
    /// Every row of `v`.
    fn of(v: &'a mut HostGradients<E>) -> Self {
        GradientRows {
            means: &mut v.means,
            conics: &mut v.conics,
            opacities: &mut v.opacities,
            values: &mut v.values,
        }
    }

    /// The first `rows` rows (of `channels` values each) and the rest.
    fn split_at(self, rows: usize, channels: usize) -> (Self, Self) {
        let (means, means_rest) = self.means.split_at_mut(2 * rows);
        let (conics, conics_rest) = self.conics.split_at_mut(3 * rows);
        let (opacities, opacities_rest) = self.opacities.split_at_mut(rows);
        let (values, values_rest) = self.values.split_at_mut(channels * rows);
        (
            GradientRows {
                means,
                conics,
                opacities,
                values,
            },
            GradientRows {
                means: means_rest,
                conics: conics_rest,
                opacities: opacities_rest,
                values: values_rest,
            },
        )
    }
}

/// Adds the slots of work tiles `tiles` (in that order, each list front to back) into `v`,
/// whose first row is input row `first`; every row the lists name must be in `v`.
fn add_slots<E: Real>(
    v: GradientRows<'_, E>,
    first: usize,
    tiles: &[usize],
    plan: &CompositePlan,
    slots: &[Vec<E>],
    channels: usize,
) {
    let stride = 6 + channels;
    for &w in tiles {
        for (j, &row) in plan.list(w).iter().enumerate() {
            let row = row as usize - first;
            let slot = &slots[w][j * stride..(j + 1) * stride];
            v.means[2 * row] += slot[0];
            v.means[2 * row + 1] += slot[1];
            v.conics[3 * row] += slot[2];
            v.conics[3 * row + 1] += slot[3];
            v.conics[3 * row + 2] += slot[4];
            v.opacities[row] += slot[5];
            for k in 0..channels {
                v.values[channels * row + k] += slot[6 + k];
            }
        }
    }
}

/// True when the plan's `rows` input rows are its poses' blocks (`pose_rows`) and every work
/// tile lists only rows of its own pose; false otherwise (or without channels, whose empty
/// gradient has no blocks to split).
fn lists_keep_to_their_poses(plan: &CompositePlan, rows: usize, channels: usize) -> bool {
    let poses = &plan.pose_rows;
    if plan.batch() == 0 || channels == 0 || rows == 0 || poses.total() != rows {
        return false;
    }
    (0..plan.tiles.len()).into_par_iter().all(|w| {
        let b = plan.batches[w];
        b < plan.batch() && {
            let own = poses.start(b)..poses.start(b) + poses.count(b);
            plan.list(w)
                .iter()
                .all(|&row| own.contains(&(row as usize)))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rows::PoseRows;
    use crate::tile_grid::TileGrid;
    use crate::tiles::TileWork;

    /// A plan of poses with `counts` rows each over a 4×3 tile grid, random lists of each
    /// pose's rows, and random slots.
    fn case(channels: usize, counts: &[usize]) -> (CompositePlan, Vec<Vec<f32>>) {
        let grid = TileGrid::new(64, 48);
        let mut state = 0x2545_f491_u64;
        let mut next = move |m: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % m
        };
        let mut work = Vec::new();
        for (b, &n) in counts.iter().enumerate() {
            for tile in 0..grid.len() {
                let mut gaussians: Vec<u32> = (0..n as u32).filter(|_| next(3) == 0).collect();
                gaussians.sort_by_key(|_| next(1000)); // any order: lists are depth-sorted
                work.push(TileWork {
                    batch: b,
                    tile,
                    gaussians,
                });
            }
        }
        let rows = PoseRows::from_counts(counts.iter().copied());
        let plan = CompositePlan::new(&work, &rows, grid);
        let slots = (0..plan.tiles.len())
            .map(|w| {
                (0..plan.list(w).len() * (6 + channels))
                    .map(|_| next(1 << 20) as f32 / 1e4 - 50.0)
                    .collect()
            })
            .collect();
        (plan, slots)
    }

    #[test]
    fn poses_summed_apart_give_the_one_thread_sums_bit_for_bit() {
        // Every pose the same rows, and each its own number of rows (one none), as a pass
        // laid out per pose has them.
        for (channels, counts) in [(1, [40, 40, 40]), (3, [40, 40, 40]), (3, [40, 0, 25])] {
            let (plan, slots) = case(channels, &counts);
            let rows = plan.pose_rows.total();
            assert!(lists_keep_to_their_poses(&plan, rows, channels));
            let apart = sum_slots(&plan, &slots, rows, channels);
            // The reference: every tile in plan order on one thread.
            let mut one = HostGradients {
                means: vec![0.0; 2 * rows],
                conics: vec![0.0; 3 * rows],
                opacities: vec![0.0; rows],
                values: vec![0.0; channels * rows],
            };
            let all: Vec<usize> = (0..plan.tiles.len()).collect();
            add_slots(GradientRows::of(&mut one), 0, &all, &plan, &slots, channels);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&apart.means), bits(&one.means));
            assert_eq!(bits(&apart.conics), bits(&one.conics));
            assert_eq!(bits(&apart.opacities), bits(&one.opacities));
            assert_eq!(bits(&apart.values), bits(&one.values));
        }
    }

    #[test]
    fn a_list_naming_another_pose_s_row_is_summed_on_one_thread() {
        let (mut plan, slots) = case(1, &[40, 40, 40]);
        let rows = plan.batch() * 40;
        // Tile 0 (pose 0) names a row of pose 2: the split would lose its term.
        plan.rows[plan.starts[0]] = 2 * 40 + 5;
        assert!(!lists_keep_to_their_poses(&plan, rows, 1));
        let v = sum_slots(&plan, &slots, rows, 1);
        let total: f32 = slots
            .iter()
            .flat_map(|s| s.chunks_exact(7).map(|s| s[5]))
            .sum();
        let summed: f32 = v.opacities.iter().sum();
        assert!(
            (total - summed).abs() <= 1e-3 * total.abs().max(1.0),
            "{total} vs {summed}"
        );
    }
}
