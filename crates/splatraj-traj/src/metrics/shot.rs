//! How closely a window's camera kept its shot preset ([`crate::shots`]): the deviation from
//! what the shot asks for at each time of the window, on an even grid of the window's times
//! (both ends included; no render is needed).
//!
//! With o the shot's object centre, u world up, c the camera centre and f its forward axis at
//! window time s, and c*(s), a(s) the shot's centre and aim point:
//!
//! - `elevation`: |elevation of c − o above the horizontal − ε|, degrees;
//! - `radius`: |‖c − o‖ − r(s)|, scene units (a dolly's distance to the object; an orbit's
//!   radius); `radius_relative` the same over r(s);
//! - `azimuth`: the angle between the horizontal parts of c − o and c*(s) − o, degrees (an
//!   orbit's progress along its sweep; 0 when either is vertical);
//! - `aim`: the angle between f and a(s) − c, degrees (how far the view is off the object, or
//!   off a reveal's pan).
//!
//! **A dolly zoom's hold** ([`ZoomHold`], `zoom`, once frames are rendered): a dolly zoom is
//! defined by the object keeping its projected size while the field of view changes, so its
//! window also reports, from the frames' coverage, the object's linear size (√coverage: a
//! length in the image, where coverage is an area) over the window's middle
//! [`MIDDLE_SHARE`] (where no pan should be, as `framed_share` judges), its smallest and
//! largest over its mean there, and how much the horizontal field of view changes: widest
//! over narrowest, over the window's frames and over the same middle frames.

use glam::DVec3;
use serde::Serialize;
use splatraj_render::camera::rotation_vector_to_matrix;

use super::window::MIDDLE_SHARE;
use crate::optimise::sampling::window_bounds;
use crate::shots::ShotPath;
use crate::trajectory::Pose;

/// Mean and worst of one deviation over a window's samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Deviation {
    /// Mean over the samples.
    pub mean: f64,
    /// Largest over the samples.
    pub max: f64,
}

impl Deviation {
    fn of(values: &[f64]) -> Self {
        Self {
            mean: values.iter().sum::<f64>() / values.len().max(1) as f64,
            max: values.iter().copied().fold(0.0, f64::max),
        }
    }
}

/// Deviations of one window's camera from its shot (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShotMetrics {
    /// The shot's kind.
    pub kind: &'static str,
    /// Samples of the window.
    pub samples: usize,
    /// Elevation off the shot's, degrees.
    pub elevation: Deviation,
    /// Distance to the object off the shot's radius at that time, scene units.
    pub radius: Deviation,
    /// `radius` over the shot's radius at that time.
    pub radius_relative: Deviation,
    /// Azimuth off the shot's at that time (orbit: progress along the sweep), degrees.
    pub azimuth: Deviation,
    /// View direction off the shot's aim point, degrees.
    pub aim: Deviation,
    /// How a dolly zoom held its object's size (module docs), once frames are rendered
    /// (filled in by the caller from [`zoom_hold`]); absent for the other shots.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zoom: Option<ZoomHold>,
}

/// One output frame of a window as [`zoom_hold`] reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZoomFrame {
    /// Its time t ∈ [0, 1].
    pub t: f64,
    /// Share of the frame the visible object covers.
    pub coverage: f64,
    /// The frame camera's horizontal field of view, degrees.
    pub fov_x_degrees: f64,
}

/// How a dolly-zoom window held its object's projected size while its field of view changed
/// (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ZoomHold {
    /// Frames in the window's middle [`MIDDLE_SHARE`], where the size is judged.
    pub frames: usize,
    /// Smallest linear size (√coverage) of those frames over their mean (None: the object
    /// shows in none of them).
    pub size_min: Option<f64>,
    /// Largest linear size of those frames over their mean.
    pub size_max: Option<f64>,
    /// Widest over narrowest horizontal field of view over the window's frames.
    pub fov_ratio: f64,
    /// The same over the middle frames.
    pub fov_ratio_middle: f64,
}

impl ZoomHold {
    /// The largest change of the linear size from its mean over the middle frames, as a share
    /// of the mean: max(1 − `size_min`, `size_max` − 1) (None with the sizes).
    pub fn size_change(&self) -> Option<f64> {
        Some((1.0 - self.size_min?).max(self.size_max? - 1.0))
    }
}

