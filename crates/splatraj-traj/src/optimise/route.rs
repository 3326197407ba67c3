//! Planned starts: routes around the scene's geometry between consecutive windows.
//!
//! Gradient descent on the clearance cost pushes each point of a path out of the nearest
//! surface, so it clears a table leg the path grazes but cannot take a path that crosses a
//! solid wall around it: every point is pushed back to the side it is on. A planned start
//! gives the optimisation a path that already goes around.
//!
//! **Grid.** The box holding the scene's robust bounds and the route's ends, padded by a
//! quarter of its size on every side (so a route may pass around an open scene's outside), is
//! cut into cubic cells of side h = max(margin, (volume / [`MAX_ROUTE_CELLS`])^⅓). A cell is
//! free when the clearance of its centre is at least m + h·√3/2: clearance is 1-Lipschitz and
//! every point of a segment between two neighbouring cells' centres is within h·√3/2 of one
//! of them, so a route along free cells keeps the margin m everywhere, not only at the
//! centres.
//!
//! **Search.** A* (the `pathfinding` crate: a maintained implementation, so no hand-written
//! priority queue) over the free cells, 26 neighbours, edge cost the centres' distance, the
//! straight-line distance as the heuristic; from the free cell nearest each end. The cell
//! path is then shortened by string pulling: from each kept point, the farthest later point
//! whose straight segment keeps the margin (checked every m/4; a segment from an end that is
//! already inside the margin may keep that end's clearance instead) is kept next.
//!
//! **Start.** [`super::start::routed_start_trajectory`] moves the start's camera centres along the
//! route over the transition around each join of windows: the last share of the earlier window and
//! the first of the later one (at least [`ROUTE_TRANSITION`], more where the pacing limits ask for
//! it: [`crate::optimise::pans`]; none inside a window with a shot, whose path is the shot's), by
//! arc length along the smoothstep 3x² − 2x³ of time (at rest at both ends of the transition).
//! Orientations stay those of the start. Joins whose straight segment already keeps the margin are
//! left alone.

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::clearance::Occupancy;

/// Most cells of a route grid (about 50³): bounds the grid's build time on large scenes.
pub const MAX_ROUTE_CELLS: usize = 128_000;

/// The most points a segment's clearance is checked at (a segment 25 000 margins long).
pub const MAX_SEGMENT_CHECKS: usize = 100_000;

/// Least share of a window on each side of a join over which a start pans (and a planned
/// start follows its route); a pan that needs longer for the pacing limits gets more
/// ([`crate::optimise::pans`]).
pub const ROUTE_TRANSITION: f64 = 0.25;

/// How starts travel between consecutive windows (`[start] route`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RouteKind {
    /// `planned` when the clearance cost is on, else `straight`.
    #[default]
    Auto,
    /// Around the geometry, on a grid search (module docs); needs `[costs.clearance]`.
    Planned,
    /// However the trajectory model joins the windows' start poses (the straight way).
    Straight,
}

/// What [`RoutePlanner::route`] found between two points.
#[derive(Debug, Clone, PartialEq)]
pub enum Route {
    /// The straight segment keeps the margin: nothing to plan.
    Straight,
    /// A polyline from the first point to the second around the geometry.
    Around(Vec<DVec3>),
    /// No free route in the grid (the ends are walled in): the straight segment is kept.
    Unreachable,
}

/// Free cells of a grid over a scene's geometry and the searches on it (module docs).
#[derive(Debug, Clone)]
pub struct RoutePlanner {
    occupancy: Occupancy,
    margin: f64,
    origin: DVec3,
    cell: f64,
    dims: [usize; 3],
    free: Vec<bool>,
}

