//! The densely sampled path the path costs read ([`super::CostDomain::Path`]): one window's
//! stretch, or every window's stretches joined so that a shared optimisation step evaluates
//! a path cost once for all windows (docs/gpu.md, "One pass a step").
//!
//! The built-in path costs (motion, clearance) are computed on the host, a stretch at a time
//! ([`super::expansion::per_stretch_on_host`]). The helpers below are for a path cost written
//! as tensor ops (a custom one, or the motion cost's tensor formulation that
//! `tests/motion_host.rs` keeps as its yardstick).
//!
//! Such a cost works on rows of the joined poses `[ΣP, 6]`: per pose (lag 0), per pair of
//! consecutive poses (lag 1: velocities, turns) or per triple (lag 2: accelerations). Row k
//! of lag `l` reads poses k ..= k + l; a row whose poses lie in two stretches pairs the end
//! of one window's path with the start of the next, which no window's cost has: it is
//! computed (so every row's arithmetic is one tensor op) but weighs nothing in
//! [`PathSamples::stretch_means`], the one place rows become per-window values. With a
//! single stretch every helper is the plain op a window on its own has always used (a mean,
//! a scalar), so a window evaluated alone keeps its digits.

use burn::tensor::{Tensor, TensorData};

use super::{CostError, QueryContext};

/// One window's stretch of a (joined) path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathStretch {
    /// How many consecutive poses of the path are this stretch's.
    pub rows: usize,
    /// Normalised time between its consecutive poses.
    pub time_step: f64,
    /// Its window's context (the orbit limit reads the object centre).
    pub context: QueryContext,
}

/// The path costs' poses: one window's stretch of the trajectory, densely sampled in time
/// order, or several windows' stretches one after the other (trajectory optimisation only).
#[derive(Debug, Clone)]
pub struct PathSamples {
    /// Poses Φ `[ΣP, 6]`: each stretch's poses at evenly spaced times, in time order.
    pub poses: Tensor<2>,
    /// The stretches, in the order of the rows (their `rows` add up to ΣP).
    stretches: Vec<PathStretch>,
    /// Duration of the whole trajectory (t from 0 to 1) in seconds, when known.
    pub seconds: Option<f64>,
}

/// A number per row of a path: one for all rows (a scalar op) or a column of them.
#[derive(Debug, Clone)]
pub enum PerRow {
    /// Every row's value.
    Same(f64),
    /// Each row's value `[N]` (boxed: a tensor handle is large).
    Rows(Box<Tensor<1>>),
}

impl PerRow {
    /// `values / self`, row by row, `[N]`.
    pub fn divide(&self, values: Tensor<1>) -> Tensor<1> {
        match self {
            PerRow::Same(v) => values.div_scalar(*v),
            PerRow::Rows(rows) => values / *rows.clone(),
        }
    }

    /// `max(values, self)`, row by row, of a column `[N, 1]`.
    pub fn floor(&self, values: Tensor<2>) -> Tensor<2> {
        match self {
            PerRow::Same(v) => values.clamp_min(*v),
            PerRow::Rows(rows) => {
                let [count] = rows.dims();
                values.max_pair(rows.clone().reshape([count, 1]))
            }
        }
    }
}

impl PathSamples {
    /// One window's stretch: poses `[P, 6]` `time_step` apart, its window's `context`.
    pub fn new(
        poses: Tensor<2>,
        time_step: f64,
        seconds: Option<f64>,
        context: QueryContext,
    ) -> Self {
        let [rows, _] = poses.dims();
        Self {
            poses,
            stretches: vec![PathStretch {
                rows,
                time_step,
                context,
            }],
            seconds,
        }
    }

    /// Several windows' stretches joined: poses `[ΣP, 6]`, the stretches in row order.
    pub fn joined(
        poses: Tensor<2>,
        stretches: Vec<PathStretch>,
        seconds: Option<f64>,
    ) -> Result<Self, CostError> {
        let [rows, _] = poses.dims();
        let total: usize = stretches.iter().map(|s| s.rows).sum();
        if stretches.is_empty() || total != rows {
            return Err(CostError::Shape(format!(
                "{} path stretches of {total} poses for a path of {rows}",
                stretches.len()
            )));
        }
        for s in &stretches {
            s.context.validate()?;
        }
        Ok(Self {
            poses,
            stretches,
            seconds,
        })
    }

    /// The stretches, in row order (one for a window's own path).
    pub fn stretches(&self) -> &[PathStretch] {
        &self.stretches
    }

    /// Normalised time between consecutive poses of the first stretch (the only one of a
    /// window's own path).
    pub fn time_step(&self) -> f64 {
        self.stretches[0].time_step
    }

