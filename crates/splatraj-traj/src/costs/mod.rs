//! Image costs on rendered object masks `[B, H, W]`, one value per sample `[B]`.
//!
//! Both are plain tensor functions: they run on the mask's device and dtype and differentiate
//! through burn's autodiff when the mask is tracked. Neither is ever NaN, and for an empty mask
//! (object out of view) TCE has a zero gradient and TRE a constant one, so that nothing but the
//! warm-start prior moves a camera that sees nothing (see each function's docs).

pub mod tce;
pub mod tre;

pub use tce::{MASS_FLOOR, NORM_EPSILON, centroid_offset, tce};
pub use tre::{DEFAULT_TARGET_RATIO, coverage, tre};