/// The hold of window `index` of `windows` (module docs) from its frames (each frame of the
/// window once, in any order); None when no frame lies in the window's middle
/// [`MIDDLE_SHARE`].
pub fn zoom_hold(frames: &[ZoomFrame], index: usize, windows: usize) -> Option<ZoomHold> {
    let (start, end) = window_bounds(index, windows.max(1));
    // As `framing.framed_share`: the share of the window, about its middle.
    let in_middle =
        |t: f64| ((t - start) / (end - start) - 0.5).abs() <= 0.5 * MIDDLE_SHARE + 1e-12;
    let middle: Vec<&ZoomFrame> = frames.iter().filter(|f| in_middle(f.t)).collect();
    if middle.is_empty() {
        return None;
    }
    let ratio = |fovs: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = fovs.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        hi / lo
    };
    let sizes: Vec<f64> = middle.iter().map(|f| f.coverage.max(0.0).sqrt()).collect();
    let mean = sizes.iter().sum::<f64>() / sizes.len() as f64;
    let relative = |pick: fn(f64, f64) -> f64, from: f64| {
        (mean > 0.0).then(|| sizes.iter().copied().fold(from, pick) / mean)
    };
    Some(ZoomHold {
        frames: middle.len(),
        size_min: relative(f64::min, f64::INFINITY),
        size_max: relative(f64::max, 0.0),
        fov_ratio: ratio(&mut frames.iter().map(|f| f.fov_x_degrees)),
        fov_ratio_middle: ratio(&mut middle.iter().map(|f| f.fov_x_degrees)),
    })
}

/// The deviations of window `index` of `windows` from `shot`, at `samples` (≥ 2) evenly spaced
/// times of the window, with the poses `pose_at` gives for times of the whole trajectory.
pub fn shot_metrics(
    shot: &ShotPath,
    index: usize,
    windows: usize,
    samples: usize,
    pose_at: &dyn Fn(&[f64]) -> Vec<Pose>,
) -> ShotMetrics {
    let samples = samples.max(2);
    let (start, end) = window_bounds(index, windows.max(1));
    let within: Vec<f64> = (0..samples)
        .map(|k| k as f64 / (samples - 1) as f64)
        .collect();
    let times: Vec<f64> = within.iter().map(|s| start + s * (end - start)).collect();
    let poses = pose_at(&times);
    let (o, up) = (shot.object_centre, shot.up);
    let horizontal = |v: DVec3| v - up * v.dot(up);
    let mut elevation = Vec::with_capacity(samples);
    let mut radius = Vec::with_capacity(samples);
    let mut relative = Vec::with_capacity(samples);
    let mut azimuth = Vec::with_capacity(samples);
    let mut aim = Vec::with_capacity(samples);
    for (&s, pose) in within.iter().zip(&poses) {
        let c = DVec3::new(pose[3], pose[4], pose[5]);
        let offset = c - o;
        let distance = offset.length();
        let wanted_radius = shot.radius_at(s);
        let height = (offset.dot(up) / distance.max(f64::MIN_POSITIVE)).clamp(-1.0, 1.0);
        elevation.push((height.asin() - shot.elevation).abs().to_degrees());
        radius.push((distance - wanted_radius).abs());
        relative.push((distance - wanted_radius).abs() / wanted_radius);
        let (got, want) = (horizontal(offset), horizontal(shot.centre_at(s) - o));
        azimuth.push(if got.length() > 1e-12 && want.length() > 1e-12 {
            got.angle_between(want).to_degrees()
        } else {
            0.0
        });
        let forward = rotation_vector_to_matrix(DVec3::new(pose[0], pose[1], pose[2])).z_axis;
        let to_aim = shot.aim_at(s) - c;
        aim.push(if to_aim.length() > 1e-12 {
            forward.angle_between(to_aim).to_degrees()
        } else {
            0.0
        });
    }
    ShotMetrics {
        kind: shot.kind,
        samples,
        elevation: Deviation::of(&elevation),
        radius: Deviation::of(&radius),
        radius_relative: Deviation::of(&relative),
        azimuth: Deviation::of(&azimuth),
        aim: Deviation::of(&aim),
        zoom: None,
    }
}
