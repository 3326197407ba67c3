//! Child processes that end with their parent: `bench render` and `study` run each
//! configuration in a child of this binary, so its peak memory is its own.
//!
//! The parent waits on a child in steps ([`output_until_stopped`]): a stop request (Ctrl-C,
//! SIGTERM: [`splatraj_scene::stop`]) kills and reaps the child and ends the parent's loop with
//! [`splatraj_scene::stop::Stopped`]. A parent killed outright (SIGKILL) cannot do that, so
//! each child watches its parent ([`exit_with_parent`]) and exits once it is gone.

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
