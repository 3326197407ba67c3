//! One module per top-level subcommand.

pub mod bench;
pub mod devices;
pub mod encode_text;
pub mod export;
pub mod pose;
pub mod query;
pub mod render;
pub mod render_path;
pub mod report;
pub mod run;
pub mod scene;
pub mod study;