    /// Number of poses ΣP.
    pub fn rows(&self) -> usize {
        self.poses.dims()[0]
    }

    /// Index of the stretch of each pose, `[ΣP]`.
    fn stretch_of_pose(&self) -> Vec<usize> {
        self.stretches
            .iter()
            .enumerate()
            .flat_map(|(i, s)| std::iter::repeat_n(i, s.rows))
            .collect()
    }

    /// `f` of each row's stretch for rows of lag `lag` (a row takes its first pose's
    /// stretch): [`PerRow::Same`] when every stretch gives the same number.
    pub fn per_row(&self, lag: usize, f: impl Fn(&PathStretch) -> f64) -> PerRow {
        let first = f(&self.stretches[0]);
        if self.stretches.iter().all(|s| f(s) == first) {
            return PerRow::Same(first);
        }
        let count = self.rows().saturating_sub(lag);
        let values: Vec<f64> = self.stretch_of_pose()[..count]
            .iter()
            .map(|&i| f(&self.stretches[i]))
            .collect();
        PerRow::Rows(Box::new(self.upload1(values)))
    }

    /// `f` of each pose's window context as rows: `[1, K]` when every stretch has the same
    /// (it broadcasts), else `[ΣP, K]`.
    pub fn context_rows<const K: usize>(&self, f: impl Fn(&QueryContext) -> [f64; K]) -> Tensor<2> {
        let first = f(&self.stretches[0].context);
        let rows: Vec<f64> = if self.stretches.iter().all(|s| f(&s.context) == first) {
            first.to_vec()
        } else {
            self.stretch_of_pose()
                .iter()
                .flat_map(|&i| f(&self.stretches[i].context))
                .collect()
        };
        let count = rows.len() / K;
        splatraj_render::host::upload(
            TensorData::new(rows, [count, K]),
            &self.poses.device(),
            self.poses.dtype(),
        )
    }

    /// Each stretch's mean of `values` `[ΣP − lag]` (rows of lag `lag`), `[W]`: over the rows
    /// whose poses all lie in the stretch; 0 for a stretch of fewer than `min_rows` poses.
    /// One stretch: the mean of all rows `[1]` (the caller checks its length). Several: one
    /// matrix product with the averaging weights, so the rows that cross from one stretch
    /// to the next weigh nothing.
    pub fn stretch_means(&self, values: Tensor<1>, lag: usize, min_rows: usize) -> Tensor<1> {
        let [count] = values.dims();
        let windows = self.stretches.len();
        if windows == 1 {
            return values.mean();
        }
        // [W, ΣP − lag]: 1/(P_i − lag) on stretch i's own rows.
        let mut weights = vec![0.0; windows * count];
        let mut start = 0;
        for (i, s) in self.stretches.iter().enumerate() {
            if s.rows >= min_rows.max(lag + 1) {
                let own = s.rows - lag;
                for k in start..start + own {
                    weights[i * count + k] = 1.0 / own as f64;
                }
            }
            start += s.rows;
        }
        let weights: Tensor<2> = splatraj_render::host::upload(
            TensorData::new(weights, [windows, count]),
            &values.device(),
            values.dtype(),
        );
        weights
            .matmul(values.reshape([count, 1]))
            .reshape([windows])
    }

    /// Each stretch's value `[W]` on every row of lag `lag`, `[ΣP − lag]` (a row takes its
    /// first pose's stretch's). One stretch: the value broadcast.
    pub fn spread(&self, values: Tensor<1>, lag: usize) -> Tensor<1> {
        let count = self.rows().saturating_sub(lag);
        let windows = self.stretches.len();
        if windows == 1 {
            return values.expand([count]);
        }
        // [ΣP − lag, W]: 1 in each row's stretch's column.
        let mut select = vec![0.0; count * windows];
        for (k, &i) in self.stretch_of_pose()[..count].iter().enumerate() {
            select[k * windows + i] = 1.0;
        }
        let select: Tensor<2> = splatraj_render::host::upload(
            TensorData::new(select, [count, windows]),
            &values.device(),
            values.dtype(),
        );
        select.matmul(values.reshape([windows, 1])).reshape([count])
    }

    /// One value per stretch `[W]` from a single value `[1]` (a window's own path: itself).
    pub fn per_stretch(&self, value: Tensor<1>) -> Tensor<1> {
        match self.stretches.len() {
            1 => value,
            windows => value.expand([windows]),
        }
    }

    fn upload1(&self, values: Vec<f64>) -> Tensor<1> {
        let count = values.len();
        splatraj_render::host::upload(
            TensorData::new(values, [count]),
            &self.poses.device(),
            self.poses.dtype(),
        )
    }
}
