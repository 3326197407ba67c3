//! Whole-or-nothing file writes: write to a temporary file beside the target, then rename.
//!
//! The temporary files being written are listed, so that a program that must quit at once (a
//! second Ctrl-C) can remove them first: [`remove_partial_files_and_exit`]. A killed process cannot;
//! its leftovers are named `.NAME.PID.partial` ([`is_partial_file`]) for whoever cleans up.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Temporary files being written now.
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Removes the temporary files of every write in progress, if no thread holds their list now
/// (before an immediate exit from a failure: the failing thread may be the one holding it, in
/// the middle of starting a write, and must not wait for itself).
pub fn remove_partial_files_if_free() {
    let paths = match IN_FLIGHT.try_lock() {
        Ok(mut paths) => std::mem::take(&mut *paths),
        Err(std::sync::TryLockError::Poisoned(poisoned)) => {
            std::mem::take(&mut *poisoned.into_inner())
        }
        Err(std::sync::TryLockError::WouldBlock) => return,
    };
    for path in paths {
        let _ = std::fs::remove_file(path);
    }
}

/// Removes the temporary files of every write in progress and ends the process with `code`,
/// holding the list meanwhile: a write creates its temporary file while it holds the list, so
/// none can appear between the removal and the exit.
pub fn remove_partial_files_and_exit(code: i32) -> ! {
    let mut paths = match IN_FLIGHT.lock() {
        Ok(paths) => paths,
        Err(poisoned) => poisoned.into_inner(),
    };
    for path in paths.drain(..) {
        let _ = std::fs::remove_file(path);
    }
    std::process::exit(code)
}

/// Whether `name` is a temporary file of [`write_atomically`] (`.NAME.PID.partial`).
pub fn is_partial_file(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".partial")
}

/// Lists `tmp` and creates it, as one step under the list's lock (see
/// [`remove_partial_files_and_exit`]).
fn create_tracked(tmp: &Path) -> std::io::Result<std::fs::File> {
    let mut paths = match IN_FLIGHT.lock() {
        Ok(paths) => paths,
        Err(poisoned) => poisoned.into_inner(),
    };
    paths.push(tmp.to_path_buf());
    std::fs::File::create(tmp)
}

fn untrack(tmp: &Path) {
    let mut paths = match IN_FLIGHT.lock() {
        Ok(paths) => paths,
        Err(poisoned) => poisoned.into_inner(),
    };
    paths.retain(|p| p != tmp);
}

/// Writes a file through `fill` so that `path` appears complete or not at all.
///
/// The temporary file lives in the same folder (a rename across file systems would not be
/// atomic) and is removed if `fill` fails. Only a new path or a regular file is replaced:
/// a device (`/dev/null`, `/dev/full`), a pipe, a socket, a folder or a symbolic link at
/// `path` is refused before anything is written, since the rename would put a regular file in
/// its place (a device node or a link the user made would be gone).
pub fn write_atomically(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    refuse_special(path)?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.partial", std::process::id()));
    let result = (|| {
        let file = create_tracked(&tmp)?;
        let mut out = std::io::BufWriter::new(file);
        fill(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    untrack(&tmp);
    result
}

/// An error unless `path` is free or a regular file (not followed if it is a link).
pub fn refuse_special(path: &Path) -> std::io::Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(()); // a new path
    };
    let kind = meta.file_type();
    let what = if kind.is_file() {
        return Ok(());
    } else if kind.is_dir() {
        "a folder"
    } else if kind.is_symlink() {
        "a symbolic link"
    } else {
        "a special file (a device, a pipe or a socket)"
    };
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!(
            "{} is {what}: splatraj replaces only regular files",
            path.display()
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_files_are_refused_and_left_alone() {
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("folder");
        std::fs::create_dir(&folder).unwrap();
        let target = dir.path().join("target.txt");
        std::fs::write(&target, "theirs").unwrap();
        let link = dir.path().join("link.txt");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        for (path, what) in [
            (Path::new("/dev/null"), "special file"),
            (folder.as_path(), "folder"),
            (link.as_path(), "symbolic link"),
        ] {
            let err = write_atomically(path, |w| w.write_all(b"ours")).unwrap_err();
            assert!(err.to_string().contains(what), "{path:?}: {err}");
        }
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "theirs");
        {
            use std::os::unix::fs::FileTypeExt;
            let null = std::fs::metadata("/dev/null").unwrap().file_type();
            assert!(null.is_char_device(), "/dev/null is still a device");
        }
        // A regular file and a new path are written.
        write_atomically(&target, |w| w.write_all(b"ours")).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "ours");
        let fresh = dir.path().join("fresh.txt");
        write_atomically(&fresh, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read_to_string(&fresh).unwrap(), "new");
    }
}
