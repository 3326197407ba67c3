//! An allocation that fails ends the program with a message and status 1, not an abort.
//!
//! Rust's standard library answers a failed allocation (outside `try_reserve`) by printing
//! "memory allocation of N bytes failed" and calling `abort()`: status 134, a core dump where
//! enabled, and the temporary files of writes in progress left behind. A stable program cannot
//! replace that answer (the hook is unstable), so [`ReportingAllocator`] remembers the size of
//! the last allocation its inner allocator refused, and [`end_failed_allocations_cleanly`]
//! installs a `SIGABRT` handler that, when such a failure came first, prints what was being
//! allocated (with the caller's context: the memory plan the work passed), removes the
//! temporary files ([`crate::atomic::remove_partial_files_if_free`]) and exits with status 1.
//! Other aborts go on as before. A failure `try_reserve` handles changes nothing: the size is
//! only read if an abort follows.

use std::alloc::{GlobalAlloc, Layout};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Bytes of the last allocation the inner allocator refused (0: none yet).
static FAILED_BYTES: AtomicUsize = AtomicUsize::new(0);

/// Words on what the program was doing, for the message (set once by
/// [`end_failed_allocations_cleanly`]).
static CONTEXT: OnceLock<fn() -> String> = OnceLock::new();

/// Status of a program ended by a failed allocation (the usual error status).
pub const EXIT_OUT_OF_MEMORY: i32 = 1;

/// A global allocator that forwards to `A` and remembers the size of a refused allocation.
pub struct ReportingAllocator<A>(pub A);

fn remember_failure(ptr: *mut u8, bytes: usize) -> *mut u8 {
    if ptr.is_null() {
        FAILED_BYTES.store(bytes, Ordering::SeqCst);
    }
    ptr
}

// SAFETY: every call forwards to `A` with the same arguments and returns its result unchanged.
unsafe impl<A: GlobalAlloc> GlobalAlloc for ReportingAllocator<A> {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract is `A`'s.
        remember_failure(unsafe { self.0.alloc(layout) }, layout.size())
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract is `A`'s.
        remember_failure(unsafe { self.0.alloc_zeroed(layout) }, layout.size())
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract is `A`'s.
        remember_failure(unsafe { self.0.realloc(ptr, layout, new_size) }, new_size)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract is `A`'s.
        unsafe { self.0.dealloc(ptr, layout) }
    }
}

/// Installs the `SIGABRT` handler that ends a failed allocation with a message naming its
/// size and `context()` (what was planned; may be empty), and status [`EXIT_OUT_OF_MEMORY`].
/// Only has an effect with [`ReportingAllocator`] as the global allocator, on Linux.
pub fn end_failed_allocations_cleanly(context: fn() -> String) {
    let _ = CONTEXT.set(context);
    #[cfg(target_os = "linux")]
    // SAFETY: installs a plain handler; `on_abort` only returns or ends the process.
    unsafe {
        libc::signal(
            libc::SIGABRT,
            on_abort as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
}

/// Set while the handler runs: an abort inside it goes on to the default action.
static HANDLING: AtomicBool = AtomicBool::new(false);

/// The handler. `abort()` raised the signal on the failing thread, outside the allocator (the
/// standard library's answer runs after the allocator returned), so allocating and writing
/// here is as safe as in the code that failed; a second failure here aborts as before.
#[cfg(target_os = "linux")]
extern "C" fn on_abort(_signal: libc::c_int) {
    let bytes = FAILED_BYTES.load(Ordering::SeqCst);
    if bytes == 0 || HANDLING.swap(true, Ordering::SeqCst) {
        // Not a failed allocation: returning lets abort() go on.
        return;
    }
    let context = CONTEXT.get().map(|context| context()).unwrap_or_default();
    let message = out_of_memory_message(bytes, &context);
    // SAFETY: writes a byte buffer this function owns to the standard error.
    unsafe {
        libc::write(2, message.as_ptr().cast(), message.len());
    }
    crate::atomic::remove_partial_files_if_free();
    // SAFETY: ends the process at once; nothing of Rust's runs after (no unwinding, no exit
    // handlers that could wait on a lock the failing thread holds).
    unsafe { libc::_exit(EXIT_OUT_OF_MEMORY) }
}

/// The message for a refused allocation of `bytes` with `context` (appended when not empty).
pub fn out_of_memory_message(bytes: usize, context: &str) -> String {
    let size = if bytes >= 1 << 30 {
        format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
    };
    let context = if context.is_empty() {
        String::new()
    } else {
        format!(" {context}")
    };
    format!(
        "error: out of memory: the system refused {size} ({bytes} bytes).{context} Make the \
         work smaller (fewer pixels, samples, poses or Gaussians) or run it where more memory \
         is free; files being written were removed.\n"
    )
}
