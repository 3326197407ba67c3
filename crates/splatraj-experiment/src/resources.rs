//! Peak memory and time of every command's work, estimated from its sizes before any work, and
//! refused when they exceed what the machine can hold or a day, with the key, option or file
//! to blame, the estimate and the limit: a run, a pose run, a render ([`RenderWork`]: also
//! `query`'s picture and `render-path`'s frames), a camera path's frames
//! ([`check_path_frames`]), worker threads ([`check_threads`]) and a study's runs
//! ([`check_study`]). Time ([`TimePlan`]) is a lower bound from the fastest costs per pixel,
//! render and step; above [`WARN_SECONDS`] it is a warning, above [`MAX_SECONDS`] a refusal
//! unless a key bounds it ([`TimeBound`]: `optimiser.time_limit_s`).
//!
//! The estimate is a sum of per-item costs measured on the demo room with the fused rasterizer
//! (release build, f32, peak resident memory by `/usr/bin/time -v`; f64 doubles each): a
//! rendered pose costs about [`GRAD_BYTES_PER_PIXEL`] per pixel with gradient and
//! [`FORWARD_BYTES_PER_PIXEL`] without, plus [`BYTES_PER_GAUSSIAN_POSE`] per Gaussian it
//! projects; the scene itself [`SCENE_BYTES_PER_GAUSSIAN`] (host copy, device copies, caches).
//! Measured: a render of 100k Gaussians at 2560×1920 peaks at 320 MB (410 MB with gradient);
//! 64 single-pose restarts at 64×48 at 412 MB; metrics at 1280×960 at 712 MB. The estimate is
//! meant to be above the real peak (mask passes prune most Gaussians, so a run uses less), and
//! only catches sizes that cannot fit: a 10⁷×10⁷ camera, 10⁸ basis functions, 10⁵ restarts.
//! The default limit is [`DEFAULT_MEMORY_FRACTION`] of the physical memory (read with
//! `sysinfo`, which knows every platform's way to ask, and a container's limit), and any limit
//! is at most that share of the process's address-space limit (`ulimit -v`), past which an
//! allocation fails however much the machine holds. A prepared experiment's plans, stage by
//! stage, are [`crate::prepare::memory_plans`]; this file knows sizes, not experiments.

use std::sync::Mutex;

use anyhow::{Result, bail};

/// Share of the physical memory a run may plan to use by default.
pub const DEFAULT_MEMORY_FRACTION: f64 = 0.75;
/// Scene bytes per Gaussian (host scene, plain and autodiff device copies, per-scene caches).
pub const SCENE_BYTES_PER_GAUSSIAN: f64 = 400.0;
/// Bytes per pixel of one pose rendered with gradient (channels, per-pixel state, backward).
pub const GRAD_BYTES_PER_PIXEL: f64 = 64.0;
/// Bytes per pixel of one pose rendered without gradient.
pub const FORWARD_BYTES_PER_PIXEL: f64 = 48.0;
/// Bytes per Gaussian projected for one pose (means, conics, depths, radii and their graph).
pub const BYTES_PER_GAUSSIAN_POSE: f64 = 64.0;
/// Bytes per basis value held while a trajectory is sampled (Ψ(t) and its graph copies).
pub const BYTES_PER_BASIS_SAMPLE: f64 = 32.0;
/// Memory of the program itself (code, runtime, thread pools).
pub const BASE_BYTES: f64 = 64e6;

/// The most memory a piece of work may plan to use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryLimit {
    /// Bytes.
    pub bytes: f64,
    /// Where the limit comes from (shown when work is refused).
    pub source: LimitSource,
}

/// Where a [`MemoryLimit`] comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LimitSource {
    /// A key or an option gave it.
    Given,
    /// [`DEFAULT_MEMORY_FRACTION`] of the physical memory, or of the control group's limit
    /// when a container holds less.
    Machine,
    /// [`DEFAULT_MEMORY_FRACTION`] of the process's address-space limit (`ulimit -v`, `prlimit
    /// --as`): above it an allocation fails whatever the machine holds, so it bounds a given
    /// limit too.
    AddressSpace,
}

