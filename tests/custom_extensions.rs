//! A trajectory model and a target source defined outside splatraj (this file), registered by
//! name and chosen by a config, the way `examples/custom_cost.rs` adds a cost:
//!
//! - `custom.hat`: piecewise-linear interpolation between `knots` evenly spaced knots (hat
//!   functions), so Φ at knot k is weight row k;
//! - `custom.near`: the Gaussians within `radius` of a named point.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use splatraj::config::ConfigError;
use splatraj::experiment::{Config, Experiment, Extensions, optimise::observer};
use splatraj::scene::Scene;
use splatraj::semantic::{
    Relevancy, Scoring, SemanticError, SourceConfig, SourceContext, TargetSource,
};
use splatraj::traj::trajectory::{
    Basis, ModelConfig, TrajectoryError, TrajectoryModel, TrajectoryRecord,
};

/// `[trajectory.custom.hat]`: hat functions on `knots` evenly spaced knots t_k = k/(knots − 1).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct HatConfig {
    #[serde(default = "four")]
    knots: usize,
}

fn four() -> usize {
    4
}

#[derive(Debug)]
struct Hat {
    knots: usize,
}

impl ModelConfig for HatConfig {
    fn init(&self, _windows: usize) -> Result<Box<dyn Basis>, TrajectoryError> {
        let hat = Hat { knots: self.knots };
        hat.validate()?;
        Ok(Box::new(hat))
    }
}

impl Basis for Hat {
    fn count(&self) -> usize {
        self.knots
    }

    fn validate(&self) -> Result<(), TrajectoryError> {
        if self.knots < 2 {
            return Err(TrajectoryError::Config(ConfigError::new(
                "trajectory.custom.hat.knots",
                format!("= {} must be at least 2", self.knots),
            )));
        }
        Ok(())
    }

    fn eval_into(&self, t: f64, row: &mut [f64]) {
        let last = (self.knots - 1) as f64;
        for (k, psi) in row.iter_mut().enumerate() {
            *psi = (1.0 - (t * last - k as f64).abs()).max(0.0);
        }
    }
}

/// `[targets.custom.near]`: named points and a radius; a query names a point.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct NearConfig {
    points: BTreeMap<String, [f32; 3]>,
    radius: f32,
}

impl SourceConfig for NearConfig {
    fn init(&self, _context: &SourceContext) -> splatraj::semantic::Result<Box<dyn TargetSource>> {
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(SemanticError::option(
                "radius",
                format!("{} must be finite and > 0", self.radius),
            ));
        }
        Ok(Box::new(self.clone()))
    }
}

impl TargetSource for NearConfig {
    fn kind(&self) -> &'static str {
        "near"
    }

    fn relevancy(&self, scene: &Scene, query: &str) -> splatraj::semantic::Result<Relevancy> {
        let Some(point) = self.points.get(query.trim()) else {
            return Err(SemanticError::NoMatch {
                what: "point".into(),
                query: query.into(),
                closest: self.points.keys().cloned().collect(),
            });
        };
        Ok(Relevancy {
            name: query.trim().to_string(),
            values: scene
                .means
                .iter()
                .map(|m| f32::from(distance(m, point) <= self.radius))
                .collect(),
            scoring: Scoring::Mask { cluster: false },
            notes: Vec::new(),
        })
    }
}

fn distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>().sqrt()
}

const MUG: [f32; 3] = [0.32, -0.22, 0.80];
const RADIUS: f32 = 0.07;

const CONFIG: &str = r#"
name = "custom-extensions"
seed = 5
[scene]
demo = { gaussians = 8000 }
[targets]
source = "custom.near"
[targets.custom.near]
points = { mug = [0.32, -0.22, 0.80] }
radius = 0.07
[[queries]]
text = "mug"
[camera]
width = 32
height = 24
[trajectory]
kind = "custom.hat"
[trajectory.custom.hat]
knots = 5
[optimiser]
iterations = 12
samples_per_window = 2
learning_rate = 0.05
"#;

fn extensions() -> Extensions {
    let mut extensions = Extensions::default();
    extensions.models.register::<HatConfig>("hat");
    extensions.sources.register::<NearConfig>("near");
    extensions
}

