//! `splatraj bench launches`: what one kernel launch, one read back and one upload cost on a
//! backend, apart from any arithmetic, and the bandwidth each way (docs/gpu.md, "What a
//! launch costs").
//!
//! An optimisation step launches about 120 kernels, reads once and uploads a few dozen times
//! (`bench step`); a 128² mask pass launches about 50. Whether that, or the host's decisions,
//! or the device's arithmetic sets a GPU step's floor depends on these figures, which no CPU
//! machine can give: lavapipe's "device" is the host's own cores, and on two of them a
//! launch's hand-over between threads costs what it costs there, not on a GPU host. So this
//! times them on the machine itself, with arithmetic too slight to count:
//!
//! - **chain**: a chain of dependent small reductions (`[64, 4]`, each summed and broadcast
//!   back, then scaled): no fusion can merge one reduction into the next, so each is at least
//!   one launch. "queued" is the host's time to issue them, "done" includes waiting for the
//!   last one's value: per launch, the GPU step's cost of a launch is between the two.
//! - **read**: one small op and a read of its one value, again and again: a read waits for
//!   the device, so this is the round trip a step pays once.
//! - **upload**: a fresh 1 KB host array uploaded (as a pass uploads its poses, lists and
//!   values), again and again, and a small value read once at the end (which waits for every
//!   write queued before it); nothing computes on the uploads.
//! - **upload 16 MiB**, **read 16 MiB**: the bandwidth each way, at about the size of a
//!   step's upload (13 MB on the first-try guitar) and a 720p output frame's read back
//!   (14.7 MB): whether uploading host-made tile lists is cheap (issue 35, item 3).
//!
//! Launches are counted ([`splatraj_render::counters`]), not assumed: the chain's "µs each"
//! divides by what the backend actually issued (zero on the CPU backends, which launch
//! nothing: there the per-iteration time is the figure).

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::{Result, bail};
use burn::tensor::{DType, Tensor, TensorData};
use serde::Serialize;
use splatraj_render::backend::BackendKind;
use splatraj_render::counters;
use splatraj_render::host;

/// Rows and columns of the small probes' tensors: far too small for arithmetic to show.
const SHAPE: [usize; 2] = [64, 4];

/// Floats of the large probes' tensors: 16 MiB, about what a step uploads (13 MB on the
/// first-try guitar) and a 720p frame's RGB, mask and alpha read back (14.7 MB).
const LARGE: usize = 4 << 20;

/// What a probe prices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Probe {
    /// A launch: dependent small reductions.
    Chain,
    /// A read back of one value: the device's round trip.
    Read,
    /// An upload of 1 KB.
    Upload,
    /// An upload of 16 MiB: the bandwidth up.
    UploadLarge,
    /// A read back of 16 MiB: the bandwidth down.
    ReadLarge,
}

impl Probe {
    /// The probe's name in the table.
    pub fn name(self) -> &'static str {
        match self {
            Probe::Chain => "chain",
            Probe::Read => "read",
            Probe::Upload => "upload",
            Probe::UploadLarge => "upload 16 MiB",
            Probe::ReadLarge => "read 16 MiB",
        }
    }

    /// Bytes an iteration moves between host and device (0: the small probes).
    pub fn bytes(self) -> usize {
        match self {
            Probe::UploadLarge | Probe::ReadLarge => 4 * LARGE,
            Probe::Chain | Probe::Read | Probe::Upload => 0,
        }
    }
}

/// One probe's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LaunchRow {
    /// What it prices.
    pub probe: Probe,
    /// Iterations timed (after as many untimed ones, for compiling).
    pub iterations: usize,
    /// Kernel launches counted over the timed iterations (0 on the CPU backends).
    pub launches: u64,
    /// Reads back counted over the timed iterations.
    pub reads: u64,
    /// Host time to issue one iteration's ops, µs.
    pub queued_us: f64,
    /// Wall time of one iteration with the final wait for the device shared out, µs.
    pub done_us: f64,
    /// What the probe prices, µs: a launch (chain), a read, an upload.
    pub us_each: f64,
    /// Bytes moved a second, GB/s, for the large probes (0 for the others).
    pub gb_per_s: f64,
}

/// What a probe prices, µs: a launch for [`Probe::Chain`] (done time over the launches
/// counted, or over the iterations where nothing was launched), else an iteration (a read, an
/// upload).
fn price(probe: Probe, iterations: usize, launches: u64, done_us: f64) -> f64 {
    let launches_each = launches as f64 / iterations.max(1) as f64;
    if probe == Probe::Chain && launches_each > 0.0 {
        done_us / launches_each
    } else {
        done_us
    }
}

/// The most iterations a probe runs: every small upload (1 KB) is kept until the wait, so this
/// bounds them to 100 MB.
pub const MAX_ITERATIONS: usize = 100_000;