impl MemoryLimit {
    /// `gigabytes` when given (must be finite and > 0), else [`DEFAULT_MEMORY_FRACTION`] of
    /// the physical memory (or 16 GB when it cannot be read); either way at most that share of
    /// the process's address-space limit.
    pub fn new(gigabytes: Option<f64>) -> Result<MemoryLimit> {
        let chosen = match gigabytes {
            Some(gb) if gb.is_finite() && gb > 0.0 => MemoryLimit {
                bytes: gb * 1e9,
                source: LimitSource::Given,
            },
            Some(gb) => bail!("the memory limit {gb} GB must be finite and > 0"),
            None => MemoryLimit {
                bytes: DEFAULT_MEMORY_FRACTION * physical_memory().unwrap_or(16e9 / 0.75),
                source: LimitSource::Machine,
            },
        };
        Ok(match address_space_limit() {
            Some(bytes) if DEFAULT_MEMORY_FRACTION * bytes < chosen.bytes => MemoryLimit {
                bytes: DEFAULT_MEMORY_FRACTION * bytes,
                source: LimitSource::AddressSpace,
            },
            _ => chosen,
        })
    }

    /// Where the limit comes from, in words (e.g. "75 % of this machine's memory").
    pub fn source_words(&self) -> String {
        let share = 100.0 * DEFAULT_MEMORY_FRACTION;
        match self.source {
            LimitSource::Given => "the limit given".to_string(),
            LimitSource::Machine => format!("{share:.0} % of this machine's memory"),
            LimitSource::AddressSpace => {
                format!("{share:.0} % of this process's address-space limit")
            }
        }
    }
}

/// Physical memory in bytes (the control group's limit when a container holds less), if the
/// platform tells.
pub fn physical_memory() -> Option<f64> {
    let mut system = sysinfo::System::new();
    system.refresh_memory();
    let total = match system.total_memory() {
        0 => return None,
        bytes => bytes,
    };
    // A container's limit reads as the host's memory in /proc/meminfo; past the group's
    // limit the kernel kills the process, so it is the memory there is.
    let contained = system
        .cgroup_limits()
        .map(|limits| limits.total_memory)
        .filter(|&bytes| bytes > 0);
    Some(contained.map_or(total, |bytes| bytes.min(total)) as f64)
}

/// The process's address-space limit in bytes (`RLIMIT_AS`), when one is set.
#[cfg(target_os = "linux")]
pub fn address_space_limit() -> Option<f64> {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit only writes the struct it is given.
    let status = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) };
    (status == 0 && limit.rlim_cur != libc::RLIM_INFINITY).then_some(limit.rlim_cur as f64)
}

/// The process's address-space limit: none known on this platform.
#[cfg(not(target_os = "linux"))]
pub fn address_space_limit() -> Option<f64> {
    None
}

/// One stage of the work and what it needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Stage {
    /// What it is, naming the keys or options that size it.
    pub what: String,
    /// Estimated bytes (the scene and base included).
    pub bytes: f64,
}

/// The stages of a piece of work; its peak is the largest.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MemoryPlan {
    /// Every stage.
    pub stages: Vec<Stage>,
}

impl MemoryPlan {
    /// Adds a stage.
    pub fn stage(&mut self, what: impl Into<String>, bytes: f64) -> &mut Self {
        self.stages.push(Stage {
            what: what.into(),
            bytes,
        });
        self
    }

    /// The largest stage.
    pub fn peak(&self) -> Option<&Stage> {
        self.stages
            .iter()
            .max_by(|a, b| a.bytes.total_cmp(&b.bytes))
    }

    /// Errors when a stage exceeds `limit`, naming the stage, the estimate and the limit, and
    /// how to raise it (`raise`: the key or option that does; empty when none does).
    pub fn check(&self, limit: MemoryLimit, raise: &str) -> Result<()> {
        if let Some(stage) = self.peak()
            // NaN (a size beyond any float) does not fit either.
            && !matches!(
                stage.bytes.partial_cmp(&limit.bytes),
                Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
            )
        {
            let source = limit.source_words();
            let raise = match limit.source {
                // A given limit would be capped again.
                LimitSource::AddressSpace => {
                    ", or raise the address-space limit (`ulimit -v`)".to_string()
                }
                _ if raise.is_empty() => String::new(),
                _ => format!(", or raise the limit with {raise}"),
            };
            bail!(
                "{} needs about {} of memory, more than the limit of {} ({source}); make it \
                 smaller{raise}",
                stage.what,
                show_bytes(stage.bytes),
                show_bytes(limit.bytes)
            );
        }
        if let Some(stage) = self.peak() {
            remember_checked_peak(stage, limit);
        }
        Ok(())
    }
}

