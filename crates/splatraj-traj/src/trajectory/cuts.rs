//! Cuts: a trajectory made of shots, each its own continuous path, with hard switches between.
//!
//! A cut ends one shot and starts the next at the boundary of two query windows (`[output]
//! transitions`, [`crate::transitions`]). The windows split t ∈ [0, 1] evenly
//! (window i of n is [i/n, (i+1)/n]); a shot is a run of consecutive windows, so shot j spans
//! [a_j, b_j] with a_j = (first window)/n and b_j = (last window + 1)/n. A time belongs to the
//! shot of its window ([`crate::optimise::sampling::window_of`]: a time on a cut belongs to the
//! later shot, t = 1 to the last), the same rule ([`window_of`], here, which
//! `optimise::sampling` re-exports) the frames, the metrics and the optimiser's samples use,
//! so every reader agrees on which side of a cut a time lies.
//!
//! [`CutModel`] is a [`Basis`] built from any built-in model: shot j gets its own copy of the
//! model for its m_j windows over its local time s = (t − a_j)/(b_j − a_j) ∈ [0, 1], and the
//! basis is block-diagonal:
//!
//! ```text
//! Ψ(t) = [0 … 0  Ψ_j(s)  0 … 0]     for t in shot j
//! ```
//!
//! so Φ(t) = Ψ(t)·W is shot j's own trajectory on its rows of W and nothing else: continuous
//! within a shot, free to jump at a cut. Because the blocks share no weight, one Adam run over
//! the whole W optimises every shot as its own trajectory over its share of the time (Adam
//! steps each weight by its own gradient), and every caller that takes a [`Trajectory`](super::Trajectory)
//! (fitting, checkpoints, `trajectory.json`, the frames) works unchanged. The shot copy of an
//! RBF gets σ scaled to local time (σ·n/m_j: the same width in t); a waypoint model gets its
//! share of the segments (at least one).

use serde::{Deserialize, Serialize};

use super::{Basis, TrajectoryError, TrajectoryModel};

/// Window `[start, end)` of query `index` among `windows` queries.
pub fn window_bounds(index: usize, windows: usize) -> (f64, f64) {
    let n = windows.max(1) as f64;
    (index as f64 / n, (index + 1) as f64 / n)
}

/// Which window a time belongs to (t = 1 belongs to the last one).
pub fn window_of(t: f64, windows: usize) -> usize {
    let n = windows.max(1);
    ((t * n as f64).floor().max(0.0) as usize).min(n - 1)
}

/// Which windows form which shot: the windows where a new shot begins.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShotSpans {
    /// Query windows n of the whole trajectory.
    pub windows: usize,
    /// The windows that begin a shot after a cut, ascending, each in 1..n (the first shot
    /// begins at window 0).
    pub cuts: Vec<usize>,
}

impl ShotSpans {
    /// One shot of all `windows` windows (no cut).
    pub fn single(windows: usize) -> Self {
        Self {
            windows,
            cuts: Vec::new(),
        }
    }

    /// Shots of `windows` windows cut before each window of `cuts`.
    pub fn new(windows: usize, mut cuts: Vec<usize>) -> Result<Self, TrajectoryError> {
        cuts.sort_unstable();
        cuts.dedup();
        if let Some(&bad) = cuts.iter().find(|&&c| c == 0 || c >= windows) {
            return Err(TrajectoryError::InvalidModel {
                key: "cuts",
                reason: format!(
                    "a cut before window {bad} is not between two of the {windows} windows"
                ),
            });
        }
        Ok(Self { windows, cuts })
    }

    /// Number of shots.
    pub fn len(&self) -> usize {
        self.cuts.len() + 1
    }

    /// Whether there is no cut (one shot).
    pub fn is_empty(&self) -> bool {
        self.cuts.is_empty()
    }

    /// The windows of shot `shot`, as a range of window indices.
    pub fn window_range(&self, shot: usize) -> std::ops::Range<usize> {
        let start = if shot == 0 { 0 } else { self.cuts[shot - 1] };
        let end = self.cuts.get(shot).copied().unwrap_or(self.windows);
        start..end
    }

    /// The shot window `window` belongs to.
    pub fn shot_of_window(&self, window: usize) -> usize {
        self.cuts.iter().take_while(|&&c| c <= window).count()
    }

    /// The shot time `t` belongs to (module docs: a time on a cut is the later shot's).
    pub fn shot_of(&self, t: f64) -> usize {
        self.shot_of_window(window_of(t, self.windows))
    }

