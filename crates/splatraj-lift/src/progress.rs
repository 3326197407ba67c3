//! Progress of a lift, for the caller to draw (the library prints nothing).

/// The phases of building a lifted field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LiftStage {
    /// Measuring what candidate views show, to choose the views.
    Plan,
    /// Rendering the chosen views in RGB.
    Render,
    /// Running the image tower on the renders.
    Encode,
    /// Lifting the features (or masks) onto the Gaussians.
    Lift,
}

impl LiftStage {
    /// The word a progress bar shows.
    pub fn name(self) -> &'static str {
        match self {
            LiftStage::Plan => "choosing views",
            LiftStage::Render => "rendering views",
            LiftStage::Encode => "encoding views",
            LiftStage::Lift => "lifting",
        }
    }
}

/// Called with (stage, done, total) as work advances.
pub type Progress = dyn Fn(LiftStage, usize, usize) + Send + Sync;

/// A progress callback that does nothing.
pub fn silent(_: LiftStage, _: usize, _: usize) {}

/// The progress hook a program installed for lifts that were given none (a source built from
/// a config file has no way to receive one).
static INSTALLED: std::sync::RwLock<Option<std::sync::Arc<Progress>>> =
    std::sync::RwLock::new(None);

/// Installs `progress` for every later lift built without its own (the CLI's progress bars).
pub fn install(progress: std::sync::Arc<Progress>) {
    *INSTALLED.write().unwrap_or_else(|e| e.into_inner()) = Some(progress);
}

/// The installed progress hook, if any.
pub fn installed() -> Option<std::sync::Arc<Progress>> {
    INSTALLED.read().unwrap_or_else(|e| e.into_inner()).clone()
}
