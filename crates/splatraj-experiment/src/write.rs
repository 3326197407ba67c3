//! Files written whole or not at all (a temporary name, then a rename): bytes, JSON, CSV, a
//! folder of files. Every stage writes through these (the checkpoint while optimising, the run
//! folder's files after it, the study's tables), so they sit below all of them.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::Serialize;
use splatraj_scene::atomic::write_atomically;

/// Writes bytes to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |w| w.write_all(bytes))
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes each `(name, bytes)` into `dir` (created if missing), each file whole or not at
/// all; returns the paths written, in order.
pub fn write_into_folder<B: AsRef<[u8]>>(dir: &Path, files: &[(&str, B)]) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    files
        .iter()
        .map(|(name, bytes)| {
            let path = dir.join(name);
            write_bytes(&path, bytes.as_ref())?;
            Ok(path)
        })
        .collect()
}

/// Writes `value` as pretty JSON to `path` atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    write_bytes(path, format!("{text}\n").as_bytes())
}

/// Writes a CSV (header, then rows of numbers or words) to `path` atomically.
pub fn write_csv(path: &Path, header: &[String], rows: &[Vec<String>]) -> Result<()> {
    let mut text = header.join(",");
    text.push('\n');
    for row in rows {
        text.push_str(&row.join(","));
        text.push('\n');
    }
    write_bytes(path, text.as_bytes())
}
