//! `splatraj bench launches`: what one kernel launch, one read back and one upload cost on a
//! backend, apart from any arithmetic (docs/gpu.md, "What a launch costs").
//!
//! An optimisation step launches about 120 kernels, reads once and uploads a few dozen times
//! (`bench step`); a 128² mask pass launches about 50. Whether that, or the host's decisions,
//! or the device's arithmetic sets a GPU step's floor depends on these three figures, which
//! no CPU machine can give: lavapipe's "device" is the host's own cores, and on two of them a
//! launch's hand-over between threads costs what it costs there, not on a GPU host. So this
//! times them on the machine itself, each on tensors too small for their arithmetic to count:
//!
//! - **chain**: a chain of dependent small reductions (`[64, 4]`, each summed and broadcast
//!   back, then scaled): no fusion can merge one reduction into the next, so each is at least
//!   one launch. "queued" is the host's time to issue them, "done" includes waiting for the
//!   last one's value: per launch, the GPU step's cost of a launch is between the two.
//! - **read**: one small op and a read of its one value, again and again: a read waits for
//!   the device, so this is the round trip a step pays once.
//! - **upload**: a fresh 1 KB host array uploaded and added to a running sum (as a pass
//!   uploads its poses, lists and values), read once at the end.
//!
//! Launches are counted ([`splatraj_render::counters`]), not assumed: "µs a launch" divides by
//! what the backend actually issued (zero on the CPU backends, which launch nothing: there the
//! per-op time is the figure).

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::Result;
use burn::tensor::{DType, Tensor, TensorData};
use serde::Serialize;
use splatraj_render::backend::BackendKind;
use splatraj_render::counters;
use splatraj_render::host;

/// Rows and columns of the probes' tensors: far too small for arithmetic to show.
const SHAPE: [usize; 2] = [64, 4];

/// One probe's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LaunchRow {
    /// `chain`, `read` or `upload`.
    pub probe: &'static str,
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
    /// What the probe prices, µs ([`LaunchRow::us_each`]).
    pub us_each: f64,
}

impl LaunchRow {
    /// What the probe prices, µs: a launch for `chain` (done time over the launches counted,
    /// or over the iterations where nothing was launched), a read or an upload (done time per
    /// iteration: fusion merges the uploads' additions, so their launches say nothing).
    pub fn us_each(&self) -> f64 {
        let launches_each = self.launches as f64 / self.iterations.max(1) as f64;
        if self.probe == "chain" && launches_each > 0.0 {
            self.done_us / launches_each
        } else {
            self.done_us
        }
    }
}

/// Times the three probes on `backend`, `iterations` each (after as many untimed).
pub fn run_launch_bench(backend: BackendKind, iterations: usize) -> Result<Vec<LaunchRow>> {
    let device = backend.device()?;
    let iterations = iterations.max(1);
    let constant: Tensor<2> = Tensor::ones(SHAPE, (&device, DType::F32));
    let chain = |n: usize| {
        let mut x: Tensor<2> = Tensor::ones(SHAPE, (&device, DType::F32));
        for _ in 0..n {
            // [64, 1] broadcast back to [64, 4]: the next sum reads this one's result.
            x = x.sum_dim(1).mul_scalar(0.25) + constant.clone();
        }
        x
    };
    let reads = |n: usize| -> Result<()> {
        for k in 0..n {
            host::to_host(constant.clone().mul_scalar(k as f64).sum())?;
        }
        Ok(())
    };
    let uploads = |n: usize| {
        let mut total = constant.clone();
        for k in 0..n {
            let values = vec![k as f32; SHAPE[0] * SHAPE[1]];
            total = total + host::upload::<2>(TensorData::new(values, SHAPE), &device, DType::F32);
        }
        total
    };

    let mut rows = Vec::new();
    // Untimed first: kernels compile and tune on first use.
    host::to_host(chain(iterations).sum())?;
    rows.push(timed("chain", iterations, || {
        let x = chain(iterations);
        let queued = Instant::now();
        Ok((x.sum(), queued))
    })?);
    reads(iterations)?;
    rows.push(timed("read", iterations, || {
        reads(iterations)?;
        Ok((constant.clone().sum(), Instant::now()))
    })?);
    host::to_host(uploads(iterations).sum())?;
    rows.push(timed("upload", iterations, || {
        let total = uploads(iterations);
        let queued = Instant::now();
        Ok((total.sum(), queued))
    })?);
    Ok(rows)
}

/// Times `issue` (which returns the value to wait for and when it finished issuing), then the
/// wait for that value, with the counters' difference.
fn timed(
    probe: &'static str,
    iterations: usize,
    issue: impl FnOnce() -> Result<(Tensor<1>, Instant)>,
) -> Result<LaunchRow> {
    let before = counters::snapshot();
    let started = Instant::now();
    let (last, issued) = issue()?;
    host::to_host(last)?;
    let done = started.elapsed().as_secs_f64();
    // Counted after the wait: burn's fusion queues ops and launches them when a read flushes
    // the queue. The final read (and its one reduction) is not the probe's.
    let counted = counters::snapshot().since(&before);
    let queued = issued.duration_since(started).as_secs_f64();
    let n = iterations as f64;
    let mut row = LaunchRow {
        probe,
        iterations,
        launches: counted.launches,
        reads: counted.reads.saturating_sub(1),
        queued_us: queued * 1e6 / n,
        done_us: done * 1e6 / n,
        us_each: 0.0,
    };
    row.us_each = row.us_each();
    Ok(row)
}

/// The rows as a table.
pub fn launch_table(backend: BackendKind, rows: &[LaunchRow]) -> String {
    let mut out = format!(
        "backend {backend}; µs per iteration; each: a launch (chain), a read, an upload\n{:<8} {:>10} {:>9} {:>6} {:>10} {:>10} {:>9}\n",
        "probe", "iterations", "launches", "reads", "queued µs", "done µs", "µs each"
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{:<8} {:>10} {:>9} {:>6} {:>10.1} {:>10.1} {:>9.1}",
            r.probe,
            r.iterations,
            r.launches,
            r.reads,
            r.queued_us,
            r.done_us,
            r.us_each()
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On the CPU backend every probe runs, reads once per `read` iteration and launches
    /// nothing; the chain's price falls back to the per-iteration time.
    #[test]
    fn probes_count_what_they_do_on_flex() {
        let rows = run_launch_bench(BackendKind::Flex, 5).unwrap();
        let probes: Vec<_> = rows.iter().map(|r| r.probe).collect();
        assert_eq!(probes, ["chain", "read", "upload"]);
        assert!(rows.iter().all(|r| r.launches == 0));
        assert_eq!(rows[1].reads, 5, "one read an iteration");
        assert_eq!(rows[0].reads, 0);
        assert_eq!(rows[2].reads, 0);
        for r in &rows {
            assert!(r.done_us >= r.queued_us && r.queued_us >= 0.0, "{r:?}");
            assert_eq!(r.us_each(), r.done_us);
        }
    }
}
