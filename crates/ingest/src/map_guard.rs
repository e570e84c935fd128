//! Memory-mapped inputs that another program truncates while they are read.
//!
//! Binary PLY and binary STL are read through a read-only memory map (vertices are looked up
//! in place, so memory does not grow with the mesh). If the file shrinks while it is mapped
//! (`truncate`, or `cp` over it, which truncates first), touching a page past the new end
//! raises SIGBUS, which by default kills the process without a word. A positioned-read
//! reader cannot give the random access to vertices the map gives without a copy of them, so
//! the fault is handled instead: [`MappedFile`] records each mapping's address range and a
//! message naming its file, and a SIGBUS handler (installed with the first map) that finds the
//! faulting address inside one writes that message to stderr and ends the process with exit
//! status [`TRUNCATED_EXIT`] — a clear error instead of a crash. A SIGBUS at any other address
//! gets the default action. The handler uses only async-signal-safe calls (`write`, `_exit`)
//! and atomics. What remains: the process still ends (it cannot go on without the bytes),
//! and a file rewritten in place at the same length is read as it is (no checksum covers an
//! input mesh). docs/RELIABILITY.md states this.

use std::fs::File;
use std::path::Path;
use std::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
use std::sync::Once;

use memmap2::Mmap;

/// Exit status of a process whose memory-mapped input was truncated under it.
pub const TRUNCATED_EXIT: i32 = 75;

/// Mappings watched at once (a build maps one input; more are simply not watched).
const SLOTS: usize = 16;

struct Slot {
    start: AtomicUsize,
    len: AtomicUsize,
    msg: AtomicPtr<u8>,
    msg_len: AtomicUsize,
}

#[allow(clippy::declare_interior_mutable_const)]
const EMPTY: Slot = Slot {
    start: AtomicUsize::new(0),
    len: AtomicUsize::new(0),
    msg: AtomicPtr::new(std::ptr::null_mut()),
    msg_len: AtomicUsize::new(0),
};
static WATCHED: [Slot; SLOTS] = [EMPTY; SLOTS];
static INSTALL: Once = Once::new();

/// A read-only map of a whole file, watched by the SIGBUS handler while it lives.
pub(crate) struct MappedFile {
    map: Mmap,
    slot: Option<usize>,
}

impl MappedFile {
    /// Maps `file` (opened from `path`) read-only and watches the mapping.
    pub fn map(path: &Path, file: &File) -> std::io::Result<MappedFile> {
        // SAFETY: a read-only shared map. If the file shrinks while mapped, reading past its
        // new end raises SIGBUS, which the handler below turns into an error exit naming the
        // file; the contents may otherwise change under us, which only changes values read.
        let map = unsafe { Mmap::map(file) }?;
        INSTALL.call_once(install_handler);
        let msg = format!(
            "error: {}: the input file was truncated or replaced while it was being read (through a memory map); stopped. Run the command again once the file is complete.\n",
            path.display()
        )
        .into_bytes()
        .into_boxed_slice();
        let slot = (!map.is_empty())
            .then(|| {
                WATCHED.iter().position(|s| {
                    s.start
                        .compare_exchange(0, usize::MAX, Ordering::AcqRel, Ordering::Relaxed)
                        .is_ok()
                })
            })
            .flatten();
        if let Some(i) = slot {
            let s = &WATCHED[i];
            let len = msg.len();
            // leaked on purpose: the handler may read it at any time (a few per process)
            s.msg.store(Box::leak(msg).as_mut_ptr(), Ordering::Release);
            s.msg_len.store(len, Ordering::Release);
            s.len.store(map.len(), Ordering::Release);
            s.start.store(map.as_ptr() as usize, Ordering::Release);
        }
        Ok(MappedFile { map, slot })
    }

    pub fn mmap(&self) -> &Mmap {
        &self.map
    }
}

impl std::ops::Deref for MappedFile {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.map
    }
}

impl Drop for MappedFile {
    fn drop(&mut self) {
        if let Some(i) = self.slot {
            let s = &WATCHED[i];
            s.len.store(0, Ordering::Release);
            s.start.store(0, Ordering::Release);
        }
    }
}

fn install_handler() {
    // SAFETY: installs a handler made only of atomics, write(2) and _exit(2).
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigbus as *const () as usize;
        sa.sa_flags = libc::SA_SIGINFO | libc::SA_ONSTACK;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGBUS, &sa, std::ptr::null_mut());
    }
}

extern "C" fn on_sigbus(_sig: libc::c_int, info: *mut libc::siginfo_t, _ctx: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo for SA_SIGINFO handlers.
    let addr = unsafe { (*info).si_addr() } as usize;
    for s in &WATCHED {
        let start = s.start.load(Ordering::Acquire);
        let len = s.len.load(Ordering::Acquire);
        if start != 0 && start != usize::MAX && addr >= start && addr - start < len {
            let msg = s.msg.load(Ordering::Acquire);
            let n = s.msg_len.load(Ordering::Acquire);
            // SAFETY: async-signal-safe calls on a leaked, immutable buffer.
            unsafe {
                libc::write(2, msg as *const libc::c_void, n);
                libc::_exit(TRUNCATED_EXIT);
            }
        }
    }
    // not one of our maps: the default action (returning re-runs the access, which faults
    // again and ends the process as SIGBUS would have)
    // SAFETY: resetting a signal disposition is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGBUS, libc::SIG_DFL);
    }
}
