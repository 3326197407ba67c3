//! Peak memory of a run, a pose run or a render, estimated from its sizes before any work, and
//! refused when it exceeds what the machine can hold, with the key to blame, the estimate and
//! the limit.
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
//! `sysinfo`, which knows every platform's way to ask). A prepared experiment's plans, stage by
//! stage, are [`crate::memory_plans`]; this file knows sizes, not experiments.

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
    /// Given (by a key or an option) or the default share of physical memory.
    pub given: bool,
}

impl MemoryLimit {
    /// `gigabytes` when given (must be finite and > 0), else [`DEFAULT_MEMORY_FRACTION`] of
    /// the physical memory (or 16 GB when it cannot be read).
    pub fn new(gigabytes: Option<f64>) -> Result<MemoryLimit> {
        match gigabytes {
            Some(gb) if gb.is_finite() && gb > 0.0 => Ok(MemoryLimit {
                bytes: gb * 1e9,
                given: true,
            }),
            Some(gb) => bail!("the memory limit {gb} GB must be finite and > 0"),
            None => Ok(MemoryLimit {
                bytes: DEFAULT_MEMORY_FRACTION * physical_memory().unwrap_or(16e9 / 0.75),
                given: false,
            }),
        }
    }
}

/// Physical memory in bytes, if the platform tells.
pub fn physical_memory() -> Option<f64> {
    let mut system = sysinfo::System::new();
    system.refresh_memory();
    match system.total_memory() {
        0 => None,
        bytes => Some(bytes as f64),
    }
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
    /// how to raise it (`raise`: the key or option that does).
    pub fn check(&self, limit: MemoryLimit, raise: &str) -> Result<()> {
        if let Some(stage) = self.peak()
            // NaN (a size beyond any float) does not fit either.
            && !matches!(
                stage.bytes.partial_cmp(&limit.bytes),
                Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
            )
        {
            let source = if limit.given {
                "the limit given".to_string()
            } else {
                format!(
                    "{:.0} % of this machine's memory",
                    100.0 * DEFAULT_MEMORY_FRACTION
                )
            };
            bail!(
                "{} needs about {} of memory, more than the limit of {} ({source}); make it \
                 smaller, or raise the limit with {raise}",
                stage.what,
                show_bytes(stage.bytes),
                show_bytes(limit.bytes)
            );
        }
        Ok(())
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

/// The key and option that raise the limit, for messages.
pub const RAISE_LIMIT: &str = "`max_memory_gb` (or --max-memory GB)";

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
            given: false,
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
    fn the_default_limit_is_a_share_of_physical_memory() {
        let limit = MemoryLimit::new(None).unwrap();
        assert!(!limit.given);
        if let Some(total) = physical_memory() {
            assert!((limit.bytes - DEFAULT_MEMORY_FRACTION * total).abs() < 1.0);
        }
        assert!(MemoryLimit::new(Some(-1.0)).is_err());
        assert_eq!(MemoryLimit::new(Some(2.0)).unwrap().bytes, 2e9);
    }
}
