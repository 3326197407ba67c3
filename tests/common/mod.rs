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
