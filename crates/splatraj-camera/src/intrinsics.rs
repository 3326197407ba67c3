//! Pinhole intrinsics in pixels, OpenCV axes (x right, y down, z forward); the centre of pixel
//! (i, j) is at (i + 0.5, j + 0.5).

use serde::{Deserialize, Serialize};

use crate::error::CameraError;

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels (the image centre is width / 2).
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
}

impl Intrinsics {
    /// Checked intrinsics: focal lengths and principal point finite, focal lengths > 0, size ≥ 1.
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: usize,
        height: usize,
    ) -> Result<Self, CameraError> {
        let intrinsics = Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        };
        if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
            return Err(CameraError::Intrinsics(format!(
                "fx = {fx}, fy = {fy} must be finite and > 0"
            )));
        }
        if !(cx.is_finite() && cy.is_finite()) {
            return Err(CameraError::Intrinsics(format!(
                "cx = {cx}, cy = {cy} must be finite"
            )));
        }
        // Beyond these the projection (x·f/z) and the 1.3·tan(fov) clamp overflow f32.
        if !(fx.max(fy) <= 1e12 && fx.min(fy) >= 1e-6 && cx.abs().max(cy.abs()) <= 1e12) {
            return Err(CameraError::Intrinsics(format!(
                "fx = {fx}, fy = {fy} must be in [1e-6, 1e12] pixels and |cx|, |cy| = {}, {} \
                 at most 1e12",
                cx.abs(),
                cy.abs()
            )));
        }
        if width == 0 || height == 0 {
            return Err(CameraError::Intrinsics(format!(
                "image size {width}×{height} must be at least 1×1"
            )));
        }
        Ok(intrinsics)
    }

    /// Square pixels, principal point at the centre, from the horizontal field of view.
    pub fn from_fov_x(
        fov_x_degrees: f64,
        width: usize,
        height: usize,
    ) -> Result<Self, CameraError> {
        if !(fov_x_degrees > 0.0 && fov_x_degrees < 180.0) {
            return Err(CameraError::Intrinsics(format!(
                "horizontal field of view {fov_x_degrees}° must be in (0°, 180°)"
            )));
        }
        let f = 0.5 * width as f64 / (0.5 * fov_x_degrees.to_radians()).tan();
        Self::new(f, f, 0.5 * width as f64, 0.5 * height as f64, width, height)
    }

    /// The same camera at another resolution: focal lengths and principal point scale with it.
    pub fn rescaled(&self, width: usize, height: usize) -> Result<Self, CameraError> {
        let (sx, sy) = (
            width as f64 / self.width as f64,
            height as f64 / self.height as f64,
        );
        Self::new(
            self.fx * sx,
            self.fy * sy,
            self.cx * sx,
            self.cy * sy,
            width,
            height,
        )
    }

    /// The camera zoomed by `s`: focal lengths fx·s, fy·s about the same principal point (the
    /// lens over time, docs/conventions.md "The lens").
    pub fn zoomed(&self, s: f64) -> Result<Self, CameraError> {
        Self::new(
            self.fx * s,
            self.fy * s,
            self.cx,
            self.cy,
            self.width,
            self.height,
        )
    }

    /// Horizontal field of view in degrees, atan(cx/fx) + atan((width − cx)/fx) (the angle
    /// between the rays through the image's left and right edges).
    pub fn horizontal_fov_degrees(&self) -> f64 {
        let w = self.width as f64;
        ((self.cx / self.fx).atan() + ((w - self.cx) / self.fx).atan()).to_degrees()
    }

    /// tan of half the field of view along x and y (for the 1.3·tan(fov) Jacobian clamp).
    pub fn tan_half_fov(&self) -> (f64, f64) {
        (
            0.5 * self.width as f64 / self.fx,
            0.5 * self.height as f64 / self.fy,
        )
    }

    /// Checks what every camera file's pinhole needs: sizes ≥ 1, positive finite focal lengths
    /// and a finite principal point ([`Intrinsics::new`] also bounds their range, for the
    /// renderer's f32 arithmetic).
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size {}×{} must be at least 1×1",
                self.width, self.height
            ));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be a positive number"));
            }
        }
        for (name, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(format!("{name} = {v} is not finite"));
            }
        }
        Ok(())
    }

    /// A centred pinhole of the given size with focal length `focal` on both axes.
    pub fn centred(focal: f64, width: usize, height: usize) -> Self {
        Self {
            fx: focal,
            fy: focal,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            width,
            height,
        }
    }

    /// Vertical field of view in degrees: 2·atan(height / (2·fy)).
    pub fn vertical_fov_degrees(&self) -> f64 {
        (2.0 * (self.height as f64 / (2.0 * self.fy)).atan()).to_degrees()
    }

    /// The focal length (pixels) of a vertical field of view in degrees over `height` pixels.
    pub fn focal_from_vertical_fov(fov_degrees: f64, height: usize) -> f64 {
        height as f64 / 2.0 / (fov_degrees.to_radians() / 2.0).tan()
    }

    /// Width over height.
    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }
}
