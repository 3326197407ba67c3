//! The real scenes of the shared data folder, for tests of any crate of the workspace (the
//! root's and other crates' tests include this file with `#[path]`: one lookup, one rule).

use std::path::{Path, PathBuf};

/// A real scene from the shared data folder, or `None` (with a notice) when it is not there.
/// `SPLATRAJ_DATA` names the folder (default: `shared/data` beside the repository, found from
/// the workspace root, the folder holding `Cargo.lock`); `SPLATRAJ_REQUIRE_DATA=1` makes
/// absence a failure.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("SPLATRAJ_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
            let root = manifest
                .ancestors()
                .find(|d| d.join("Cargo.lock").is_file())
                .unwrap_or(manifest);
            root.join("../shared/data")
        });
    let path = dir.join(name);
    if path.exists() {
        return Some(path);
    }
    if std::env::var("SPLATRAJ_REQUIRE_DATA").is_ok_and(|v| v == "1") {
        panic!("{} is missing and SPLATRAJ_REQUIRE_DATA=1", path.display());
    }
    eprintln!(
        "skipped: {} not found (set SPLATRAJ_DATA to the shared data folder)",
        path.display()
    );
    None
}
