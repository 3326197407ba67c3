//! Trajectory models: camera poses Φ(t) `[B, 6]` as a linear function of fixed bases of t.
//!
//! Every model of docs/conventions.md ("Optimisation problem") has the same shape: six independent
//! scalar functions of normalised time t ∈ [0, 1], each a weighted sum of the same K basis
//! functions,
//!
//! ```text
//! Φ(t) = Ψ(t) · W        Ψ(t): [B, K] basis values, W: [K, 6] weights (the only parameters)
//! ```
//!
//! with Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z] (rotation vector of R_wc, camera centre;
//! docs/conventions.md "Conventions"). Models differ only in Ψ, so the design splits the two:
//!
//! - [`Basis`] is a plain trait (no burn types in its required methods): the number of bases K
//!   and ψ_k(t) on the host in f64; optionally a tensor evaluation that avoids a host round trip.
//!   One file per model implements it: [`rbf`] (SplaTraj), [`waypoint`], [`polynomial`].
//! - [`TrajectoryModel`] is the serialisable choice among them (`kind = "rbf" | "waypoint" |
//!   "polynomial"` plus that model's parameters, or `kind = "custom.<name>"` for a model another
//!   crate registered), an enum that forwards [`Basis`] to its variant.
//! - [`Trajectory`] is the one burn Module: `weights: Param<Tensor<2>>` `[K, 6]` plus the model
//!   as a `#[module(skip)]` field (burn 0.22's derive needs Debug + Clone + Send for a skipped
//!   field and keeps it out of parameter traversal, device moves and records).
//!
//! Why not a generic `Trajectory<B: Basis>` or a `Box<dyn Basis>` inside the module: the model is
//! chosen at run time from the config, and the optimiser, checkpoints and `trajectory.json` want
//! one concrete, serialisable Module type. A generic would push the dispatch into every caller;
//! a bare trait object cannot be (de)serialised. The enum keeps both.
//!
//! **Extending** (the pattern of the costs): a model is a config struct (serde, its parameters)
//! implementing [`ModelConfig`] (`init(windows)` builds its [`Basis`]), in a file of its own. A
//! crate outside splatraj registers it under a name in a [`ModelRegistry`]; a config chooses it
//! with `[trajectory] kind = "custom.<name>"` and gives its parameters in
//! `[trajectory.custom.<name>]`. Read from a file, it is a [`TrajectoryModel::Custom`] holding
//! the name and the table; [`TrajectoryModel::build_with`] builds its basis from the registry
//! (and sets the window count of the built-in RBF), and `trajectory.json` keeps name, table and
//! window count so that the same registry reads it back.
//!
//! Times outside [0, 1] are accepted: the RBF and polynomial models extend analytically, the
//! waypoint model holds its first/last segment. Rotation vectors are fitted and interpolated
//! component-wise, so a pose sequence handed to [`Trajectory::fit`] should not jump between
//! equivalent rotation vectors (θ and θ − 2π along the same axis): unwrap it first.

pub mod cuts;
pub mod lens;
pub mod polynomial;
pub mod rbf;
pub mod registry;
pub mod waypoint;

mod lstsq;

use burn::module::{Module, Param};
use burn::tensor::{DType, Device, Tensor, TensorData};
use serde::de::Error as _;
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub use cuts::{CutModel, ShotSpans};
pub use lens::{DEFAULT_ZOOM_MAX, DEFAULT_ZOOM_MIN, Lens, LensPath, ZoomRange};
pub use lstsq::DEFAULT_RIDGE;
pub use polynomial::Polynomial;
pub use rbf::{Rbf, RbfNormalisation};
pub use registry::{CUSTOM_PREFIX, CustomModel, ModelConfig, ModelRegistry};
pub use waypoint::Waypoint;

/// Number of pose components: rotation vector (3) then camera centre (3).
pub const POSE_DIM: usize = 6;

/// One camera pose Φ = [ω_x, ω_y, ω_z, c_x, c_y, c_z] on the host.
pub type Pose = [f64; POSE_DIM];

