//! Child processes that end with their parent: `bench render` and `study` run each
//! configuration in a child of this binary, so its peak memory is its own.
//!
//! The parent waits on a child in steps ([`output_until_stopped`]): a stop request (Ctrl-C,
//! SIGTERM: [`splatraj_scene::stop`]) kills and reaps the child and ends the parent's loop with
//! [`splatraj_scene::stop::Stopped`]. A parent killed outright (SIGKILL) cannot do that: on
//! Linux the kernel kills the child with it (`die_with_parent`); elsewhere each child watches
//! its parent ([`exit_with_parent`]) and exits once it is gone.

use std::io::Read;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use anyhow::{Result, anyhow};
use splatraj_scene::stop::{Since, Stopped};

/// How often a parent looks at its child, and a child at its parent.
pub const POLL: Duration = Duration::from_millis(100);

/// Exit status of a child whose parent is gone (128 + SIGHUP, as a shell's children get).
pub const EXIT_ORPHANED: i32 = 129;

/// Runs `command` to its end and returns its output, as [`Command::output`], unless a stop is
/// requested meanwhile: then the child is killed and reaped, and the error is [`Stopped`]
/// naming `what` the child was doing.
pub fn output_until_stopped(command: &mut Command, what: &str) -> Result<Output> {
    let since = Since::now();
    die_with_parent(command);
    let mut child = command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| anyhow!("cannot start {what}: {e}"))?;
    // Both pipes drained on threads of their own, so a child writing much never blocks.
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let status = loop {
        if since.stopped() {
            end(&mut child);
            return Err(Stopped {
                what: format!("{what} was ended"),
            }
            .into());
        }
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) => std::thread::sleep(POLL),
            Err(e) => {
                end(&mut child);
                return Err(anyhow!("cannot wait for {what}: {e}"));
            }
        }
    };
    let join = |reader: std::thread::JoinHandle<Vec<u8>>| reader.join().unwrap_or_default();
    Ok(Output {
        status,
        stdout: join(stdout),
        stderr: join(stderr),
    })
}

fn drain(pipe: Option<impl Read + Send + 'static>) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_end(&mut bytes);
        }
        bytes
    })
}

/// Kills `child` and waits for it, so no process is left behind.
fn end(child: &mut Child) {
    let _ = child.kill();
    let _ = child.wait();
}

/// Has the kernel kill the child `command` starts as soon as this process dies (Linux: the
/// parent-death signal, set between fork and exec). Polling alone ([`exit_with_parent`]) leaves
/// the child running for a while after a SIGKILLed parent; SIGKILL ends it at once, and its
/// results had only one reader, the parent, which is gone (a temporary file it was writing is
/// left as any killed process leaves it: [`splatraj_scene::atomic::is_partial_file`]).
/// The signal comes when the spawning thread ends: [`output_until_stopped`] waits on it.
#[cfg(target_os = "linux")]
fn die_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    let parent = std::process::id();
    // SAFETY: the hook runs in the forked child before exec and only calls prctl, getppid and
    // _exit, which are async-signal-safe; it allocates nothing and takes no lock.
    unsafe {
        command.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // The parent may have died between fork and prctl: then no signal will come.
            if libc::getppid() as u32 != parent {
                libc::_exit(EXIT_ORPHANED);
            }
            Ok(())
        });
    }
}

/// Elsewhere the child polls for its parent instead ([`exit_with_parent`]).
#[cfg(not(target_os = "linux"))]
fn die_with_parent(_command: &mut Command) {}

/// In a child process: exits (with [`EXIT_ORPHANED`]) once the parent is gone, checked every
/// [`POLL`] on a thread of its own. On Unix an orphan is handed to another parent (init or a
/// subreaper), so a parent id that changes means the parent died.
pub fn exit_with_parent() {
    #[cfg(unix)]
    {
        let parent = std::os::unix::process::parent_id();
        std::thread::spawn(move || {
            loop {
                std::thread::sleep(POLL);
                if std::os::unix::process::parent_id() != parent {
                    splatraj_scene::atomic::remove_partial_files_and_exit(EXIT_ORPHANED);
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_child_that_ends_gives_its_output() {
        let output = output_until_stopped(
            Command::new("sh").args(["-c", "echo out; echo err >&2; exit 3"]),
            "a shell",
        )
        .unwrap();
        assert_eq!(output.status.code(), Some(3));
        assert_eq!(String::from_utf8_lossy(&output.stdout), "out\n");
        assert_eq!(String::from_utf8_lossy(&output.stderr), "err\n");
    }
}
