//! The preparation stage: from a config to everything the optimisation needs, checked before
//! any work. The scene is read ([`scene_files`]) and its up found ([`scene_up`]); each query
//! becomes a target ([`grounding`], with the lifted language field's plan in [`lifted`]); the
//! views that show each target ([`views`]) give the starts ([`starts`]), and where the
//! windows pan or cut ([`transitions`]); the optimisation may
//! render a coarse copy of a large scene ([`optimised_scene`]); and the memory and time of the
//! work are planned against the limits ([`memory_plans`]); what the clearance cost and the
//! motion limits read is in [`clearance`]. [`experiment::Experiment::prepare`]
//! runs these in order, and its [`experiment::Experiment`] is what every later stage shares
//! (what several stages ask for is judged once, in a [`memo::Memo`]).

pub mod clearance;
pub mod experiment;
pub mod grounding;
pub mod lifted;
pub mod memo;
pub mod memory_plans;
pub mod optimised_scene;
pub mod scene_files;
pub mod scene_up;
pub mod shot_lens;
pub mod starts;
pub mod transitions;
pub mod views;