/// Why a trajectory model or trajectory could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// A model parameter is out of range; `key` is the parameter's name in the config.
    #[error("trajectory model: `{key}` {reason}")]
    InvalidModel {
        /// Config key of the offending parameter (e.g. `sigma`).
        key: &'static str,
        /// What is wrong and what is allowed.
        reason: String,
    },
    /// The weights do not have one row per basis function.
    #[error("trajectory weights: expected {expected} rows (one per basis function), got {got}")]
    WeightRows {
        /// Number of basis functions K of the model.
        expected: usize,
        /// Rows given.
        got: usize,
    },
    /// A weight is NaN, infinite or beyond ±[`MAX_WEIGHT`] (no renderable path has such a
    /// weight; its poses would overflow the renderer).
    #[error(
        "trajectory weights: row {row}, component {component} = {value:e} is not finite or \
         beyond ±{MAX_WEIGHT:e}"
    )]
    WeightValue {
        /// Row (basis function).
        row: usize,
        /// Pose component (0-2 rotation vector, 3-5 centre).
        component: usize,
        /// The value.
        value: f64,
    },
    /// Fitting data is inconsistent (lengths differ, nothing given, or a non-finite value).
    #[error("trajectory fit: {0}")]
    FitData(String),
    /// A custom model ([`ModelRegistry`]) is unknown, its table is malformed, or its own
    /// `init` refused it; the error's key is the config key at fault (e.g.
    /// `trajectory.custom.hat`).
    #[error(transparent)]
    Config(#[from] splatraj_config::ConfigError),
}

/// A family of K scalar basis functions ψ_k(t); one implementation per trajectory model.
/// `Debug + Send + Sync` so that a built custom basis can sit in the [`Trajectory`] module.
pub trait Basis: std::fmt::Debug + Send + Sync {
    /// Number of basis functions K (rows of the weight matrix).
    fn count(&self) -> usize;

    /// Checks the model's parameters; every constructor of [`Trajectory`] calls it first.
    fn validate(&self) -> Result<(), TrajectoryError>;

    /// Writes ψ_1(t) … ψ_K(t) into `row` (length K), in f64 on the host.
    fn eval_into(&self, t: f64, row: &mut [f64]);

    /// Basis matrix for `times`, row-major `[B, K]`, on the host.
    fn matrix(&self, times: &[f64]) -> Vec<f64> {
        let k = self.count();
        let mut out = vec![0.0; times.len() * k];
        for (row, &t) in out.chunks_exact_mut(k).zip(times) {
            self.eval_into(t, row);
        }
        out
    }

    /// Basis matrix `[B, K]` for times `[B]`, on the times' device and in their dtype.
    ///
    /// The default reads the times back to the host and evaluates [`Basis::matrix`]; models whose
    /// basis is a few elementwise ops override it to stay on the device. Times carry no gradient
    /// (they are sampled, not optimised), so neither version needs to differentiate in t.
    fn tensor(&self, times: Tensor<1>) -> Tensor<2> {
        let (device, dtype) = (times.device(), times.dtype());
        let [batch] = times.dims();
        let host = times
            .into_data()
            .try_into_vec_as::<f64>()
            .expect("float tensor data converts to f64");
        let data = TensorData::new(self.matrix(&host), [batch, self.count()]);
        splatraj_render::host::upload(data, &device, dtype)
    }
}

/// The trajectory model chosen in the config: which basis, with its parameters.
///
/// Serialised with an internal tag, e.g. TOML `kind = "rbf"`, `centres_per_window = 3`;
/// unknown keys are errors. A registered model is `kind = "custom.<name>"` with its table in
/// `custom.<name>` (see [`registry`]).
#[derive(Debug, Clone, PartialEq)]
pub enum TrajectoryModel {
    /// Squared-exponential RBFs, centres spread over the query windows (SplaTraj).
    Rbf(Rbf),
    /// Piecewise-constant segments (baseline).
    Waypoint(Waypoint),
    /// Monomials 1, t, …, t^(N−1) (baseline).
    Polynomial(Polynomial),
    /// A model registered by another crate ([`ModelRegistry`]).
    Custom(CustomModel),
    /// A built-in model cut into shots, each its own path (`kind = "cuts"`, [`cuts`]).
    Cuts(CutModel),
}

