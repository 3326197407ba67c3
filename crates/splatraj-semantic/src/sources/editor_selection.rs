//! A part given as the splats a user selected in an editor (SuperSplat's brush, lasso, sphere or
//! box, exported as its own file; any tool that writes a subset of the scene): read with the
//! scene crate's readers (every format they read) and matched to this scene's Gaussians.
//!
//! **Matching.** Each selected splat takes the nearest Gaussian of the scene, not yet taken,
//! that lies within the position tolerance and whose scales and base colour agree with it
//! ([`SCALE_TOLERANCE`], [`COLOUR_TOLERANCE`]): position finds the Gaussian, scale and colour
//! confirm it, so that two Gaussians at one place (real captures have them) are told apart
//! and a file from another capture that happens to have a splat near one of ours is not taken
//! for ours. Candidates come from a k-d tree of the scene's centres (kiddo, through
//! [`PointIndex`]): a scene has up to millions of Gaussians and a selection tens of thousands,
//! so a linear search per splat would cost 10¹⁰ distance evaluations.
//!
//! **Tolerance.** A selection written in the scene's own format and precision lands exactly on
//! its Gaussians; one written in another (a compressed PLY or SPZ export of a PLY scene) moves
//! each centre by that format's quantisation step, a small share of the scene's spacing (the
//! median distance between neighbouring Gaussians, measured on the scene). The tolerance is
//! [`POSITION_TOLERANCE`] of that spacing: on the real captures the quantised exports moved
//! centres by at most 0.26 of it (donut written as SPZ, whose 1/4096-unit grid is a third of
//! that scene's spacing; measured in `tests/editor_selection.rs`), while a file from
//! another capture, or this one moved, turned or scaled in the editor before export, has most
//! of its splats farther than that from any of ours with a matching scale and colour.
//!
//! **Verdict.** A selection whose matched share is below [`MIN_MATCHED_SHARE`] is refused,
//! naming the file, the share and the median distance to the scene's nearest Gaussian (in
//! scene units and in spacings); an empty one is refused too. One that matches all but a few
//! splats is kept, with a note saying how many were left out.

use std::path::{Path, PathBuf};

use splatraj_scene::{InvalidPolicy, ReadOptions, Scene, read_scene};

use crate::cluster::PointIndex;
use crate::error::{Result, SemanticError};

/// Position tolerance, as a share of the scene's spacing (median nearest-neighbour distance).
pub const POSITION_TOLERANCE: f32 = 0.5;
/// Largest difference of a scale's logarithm (per axis) between a selected splat and its
/// Gaussian: SPZ stores log-scales in steps of 1/16, SOG in a 256-entry codebook.
pub const SCALE_TOLERANCE: f32 = 0.25;
/// Largest difference of a base colour channel (0–1) between a selected splat and its
/// Gaussian: 8-bit colour and SOG's codebook move it by a few hundredths.
pub const COLOUR_TOLERANCE: f32 = 0.1;
/// Scales below this share of the scene's spacing compare as equal to it (see [`agree`]).
pub const SCALE_FLOOR: f32 = 0.01;
/// Share of the selected splats that must match for the file to count as a subset of the
/// scene: an exact subset matches all of them; a few left out are noted, more refuse it.
pub const MIN_MATCHED_SHARE: f64 = 0.99;
/// Nearest candidates looked at per selected splat (near-duplicates of a Gaussian).
const CANDIDATES: usize = 8;
/// Scene Gaussians sampled to measure the spacing.
const SPACING_SAMPLES: usize = 4096;

/// A selection file, read: the selected splats and where they came from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SelectionFile {
    /// The file.
    pub path: PathBuf,
    /// The selected splats.
    pub splats: Scene,
    /// Splats dropped on reading because they cannot be rendered (so cannot be in the scene).
    pub dropped: usize,
}

impl SelectionFile {
    /// Reads `path` with the scene readers (any format they read); an empty selection is
    /// refused, naming the file.
    pub fn read(path: &Path) -> Result<Self> {
        let options = ReadOptions {
            invalid: InvalidPolicy::Drop,
            labels: None,
        };
        let loaded = read_scene(path, &options).map_err(|e| {
            SemanticError::file(path, format!("cannot read the selection file: {e}"))
        })?;
        if loaded.scene.is_empty() {
            return Err(SemanticError::file(
                path,
                if loaded.dropped > 0 {
                    format!(
                        "the selection holds no usable splat ({} dropped as invalid)",
                        loaded.dropped
                    )
                } else {
                    "the selection is empty: it holds no splat; select the part in the editor \
                     and export only the selected splats"
                        .to_string()
                },
            ));
        }
        Ok(SelectionFile {
            path: path.to_path_buf(),
            splats: loaded.scene,
            dropped: loaded.dropped,
        })
    }
}

/// How a selection file matched a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectionMatch {
    /// The scene's Gaussians it matched, sorted.
    pub indices: Vec<usize>,
    /// Splats in the file.
    pub selected: usize,
    /// Splats with a scene Gaussian within the tolerance whose scale or colour disagreed.
    pub attributes_differ: usize,
    /// Median distance from a selected splat to the scene's nearest Gaussian.
    pub median_distance: f32,
    /// The scene's spacing: median distance between neighbouring Gaussians.
    pub spacing: f32,
    /// The position tolerance used.
    pub tolerance: f32,
}

impl SelectionMatch {
    /// Share of the selected splats matched.
    pub fn share(&self) -> f64 {
        self.indices.len() as f64 / self.selected.max(1) as f64
    }

