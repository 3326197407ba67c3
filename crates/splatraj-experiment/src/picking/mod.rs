//! Picking parts before a run: `splatraj query` (a phrase, region or selection against a
//! scene, drawn as a picture: [`query`]) and `splatraj scene views` (the click-to-pick page:
//! [`views_page`]).

pub mod query;
pub mod views_page;
