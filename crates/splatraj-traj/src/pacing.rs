//! Pacing: how fast the camera may turn and circle its subject for a viewer to follow.
//!
//! Two rates, both in degrees per second, both measured on the dense path grid
//! ([`crate::metrics::path`]):
//!
//! - **turning**: the angle the view itself turns (a pan or tilt);
//! - **orbiting**: the angle the direction from the window's object centre to the camera
//!   turns (the camera circling the subject, which the viewer reads as the subject turning).
//!
//! At 30 frames per second a viewer follows either motion up to about 45°/s, 1.5° a frame;
//! faster reads as a whip and judders, since the same detail jumps further between frames
//! than the eye tracks (cinematographers' strobing tables put a comfortable pan of a 60° lens
//! at 3–7 s per frame width, 10–20°/s; 45°/s is brisk, the upper end of what still reads as a
//! move rather than a cut). The first-try benchmark before these limits turned at up to
//! 61°/s and orbited at up to 83°/s on the pans between opposite sides of a part. The limits
//! are stated per second at the default 30 fps and kept at other frame rates (a faster rate
//! judders less, a slower one more: at 24 fps 45°/s is 1.9° a frame).
//!
//! The verdict holds every window to these limits ([`mod@crate::metrics::verdict`]); the motion
//! cost of a config without `[costs]` aims a little below them
//! ([`crate::costs::motion::FIRST_TRY_MAX_ANGULAR_SPEED`]).

/// Fastest turn of the view a viewer follows, degrees per second (module docs).
pub const MAX_TURN_RATE: f64 = 45.0;

/// Fastest orbit of the camera about its subject a viewer follows, degrees per second.
pub const MAX_ORBIT_RATE: f64 = 45.0;
