//! One module per top-level subcommand.

pub mod bench;
pub mod query;
pub mod render;
pub mod scene;