/// The largest stage of the last plan that passed its check and the limit it passed: what an
/// allocation failing anyway was most likely part of.
static CHECKED_PEAK: Mutex<Option<(Stage, MemoryLimit)>> = Mutex::new(None);

fn remember_checked_peak(stage: &Stage, limit: MemoryLimit) {
    let mut checked = match CHECKED_PEAK.lock() {
        Ok(checked) => checked,
        Err(poisoned) => poisoned.into_inner(),
    };
    *checked = Some((stage.clone(), limit));
}

/// Calls `show` with the largest stage of the last memory plan that passed its check and the
/// limit it passed, without waiting for the lock (`None` when none passed or it is held):
/// the message of an allocation failure, which may come from the thread recording one.
pub fn with_last_checked_peak(show: impl FnOnce(Option<(&Stage, &MemoryLimit)>)) {
    match CHECKED_PEAK.try_lock() {
        Ok(checked) => show(checked.as_ref().map(|(stage, limit)| (stage, limit))),
        Err(_) => show(None),
    }
}

/// Bytes of rendering `poses` poses of `pixels` pixels each over `gaussians` Gaussians, with
/// gradient or not, at `float_bytes` (4 or 8) per value.
pub fn render_bytes(
    poses: usize,
    pixels: f64,
    gaussians: usize,
    gradient: bool,
    float_bytes: usize,
) -> f64 {
    let per_pixel = if gradient {
        GRAD_BYTES_PER_PIXEL
    } else {
        FORWARD_BYTES_PER_PIXEL
    };
    let per_gaussian = if gradient {
        BYTES_PER_GAUSSIAN_POSE
    } else {
        0.5 * BYTES_PER_GAUSSIAN_POSE
    };
    let scale = float_bytes as f64 / 4.0;
    poses as f64 * (pixels * per_pixel + gaussians as f64 * per_gaussian) * scale
}

/// Bytes of the scene on the host and devices, plus the program itself.
pub fn scene_bytes(gaussians: usize, float_bytes: usize) -> f64 {
    BASE_BYTES + gaussians as f64 * SCENE_BYTES_PER_GAUSSIAN * (float_bytes as f64 / 4.0).max(1.0)
}

/// Bytes of sampling a trajectory of `basis` functions at `samples` times.
pub fn basis_bytes(basis: usize, samples: usize) -> f64 {
    basis as f64 * samples as f64 * BYTES_PER_BASIS_SAMPLE
}

/// `12.3 GB`, `456 MB`, …
pub fn show_bytes(bytes: f64) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < UNITS.len() {
        value /= 1000.0;
        unit += 1;
    }
    if !value.is_finite() {
        return "more than any machine holds".to_string();
    }
    format!("{value:.1} {}", UNITS[unit])
}

/// Bytes a frame of a camera path holds before it is rendered (time, pose, camera, and its
/// share of the exported files' text).
pub const PATH_BYTES_PER_FRAME: f64 = 512.0;
/// Bytes per optimisation step and window kept in the history (the cost terms, the pose).
pub const HISTORY_BYTES_PER_WINDOW_STEP: f64 = 256.0;
/// Bytes per restart and basis function (the start, the best weights, Adam's two moments).
pub const RESTART_BYTES_PER_BASIS: f64 = 4.0 * 6.0 * 8.0;
/// Bytes of one run of a study's plan (its entry, its row, its share of the summary).
pub const STUDY_BYTES_PER_RUN: f64 = 2048.0;
/// Bytes of one worker thread (its stack, [`WORKER_STACK_BYTES`]).
pub const WORKER_STACK_BYTES: f64 = 8.0 * 1024.0 * 1024.0;
/// Steps per second no optimisation exceeds (for the steps a time limit lets run).
pub const MAX_STEPS_PER_SECOND: f64 = 1000.0;

