//! Whole-or-nothing file writes: write to a temporary file beside the target, then rename.
//!
//! The temporary files being written are listed, so that a program that must quit at once (a
//! second Ctrl-C) can remove them first: [`remove_partial_files`]. A killed process cannot;
//! its leftovers are named `.NAME.PID.partial` ([`is_partial_file`]) for whoever cleans up.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files being written now.
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Removes the temporary files of every write in progress (before an immediate exit).
pub fn remove_partial_files() {
    let paths = match IN_FLIGHT.lock() {
        Ok(mut paths) => std::mem::take(&mut *paths),
        Err(poisoned) => std::mem::take(&mut *poisoned.into_inner()),
    };
    for path in paths {
        let _ = std::fs::remove_file(path);
    }
}

/// Whether `name` is a temporary file of [`write_atomically`] (`.NAME.PID.partial`).
pub fn is_partial_file(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".partial")
}

fn track(tmp: &Path, writing: bool) {
    let mut paths = match IN_FLIGHT.lock() {
        Ok(paths) => paths,
        Err(poisoned) => poisoned.into_inner(),
    };
    if writing {
        paths.push(tmp.to_path_buf());
    } else {
        paths.retain(|p| p != tmp);
    }
}

/// Writes a file through `fill` so that `path` appears complete or not at all.
///
/// The temporary file lives in the same folder (a rename across file systems would not be
/// atomic) and is removed if `fill` fails.
pub fn write_atomically(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.partial", std::process::id()));
    track(&tmp, true);
    let result = (|| {
        let file = std::fs::File::create(&tmp)?;
        let mut out = std::io::BufWriter::new(file);
        fill(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    track(&tmp, false);
    result
}
