//! What the process asks of the operating system: peak resident memory, free disk space, and
//! the interrupt flag set by Ctrl-C.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

pub(crate) static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Asks a running build to stop at the next safe point (between batches); its work folder is
/// kept so the same command resumes it.
pub fn request_interrupt() {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// True once [`request_interrupt`] was called.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Peak resident set size of this process so far, in bytes: `VmHWM` of `/proc/self/status`,
/// the high-water mark of this program's own address space. `getrusage`'s `ru_maxrss` is
/// only the fallback: Linux carries the launching process's peak into it across `fork` and
/// `exec` (a build started from a 1.5 GB Python process reported 1.5 GB).
pub fn peak_rss() -> u64 {
    if let Some(b) = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| vm_hwm(&s))
    {
        return b;
    }
    peak_rss_getrusage()
}

/// The `VmHWM:` line of a `/proc/<pid>/status` text, in bytes.
fn vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let mut t = line["VmHWM:".len()..].split_whitespace();
    let n: u64 = t.next()?.parse().ok()?;
    match t.next() {
        Some("kB") => Some(n * 1024),
        _ => None,
    }
}

fn peak_rss_getrusage() -> u64 {
    // SAFETY: getrusage only writes the struct we pass.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) } != 0 {
        return 0;
    }
    // Linux reports kilobytes.
    ru.ru_maxrss.max(0) as u64 * 1024
}

/// Free bytes for an unprivileged user on the file system holding `dir`, if known.
pub fn free_disk(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: statvfs only writes the struct we pass; `c` is a valid C string.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return None;
    }
    Some(st.f_bavail as u64 * st.f_frsize as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vm_hwm_is_parsed() {
        let s = "Name:\tvoxlod\nVmPeak:\t  10 kB\nVmHWM:\t    2048 kB\nVmRSS:\t 1 kB\n";
        assert_eq!(vm_hwm(s), Some(2048 * 1024));
        assert_eq!(vm_hwm("VmRSS: 1 kB"), None);
        // this process has touched memory, and its peak is at least what it holds now
        let v = vec![1u8; 32 << 20];
        assert!(peak_rss() >= 32 << 20, "{}", peak_rss());
        drop(v);
    }
}
