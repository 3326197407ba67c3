//! `[start]`: where the optimisation starts.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use splatraj_traj::optimise::{ObjectView, RouteKind, StartDistribution};

/// How starting poses are drawn when no `pose` or `trajectory` is given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartKind {
    /// Each window starts from the viewpoint a search finds where its object shows, unhidden
    /// and framed, with short moves between windows (`splatraj_traj::optimise::views`);
    /// restarts try other viewpoints.
    #[default]
    Search,
    /// Each window starts at a camera looking at its object from its prior radius, all from
    /// one side (restarts jitter the azimuth by up to ±`jitter` degrees).
    Objects,
    /// Seeded random cameras in the scene looking at its centre (`spread`).
    Random,
}

/// `[start]`: where the optimisation starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StartConfig {
    /// Object-facing or random starts.
    pub kind: StartKind,
    /// Objects: azimuth jitter of restarts after the first, degrees (≥ 0).
    pub jitter: f64,
    /// Objects: elevation of the view above the horizontal, degrees, in (−90, 90); a flat
    /// scene seen from its front wants a steep one.
    pub elevation: f64,
    /// Random starts: camera centres within `spread` × the scene's half-extent of its centre
    /// (see `splatraj_traj::optimise::start`), in (0, 1].
    pub spread: f64,
    /// Independent random starts; the best result is kept (≥ 1).
    pub restarts: usize,
    /// How the start travels between consecutive windows: `auto` (default: `planned` when
    /// `[costs.clearance]` is on, else `straight`), `planned` (around the geometry: a grid
    /// search keeping the clearance margin, for joins whose straight way does not; see
    /// `splatraj_traj::optimise::route`) or `straight`. Gradient descent alone cannot take a
    /// path that crosses a wall around it; a planned start can.
    pub route: RouteKind,
    /// A fixed start pose Φ = [ω, c] (instead of random starts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose: Option<[f64; 6]>,
    /// A path to start from, re-fitted to `[trajectory]`: an earlier run's `trajectory.json`, or
    /// another tool's camera file (nerfstudio `camera_path.json`, COLMAP `images.txt`, INRIA
    /// `cameras.json`, SuperSplat `settings.json`; see `docs/interchange.md`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<PathBuf>,
}

impl StartConfig {
    /// How object starts look at their objects.
    pub fn object_view(&self) -> ObjectView {
        ObjectView {
            elevation_degrees: self.elevation,
            jitter_degrees: self.jitter,
        }
    }

    /// The random-start distribution.
    pub fn distribution(&self) -> StartDistribution {
        StartDistribution {
            spread: self.spread,
        }
    }
}

impl Default for StartConfig {
    fn default() -> Self {
        Self {
            kind: StartKind::Search,
            jitter: ObjectView::default().jitter_degrees,
            elevation: ObjectView::default().elevation_degrees,
            spread: StartDistribution::default().spread,
            restarts: 1,
            route: RouteKind::Auto,
            pose: None,
            trajectory: None,
        }
    }
}