/// Time no render of one pose takes less than, per pixel (a lower bound: 1000 Mpixel/s).
pub const MIN_SECONDS_PER_PIXEL: f64 = 1e-9;
/// Time no render of one pose takes less than, whatever its size (the tens of tensor
/// operations of a pass, each at least microseconds).
pub const MIN_SECONDS_PER_RENDER: f64 = 1e-4;
/// Time no optimisation step takes less than (the renders, a backward pass, Adam).
pub const MIN_SECONDS_PER_STEP: f64 = 1e-3;
/// Time no study run takes less than (a process, a scene, a step, the metrics).
pub const MIN_SECONDS_PER_STUDY_RUN: f64 = 0.1;
/// Above this estimate the work is announced with a warning.
pub const WARN_SECONDS: f64 = 3600.0;
/// Above this estimate (a lower bound) work without a time limit is refused.
pub const MAX_SECONDS: f64 = 24.0 * 3600.0;

/// The time of a piece of work: a lower bound, item by item, from its sizes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TimePlan {
    /// Each item: what it is (naming the keys or options that size it) and its seconds.
    pub items: Vec<(String, f64)>,
}

/// How the time of a piece of work is bounded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeBound<'a> {
    /// Nothing stops it but its end.
    Unbounded,
    /// A key stops it after its seconds (when set).
    Key {
        /// The key or option (e.g. `optimiser.time_limit_s`).
        key: &'a str,
        /// Its value, if set.
        seconds: Option<f64>,
    },
}

impl TimePlan {
    /// Adds an item.
    pub fn item(&mut self, what: impl Into<String>, seconds: f64) -> &mut Self {
        self.items.push((what.into(), seconds));
        self
    }

    /// The sum of the items.
    pub fn total(&self) -> f64 {
        self.items.iter().map(|(_, s)| s).sum()
    }

    /// The largest item's description.
    fn largest(&self) -> &str {
        self.items
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or("the work", |(w, _)| w.as_str())
    }

    /// Errors when the work would take more than [`MAX_SECONDS`] and `bound` does not stop it,
    /// naming the largest item, the estimate and the limit; warns (on the log) above
    /// [`WARN_SECONDS`]. Returns the warning, if any.
    pub fn check(&self, bound: TimeBound<'_>) -> Result<Option<String>> {
        let total = self.total();
        let limit = match bound {
            TimeBound::Key {
                seconds: Some(s), ..
            } => Some(s),
            _ => None,
        };
        let estimate = format!("at least {}", show_seconds(total));
        let fits = total.partial_cmp(&MAX_SECONDS) == Some(std::cmp::Ordering::Less);
        if limit.is_none() && !fits {
            let raise = match bound {
                TimeBound::Key { key, .. } => format!(", or bound it with {key}"),
                TimeBound::Unbounded => String::new(),
            };
            bail!(
                "{} would take {estimate}, more than the {} splatraj starts without a time \
                 limit; make it smaller{raise}",
                self.largest(),
                show_seconds(MAX_SECONDS)
            );
        }
        if total.partial_cmp(&WARN_SECONDS) != Some(std::cmp::Ordering::Greater) {
            return Ok(None);
        }
        let warning = match (bound, limit) {
            (TimeBound::Key { key, .. }, Some(s)) if s < total => format!(
                "{} would take {estimate}: {key} = {s} stops it before",
                self.largest()
            ),
            _ => format!("{} will take {estimate}", self.largest()),
        };
        tracing::warn!("{warning}");
        Ok(Some(warning))
    }
}

/// `3.2 s`, `4.5 min`, `7.1 h`, `12 days`.
pub fn show_seconds(seconds: f64) -> String {
    if !seconds.is_finite() {
        "longer than any machine runs".to_string()
    } else if seconds < 60.0 {
        format!("{seconds:.1} s")
    } else if seconds < 3600.0 {
        format!("{:.1} min", seconds / 60.0)
    } else if seconds < 86400.0 * 2.0 {
        format!("{:.1} h", seconds / 3600.0)
    } else {
        format!("{:.0} days", seconds / 86400.0)
    }
}

/// A lower bound of the time of `renders` renders of `pixels` pixels each.
pub fn render_seconds(renders: f64, pixels: f64) -> f64 {
    renders * (MIN_SECONDS_PER_RENDER + pixels * MIN_SECONDS_PER_PIXEL)
}

/// `width × height` as a float (no overflow).
pub fn pixels(width: usize, height: usize) -> f64 {
    width as f64 * height as f64
}