impl RoutePlanner {
    /// A grid over the box `lo`..`hi` (padded, see the module docs) for routes that keep
    /// `margin` (> 0) from `occupancy`'s surfaces.
    pub fn new(occupancy: &Occupancy, margin: f64, lo: DVec3, hi: DVec3) -> Self {
        let pad = 0.25 * (hi - lo).abs() + DVec3::splat(2.0 * margin);
        let (lo, hi) = (lo.min(hi) - pad, lo.max(hi) + pad);
        let size = hi - lo;
        let volume = size.x * size.y * size.z;
        let cell = margin.max((volume / MAX_ROUTE_CELLS as f64).cbrt());
        let dims = [0, 1, 2].map(|k| ((size[k] / cell).ceil() as usize).max(1));
        let needed = margin + cell * 3f64.sqrt() * 0.5;
        let mut planner = Self {
            occupancy: occupancy.clone(),
            margin,
            origin: lo,
            cell,
            dims,
            free: Vec::new(),
        };
        let count = dims[0] * dims[1] * dims[2];
        planner.free = (0..count)
            .into_par_iter()
            .map(|i| planner.occupancy.is_clear(planner.centre(i), needed))
            .collect();
        planner
    }

    /// Side of a cell, scene units.
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// Cells along x, y, z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    fn index(&self, [x, y, z]: [usize; 3]) -> usize {
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    fn coords(&self, i: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    fn centre(&self, i: usize) -> DVec3 {
        let [x, y, z] = self.coords(i);
        self.origin + (DVec3::new(x as f64, y as f64, z as f64) + 0.5) * self.cell
    }

    /// Clearance of `p`, searched up to the margin (beyond it: the margin).
    fn clearance(&self, p: DVec3) -> f64 {
        self.occupancy
            .nearest_within(p, self.margin)
            .map_or(self.margin, |c| c.surface.distance.min(self.margin))
    }

    /// Whether the segment a–b keeps the margin (or, from an end already inside it, that
    /// end's clearance), checked every margin/4 (at most [`MAX_SEGMENT_CHECKS`] points).
    pub fn segment_is_clear(&self, a: DVec3, b: DVec3) -> bool {
        let needed = self.margin.min(self.clearance(a)).min(self.clearance(b)) - 1e-9;
        // Capped: a margin tiny against the segment (a degenerate scale) must not take
        // forever; the cap is far above what a scene's own proportions ask for.
        let steps =
            ((a.distance(b) / (0.25 * self.margin)).ceil() as usize).clamp(1, MAX_SEGMENT_CHECKS);
        (0..=steps).all(|k| self.clearance(a.lerp(b, k as f64 / steps as f64)) >= needed)
    }

    /// The free cell nearest `p` (None when no cell is free).
    fn nearest_free(&self, p: DVec3) -> Option<usize> {
        (0..self.free.len())
            .filter(|&i| self.free[i])
            .min_by(|&i, &j| {
                self.centre(i)
                    .distance_squared(p)
                    .total_cmp(&self.centre(j).distance_squared(p))
            })
    }

    /// A route from `a` to `b` that keeps the margin (module docs).
    pub fn route(&self, a: DVec3, b: DVec3) -> Route {
        if self.segment_is_clear(a, b) {
            return Route::Straight;
        }
        let (Some(from), Some(to)) = (self.nearest_free(a), self.nearest_free(b)) else {
            return Route::Unreachable;
        };
        // Integer costs for A* (it needs an ordered cost): thousandths of a cell.
        let scale = 1000.0;
        let goal = self.coords(to);
        let found = pathfinding::directed::astar::astar(
            &from,
            |&i| {
                let [x, y, z] = self.coords(i).map(|v| v as i64);
                let mut next = Vec::with_capacity(26);
                for dz in -1..=1i64 {
                    for dy in -1..=1i64 {
                        for dx in -1..=1i64 {
                            let n = [x + dx, y + dy, z + dz];
                            if (dx, dy, dz) == (0, 0, 0)
                                || (0..3).any(|k| n[k] < 0 || n[k] >= self.dims[k] as i64)
                            {
                                continue;
                            }
                            let j = self.index(n.map(|v| v as usize));
                            if self.free[j] {
                                let length = ((dx * dx + dy * dy + dz * dz) as f64).sqrt();
                                next.push((j, (length * scale).round() as u64));
                            }
                        }
                    }
                }
                next
            },
            |&i| {
                let c = self.coords(i);
                let d: f64 = (0..3).map(|k| (c[k] as f64 - goal[k] as f64).powi(2)).sum();
                (d.sqrt() * scale).floor() as u64
            },
            |&i| i == to,
        );
        let Some((cells, _)) = found else {
            return Route::Unreachable;
        };
        let mut points = Vec::with_capacity(cells.len() + 2);
        points.push(a);
        points.extend(cells.iter().map(|&i| self.centre(i)));
        points.push(b);
        Route::Around(self.pull(&points))
    }

    /// String pulling: the farthest reachable point next, from each kept point.
    fn pull(&self, points: &[DVec3]) -> Vec<DVec3> {
        let mut kept = vec![points[0]];
        let mut i = 0;
        while i + 1 < points.len() {
            let mut j = i + 1;
            while j + 1 < points.len() && self.segment_is_clear(points[i], points[j + 1]) {
                j += 1;
            }
            kept.push(points[j]);
            i = j;
        }
        kept
    }
}

/// The point at share `u` ∈ [0, 1] of a polyline's length.
pub fn along(points: &[DVec3], u: f64) -> DVec3 {
    let lengths: Vec<f64> = points.windows(2).map(|w| w[0].distance(w[1])).collect();
    let total: f64 = lengths.iter().sum();
    let mut left = u.clamp(0.0, 1.0) * total;
    for (w, &length) in points.windows(2).zip(&lengths) {
        if left <= length && length > 0.0 {
            return w[0].lerp(w[1], left / length);
        }
        left -= length;
    }
    *points.last().expect("a polyline has points")
}

/// One join's transition: the routes' polyline and the times it spans.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    /// Index of the earlier window.
    pub window: usize,
    /// The route's points (first: the earlier window's end centre).
    pub points: Vec<DVec3>,
    /// Start and end of the transition in normalised time.
    pub times: (f64, f64),
}

