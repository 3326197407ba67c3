//! Camera paths in splatraj's conventions (`docs/conventions.md`): frames of a [`CameraPose`]
//! (R_wc and the centre, OpenCV camera axes) and, where the file has them, [`Intrinsics`].
//!
//! The pose and intrinsics types, the rotation checks and the axis conversions come from the
//! `splatraj-camera` crate, which the renderer shares; every format module converts between
//! them and its own file. Nothing here depends on burn.

use glam::DVec3;

pub use splatraj_camera::{CameraPose, Intrinsics, ROTATION_TOLERANCE, nearest_rotation};

/// One camera of a path: its pose and, where the file has them, its intrinsics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The pose.
    pub pose: CameraPose,
    /// The intrinsics (every export needs them; imports give them when the file has them).
    pub camera: Option<Intrinsics>,
}

/// A camera path: frames in order, shown at `fps` frames per second, in shots separated by
/// cuts.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraPath {
    /// The frames, in playing order.
    pub frames: Vec<Frame>,
    /// Frames per second, where the file says.
    pub fps: Option<f64>,
    /// Length in seconds, where the file says (readers check it is finite and > 0; its
    /// frames at `fps` are sized by whoever renders them).
    pub seconds: Option<f64>,
    /// The frames that begin a new shot after a cut, ascending, each in 1..frames: between
    /// frame k − 1 and frame k of a cut the camera switches, and nothing interpolates across
    /// (empty: one continuous shot).
    pub cuts: Vec<usize>,
}

impl CameraPath {
    /// Frames without timing (camera files that list views: COLMAP, INRIA, transforms.json).
    pub fn untimed(frames: Vec<Frame>) -> Self {
        Self {
            frames,
            fps: None,
            seconds: None,
            cuts: Vec::new(),
        }
    }

    /// A path of `poses` (Φ) all seen through `camera`, at `fps`.
    pub fn from_phis(poses: &[[f64; 6]], camera: Intrinsics, fps: f64) -> Self {
        Self {
            frames: poses
                .iter()
                .map(|&phi| Frame {
                    pose: CameraPose::from_phi(phi),
                    camera: Some(camera),
                })
                .collect(),
            fps: Some(fps),
            seconds: None,
            cuts: Vec::new(),
        }
    }

    /// Checks `cuts` against the frames: ascending, each in 1..frames (why not, in words).
    pub fn check_cuts(&self) -> Result<(), String> {
        check_cuts(&self.cuts, self.frames.len())
    }

    /// The shot frame `frame` belongs to (0 before the first cut).
    pub fn shot_of_frame(&self, frame: usize) -> usize {
        self.cuts.iter().take_while(|&&c| c <= frame).count()
    }

    /// The poses as Φ = [ω, c].
    pub fn phis(&self) -> Vec<[f64; 6]> {
        self.frames.iter().map(|f| f.pose.phi()).collect()
    }

    /// The poses as Φ with each ω the rotation vector of its rotation nearest the previous
    /// frame's (angles may pass π), so a path that turns smoothly has smooth Φ: what a
    /// trajectory model should be fitted to.
    pub fn continuous_phis(&self) -> Vec<[f64; 6]> {
        let mut out: Vec<[f64; 6]> = Vec::with_capacity(self.frames.len());
        for phi in self.phis() {
            let omega = DVec3::new(phi[0], phi[1], phi[2]);
            let best = match out.last() {
                Some(prev) => {
                    let prev = DVec3::new(prev[0], prev[1], prev[2]);
                    let angle = omega.length();
                    let axis = if angle > 0.0 {
                        omega / angle
                    } else {
                        // A zero rotation is also a full turn about any axis: the previous one.
                        prev.normalize_or_zero()
                    };
                    // Every rotation vector of this rotation: axis·(angle + 2πk).
                    (-3i32..=3)
                        .map(|k| axis * (angle + 2.0 * std::f64::consts::PI * f64::from(k)))
                        .min_by(|a, b| a.distance(prev).total_cmp(&b.distance(prev)))
                        .unwrap_or(omega)
                }
                None => omega,
            };
            out.push([best.x, best.y, best.z, phi[3], phi[4], phi[5]]);
        }
        out
    }

    /// [`CameraPath::continuous_phis`] resampled at `count` evenly spaced times over the path
    /// (the frames at evenly spaced times, linear in Φ between them, but never across a cut:
    /// between the two frames of a cut a sample takes the nearer one): dense samples to fit a
    /// trajectory model to.
    pub fn resampled_phis(&self, count: usize) -> Vec<[f64; 6]> {
        let phis = self.continuous_phis();
        if phis.len() < 2 || count < 2 {
            return phis.first().map_or(Vec::new(), |p| vec![*p; count]);
        }
        let last = (phis.len() - 1) as f64;
        (0..count)
            .map(|i| {
                let s = i as f64 / (count - 1) as f64 * last;
                let k = (s.floor() as usize).min(phis.len() - 2);
                let f = s - k as f64;
                if self.cuts.contains(&(k + 1)) {
                    return if f < 0.5 { phis[k] } else { phis[k + 1] };
                }
                std::array::from_fn(|j| phis[k][j] * (1.0 - f) + phis[k + 1][j] * f)
            })
            .collect()
    }
}

/// Checks frame indices of cuts against `frames` frames: ascending, each in 1..frames.
pub fn check_cuts(cuts: &[usize], frames: usize) -> Result<(), String> {
    if let Some(bad) = cuts.iter().find(|&&c| c == 0 || c >= frames) {
        return Err(format!(
            "a cut before frame {bad} is not between two of the {frames} frames"
        ));
    }
    if cuts.windows(2).any(|w| w[0] >= w[1]) {
        return Err(format!("{cuts:?} are not ascending"));
    }
    Ok(())
}
