//! One output frame's metrics: a row of `frame_metrics.csv`, written by the path renderer and
//! read by the run's summary (a leaf, so that both can name it).

/// One frame's metrics for the object of its window (a row of `frame_metrics.csv`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameMetrics {
    /// Frame index.
    pub frame: usize,
    /// Time t ∈ [0, 1].
    pub t: f64,
    /// Its window.
    pub window: usize,
    /// Target centring error; `None` when the frame does not show the object (an empty mask
    /// has no centre: undefined, not 0; an empty cell in `frame_metrics.csv`).
    pub tce: Option<f64>,
    /// Target ratio error.
    pub tre: f64,
    /// Share of the frame the visible object covers.
    pub coverage: f64,
}
