//! Progress reports from the long loops of an [`crate::Experiment`], and the answer that stops
//! them (Ctrl-C, a time budget, a test).

pub use splatraj_traj::optimise::Flow;

/// Where a loop is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// A trajectory optimisation step finished.
    Trajectory {
        /// Restart (0-based) and how many there are.
        restart: usize,
        /// Restarts in all.
        restarts: usize,
        /// Step (0-based) of this restart.
        step: usize,
        /// Steps per restart.
        steps: usize,
        /// Sampled loss of this step.
        total: f64,
        /// Lowest sampled loss of this restart so far.
        best: f64,
    },
    /// A batched single-pose step finished.
    Pose {
        /// Step (0-based).
        step: usize,
        /// Steps in all.
        steps: usize,
        /// Lowest total so far over all starts.
        best: f64,
    },
    /// The work moved on to its next phase.
    Phase(Phase),
    /// A frame was rendered.
    Frame {
        /// Frames done.
        done: usize,
        /// Frames in all.
        frames: usize,
    },
}

/// A phase of an experiment: its optimisation, and what follows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// The optimisation begins (its run folder made): `steps` in all, over every restart.
    Optimisation {
        /// Steps in all (restarts × iterations, or a pose run's iterations).
        steps: usize,
    },
    /// The optimisation ended (`stop` says why); metrics, frames, video and exports follow.
    Outputs {
        /// Frames to render.
        frames: usize,
        /// Why the optimisation ended.
        stop: crate::RunStop,
    },
    /// SGLD chains start from the best pose.
    Sgld {
        /// Chains.
        chains: usize,
    },
}

/// Told of every step; [`Flow::Stop`] ends the loop, keeping the best so far.
pub trait Observer {
    /// One step finished.
    fn progress(&mut self, progress: &Progress) -> Flow;

    /// A line for the person running the work, worded by the library (the plan of a run, its
    /// folder, a resume): a command shows it as it comes; by default it is dropped.
    fn line(&mut self, _line: &str) {}
}

impl<F: FnMut(&Progress) -> Flow> Observer for F {
    fn progress(&mut self, progress: &Progress) -> Flow {
        self(progress)
    }
}

/// An observer that never stops anything.
pub fn quiet() -> impl Observer {
    |_: &Progress| Flow::Continue
}

/// An observer that stops at a stop request (Ctrl-C, SIGTERM: [`splatraj_scene::stop`]) made
/// `since`, and says nothing.
pub fn until_stopped(since: splatraj_scene::stop::Since) -> impl Observer {
    move |_: &Progress| {
        if since.stopped() {
            Flow::Stop
        } else {
            Flow::Continue
        }
    }
}
