//! Output folders written whole: `render --out`, `render-path --out` and `export --out` fill a fresh staging
//! folder beside the target (`.NAME.PID.partial`) and rename it into place once every file is
//! written, so a re-run replaces the old folder whole (no old frames beside a new video) and a
//! failed run leaves the old folder as it was.
//!
//! A lock file beside the target (`.NAME.lock`, holding the writer's process id) keeps two
//! writers from replacing each other's folder half-way: the second is refused, naming the
//! first's process; a lock whose process is gone (killed) is taken over. An existing target
//! must be a folder holding only names the command writes ([`OutputFolder::begin`]'s `ours`):
//! a folder of the user's other files is refused, never replaced.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// A folder being written: fill [`OutputFolder::path`], then [`OutputFolder::commit`].
/// Dropped without a commit, it removes what it wrote and releases the lock.
#[derive(Debug)]
pub struct OutputFolder {
    target: PathBuf,
    staging: PathBuf,
    lock: PathBuf,
    committed: bool,
}

/// `target`'s parent folder (`.` for a bare name) and its file name.
fn split(target: &Path) -> Result<(PathBuf, String)> {
    let name = target
        .file_name()
        .with_context(|| {
            format!(
                "the output folder {} has no name of its own (`.` or `..`), so it cannot be \
                 replaced whole: give a named folder",
                target.display()
            )
        })?
        .to_string_lossy()
        .into_owned();
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name))
}

/// Whether process `pid` is alive (Linux: its `/proc` entry exists).
fn process_alive(pid: u32) -> bool {
    Path::new("/proc").join(pid.to_string()).exists()
}

impl OutputFolder {
    /// Starts writing the folder `target`, whose files may only be named `ours` (an existing
    /// target holding anything else is refused, naming it; so is a target that is not a
    /// folder). Takes the lock and makes the staging folder (and `target`'s parents).
    pub fn begin(target: &Path, ours: &[&str]) -> Result<Self> {
        let (parent, name) = split(target)?;
        Self::check(target, ours)?;
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("cannot create the folder {}", parent.display()))?;
        let lock = parent.join(format!(".{name}.lock"));
        take_lock(&lock, target)?;
        let staging = parent.join(format!(".{name}.{}.partial", std::process::id()));
        let folder = OutputFolder {
            target: target.to_path_buf(),
            staging,
            lock,
            committed: false,
        };
        // A leftover of this process id (an earlier, killed process) goes first.
        let _ = std::fs::remove_dir_all(&folder.staging);
        std::fs::create_dir(&folder.staging)
            .with_context(|| format!("cannot create {}", folder.staging.display()))?;
        Ok(folder)
    }

    /// Errors unless `target` may be written whole: new, or a folder holding only names of
    /// `ours` (what [`OutputFolder::begin`] checks first; for a command that begins only after
    /// long work).
    pub fn check(target: &Path, ours: &[&str]) -> Result<()> {
        split(target)?;
        if let Ok(meta) = std::fs::symlink_metadata(target) {
            if !meta.is_dir() {
                bail!(
                    "the output folder {} exists and is not a folder",
                    target.display()
                );
            }
            let entries = std::fs::read_dir(target)
                .with_context(|| format!("cannot read the output folder {}", target.display()))?;
            for entry in entries {
                let entry = entry?;
                let file = entry.file_name().to_string_lossy().into_owned();
                if !ours.contains(&file.as_str()) {
                    bail!(
                        "the output folder {} holds {file:?}, which this command does not \
                         write: give a new folder, or one holding only an earlier output \
                         (it is replaced whole)",
                        target.display()
                    );
                }
            }
        }
        Ok(())
    }

    /// Where the files go until the commit.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Puts the written folder in place of the target (an old target is replaced whole) and
    /// releases the lock; returns the target.
    pub fn commit(mut self) -> Result<PathBuf> {
        let old = self.staging.with_extension("old");
        if self.target.exists() {
            std::fs::rename(&self.target, &old)
                .with_context(|| format!("cannot move the old {} aside", self.target.display()))?;
        }
        if let Err(e) = std::fs::rename(&self.staging, &self.target) {
            // Put the old folder back: the target is as it was.
            let _ = std::fs::rename(&old, &self.target);
            return Err(e).with_context(|| format!("cannot create {}", self.target.display()));
        }
        self.committed = true;
        let _ = std::fs::remove_dir_all(&old);
        let _ = std::fs::remove_file(&self.lock);
        Ok(self.target.clone())
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
            let _ = std::fs::remove_file(&self.lock);
        }
    }
}