/// Renders of one size, sized by options or a file, checked before any work: `what` names
/// what sizes them (e.g. "`--repeats` = 1000000000 renders at `--width` × `--height`").
#[derive(Debug, Clone, PartialEq)]
pub struct RenderWork {
    /// What the renders are, naming the keys, options or file that size them.
    pub what: String,
    /// How many renders in all.
    pub renders: f64,
    /// How many are held at once.
    pub at_once: usize,
    /// Width and height of each.
    pub size: (usize, usize),
    /// Gaussians of the scene (0 when not known yet: the scene is checked when read).
    pub gaussians: usize,
    /// With a pose gradient or not.
    pub gradient: bool,
    /// Bytes per float (4 or 8).
    pub float_bytes: usize,
}

impl RenderWork {
    /// The memory of the renders held at once, and the time of them all.
    pub fn plans(&self) -> (MemoryPlan, TimePlan) {
        let (w, h) = self.size;
        let mut memory = MemoryPlan::default();
        memory.stage(
            format!("{} ({} × {} pixels)", self.what, w, h),
            scene_bytes(self.gaussians, self.float_bytes)
                + render_bytes(
                    self.at_once,
                    pixels(w, h),
                    self.gaussians,
                    self.gradient,
                    self.float_bytes,
                ),
        );
        let mut time = TimePlan::default();
        time.item(
            format!("{} ({} × {} pixels)", self.what, w, h),
            render_seconds(self.renders, pixels(w, h)),
        );
        (memory, time)
    }

    /// Errors when the renders do not fit `limit` (raised by `raise`) or would take more than
    /// [`MAX_SECONDS`]; warns when long.
    pub fn check(&self, limit: MemoryLimit, raise: &str) -> Result<()> {
        self.check_beside(None, limit, raise)
    }

    /// [`RenderWork::check`] with buffers held beside the renders all along: `(what they
    /// are, bytes)`, such as an output frame writer's queues.
    pub fn check_beside(
        &self,
        held: Option<(&str, f64)>,
        limit: MemoryLimit,
        raise: &str,
    ) -> Result<()> {
        let (mut memory, time) = self.plans();
        if let Some((what, bytes)) = held {
            for stage in &mut memory.stages {
                stage.what = format!("{} with {what} ({})", stage.what, show_bytes(bytes));
                stage.bytes += bytes;
            }
        }
        memory.check(limit, raise)?;
        time.check(TimeBound::Unbounded)?;
        Ok(())
    }
}

/// Errors when `frames` frames sampled from a model of `basis` functions (0: the file's own
/// frames) do not fit the default memory limit; `what` names what sizes them.
pub fn check_path_frames(what: &str, frames: f64, basis: usize) -> Result<()> {
    let mut plan = MemoryPlan::default();
    plan.stage(
        format!("{what}: {frames} frames from {basis} basis functions"),
        BASE_BYTES + frames * (PATH_BYTES_PER_FRAME + 8.0 * basis as f64),
    );
    plan.check(MemoryLimit::new(None)?, "")
}

/// Errors when `threads` worker threads do not fit the default memory limit.
pub fn check_threads(what: &str, threads: usize) -> Result<()> {
    let mut plan = MemoryPlan::default();
    plan.stage(
        format!("{what} = {threads} worker threads"),
        BASE_BYTES + threads as f64 * WORKER_STACK_BYTES,
    );
    plan.check(MemoryLimit::new(None)?, "")
}

/// Errors when a study of `runs` runs (`variants` × `--seeds`) does not fit the default
/// memory limit or would take more than [`MAX_SECONDS`]; warns when long.
pub fn check_study(variants: f64, seeds: usize, runs: f64) -> Result<()> {
    let what = format!(
        "a study of {runs} runs ({variants} variants of `--vary`, `study.vary` and `--grid` × \
         `--seeds` = {seeds})"
    );
    let mut memory = MemoryPlan::default();
    memory.stage(what.clone(), BASE_BYTES + runs * STUDY_BYTES_PER_RUN);
    memory.check(MemoryLimit::new(None)?, "")?;
    let mut time = TimePlan::default();
    time.item(what, runs * MIN_SECONDS_PER_STUDY_RUN);
    time.check(TimeBound::Unbounded)?;
    Ok(())
}

/// The key and option that raise the limit, for messages.
pub const RAISE_LIMIT: &str = "`max_memory_gb` (or --max-memory GB)";