/// A cut model's serde form: its fields after `kind = "cuts"`.
#[derive(Serialize)]
struct TaggedCuts<'a> {
    kind: &'static str,
    #[serde(flatten)]
    model: &'a CutModel,
}

/// The built-in models' serde form (the internally tagged enum the derive writes).
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
enum Builtin {
    Rbf(Rbf),
    Waypoint(Waypoint),
    Polynomial(Polynomial),
}

impl Serialize for TrajectoryModel {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Rbf(m) => Builtin::Rbf(m.clone()).serialize(serializer),
            Self::Waypoint(m) => Builtin::Waypoint(m.clone()).serialize(serializer),
            Self::Polynomial(m) => Builtin::Polynomial(m.clone()).serialize(serializer),
            Self::Cuts(m) => TaggedCuts {
                kind: "cuts",
                model: m,
            }
            .serialize(serializer),
            Self::Custom(c) => {
                let mut map = serializer.serialize_map(None)?;
                map.serialize_entry("kind", &c.kind())?;
                if let Some(windows) = c.windows {
                    map.serialize_entry("windows", &windows)?;
                }
                let table = toml::Table::from_iter([(c.name.clone(), c.params.clone())]);
                map.serialize_entry("custom", &table)?;
                map.end()
            }
        }
    }
}

impl<'de> Deserialize<'de> for TrajectoryModel {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let value = toml::Value::deserialize(deserializer)?;
        let kind = value.get("kind").and_then(toml::Value::as_str);
        if kind == Some("cuts") {
            let mut table = value.as_table().cloned().unwrap_or_default();
            table.remove("kind");
            return CutModel::deserialize(toml::Value::Table(table))
                .map(Self::Cuts)
                .map_err(|e| D::Error::custom(e.message().trim_end()));
        }
        let custom_name = kind
            .and_then(|k| k.strip_prefix(CUSTOM_PREFIX))
            .map(str::to_string);
        let builtin = matches!(kind, Some("rbf" | "waypoint" | "polynomial"));
        let Some(name) = custom_name else {
            return Builtin::deserialize(value)
                .map(|b| match b {
                    Builtin::Rbf(m) => Self::Rbf(m),
                    Builtin::Waypoint(m) => Self::Waypoint(m),
                    Builtin::Polynomial(m) => Self::Polynomial(m),
                })
                .map_err(|e| {
                    let message = e.message().trim_end().to_string();
                    // Only an unknown `kind` may be a registered model's name; an unknown
                    // value of another key (`normalisation`) is that key's.
                    if message.contains("unknown variant") && !builtin {
                        D::Error::custom(format!(
                            "{message}, or `custom.<name>` for a registered model"
                        ))
                    } else {
                        D::Error::custom(message)
                    }
                });
        };
        let mut table = match value {
            toml::Value::Table(t) => t,
            _ => unreachable!("a value with a `kind` key is a table"),
        };
        table.remove("kind");
        let windows =
            match table.remove("windows") {
                None => None,
                Some(w) => Some(usize::deserialize(w).map_err(|e| {
                    D::Error::custom(format!("`windows`: {}", e.message().trim_end()))
                })?),
            };
        let mut custom = match table.remove("custom") {
            None => toml::Table::new(),
            Some(toml::Value::Table(t)) => t,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "`custom` must be a table holding `[trajectory.custom.{name}]`, got {other}"
                )));
            }
        };
        if let Some(key) = table.keys().next() {
            return Err(D::Error::custom(format!(
                "unknown field `{key}`: the parameters of `custom.{name}` go in \
                 `[trajectory.custom.{name}]`"
            )));
        }
        let params = custom
            .remove(&name)
            .unwrap_or_else(|| toml::Value::Table(toml::Table::new()));
        if let Some(other) = custom.keys().next() {
            return Err(D::Error::custom(format!(
                "`custom.{other}` is not the chosen model (kind = \"custom.{name}\")"
            )));
        }
        let mut model = CustomModel::new(name, params);
        model.windows = windows;
        Ok(Self::Custom(model))
    }
}