/// Creates the lock file `lock` for `target`, or refuses while a live process holds it.
fn take_lock(lock: &Path, target: &Path) -> Result<()> {
    for _ in 0..2 {
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(lock)
        {
            Ok(mut file) => {
                use std::io::Write;
                write!(file, "{}", std::process::id())
                    .with_context(|| format!("cannot write {}", lock.display()))?;
                return Ok(());
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let holder = std::fs::read_to_string(lock)
                    .ok()
                    .and_then(|t| t.trim().parse::<u32>().ok());
                match holder {
                    Some(pid) if process_alive(pid) => bail!(
                        "another splatraj (process {pid}) is writing {}: wait for it, or \
                         give another --out (lock file {})",
                        target.display(),
                        lock.display()
                    ),
                    // A killed writer's lock (or one being written this instant): retake it.
                    _ => {
                        let _ = std::fs::remove_file(lock);
                    }
                }
            }
            Err(e) => {
                return Err(e).with_context(|| format!("cannot create {}", lock.display()));
            }
        }
    }
    bail!("cannot take the lock {}", lock.display())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_commit_replaces_the_old_folder_whole_and_a_drop_leaves_it_alone() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("old.png"), "old").unwrap();
        let ours = ["old.png", "new.png"];

        let folder = OutputFolder::begin(&target, &ours).unwrap();
        std::fs::write(folder.path().join("new.png"), "new").unwrap();
        drop(folder);
        let names = |p: &Path| -> Vec<String> {
            let mut n: Vec<String> = std::fs::read_dir(p)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        assert_eq!(
            names(&target),
            ["old.png"],
            "an abandoned write changes nothing"
        );
        assert_eq!(
            names(dir.path()),
            ["out"],
            "no staging folder or lock is left"
        );

        let folder = OutputFolder::begin(&target, &ours).unwrap();
        std::fs::write(folder.path().join("new.png"), "new").unwrap();
        folder.commit().unwrap();
        assert_eq!(
            names(&target),
            ["new.png"],
            "the old file went with the old folder"
        );
        assert_eq!(names(dir.path()), ["out"]);
    }

    #[test]
    fn a_second_writer_is_refused_while_the_first_holds_the_lock() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        let first = OutputFolder::begin(&target, &[]).unwrap();
        let err = OutputFolder::begin(&target, &[]).unwrap_err().to_string();
        assert!(
            err.contains("another splatraj") && err.contains(".out.lock"),
            "{err}"
        );
        drop(first);
        OutputFolder::begin(&target, &[]).unwrap();
    }

    #[test]
    fn a_dead_writers_lock_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        // Process ids stop well below this on Linux (pid_max ≤ 2^22).
        std::fs::write(dir.path().join(".out.lock"), "999999999").unwrap();
        OutputFolder::begin(&target, &[]).unwrap().commit().unwrap();
        assert!(target.is_dir());
    }

    #[test]
    fn a_folder_of_other_files_or_a_file_is_refused_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("notes.txt"), "mine").unwrap();
        let err = OutputFolder::begin(&target, &["video.mp4"]).unwrap_err();
        assert!(err.to_string().contains("notes.txt"), "{err}");
        assert_eq!(
            std::fs::read_to_string(target.join("notes.txt")).unwrap(),
            "mine"
        );
        let file = dir.path().join("file");
        std::fs::write(&file, "x").unwrap();
        let err = OutputFolder::begin(&file, &[]).unwrap_err();
        assert!(err.to_string().contains("is not a folder"), "{err}");
    }
}
