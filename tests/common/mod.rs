//! Helpers shared by the CLI integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fixture scene file of the scene crate (`crates/splatraj-scene/tests/data/NAME`).
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/splatraj-scene/tests/data")
        .join(name)
}

/// Runs the `splatraj` binary with `args`.
pub fn splatraj(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args(args)
        .output()
        .expect("binary runs")
}

/// The process's standard error as text.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The process's standard output as text.
pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// A path as `&str` for command arguments.
pub fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A failure is one `error:` paragraph, a non-zero exit, and never a panic.
pub fn assert_clean_failure(output: &Output, mentions: &[&str]) {
    let err = stderr(output);
    assert!(!output.status.success(), "should fail: {err}");
    assert!(err.starts_with("error: "), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one paragraph: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("internal error"),
        "{err}"
    );
    for m in mentions {
        assert!(err.contains(m), "{err:?} does not mention {m:?}");
    }
}

/// A tiny run config (3 000 Gaussians, two queries, a few steps) for end-to-end runs.
pub const TINY_CONFIG: &str = r#"
name = "tiny"
seed = 3
[scene]
demo = { gaussians = 3000, seed = 7 }
[[queries]]
text = "red mug"
[[queries]]
text = "blue box"
[camera]
width = 32
height = 24
[optimiser]
iterations = 3
samples_per_window = 2
[output]
# Three steps frame nothing: the verdict warns, and the tests read the folder.
verdict = "warn"
frames = 3
width = 40
height = 30
trajectory_samples = 5
metric_samples = 2
ldj_samples = 11
[pose.optimiser]
iterations = 3
[sgld]
iterations = 4
burn_in = 1
thin = 1
"#;