/// Times the probes on `backend`: the small ones `iterations` times each, the large ones a
/// fiftieth of that (3 to 20), each after as many untimed.
/// More than [`MAX_ITERATIONS`], or none, is an error.
pub fn run_launch_bench(backend: BackendKind, iterations: usize) -> Result<Vec<LaunchRow>> {
    if !(1..=MAX_ITERATIONS).contains(&iterations) {
        bail!(
            "{iterations} iterations: a probe runs 1 to {MAX_ITERATIONS} (each small upload is \
             kept on the device until the probe's end)"
        );
    }
    let device = backend.device()?;
    // At most 20: the large uploads are all kept until the wait (320 MiB).
    let large_iterations = (iterations / 50).clamp(3, 20);
    let constant: Tensor<2> = Tensor::ones(SHAPE, (&device, DType::F32));
    let large: Tensor<1> = Tensor::ones([LARGE], (&device, DType::F32));
    let chain = |n: usize| {
        let mut x: Tensor<2> = Tensor::ones(SHAPE, (&device, DType::F32));
        for _ in 0..n {
            // [64, 1] broadcast back to [64, 4]: the next sum reads this one's result.
            x = x.sum_dim(1).mul_scalar(0.25) + constant.clone();
        }
        x.sum()
    };
    let reads = |n: usize| -> Result<Tensor<1>> {
        for k in 0..n {
            host::to_host(constant.clone().mul_scalar(k as f64).sum())?;
        }
        Ok(constant.clone().sum())
    };
    // The uploaded tensors are kept, not computed on: the wait for a small value at the end
    // waits for every write queued before it, and no arithmetic on the data is timed.
    let uploads = |n: usize, len: usize| {
        let shape = [len];
        let kept: Vec<Tensor<1>> = (0..n)
            .map(|k| {
                let values = vec![k as f32; len];
                host::upload::<1>(TensorData::new(values, shape), &device, DType::F32)
            })
            .collect();
        (kept, constant.clone().sum())
    };
    let large_reads = |n: usize| -> Result<Tensor<1>> {
        for _ in 0..n {
            // The bytes as stored (no conversion to f64): the transfer, not our copy.
            host::read_data(large.clone())?;
        }
        Ok(constant.clone().sum())
    };

    // Each untimed first: kernels compile and tune on first use.
    let mut rows = Vec::new();
    host::to_host(chain(iterations))?;
    rows.push(timed(Probe::Chain, iterations, || {
        Ok(((), chain(iterations)))
    })?);
    host::to_host(reads(iterations)?)?;
    rows.push(timed(Probe::Read, iterations, || {
        Ok(((), reads(iterations)?))
    })?);
    let small = SHAPE[0] * SHAPE[1];
    host::to_host(uploads(iterations, small).1)?;
    rows.push(timed(Probe::Upload, iterations, || {
        Ok(uploads(iterations, small))
    })?);
    host::to_host(uploads(large_iterations, LARGE).1)?;
    rows.push(timed(Probe::UploadLarge, large_iterations, || {
        Ok(uploads(large_iterations, LARGE))
    })?);
    host::to_host(large_reads(large_iterations)?)?;
    rows.push(timed(Probe::ReadLarge, large_iterations, || {
        Ok(((), large_reads(large_iterations)?))
    })?);
    Ok(rows)
}

/// Times `issue` (which returns what it made, kept until the wait is over, and the value to
/// wait for), then the wait for that value, with the counters' difference.
fn timed<T>(
    probe: Probe,
    iterations: usize,
    issue: impl FnOnce() -> Result<(T, Tensor<1>)>,
) -> Result<LaunchRow> {
    let before = counters::snapshot();
    let started = Instant::now();
    let (made, last) = issue()?;
    let queued = started.elapsed().as_secs_f64();
    host::to_host(last)?;
    let done = started.elapsed().as_secs_f64();
    drop(made);
    // Counted after the wait: burn's fusion queues ops and launches them when a read flushes
    // the queue. The final read (and its one reduction) is not the probe's.
    let counted = counters::snapshot().since(&before);
    let n = iterations as f64;
    let done_us = done * 1e6 / n;
    Ok(LaunchRow {
        probe,
        iterations,
        launches: counted.launches,
        reads: counted.reads.saturating_sub(1),
        queued_us: queued * 1e6 / n,
        done_us,
        us_each: price(probe, iterations, counted.launches, done_us),
        // 0 for the small probes, which move no bytes worth a rate.
        gb_per_s: probe.bytes() as f64 / (done_us * 1e3),
    })
}

/// The rows as a table.
pub fn launch_table(backend: BackendKind, rows: &[LaunchRow]) -> String {
    let mut out = format!(
        "backend {backend}; µs per iteration; each: a launch (chain), a read, an upload\n{:<14} {:>10} {:>9} {:>6} {:>10} {:>10} {:>9} {:>6}\n",
        "probe", "iterations", "launches", "reads", "queued µs", "done µs", "µs each", "GB/s"
    );
    for r in rows {
        let rate = if r.gb_per_s > 0.0 {
            format!("{:.2}", r.gb_per_s)
        } else {
            "-".into()
        };
        let _ = writeln!(
            out,
            "{:<14} {:>10} {:>9} {:>6} {:>10.1} {:>10.1} {:>9.1} {:>6}",
            r.probe.name(),
            r.iterations,
            r.launches,
            r.reads,
            r.queued_us,
            r.done_us,
            r.us_each,
            rate
        );
    }
    out
}
