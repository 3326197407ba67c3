//! The compositing rules' constants (docs/conventions.md, rules 7 and 8), in a leaf of their
//! own: the binning (`alpha_reach`) and both compositing paths read them.

/// Largest alpha a Gaussian can reach (INRIA).
pub const MAX_ALPHA: f64 = 0.99;
/// Smallest alpha that counts (INRIA: 1/255).
pub const MIN_ALPHA: f64 = 1.0 / 255.0;
/// A pixel stops before T would fall below this.
pub const MIN_TRANSMITTANCE: f64 = 1e-4;
