//! Children die with their parent: a `bench render` child whose parent is killed outright
//! (SIGKILL, which no handler sees) is killed by the kernel at once, not left running.
//!
//! This test process makes itself the subreaper of its orphans (Linux), so the orphaned child
//! becomes its own and `waitpid` tells how it ended: by SIGKILL from the kernel (the parent-death
//! signal), where a child that only polled for its parent would exit on its own later.

#![cfg(target_os = "linux")]

use std::process::{Command, Stdio};
use std::time::Duration;

/// The process ids whose parent is `parent` (from `/proc/PID/stat`) and that run a
/// `bench render --one` child: already past exec, so its parent-death signal is set (a fork
/// not yet exec'd still has its parent's command line).
fn bench_children_of(parent: u32) -> Vec<i32> {
    let mut children = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<i32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else {
            continue;
        };
        // The parent id is the second field after the command name, which may hold spaces.
        let after_name = stat.rfind(')').map_or("", |i| &stat[i + 1..]);
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        if after_name.split_whitespace().nth(1) == Some(&parent.to_string())
            && cmdline.split(|&b| b == 0).any(|arg| arg == b"--one")
        {
            children.push(pid);
        }
    }
    children
}

#[test]
fn a_bench_render_child_is_killed_with_its_parent_when_the_parent_is_sigkilled() {
    // SAFETY: prctl with these arguments only sets a flag of this process.
    assert_eq!(
        unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1 as libc::c_ulong) },
        0
    );
    // Enough repeats that the first child is still timing when its parent is killed.
    let mut parent = Command::new(env!("CARGO_BIN_EXE_splatraj"))
        .args(["bench", "render", "--sizes", "2000", "--resolutions", "64"])
        .args(["--repeats", "100000"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let child = loop {
        if let Some(&pid) = bench_children_of(parent.id()).first() {
            break pid;
        }
        if let Some(status) = parent.try_wait().unwrap() {
            panic!("bench render ended ({status}) before starting a child");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    parent.kill().unwrap();
    parent.wait().unwrap();
    let mut status = 0;
    // SAFETY: waits for a process that is now this process's child (the subreaper's orphan).
    let reaped = unsafe { libc::waitpid(child, &mut status, 0) };
    assert_eq!(reaped, child, "the orphan is this subreaper's child");
    assert!(
        libc::WIFSIGNALED(status) && libc::WTERMSIG(status) == libc::SIGKILL,
        "the child was not killed by its parent's death: wait status {status:#x}"
    );
}