impl Default for TrajectoryModel {
    /// The paper's model: RBF with its defaults.
    fn default() -> Self {
        Self::Rbf(Rbf::default())
    }
}

impl TrajectoryModel {
    /// The model's basis as a trait object (the one place that lists the variants).
    pub fn basis(&self) -> &dyn Basis {
        match self {
            Self::Rbf(b) => b,
            Self::Waypoint(b) => b,
            Self::Polynomial(b) => b,
            Self::Custom(c) => c.basis(),
            Self::Cuts(c) => c,
        }
    }

    /// The model's config name (`rbf`, `waypoint`, `polynomial`, `custom.<name>`), as in
    /// `kind`.
    pub fn name(&self) -> String {
        match self {
            Self::Rbf(_) => "rbf".into(),
            Self::Waypoint(_) => "waypoint".into(),
            Self::Polynomial(_) => "polynomial".into(),
            Self::Custom(c) => c.kind(),
            Self::Cuts(c) => format!("{} with cuts", c.model().name()),
        }
    }

    /// The same model for `n` query windows: sets the RBF's window count, leaves others as
    /// they are (their bases do not depend on the queries; a custom model's basis is built
    /// for its windows by [`TrajectoryModel::build_with`]).
    pub fn with_windows(self, n: usize) -> Self {
        match self {
            Self::Rbf(rbf) => Self::Rbf(Rbf { windows: n, ..rbf }),
            other => other,
        }
    }

    /// The shots of this model over `windows` windows: a cut model's, else one shot.
    pub fn shots(&self, windows: usize) -> ShotSpans {
        match self {
            Self::Cuts(c) => c.spans().clone(),
            _ => ShotSpans::single(windows),
        }
    }

    /// This model cut into `spans`' shots (itself when there is no cut; a cut model is cut
    /// afresh from the model its shots use).
    pub fn cut(self, spans: ShotSpans) -> Result<Self, TrajectoryError> {
        let base = match self {
            Self::Cuts(c) => c.model().clone(),
            other => other,
        };
        if spans.is_empty() {
            return Ok(base.with_windows(spans.windows));
        }
        Ok(Self::Cuts(CutModel::new(base, spans)?))
    }
}

impl Basis for TrajectoryModel {
    fn count(&self) -> usize {
        self.basis().count()
    }
    fn validate(&self) -> Result<(), TrajectoryError> {
        self.basis().validate()
    }
    fn eval_into(&self, t: f64, row: &mut [f64]) {
        self.basis().eval_into(t, row)
    }
    fn matrix(&self, times: &[f64]) -> Vec<f64> {
        self.basis().matrix(times)
    }
    fn tensor(&self, times: Tensor<1>) -> Tensor<2> {
        self.basis().tensor(times)
    }
}

/// Largest weight a [`TrajectoryRecord`] may hold, in absolute value: the largest camera
/// coordinate the renderer accepts (`splatraj_render::camera_file::MAX_COORDINATE`).
pub const MAX_WEIGHT: f64 = splatraj_render::camera_file::MAX_COORDINATE;

/// A model with its weights, as written to `trajectory.json` and read back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryRecord {
    /// Which basis and its parameters.
    pub model: TrajectoryModel,
    /// Weights W, one row of six per basis function `[K][6]`.
    pub weights: Vec<Pose>,
    /// The zoom s(t) when the lens zooms ([`lens`]); absent (files from before the zoom, or a
    /// fixed lens): s ≡ 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<LensPath>,
}

