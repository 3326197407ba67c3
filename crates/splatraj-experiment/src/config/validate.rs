//! Range checks of a parsed [`Config`] that serde cannot express. Each failure is one
//! [`ConfigError`] naming the key, whichever crate found it: the costs' and trajectory
//! models' own checks, the optimisers', the shots', the rendering approximations'.

use splatraj_config::ConfigError;
use splatraj_traj::costs::CostError;
use splatraj_traj::optimise::{OptimiseError, RouteKind};
use splatraj_traj::shots::ShotSpec;
use splatraj_traj::trajectory::TrajectoryError;

use super::{Config, LensKind};
use crate::extensions::Extensions;

impl Config {
    /// Range checks that serde cannot express, with the built-in costs only; errors name the
    /// key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_with(&Extensions::default())
    }

    /// [`Config::validate`] for a config that may name the costs, models and sources
    /// registered in `extensions`.
    pub fn validate_with(&self, extensions: &Extensions) -> Result<(), ConfigError> {
        let bad = |key: &str, reason: String| Err(ConfigError::new(key, reason));
        if self.name.is_empty()
            || self
                .name
                .chars()
                .any(|c| !(c.is_alphanumeric() || "-_.".contains(c)))
        {
            return bad(
                "name",
                format!(
                    "= {:?} must be non-empty and use only letters, digits, '-', '_', '.'",
                    self.name
                ),
            );
        }
        match (&self.scene.path, &self.scene.demo) {
            (Some(_), Some(_)) => return bad("scene", "gives `path` and `demo`: give one".into()),
            (None, None) => {
                return bad("scene", "needs `path` (a scene file) or `demo = {}`".into());
            }
            _ => {}
        }
        if let Some(up) = self.scene.up
            && !(up.iter().all(|v| v.is_finite()) && up.iter().any(|v| *v != 0.0))
        {
            return bad("scene.up", format!("= {up:?} must be finite and non-zero"));
        }
        if let Some(gb) = self.max_memory_gb
            && !(gb.is_finite() && gb > 0.0)
        {
            return bad("max_memory_gb", format!("= {gb} must be finite and > 0"));
        }
        if self.queries.is_empty() {
            return bad("queries", "needs at least one `[[queries]]` table".into());
        }
        for (i, q) in self.queries.iter().enumerate() {
            if let Some(r) = q.target_ratio
                && !(r > 0.0 && r <= 1.0)
            {
                return bad(
                    &format!("queries.{i}.target_ratio"),
                    format!("= {r} must be in (0, 1]"),
                );
            }
            if let (Some(shot), Some(hold)) = (&q.shot, q.hold) {
                return bad(
                    &format!("queries.{i}.hold"),
                    format!(
                        "= \"{}\" and `queries.{i}.shot` (kind \"{}\") both say what the \
                         window does: `hold` is a shot preset's short name; keep one",
                        hold.name(),
                        shot.kind()
                    ),
                );
            }
            if let Some(shot) = &q.shot
                && let Err(e) = shot.validate()
            {
                return bad(&format!("queries.{i}.shot.{}", e.field), e.reason);
            }
            // A dolly zoom zooms: refused before any work when the lens cannot.
            if let Some(shot) = &q.shot
                && matches!(shot, ShotSpec::DollyZoom(_))
                && self.camera.lens == LensKind::Fixed
            {
                return bad(
                    "camera.lens",
                    format!(
                        "= \"fixed\", but `queries.{i}.shot` (dolly-zoom) zooms: set \
                         `camera.lens = \"zoom\"`"
                    ),
                );
            }
        }
        if self.start.route == RouteKind::Planned && self.costs.clearance.is_none() {
            return bad(
                "start.route",
                "= \"planned\" routes around the geometry the clearance cost keeps clear of: \
                 add `[costs.clearance]` (with its `margin`), or use \"auto\""
                    .into(),
            );
        }
        self.camera.intrinsics()?;
        self.camera.lens()?;
        self.costs
            .build_with(&extensions.costs)
            .map_err(cost_error)?;
        self.trajectory
            .build_with(self.queries.len(), &extensions.models)
            .and_then(|model| model.basis().validate())
            .map_err(trajectory_error)?;
        if let splatraj_semantic::SourceKind::Custom(name) = &self.targets.source
            && !extensions.sources.contains(name)
        {
            return bad(
                "targets.source",
                format!("= \"custom.{name}\" {}", extensions.sources.unregistered()),
            );
        }
        self.optimiser
            .validate()
            .map_err(|e| optimise_error("optimiser", e))?;
        if self.start.restarts == 0 {
            return bad("start.restarts", "must be ≥ 1".into());
        }
        if !(self.start.spread > 0.0 && self.start.spread <= 1.0) {
            return bad(
                "start.spread",
                format!("= {} must be in (0, 1]", self.start.spread),
            );
        }
        if !(self.start.jitter.is_finite() && self.start.jitter >= 0.0) {
            return bad(
                "start.jitter",
                format!("= {} must be finite and ≥ 0 degrees", self.start.jitter),
            );
        }
        if self.start.elevation.is_nan() || self.start.elevation.abs() >= 90.0 {
            return bad(
                "start.elevation",
                format!("= {} must be in (−90, 90) degrees", self.start.elevation),
            );
        }
        if self.start.pose.is_some() && self.start.trajectory.is_some() {
            return bad("start", "gives `pose` and `trajectory`: give one".into());
        }
        if let Some(p) = self.start.pose {
            splatraj_render::camera_file::check_pose_range(&p)
                .map_err(|e| ConfigError::new("start.pose", e.to_string()))?;
        }
        self.output.validate()?;
        self.pose
            .optimiser
            .validate()
            .map_err(|e| optimise_error("pose.optimiser", e))?;
        if self.pose.query >= self.queries.len() {
            return bad(
                "pose.query",
                format!(
                    "= {} but there are {} queries (0-based)",
                    self.pose.query,
                    self.queries.len()
                ),
            );
        }
        self.sgld
            .validate()
            .map_err(|e| optimise_error("sgld", e))?;
        self.optimise_gaussians.check()?;
        self.approximations
            .check()
            .map_err(|e| e.within("approximations"))?;
        self.study.validate()
    }
}

/// A cost's error as the config's: a bad key as it is, anything else on `costs`.
fn cost_error(e: CostError) -> ConfigError {
    match e {
        CostError::InvalidConfig(e) => e,
        other => ConfigError::new("costs", format!("cannot be built: {other}")),
    }
}

/// A trajectory model's error as the config's, on `trajectory.<parameter>`.
fn trajectory_error(e: TrajectoryError) -> ConfigError {
    match e {
        TrajectoryError::Config(e) => e,
        TrajectoryError::InvalidModel { key, reason } => {
            ConfigError::new(format!("trajectory.{key}"), reason)
        }
        other => ConfigError::new("trajectory", format!("cannot be built: {other}")),
    }
}

/// An optimiser's error as the config's, on `<table>.<field>`.
fn optimise_error(table: &str, e: OptimiseError) -> ConfigError {
    match e {
        OptimiseError::InvalidOptions { field, reason } => {
            ConfigError::new(format!("{table}.{field}"), reason)
        }
        other => ConfigError::new(table, format!("is not usable: {other}")),
    }
}
