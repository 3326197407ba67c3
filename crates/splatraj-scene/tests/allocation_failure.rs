//! A refused allocation ends the process with status 1, a message naming its size and the
//! program's context, and no temporary file left: the behaviour `splatraj` installs in `main`.
//!
//! The failing program is this test binary run again as a child (an abort cannot be caught in
//! the process that observes it); the child asks for 64 TiB, more than any machine here holds,
//! which Linux refuses under every overcommit mode.

#![cfg(target_os = "linux")]

use std::path::Path;
use std::process::Command;

use splatraj_scene::allocation::{ReportingAllocator, end_failed_allocations_cleanly};

#[global_allocator]
static ALLOCATOR: ReportingAllocator<std::alloc::System> = ReportingAllocator(std::alloc::System);

/// Set in the child: the folder it writes into.
const CHILD_FOLDER: &str = "ALLOCATION_FAILURE_CHILD_FOLDER";

const TIB_64: usize = 64 << 40;

fn context() -> String {
    "while testing the handler.".to_string()
}

/// The child: a failed allocation inside a whole-or-nothing write.
fn fail_inside_a_write(folder: &Path) -> ! {
    end_failed_allocations_cleanly(context);
    let _ = splatraj_scene::atomic::write_atomically(&folder.join("out.bin"), |out| {
        out.write_all(b"the start of a file")?;
        let huge = vec![1u8; TIB_64];
        out.write_all(&huge[..1])
    });
    unreachable!("the allocation of 64 TiB succeeded");
}

#[test]
fn a_refused_allocation_ends_with_status_1_a_message_and_no_partial_file() {
    if let Some(folder) = std::env::var_os(CHILD_FOLDER) {
        fail_inside_a_write(Path::new(&folder));
    }
    let folder = tempfile::tempdir().unwrap();
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "a_refused_allocation_ends_with_status_1_a_message_and_no_partial_file",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_FOLDER, folder.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "status {:?}: {stderr}",
        out.status
    );
    assert!(
        stderr.contains("error: out of memory")
            && stderr.contains(&format!("({TIB_64} bytes)"))
            && stderr.contains("65536.0 GiB")
            && stderr.contains("while testing the handler."),
        "{stderr}"
    );
    let left: Vec<_> = std::fs::read_dir(folder.path())
        .unwrap()
        .map(|entry| entry.unwrap().file_name())
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn an_abort_without_a_failed_allocation_still_aborts() {
    if std::env::var_os("ALLOCATION_FAILURE_CHILD_ABORT").is_some() {
        end_failed_allocations_cleanly(context);
        std::process::abort();
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "an_abort_without_a_failed_allocation_still_aborts",
            "--nocapture",
        ])
        .env("ALLOCATION_FAILURE_CHILD_ABORT", "1")
        .output()
        .unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert_eq!(out.status.signal(), Some(SIGABRT), "{:?}", out.status);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("out of memory"));
}

/// SIGABRT's number on Linux (every architecture).
const SIGABRT: i32 = 6;