/// Process peak resident set (VmHWM), MB; None where /proc is missing.
pub fn peak_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_huge_camera_is_refused_naming_the_stage_and_the_limit() {
        let mut plan = MemoryPlan::default();
        let pixels = 1e7 * 1e7;
        plan.stage("scene", scene_bytes(1000, 4)).stage(
            "a render at `camera.width` × `camera.height` = 10000000 × 10000000",
            render_bytes(1, pixels, 1000, false, 4),
        );
        let limit = MemoryLimit {
            bytes: 8e9,
            source: LimitSource::Machine,
        };
        let message = plan.check(limit, "--max-memory").unwrap_err().to_string();
        assert!(message.contains("`camera.width`"), "{message}");
        assert!(message.contains("4.8 PB"), "{message}");
        assert!(message.contains("8.0 GB"), "{message}");
        // A small render fits.
        let mut small = MemoryPlan::default();
        small.stage("render", render_bytes(1, 320.0 * 240.0, 100_000, true, 4));
        small.check(limit, "--max-memory").unwrap();
    }

    #[test]
    fn buffers_held_beside_renders_count_against_the_limit() {
        let work = RenderWork {
            what: "270 frames".into(),
            renders: 270.0,
            at_once: 2,
            size: (1280, 720),
            gaussians: 100_000,
            gradient: false,
            float_bytes: 4,
        };
        let (memory, _) = work.plans();
        let renders = memory.peak().unwrap().bytes;
        // A limit between the renders alone and the renders with the writer's buffers.
        let held = 400e6;
        let limit = MemoryLimit {
            bytes: renders + held / 2.0,
            source: LimitSource::Given,
        };
        work.check(limit, "").unwrap();
        work.check_beside(Some(("the writer's queues", held / 4.0)), limit, "")
            .unwrap();
        let message = work
            .check_beside(Some(("the writer's queues", held)), limit, "")
            .unwrap_err()
            .to_string();
        assert!(message.contains("270 frames"), "{message}");
        assert!(
            message.contains("the writer's queues (400.0 MB)"),
            "{message}"
        );
    }

    #[test]
    fn the_default_limit_is_a_share_of_physical_memory() {
        let limit = MemoryLimit::new(None).unwrap();
        let space = address_space_limit().unwrap_or(f64::INFINITY);
        if let Some(total) = physical_memory()
            && total < space
        {
            assert_eq!(limit.source, LimitSource::Machine);
            assert!((limit.bytes - DEFAULT_MEMORY_FRACTION * total).abs() < 1.0);
        }
        assert!(MemoryLimit::new(Some(-1.0)).is_err());
        assert_eq!(MemoryLimit::new(Some(2.0)).unwrap().bytes, 2e9);
    }

    #[test]
    fn time_is_refused_above_the_ceiling_unless_a_key_bounds_it() {
        let mut plan = TimePlan::default();
        plan.item("`--repeats` = 1000000000 renders", 2.0 * MAX_SECONDS);
        let message = plan.check(TimeBound::Unbounded).unwrap_err().to_string();
        assert!(message.contains("`--repeats`"), "{message}");
        assert!(message.contains("at least 2 days"), "{message}");
        let bound = TimeBound::Key {
            key: "`optimiser.time_limit_s`",
            seconds: None,
        };
        let message = plan.check(bound).unwrap_err().to_string();
        assert!(message.contains("`optimiser.time_limit_s`"), "{message}");
        // With the limit set, only a warning naming it.
        let bound = TimeBound::Key {
            key: "`optimiser.time_limit_s`",
            seconds: Some(60.0),
        };
        let warning = plan.check(bound).unwrap().unwrap();
        assert!(warning.contains("stops it before"), "{warning}");
        // Short work passes silently.
        let mut short = TimePlan::default();
        short.item("a render", render_seconds(1.0, 320.0 * 240.0));
        assert_eq!(short.check(TimeBound::Unbounded).unwrap(), None);
    }

    #[test]
    fn path_frames_are_refused_by_frames_times_basis_functions() {
        check_path_frames("a path", 300.0, 24).unwrap();
        // A trajectory.json claiming 10⁹ basis functions, evaluated at 1000 frames.
        let message = check_path_frames("the path of t.json", 1000.0, 1_000_000_000)
            .unwrap_err()
            .to_string();
        assert!(message.contains("t.json"), "{message}");
        assert!(message.contains("1000000000 basis functions"), "{message}");
        // 10⁹ fps × 10³ s.
        assert!(check_path_frames("`--fps` × `--seconds`", 1e12, 24).is_err());
    }
}
