//! What the process asks of the operating system: peak resident memory, free disk space,
//! whether a GPU device exists, and the interrupt flag set by Ctrl-C.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

pub(crate) static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Leaf chunks after which a build requests an interrupt; `u64::MAX`: never.
static INTERRUPT_AFTER_CHUNKS: AtomicU64 = AtomicU64::new(u64::MAX);

/// For tests of resuming (`--debug-interrupt-after-chunks`): every build of this process
/// requests an interrupt once `n` leaf chunks are in a stage's log (`None`: never).
#[doc(hidden)]
pub fn interrupt_after_chunks(n: Option<u64>) {
    INTERRUPT_AFTER_CHUNKS.store(n.unwrap_or(u64::MAX), Ordering::SeqCst);
}

/// The chunk count set by [`interrupt_after_chunks`], if one is.
pub(crate) fn interrupt_after() -> Option<u64> {
    Some(INTERRUPT_AFTER_CHUNKS.load(Ordering::SeqCst)).filter(|&n| n != u64::MAX)
}

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

/// Whether a hardware GPU may be present, decided from device nodes without loading a graphics
/// driver. On Linux every GPU driver a Vulkan or GL driver can use exposes one: the kernel's
/// DRM drivers `/dev/dri/renderD*` (Mesa's drivers open it), NVIDIA's driver `/dev/nvidia*`,
/// WSL2 `/dev/dxg`; with none of them every adapter found would be a CPU emulation (lavapipe)
/// or nothing, so `--backend auto` need not load the Vulkan loader and driver (about 50 MiB
/// of resident LLVM for lavapipe) to learn it. True elsewhere, and when `WGPU_BACKEND`,
/// `VK_ICD_FILENAMES` or `VK_DRIVER_FILES` choose a driver (then the adapter is probed).
pub(crate) fn may_have_gpu() -> bool {
    if !cfg!(target_os = "linux")
        || ["WGPU_BACKEND", "VK_ICD_FILENAMES", "VK_DRIVER_FILES"]
            .iter()
            .any(|v| std::env::var_os(v).is_some())
    {
        return true;
    }
    gpu_device_node(Path::new("/dev")).is_some()
}

/// The first GPU device node under `dev` (a `/dev`): `dri/renderD*`, `nvidia*`, `dxg`.
fn gpu_device_node(dev: &Path) -> Option<std::path::PathBuf> {
    let named = |dir: &Path, f: &dyn Fn(&str) -> bool| {
        std::fs::read_dir(dir)
            .ok()?
            .flatten()
            .map(|e| e.path())
            .find(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(f))
    };
    named(&dev.join("dri"), &|n| n.starts_with("renderD"))
        .or_else(|| named(dev, &|n| n.starts_with("nvidia") || n == "dxg"))
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

    /// Device nodes in a made-up `/dev`: only a render node, an NVIDIA node or WSL's dxg
    /// count (a DRM card node without a render node, as on a display-only controller, does not).
    #[test]
    fn gpu_device_nodes_are_found() {
        let dev = tempfile::tempdir().unwrap();
        let d = dev.path();
        assert_eq!(gpu_device_node(d), None);
        std::fs::create_dir(d.join("dri")).unwrap();
        std::fs::write(d.join("dri/card0"), "").unwrap();
        std::fs::write(d.join("null"), "").unwrap();
        assert_eq!(gpu_device_node(d), None);
        std::fs::write(d.join("dri/renderD128"), "").unwrap();
        assert_eq!(gpu_device_node(d), Some(d.join("dri/renderD128")));
        for node in ["nvidia0", "dxg"] {
            let other = tempfile::tempdir().unwrap();
            std::fs::write(other.path().join(node), "").unwrap();
            assert_eq!(gpu_device_node(other.path()), Some(other.path().join(node)));
        }
    }
}