impl TrajectoryRecord {
    /// Checks what every reader of a `trajectory.json` (or checkpoint) relies on: one row of
    /// weights per basis function (for a built-in model; a custom model's count needs its
    /// registry) and every weight finite within ±[`MAX_WEIGHT`].
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        // A built-in model must be a valid one (e.g. not an RBF of 0 windows); a custom one
        // can only be checked by its registry.
        if !matches!(self.model, TrajectoryModel::Custom(_)) {
            self.model.validate()?;
        }
        if self.model.validate().is_ok() && self.weights.len() != self.model.count() {
            return Err(TrajectoryError::WeightRows {
                expected: self.model.count(),
                got: self.weights.len(),
            });
        }
        for (row, w) in self.weights.iter().enumerate() {
            if let Some(component) = w
                .iter()
                .position(|v| !(v.is_finite() && v.abs() <= MAX_WEIGHT))
            {
                return Err(TrajectoryError::WeightValue {
                    row,
                    component,
                    value: w[component],
                });
            }
        }
        if let Some(lens) = &self.lens {
            lens.validate(self.weights.len())?;
        }
        Ok(())
    }

    /// This record with the lens `lens`: none for the fixed lens; for a zoom, its own zoom
    /// when it has one of that range (a start read from a `trajectory.json`), else zero
    /// weights (s ≡ 1).
    pub fn with_lens(self, lens: Lens) -> Self {
        let own = match lens {
            Lens::Zoom(range) => self.lens.filter(|l| l.range == range),
            Lens::Fixed => None,
        };
        let count = self.weights.len();
        Self {
            lens: own.or_else(|| lens.start(count)),
            ..self
        }
    }

    /// The zoom s at each of `times` (1 for a fixed lens), on the host in f64; needs a
    /// built-in model (a custom one's basis needs its registry: [`Trajectory::zooms_at`]).
    pub fn zooms_at(&self, times: &[f64]) -> Vec<f64> {
        match &self.lens {
            None => vec![1.0; times.len()],
            Some(lens) => lens.zooms(&self.model.matrix(times)),
        }
    }
}

/// A camera trajectory Φ(t) = Ψ(t)·W: the burn Module the optimiser updates.
#[derive(Module, Debug)]
pub struct Trajectory {
    /// Weights W `[K, 6]`: row k scales basis ψ_k in each of the six pose components.
    pub weights: Param<Tensor<2>>,
    /// The basis; not a parameter (skipped by the Module derive).
    #[module(skip)]
    model: TrajectoryModel,
    /// The zoom's free weights w_s `[K, 1]` when the lens zooms ([`lens`]): optimised with W.
    pub lens: Option<Param<Tensor<2>>>,
    /// The zoom's range (set exactly when `lens` is).
    #[module(skip)]
    zoom_range: Option<ZoomRange>,
}

impl Trajectory {
    /// A trajectory with all weights zero (Φ ≡ 0), in `dtype` on `device`.
    pub fn zeros(
        model: TrajectoryModel,
        device: &Device,
        dtype: DType,
    ) -> Result<Self, TrajectoryError> {
        model.validate()?;
        let weights = vec![[0.0; POSE_DIM]; model.count()];
        Self::from_weights(model, &weights, device, dtype)
    }

    /// A trajectory with the given weights `[K][6]`, in `dtype` on `device`.
    pub fn from_weights(
        model: TrajectoryModel,
        weights: &[Pose],
        device: &Device,
        dtype: DType,
    ) -> Result<Self, TrajectoryError> {
        model.validate()?;
        if weights.len() != model.count() {
            return Err(TrajectoryError::WeightRows {
                expected: model.count(),
                got: weights.len(),
            });
        }
        let flat: Vec<f64> = weights.iter().flatten().copied().collect();
        let data = TensorData::new(flat, [weights.len(), POSE_DIM]);
        let weights = Param::from_tensor(splatraj_render::host::upload(data, device, dtype));
        Ok(Self {
            weights,
            model,
            lens: None,
            zoom_range: None,
        })
    }

    /// This trajectory with the zoom `lens` (None: the fixed lens), on the weights' device and
    /// in their dtype.
    pub fn with_lens(mut self, lens: Option<&LensPath>) -> Result<Self, TrajectoryError> {
        let Some(lens) = lens else {
            self.lens = None;
            self.zoom_range = None;
            return Ok(self);
        };
        lens.validate(self.model.count())?;
        let value = self.weights.val();
        let data = TensorData::new(lens.weights.clone(), [lens.weights.len(), 1]);
        let tensor = splatraj_render::host::upload(data, &value.device(), value.dtype());
        self.lens = Some(Param::from_tensor(tensor));
        self.zoom_range = Some(lens.range);
        Ok(self)
    }

