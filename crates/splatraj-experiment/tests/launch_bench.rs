//! `bench launches` on the CPU backend: every probe runs, counted as it should be.
//!
//! Its own test binary: the read counter is process-wide, and the library's unit tests that
//! render read beside each other (the other test here reads nothing).

use splatraj_experiment::bench::launches::{MAX_ITERATIONS, Probe, run_launch_bench};
use splatraj_render::backend::BackendKind;

/// On the CPU backend every probe runs, each read probe reads once an iteration, nothing
/// is launched, the chain's price falls back to the per-iteration time and the large
/// probes' rate is their bytes over their time.
#[test]
fn probes_count_what_they_do_on_flex() {
    let rows = run_launch_bench(BackendKind::Flex, 5).unwrap();
    let probes: Vec<_> = rows.iter().map(|r| r.probe).collect();
    assert_eq!(
        probes,
        [
            Probe::Chain,
            Probe::Read,
            Probe::Upload,
            Probe::UploadLarge,
            Probe::ReadLarge
        ]
    );
    let reads: Vec<_> = rows.iter().map(|r| r.reads).collect();
    assert_eq!(reads, [0, 5, 0, 0, 3], "a read an iteration, 3 large ones");
    assert!(rows.iter().all(|r| r.launches == 0));
    for r in &rows {
        assert!(r.done_us >= r.queued_us && r.queued_us >= 0.0, "{r:?}");
        assert_eq!(r.us_each, r.done_us);
        let expected = r.probe.bytes() as f64 / (r.done_us * 1e3);
        assert!(
            (r.gb_per_s - expected).abs() <= 1e-9 * expected.max(1.0),
            "{r:?}"
        );
    }
}

/// No iterations, or more than the kept uploads are bounded to, is an error naming the range,
/// before any work.
#[test]
fn iterations_out_of_range_are_refused() {
    for iterations in [0, MAX_ITERATIONS + 1] {
        let error = run_launch_bench(BackendKind::Flex, iterations).unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains(&format!("1 to {MAX_ITERATIONS}")),
            "{message}"
        );
    }
}