impl Transition {
    /// The camera centre at time `t` within the transition.
    pub fn centre_at(&self, t: f64) -> DVec3 {
        let (start, end) = self.times;
        let x = ((t - start) / (end - start)).clamp(0.0, 1.0);
        along(&self.points, x * x * (3.0 - 2.0 * x))
    }
}

/// The transitions of a start over `windows` windows: for each join whose straight segment
/// (from `ends[i].0`, the end centre of window i, to `ends[i].1`, the start centre of window
/// i + 1) does not keep the margin, the planned route over the times described in the module
/// docs, over `shares[i]` of each window (a join beyond the list: [`ROUTE_TRANSITION`]);
/// `shot[i]` says window i follows a shot (no transition inside it). The second list holds
/// the joins that found no route.
pub fn plan_transitions(
    planner: &RoutePlanner,
    ends: &[(DVec3, DVec3)],
    shot: &[bool],
    shares: &[f64],
) -> (Vec<Transition>, Vec<usize>) {
    let n = shot.len().max(1) as f64;
    let mut transitions = Vec::new();
    let mut unreachable = Vec::new();
    for (i, &(a, b)) in ends.iter().enumerate() {
        let join = (i + 1) as f64 / n;
        let share = shares.get(i).copied().unwrap_or(ROUTE_TRANSITION);
        let before = if shot[i] { 0.0 } else { share / n };
        let after = if shot.get(i + 1).copied().unwrap_or(true) {
            0.0
        } else {
            share / n
        };
        if before + after <= 0.0 {
            continue;
        }
        match planner.route(a, b) {
            Route::Straight => {}
            Route::Unreachable => unreachable.push(i),
            Route::Around(points) => transitions.push(Transition {
                window: i,
                points,
                times: (join - before, join + after),
            }),
        }
    }
    (transitions, unreachable)
}