    /// The zoom's range and weights on the host; None for the fixed lens.
    pub fn lens_path(&self) -> Option<LensPath> {
        let (param, range) = (self.lens.as_ref()?, self.zoom_range?);
        let weights = param
            .val()
            .into_data()
            .try_into_vec_as::<f64>()
            .expect("float tensor data converts to f64");
        Some(LensPath { range, weights })
    }

    /// Zooms s(t) `[B]` for host times `[B]`, differentiable in the zoom's weights (the basis
    /// evaluated on the host, as [`Trajectory::forward_at`]); None for the fixed lens.
    pub fn zoom_at(&self, times: &[f64]) -> Option<Tensor<1>> {
        let (param, range) = (self.lens.as_ref()?, self.zoom_range?);
        let weights = param.val();
        let (device, dtype) = (weights.device(), weights.dtype());
        let data = TensorData::new(self.model.matrix(times), [times.len(), self.model.count()]);
        let u = splatraj_render::host::upload::<2>(data, &device, dtype).matmul(weights); // [B, 1]
        Some(range.zoom_tensor(u.reshape([times.len()])))
    }

    /// Zooms s(t) at any times on the host in f64 (1 for the fixed lens).
    pub fn zooms_at(&self, times: &[f64]) -> Vec<f64> {
        match self.lens_path() {
            None => vec![1.0; times.len()],
            Some(lens) => lens.zooms(&self.model.matrix(times)),
        }
    }

    /// A trajectory from a record (e.g. a `trajectory.json` read back).
    pub fn from_record(
        record: &TrajectoryRecord,
        device: &Device,
        dtype: DType,
    ) -> Result<Self, TrajectoryError> {
        Self::from_weights(record.model.clone(), &record.weights, device, dtype)?
            .with_lens(record.lens.as_ref())
    }

    /// The least-squares trajectory of this model through `poses` at `times`.
    ///
    /// Minimises Σ_b ‖Ψ(t_b)·W − Φ_b‖² + λ‖W‖² on the host in f64 (Householder QR of the
    /// ridge-augmented basis matrix, so the normal equations' squared condition number is never
    /// formed), with λ = ([`DEFAULT_RIDGE`] · largest basis column norm)². The ridge is only
    /// there for bases the times do not reach (a waypoint segment without a sample gets weight
    /// 0): sample at least as densely as the model's finest feature. Used to start from a given
    /// trajectory and to move a trajectory from one model to another.
    pub fn fit(
        model: TrajectoryModel,
        times: &[f64],
        poses: &[Pose],
        device: &Device,
        dtype: DType,
    ) -> Result<Self, TrajectoryError> {
        Self::fit_with_ridge(model, times, poses, DEFAULT_RIDGE, device, dtype)
    }

    /// [`Trajectory::fit`] with an explicit relative ridge (√λ over the largest column norm).
    pub fn fit_with_ridge(
        model: TrajectoryModel,
        times: &[f64],
        poses: &[Pose],
        ridge: f64,
        device: &Device,
        dtype: DType,
    ) -> Result<Self, TrajectoryError> {
        model.validate()?;
        if times.len() != poses.len() {
            return Err(TrajectoryError::FitData(format!(
                "{} times but {} poses",
                times.len(),
                poses.len()
            )));
        }
        if times.is_empty() {
            return Err(TrajectoryError::FitData("no poses to fit".into()));
        }
        if !(ridge.is_finite() && ridge >= 0.0) {
            return Err(TrajectoryError::FitData(format!(
                "ridge must be finite and ≥ 0, got {ridge}"
            )));
        }
        if let Some(b) = (0..times.len())
            .find(|&b| !times[b].is_finite() || poses[b].iter().any(|v| !v.is_finite()))
        {
            return Err(TrajectoryError::FitData(format!(
                "sample {b} (t = {}) is not finite",
                times[b]
            )));
        }
        let basis = model.matrix(times);
        let targets: Vec<f64> = poses.iter().flatten().copied().collect();
        let weights = lstsq::ridge_lstsq(&basis, times.len(), model.count(), &targets, ridge);
        Self::from_weights(model, &weights, device, dtype)
    }