    /// Start and end of shot `shot` in t.
    pub fn span(&self, shot: usize) -> (f64, f64) {
        let range = self.window_range(shot);
        let n = self.windows.max(1);
        (
            window_bounds(range.start, n).0,
            window_bounds(range.end - 1, n).1,
        )
    }

    /// The times of the cuts, ascending.
    pub fn cut_times(&self) -> Vec<f64> {
        let n = self.windows.max(1) as f64;
        self.cuts.iter().map(|&c| c as f64 / n).collect()
    }

    /// Whether `a` and `b` lie in the same shot (a motion between them is a real one).
    pub fn same_shot(&self, a: f64, b: f64) -> bool {
        self.shot_of(a) == self.shot_of(b)
    }
}

/// A trajectory model cut into shots (module docs): `model`'s basis per shot, block-diagonal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "CutModelFile", into = "CutModelFile")]
pub struct CutModel {
    /// The model each shot uses (for all n windows; each shot gets its copy for its own).
    model: Box<TrajectoryModel>,
    /// The shots.
    spans: ShotSpans,
    /// Shot j's model, built once (for its windows and its local time).
    shots: Vec<TrajectoryModel>,
    /// Row of W where shot j's block begins (and, last, K).
    offsets: Vec<usize>,
}

/// `model = { kind = "cuts", windows, cuts, model = { … } }` as written in `trajectory.json`.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CutModelFile {
    windows: usize,
    cuts: Vec<usize>,
    model: Box<TrajectoryModel>,
}

impl TryFrom<CutModelFile> for CutModel {
    type Error = TrajectoryError;
    fn try_from(file: CutModelFile) -> Result<Self, TrajectoryError> {
        CutModel::new(*file.model, ShotSpans::new(file.windows, file.cuts)?)
    }
}

impl From<CutModel> for CutModelFile {
    fn from(model: CutModel) -> Self {
        Self {
            windows: model.spans.windows,
            cuts: model.spans.cuts,
            model: model.model,
        }
    }
}

/// `model` as shot `shot` of `spans` holds it: for its windows, over its local time.
fn shot_model(model: &TrajectoryModel, spans: &ShotSpans, shot: usize) -> TrajectoryModel {
    let m = spans.window_range(shot).len();
    let n = spans.windows.max(1);
    match model {
        TrajectoryModel::Rbf(rbf) => TrajectoryModel::Rbf(super::Rbf {
            windows: m,
            sigma: rbf.sigma.map(|s| s * n as f64 / m as f64),
            ..rbf.clone()
        }),
        TrajectoryModel::Waypoint(w) => TrajectoryModel::Waypoint(super::Waypoint {
            segments: (w.segments * m).div_ceil(n).max(1),
        }),
        other => other.clone(),
    }
}

impl CutModel {
    /// `model` (built in, not itself cut) cut into the shots of `spans`.
    pub fn new(model: TrajectoryModel, spans: ShotSpans) -> Result<Self, TrajectoryError> {
        if matches!(model, TrajectoryModel::Custom(_) | TrajectoryModel::Cuts(_)) {
            return Err(TrajectoryError::InvalidModel {
                key: "kind",
                reason: format!(
                    "cuts need a built-in model (rbf, waypoint or polynomial), not {}",
                    model.name()
                ),
            });
        }
        let model = model.with_windows(spans.windows);
        let shots: Vec<TrajectoryModel> = (0..spans.len())
            .map(|j| shot_model(&model, &spans, j))
            .collect();
        let mut offsets = vec![0];
        for shot in &shots {
            offsets.push(offsets.last().copied().unwrap_or(0) + shot.count());
        }
        Ok(Self {
            model: Box::new(model),
            spans,
            shots,
            offsets,
        })
    }

    /// The shots.
    pub fn spans(&self) -> &ShotSpans {
        &self.spans
    }

    /// The model every shot uses.
    pub fn model(&self) -> &TrajectoryModel {
        &self.model
    }
}

impl Basis for CutModel {
    fn count(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    fn validate(&self) -> Result<(), TrajectoryError> {
        self.shots.iter().try_for_each(|m| m.validate())
    }

    fn eval_into(&self, t: f64, row: &mut [f64]) {
        row.fill(0.0);
        let shot = self.spans.shot_of(t);
        let (a, b) = self.spans.span(shot);
        let s = (t - a) / (b - a);
        let block = &mut row[self.offsets[shot]..self.offsets[shot + 1]];
        self.shots[shot].eval_into(s, block);
    }
}
