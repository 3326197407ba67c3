//! Normalised units for pose-like parameters, so one Adam learning rate fits both halves of Φ.
//!
//! Φ mixes units: ω in radians, c in scene units (metres in one capture, arbitrary units in
//! another). burn's Adam takes one learning rate per step, and Adam's step is about the
//! learning rate in each coordinate whatever the gradient's scale. So the optimisers keep their
//! parameters in normalised units, where the position columns are divided by
//! [`PoseUnits::position`], and map them to scene units inside the graph (Φ is linear in the
//! parameters, so this is one multiply). A step of size lr then moves the camera lr radians or
//! lr·position scene units, and the same config works for a scene in metres or in centimetres.

use burn::tensor::{Tensor, TensorData};

use crate::trajectory::{POSE_DIM, Pose};

/// Radians per normalised unit of ω and scene units per normalised unit of c.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseUnits {
    /// Radians per normalised rotation unit (> 0; 1 for trajectories).
    pub rotation: f64,
    /// Scene units per normalised position unit (> 0).
    pub position: f64,
}

impl PoseUnits {
    /// Rotation in radians, position in `position` scene units.
    pub fn with_position(position: f64) -> Self {
        Self {
            rotation: 1.0,
            position,
        }
    }

    /// The six column factors: `rotation` for ω, `position` for c.
    pub fn factors(&self) -> [f64; POSE_DIM] {
        let (r, p) = (self.rotation, self.position);
        [r, r, r, p, p, p]
    }

    /// Checks both factors are finite and > 0; errors name `field`'s parts.
    pub fn validate(&self) -> Result<(), super::OptimiseError> {
        for (field, v) in [
            ("rotation_unit", self.rotation),
            ("position_unit", self.position),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(super::OptimiseError::InvalidOptions {
                    field,
                    reason: format!("= {v} must be finite and > 0"),
                });
            }
        }
        Ok(())
    }

    /// Normalised `[.., 6]` values to scene units (differentiable).
    pub fn to_scene(&self, normalised: Tensor<2>) -> Tensor<2> {
        let row = splatraj_render::host::upload::<2>(
            TensorData::new(self.factors().to_vec(), [1, POSE_DIM]),
            &normalised.device(),
            normalised.dtype(),
        );
        normalised * row
    }

    /// A pose (or weight row) in scene units to normalised units, on the host.
    pub fn normalise(&self, pose: &Pose) -> Pose {
        let f = self.factors();
        std::array::from_fn(|i| pose[i] / f[i])
    }

    /// A normalised pose to scene units on the host as [`PoseUnits::to_scene`] computes it in
    /// `dtype` (in f32: value, factor and product each rounded to f32), so that the host
    /// values are the tensor's own (the costs computed on the host expand about them).
    pub fn to_scene_as(&self, normalised: &Pose, dtype: burn::tensor::DType) -> Pose {
        match dtype {
            burn::tensor::DType::F32 => {
                let f = self.factors();
                std::array::from_fn(|i| f64::from(normalised[i] as f32 * f[i] as f32))
            }
            _ => self.denormalise(normalised),
        }
    }

    /// A normalised pose (or weight row) to scene units, on the host.
    pub fn denormalise(&self, pose: &Pose) -> Pose {
        let f = self.factors();
        std::array::from_fn(|i| pose[i] * f[i])
    }
}
