//! `bench launches` on the CPU backend: every probe runs, counted as it should be.
//!
//! Its own test binary with one test: the read counter is process-wide, and the library's unit
//! tests that render read beside each other.

use splatraj_experiment::bench::launches::{Probe, run_launch_bench};
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