    /// This trajectory's poses, and its zoom when the lens zooms, re-fitted with another model
    /// on `samples` evenly spaced times (the zoom as its free value u(t) at the same times,
    /// [`LensPath::fit_free`], in the same range).
    pub fn refit(&self, model: TrajectoryModel, samples: usize) -> Result<Self, TrajectoryError> {
        let times = uniform_times(samples);
        let poses = self.poses_at(&times);
        let value = self.weights.val();
        let fitted = Self::fit(model, &times, &poses, &value.device(), value.dtype())?;
        let lens = self
            .lens_path()
            .map(|lens| {
                let free = lens.free_values(&self.model.matrix(&times));
                LensPath::fit_free(fitted.model(), lens.range, &times, &free)
            })
            .transpose()?;
        fitted.with_lens(lens.as_ref())
    }

    /// The basis model.
    pub fn model(&self) -> &TrajectoryModel {
        &self.model
    }

    /// Weights W on the host, one row of six per basis function `[K][6]`.
    pub fn host_weights(&self) -> Vec<Pose> {
        let flat = self
            .weights
            .val()
            .into_data()
            .try_into_vec_as::<f64>()
            .expect("float tensor data converts to f64");
        flat.chunks_exact(POSE_DIM)
            .map(|row| row.try_into().expect("rows of six"))
            .collect()
    }

    /// Model and weights, ready to serialise.
    pub fn record(&self) -> TrajectoryRecord {
        TrajectoryRecord {
            model: self.model.clone(),
            weights: self.host_weights(),
            lens: self.lens_path(),
        }
    }

    /// Poses Φ(t) `[B, 6]` for times `[B]` (same device as the weights; any float dtype, the
    /// basis is evaluated in the weights' dtype). Differentiable in the weights.
    pub fn forward(&self, times: Tensor<1>) -> Tensor<2> {
        let weights = self.weights.val();
        let dtype = weights.dtype();
        // Evaluate the basis in the weights' dtype: an f32 time grid against f64 weights would
        // otherwise panic in the matmul (mixed dtypes), and f64 times keep full precision.
        let times = if times.dtype() == dtype {
            times
        } else {
            times.cast(dtype)
        };
        let basis = self.model.tensor(times); // [B, K]
        let basis = if basis.dtype() == dtype {
            basis
        } else {
            basis.cast(dtype)
        };
        basis.matmul(weights) // [B, K]·[K, 6] = [B, 6]
    }

    /// Poses Φ(t) `[B, 6]` for host times `[B]`: the basis evaluated on the host in f64 and
    /// uploaded (one upload, no read back, for every model). Differentiable in the weights.
    pub fn forward_at(&self, times: &[f64]) -> Tensor<2> {
        let weights = self.weights.val();
        let (device, dtype) = (weights.device(), weights.dtype());
        let data = TensorData::new(self.model.matrix(times), [times.len(), self.model.count()]);
        splatraj_render::host::upload::<2>(data, &device, dtype).matmul(weights) // [B, 6]
    }

    /// Poses Φ(t) at any times, on the host in f64 (reads the weights once).
    pub fn poses_at(&self, times: &[f64]) -> Vec<Pose> {
        let weights = self.host_weights();
        let k = self.model.count();
        let basis = self.model.matrix(times);
        basis
            .chunks_exact(k)
            .map(|row| {
                let mut pose = [0.0; POSE_DIM];
                for (psi, w) in row.iter().zip(&weights) {
                    for (p, wj) in pose.iter_mut().zip(w) {
                        *p += psi * wj;
                    }
                }
                pose
            })
            .collect()
    }
}

/// `count` evenly spaced times from 0 to 1 inclusive (`[0.0]` for one, empty for zero).
pub fn uniform_times(count: usize) -> Vec<f64> {
    match count {
        0 => Vec::new(),
        1 => vec![0.0],
        _ => {
            let last = (count - 1) as f64;
            (0..count).map(|i| i as f64 / last).collect()
        }
    }
}
