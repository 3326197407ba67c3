//! Helpers shared by the scene crate's integration tests.
#![allow(dead_code)] // each test binary uses a different subset

use std::path::PathBuf;

/// A fixture copied into the repository (`tests/data/NAME`).
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// A larger real scene from the shared data folder, or `None` (with a notice) when it is not
/// there. `SPLATRAJ_DATA` overrides the folder; `SPLATRAJ_REQUIRE_DATA=1` makes absence a failure.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("SPLATRAJ_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
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

/// Offset of the first payload byte of a PLY file (just after `end_header\n`).
pub fn payload_offset(bytes: &[u8]) -> usize {
    let marker = b"end_header\n";
    bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("PLY has end_header")
        + marker.len()
}

/// Little-endian f32 at byte `at`.
pub fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

/// Little-endian u32 at byte `at`.
pub fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}