    /// One line for the user: `matched 1234 of 1234 splats (100.0 %) of head.ply`.
    pub fn describe(&self, path: &Path) -> String {
        let left = self.selected - self.indices.len();
        let mut line = format!(
            "selection {}: matched {} of {} splats ({:.1} %) to the scene's Gaussians",
            path.display(),
            self.indices.len(),
            self.selected,
            100.0 * self.share()
        );
        if left > 0 {
            line.push_str(&format!(
                "; {left} left out (no Gaussian within {:.3e} with the same scale and colour)",
                self.tolerance
            ));
        }
        line
    }
}

/// Matches `selection` to `scene`'s Gaussians (see the module docs); refuses a selection that
/// is not a subset of the scene, naming the file, the share matched and at what distance.
pub fn match_selection(scene: &Scene, selection: &SelectionFile) -> Result<SelectionMatch> {
    let path = &selection.path;
    let splats = &selection.splats;
    if scene.is_empty() {
        return Err(SemanticError::EmptyScene);
    }
    let index = PointIndex::new(&scene.means)?;
    let spacing = spacing(scene, &index);
    let tolerance = POSITION_TOLERANCE * spacing;
    let floor = SCALE_FLOOR * spacing;
    let mut taken = vec![false; scene.len()];
    let mut indices = Vec::with_capacity(splats.len());
    let mut attributes_differ = 0usize;
    let mut nearest = Vec::with_capacity(splats.len());
    for s in 0..splats.len() {
        let candidates = index.nearest(&splats.means[s], CANDIDATES);
        nearest.push(candidates.first().map_or(f32::INFINITY, |c| c.1));
        let close: Vec<usize> = candidates
            .iter()
            .filter(|(i, d)| *d <= tolerance && !taken[*i])
            .map(|(i, _)| *i)
            .collect();
        match close
            .into_iter()
            .find(|&g| agree(scene, g, splats, s, floor))
        {
            Some(g) => {
                taken[g] = true;
                indices.push(g);
            }
            None if candidates.iter().any(|(_, d)| *d <= tolerance) => attributes_differ += 1,
            None => {}
        }
    }
    indices.sort_unstable();
    nearest.sort_by(f32::total_cmp);
    let matched = SelectionMatch {
        indices,
        selected: splats.len(),
        attributes_differ,
        median_distance: nearest[nearest.len() / 2],
        spacing,
        tolerance,
    };
    if matched.share() < MIN_MATCHED_SHARE {
        return Err(not_a_subset(path, &matched));
    }
    Ok(matched)
}

/// The refusal of a selection that matched too few splats: the share, the distances and the
/// likely causes.
fn not_a_subset(path: &Path, m: &SelectionMatch) -> SemanticError {
    let spacings = if m.spacing > 0.0 {
        format!(
            " ({:.1} × the scene's spacing {:.3e})",
            m.median_distance / m.spacing,
            m.spacing
        )
    } else {
        String::new()
    };
    let attributes = if m.attributes_differ > 0 {
        format!(
            "; {} more lie on a Gaussian of the scene but differ in scale or colour",
            m.attributes_differ
        )
    } else {
        String::new()
    };
    SemanticError::file(
        path,
        format!(
            "the selection is not part of this scene: {} of its {} splats ({:.1} %, {:.0} % \
             needed) match a Gaussian within {:.3e} with the same scale and colour{attributes}; \
             the median distance from a selected splat to the nearest Gaussian is \
             {:.3e}{spacings}. Export the selection from this very scene file, and if the \
             scene was moved, turned or scaled in the editor, export the whole scene with it \
             and use that file as [scene] path",
            m.indices.len(),
            m.selected,
            100.0 * m.share(),
            100.0 * MIN_MATCHED_SHARE,
            m.tolerance,
            m.median_distance,
        ),
    )
}

/// The scene's spacing: the median distance from a Gaussian to its nearest other one, over
/// up to [`SPACING_SAMPLES`] evenly strided Gaussians, ignoring exact duplicates (which would
/// make it 0 where a trainer left copies).
fn spacing(scene: &Scene, index: &PointIndex) -> f32 {
    let step = scene.len().div_ceil(SPACING_SAMPLES).max(1);
    let mut distances: Vec<f32> = (0..scene.len())
        .step_by(step)
        .filter_map(|i| {
            index
                .nearest(&scene.means[i], 4)
                .into_iter()
                .map(|(_, d)| d)
                .find(|&d| d > 0.0)
        })
        .collect();
    if distances.is_empty() {
        return 0.0;
    }
    distances.sort_by(f32::total_cmp);
    distances[distances.len() / 2]
}

/// Whether splat `s` of `splats` and Gaussian `g` of `scene` have the same scales (per axis,
/// in log, each at least `floor`) and base colour (each channel in [0, 1]), within the
/// tolerances. The floor and the clamp are where formats saturate: SPZ stores log-scales from
/// −10 and colours up to about 1.44, and an axis far thinner than the scene's spacing is flat
/// whatever its exact width; a colour beyond [0, 1] shows as its end.
fn agree(scene: &Scene, g: usize, splats: &Scene, s: usize, floor: f32) -> bool {
    let (a, b) = (scene.scales[g], splats.scales[s]);
    let log = |v: f32| v.max(floor).ln();
    let scales = (0..3).all(|k| (log(a[k]) - log(b[k])).abs() <= SCALE_TOLERANCE);
    let (c, d) = (scene.base_color(g), splats.base_color(s));
    let colour = (0..3).all(|k| (c[k].min(1.0) - d[k].min(1.0)).abs() <= COLOUR_TOLERANCE);
    scales && colour
}
