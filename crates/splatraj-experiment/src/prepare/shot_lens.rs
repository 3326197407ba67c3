//! The zoom of the shots that zoom (`kind = "dolly-zoom"`, `splatraj_traj::shots`): the
//! start's (z*(s) of each such window fitted into the trajectory's basis, s = 1 elsewhere),
//! and the optimised trajectory's, locked to its camera's distance.
//!
//! **Why lock.** The optimiser holds the object's size only as well as TRE's mean over a few
//! samples can (the demo's plant: ±12 % in linear size), and the prior and clearance keep the
//! camera off the shot's exact radii. A dolly zoom is defined by the size staying put, which
//! for a pinhole is s/d constant (an image size is ∝ f·s·R/d). So after the optimisation the
//! zoom of each dolly-zoom window is refitted to s(t) = d(t)/r_w, d(t) the optimised camera's
//! distance to the object and r_w the working radius (where s = 1 frames it at its target
//! ratio); the other windows keep their optimised zoom.

use anyhow::{Context, Result, bail};
use glam::DVec3;
use splatraj_traj::optimise::sampling::{window_bounds, window_of};
use splatraj_traj::shots::ShotPath;
use splatraj_traj::trajectory::{Lens, LensPath, TrajectoryRecord, ZoomRange};

use crate::prepare::experiment::Experiment;

/// Fitting points per window of the start's zoom: dense enough for the finest basis the
/// config can ask for (the RBF's centres per window are a handful).
const ZOOM_FIT_POINTS: usize = 64;

/// The dolly-zoom windows of `shots`' first, if any.
fn first_zooming(shots: &[Option<ShotPath>]) -> Option<usize> {
    shots
        .iter()
        .position(|s| s.is_some_and(|s| s.zoom_radius.is_some()))
}

impl Experiment {
    /// `record` with the zoom of each dolly-zoom window locked to its camera's distance,
    /// s(t) = d(t)/r_w (module docs), the other windows' zoom as it is, refitted into the
    /// basis; `record` as it is when no shot zooms.
    pub fn lock_shot_zoom(&self, record: TrajectoryRecord) -> Result<TrajectoryRecord> {
        let shots = self.shot_paths()?;
        let (Some(_), Some(lens)) = (first_zooming(&shots), &record.lens) else {
            return Ok(record);
        };
        let range = lens.range;
        let n = self.windows.len();
        let times: Vec<f64> = (0..n * ZOOM_FIT_POINTS)
            .map(|k| (k as f64 + 0.5) / (n * ZOOM_FIT_POINTS) as f64)
            .collect();
        let trajectory = self.trajectory(&record)?;
        let poses = trajectory.poses_at(&times);
        let optimised = trajectory.zooms_at(&times);
        // Strictly inside the range, where the fit's free value is finite.
        let (lo, hi) = (range.min * (1.0 + 1e-6), range.max * (1.0 - 1e-6));
        let zooms: Vec<f64> = times
            .iter()
            .zip(&poses)
            .zip(optimised)
            .map(|((&t, pose), zoom)| {
                let i = window_of(t, n);
                match shots[i].and_then(|s| s.zoom_radius.map(|r| (s, r))) {
                    Some((shot, r)) => {
                        let d = (DVec3::from_slice(&pose[3..]) - shot.object_centre).length();
                        (d / r).clamp(lo, hi)
                    }
                    None => zoom,
                }
            })
            .collect();
        let lens = LensPath::fit(&record.model, range, &times, &zooms)
            .context("locking the dolly-zoom shots' zoom to the camera's distance")?;
        Ok(TrajectoryRecord {
            lens: Some(lens),
            ..record
        })
    }

    /// Errors naming the key when a dolly-zoom shot cannot zoom as it asks: the lens is fixed
    /// (`camera.lens`), or its zoom z*(s) = r(s)/r_w leaves `camera.zoom_range`. The zoom
    /// depends on the working radius r_w, known once the scene is read: [`Experiment::prepare`]
    /// calls this, so `run --check` refuses such a shot and no run folder is made for it.
    pub fn check_shot_zoom(&self) -> Result<()> {
        self.shot_zoom_range(&self.shot_paths()?).map(drop)
    }

    /// The zoom's range when some shot of `shots` zooms (None when none does), after checking
    /// that each zooming shot's zoom lies strictly inside it (the lens's map never reaches its
    /// ends: `splatraj_traj::trajectory::lens`); errors name the key.
    fn shot_zoom_range(&self, shots: &[Option<ShotPath>]) -> Result<Option<ZoomRange>> {
        let Some(first) = first_zooming(shots) else {
            return Ok(None);
        };
        let Lens::Zoom(range) = self.config.camera.lens()? else {
            bail!(
                "`queries.{first}.shot` (dolly-zoom) zooms: it needs `camera.lens = \"zoom\"` \
                 (the camera's lens is fixed)"
            );
        };
        for (i, shot) in shots.iter().enumerate() {
            let Some((shot, working)) = shot.and_then(|s| s.zoom_radius.map(|r| (s, r))) else {
                continue;
            };
            // r(s) is linear in s (the dolly's line), so the zoom's extremes are its ends.
            let (from, to) = shot.radius;
            let (low, high) = (from.min(to) / working, from.max(to) / working);
            if !(low > range.min && high < range.max) {
                bail!(
                    "`queries.{i}.shot` (dolly-zoom) needs the zoom from {:.3} to {:.3} (its \
                     radius from {from:.4} to {to:.4} over the working radius {working:.4}), \
                     not strictly inside `camera.zoom_range` = [{}, {}]: widen the range \
                     beyond [{low:.3}, {high:.3}], or bring `from` and `to` toward the working \
                     radius",
                    from / working,
                    to / working,
                    range.min,
                    range.max
                );
            }
        }
        Ok(Some(range))
    }

    /// `start` with its zoom following the dolly-zoom shots' z*(s) in their windows (and
    /// s = 1 in the others), fitted into the trajectory's basis; `start` as it is when no
    /// shot zooms. Errors name the key as [`Experiment::check_shot_zoom`]'s.
    pub fn with_shot_zoom(&self, start: TrajectoryRecord) -> Result<TrajectoryRecord> {
        let shots = self.shot_paths()?;
        let Some(range) = self.shot_zoom_range(&shots)? else {
            return Ok(start);
        };
        let n = self.windows.len();
        let mut times = Vec::with_capacity(n * ZOOM_FIT_POINTS);
        let mut zooms = Vec::with_capacity(n * ZOOM_FIT_POINTS);
        for (i, shot) in shots.iter().enumerate() {
            let (start_t, end_t) = window_bounds(i, n);
            for k in 0..ZOOM_FIT_POINTS {
                let s = (k as f64 + 0.5) / ZOOM_FIT_POINTS as f64;
                times.push(start_t + s * (end_t - start_t));
                zooms.push(shot.and_then(|shot| shot.zoom_at(s)).unwrap_or(1.0));
            }
        }
        let lens = LensPath::fit(&start.model, range, &times, &zooms)
            .context("fitting the start's zoom to the dolly-zoom shots")?;
        Ok(TrajectoryRecord {
            lens: Some(lens),
            ..start
        })
    }
}
