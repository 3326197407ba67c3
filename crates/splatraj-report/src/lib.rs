//! The pages and video a person looks at, for splatraj.
//!
//! - [`report`]: `report.html`, one self-contained page about a run (metrics, keyframes, plots,
//!   the video, the config);
//! - [`views_page`]: `views.html`, rendered views of a scene to pick its parts by clicking;
//! - [`video`]: frames to an H.264 MP4 (`video.mp4`) without a system ffmpeg, and back.
//!
//! It lays out what the caller gathered and encodes frames; it renders nothing, reads no run
//! folder and does not depend on burn. Camera files of other tools (nerfstudio, COLMAP, INRIA,
//! SuperSplat) are the `splatraj-camera-paths` crate's.

#![warn(missing_docs)]

pub mod report;
pub mod video;
pub mod views_page;
