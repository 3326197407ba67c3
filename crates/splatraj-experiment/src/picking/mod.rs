//! Picking parts before a run: `splatraj query` (a phrase, region or selection against a
//! scene, drawn as a picture: [`query`]; its options made into one config:
//! [`query_options`]; the command whole: [`query_run`]) and `splatraj scene views` (the click-to-pick page:
//! [`views_page`], with its strip of candidate ups: [`up_choices`]; each view rendered by
//! [`view_render`]).

pub mod query;
pub mod query_options;
pub mod query_run;
pub mod up_choices;
pub mod view_render;
pub mod views_page;