#[test]
fn a_registered_model_and_source_run_through_a_config() {
    let extensions = extensions();
    let config = Config::from_toml(CONFIG, Path::new("."), &extensions).unwrap();
    assert_eq!(config.trajectory.name(), "custom.hat");
    assert_eq!(config.targets.source.name(), "custom.near");
    let experiment = Experiment::prepare_with(&config, &extensions).unwrap();

    // The source grounded the query: exactly the Gaussians near the mug.
    let expected = experiment
        .scene
        .means
        .iter()
        .filter(|m| distance(m, &MUG) <= RADIUS)
        .count();
    assert!(expected > 50, "{expected} Gaussians near the mug");
    assert_eq!(experiment.selected, vec![expected]);
    let centre = experiment.windows[0].context.object_centre;
    let off: f64 = (0..3).map(|i| (centre[i] - MUG[i] as f64).powi(2)).sum();
    assert!(off.sqrt() < RADIUS as f64, "object centre {centre:?}");

    // The model is the registered one, five knots.
    let model = &experiment.model;
    assert!(matches!(model, TrajectoryModel::Custom(_)));
    assert_eq!(model.count(), 5);

    let run = experiment.run_trajectory(&mut observer::quiet()).unwrap();
    let best = &run.best().best;
    assert_eq!(best.model.name(), "custom.hat");
    assert_eq!(best.weights.len(), 5);
    assert!(run.best().best_total.is_finite());

    // Φ at knot k is weight row k: the hat basis is what the trajectory evaluates.
    let trajectory = experiment.trajectory(best).unwrap();
    let poses = trajectory.poses_at(&[0.0, 0.25, 0.5, 0.75, 1.0]);
    for (pose, row) in poses.iter().zip(&best.weights) {
        for (p, w) in pose.iter().zip(row) {
            assert!((p - w).abs() < 1e-5, "{pose:?} vs {row:?}");
        }
    }

    // trajectory.json reads back through the same registry, with the same poses.
    let json = serde_json::to_string(&experiment.trajectory_file(&trajectory).unwrap()).unwrap();
    let record: TrajectoryRecord = serde_json::from_str(&json).unwrap();
    assert_eq!(record.model, best.model);
    let again = experiment.trajectory(&record).unwrap();
    assert_eq!(
        again.poses_at(&[0.1, 0.6]),
        trajectory.poses_at(&[0.1, 0.6])
    );

    // The optimised trajectory keeps the mug in view.
    let evaluation = experiment.evaluate(&trajectory).unwrap();
    assert!(evaluation.windows[0].visible, "{:?}", evaluation.windows);
}

#[test]
fn unregistered_or_misconfigured_extensions_are_errors_naming_the_key() {
    let with = |from: &str, to: &str| CONFIG.replace(from, to);
    for (text, words) in [
        (
            with("custom.hat\"", "custom.spline\""),
            &["custom.spline", "hat"][..],
        ),
        (
            with("source = \"custom.near\"", "source = \"custom.far\""),
            &["custom.far", "near"][..],
        ),
        (with("knots = 5", "knots = 1"), &["knots", "at least 2"][..]),
        (with("knots = 5", "knot = 5"), &["knot", "custom.hat"][..]),
        (
            with("kind = \"custom.hat\"", "kind = \"spline\""),
            &["spline", "custom."][..],
        ),
    ] {
        let err = Config::from_toml(&text, Path::new("."), &extensions()).unwrap_err();
        let message = format!("{err:#}");
        for w in words {
            assert!(message.contains(w), "{w:?} missing from {message}");
        }
    }
    // A source's own checks and stray tables surface when it is built.
    for (text, words) in [
        (
            with("radius = 0.07", "radius = -1.0"),
            &["targets.custom.near", "radius"][..],
        ),
        (
            format!("{CONFIG}\n[targets.custom.other]\nx = 1\n"),
            &["targets.custom.other", "custom.near"][..],
        ),
    ] {
        let config = Config::from_toml(&text, Path::new("."), &extensions()).unwrap();
        let err = Experiment::prepare_with(&config, &extensions()).unwrap_err();
        let message = format!("{err:#}");
        for w in words {
            assert!(message.contains(w), "{w:?} missing from {message}");
        }
    }
    // Without its registry a custom model cannot be built, and says so.
    let config = Config::from_toml(CONFIG, Path::new("."), &extensions()).unwrap();
    let err = Config::validate(&config).unwrap_err();
    assert!(format!("{err:#}").contains("custom.hat"), "{err:#}");
}
