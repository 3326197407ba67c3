//! The integer side of a fused compositing pass: which rows each (pose, tile) composites.

use crate::rasterize::MIN_TRANSMITTANCE;
use crate::rows::PoseRows;
use crate::tiles::{TILE_SIZE, TileGrid, TileWork};

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
}

impl CompositePlan {
    /// Flattens `work`, whose entries are each pose's own rows, into input rows
    /// `rows.start(pose) + entry` (every list keeps to its pose's rows).
    pub fn new(work: &[TileWork], rows: &PoseRows, grid: TileGrid) -> Self {
        let mut starts = Vec::with_capacity(work.len() + 1);
        let mut flat = Vec::with_capacity(work.iter().map(|w| w.gaussians.len()).sum());
        starts.push(0);
        for w in work {
            let base = rows.start(w.batch) as u32;
            flat.extend(w.gaussians.iter().map(|&g| base + g));
            starts.push(flat.len());
        }
        CompositePlan {
            grid,
            pose_rows: rows.clone(),
            batches: work.iter().map(|w| w.batch).collect(),
            tiles: work.iter().map(|w| w.tile).collect(),
            starts,
            rows: flat,
            stop_transmittance: MIN_TRANSMITTANCE,
        }
    }

    /// The same plan with another stopping transmittance (an approximation when larger).
    pub fn with_stop_transmittance(self, stop_transmittance: f64) -> Self {
        CompositePlan {
            stop_transmittance,
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

    /// Pixel coordinates of the top-left corner of `tile`.
    pub fn tile_origin(&self, tile: usize) -> (usize, usize) {
        (
            (tile % self.grid.tiles_x) * TILE_SIZE,
            (tile / self.grid.tiles_x) * TILE_SIZE,
        )
    }
}
