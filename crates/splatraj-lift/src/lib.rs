//! Training-free semantic fields: what rendered views of a scene say, lifted onto its Gaussians.
//!
//! Most captures carry no trained language field. This crate makes one from the scene itself:
//! it chooses views from the scene's geometry ([`views`]; or takes the capture's cameras),
//! renders them, runs CLIP's image tower with ClearCLIP's dense patch features
//! ([`splatraj_semantic::image_encoder`]), and lifts the features onto the Gaussians as the
//! blending-weight average over views and pixels, computed by the rasterizer's own backward
//! ([`splatraj_render::lift`]) so that hidden Gaussians get no vote ([`field`]). Features are
//! stored compressed to a principal subspace ([`pca`]) and cached beside the scene ([`cache`]);
//! the `lifted` target source ([`source`]) scores free-text queries against them. The same
//! lifting turns 2D label masks with their cameras into per-Gaussian labels ([`masks`]).
//! [`mask_files`] reads such masks from a segmenter's PNGs, matched by name to the capture's
//! cameras ([`cameras`]).
//!
//! It does not read config files or scene files, choose objects among the relevant Gaussians
//! (the semantic crate's selection does that) or draw progress (callers get [`progress`]
//! callbacks).

#![warn(missing_docs)]

pub mod cache;
pub mod cameras;
pub mod error;
pub mod field;
pub mod mask_files;
pub mod mask_summary;
pub mod masks;
pub mod pca;
pub mod progress;
pub mod source;
pub mod views;

pub use error::{LiftError, Result};

/// A Gaussian whose blending weights sum to less than this over all views (in pixels at the
/// lifting size) has no vote: no view showed it.
pub const MIN_WEIGHT: f32 = 1e-3;
pub use cameras::{NamedView, read_views};
pub use field::{FieldOptions, LiftedField};
pub use mask_files::{MaskFiles, MaskLift, lift_mask_files, read_masks};
pub use masks::{LiftedLabels, MaskOptions, MaskView, lift_masks};
pub use progress::{LiftStage, Progress};
pub use source::{LIFTED, LiftedConfig, LiftedSource, default_cache_dir};
pub use views::{Placement, View, ViewOptions, ViewPlan, plan_views};
