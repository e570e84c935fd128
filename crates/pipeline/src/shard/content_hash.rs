//! The input's content checksum for sharded builds: XXH3-64 (seed 0, the default secret; Yann
//! Collet's xxHash, the value `xxhsum -H3` prints) of every byte of the file, read in order.
//!
//! `plan` takes it during its pass over the input and stores it in the plan; each shard takes
//! it again during its one pass and refuses an input whose bytes changed, even when size,
//! modification time and the first and last MiB are the same (docs/FORMAT.md 15.1). It runs
//! on a thread of its own beside the pass: reading is sequential and XXH3 runs at several
//! GB/s, so it costs a few percent of a pass that decodes and bins every triangle.

use std::io::Read;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use xxhash_rust::xxh3::Xxh3Default;

use super::plan_file::{hex64, ShardScope};
use crate::context::BuildContext;
use crate::error::StageError;

/// Bytes read per step (one buffer, reused).
const BLOCK: usize = 4 << 20;

/// XXH3-64 of the file at `path`, or `None` if `stop` was set before the end (checked between
/// blocks of 4 MiB).
pub(crate) fn xxh3_of_file(path: &Path, stop: &AtomicBool) -> Result<Option<u64>, StageError> {
    let mut f = voxlod_io::open_regular(path).map_err(|e| match e {
        voxlod_io::BoundError::Io(e) => StageError::io("opening", path)(e),
        e => StageError::io("opening", path)(std::io::Error::other(e.to_string())),
    })?;
    let mut h = Xxh3Default::new();
    let mut buf = vec![0u8; BLOCK];
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let n = match f.read(&mut buf) {
            Ok(0) => return Ok(Some(h.digest())),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(StageError::io("reading", path)(e)),
        };
        h.update(&buf[..n]);
    }
}

/// XXH3-64 of each segment of the file at `path` that `ends` cut from its start (segment `i`
/// is `[ends[i-1], ends[i])`, the first from byte 0; `ends` increasing), read in order in one
/// pass; `None` if `stop` was set before the end. A file shorter than the last end is an error.
pub(crate) fn xxh3_of_segments(
    path: &Path,
    ends: &[u64],
    stop: &AtomicBool,
) -> Result<Option<Vec<u64>>, StageError> {
    let mut f = voxlod_io::open_regular(path).map_err(|e| match e {
        voxlod_io::BoundError::Io(e) => StageError::io("opening", path)(e),
        e => StageError::io("opening", path)(std::io::Error::other(e.to_string())),
    })?;
    let mut out = Vec::with_capacity(ends.len());
    let mut h = Xxh3Default::new();
    let mut buf = vec![0u8; BLOCK];
    let mut at = 0u64;
    for &end in ends {
        while at < end {
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            let want = (end - at).min(BLOCK as u64) as usize;
            let n = match f.read(&mut buf[..want]) {
                Ok(0) => {
                    return Err(StageError::io("reading", path)(std::io::Error::new(
                        std::io::ErrorKind::UnexpectedEof,
                        format!("the file ends at byte {at}, before {end} (it changed while read)"),
                    )))
                }
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(StageError::io("reading", path)(e)),
            };
            h.update(&buf[..n]);
            at += n as u64;
        }
        out.push(h.digest());
        h.reset();
    }
    Ok(Some(out))
}

/// Runs `pass` while [`xxh3_of_file`] of `path` runs on a thread of its own; returns both
/// results. The checksum runs to the end of the file even if the pass fails (the caller
/// explains a failed pass by a changed input, if it changed), unless `interrupt` is set
/// (Ctrl-C), which stops it (`None`).
pub(crate) fn beside<R>(
    path: &Path,
    interrupt: &AtomicBool,
    pass: impl FnOnce() -> R,
) -> (R, Result<Option<u64>, StageError>) {
    std::thread::scope(|s| {
        let hash = s.spawn(|| xxh3_of_file(path, interrupt));
        let r = pass();
        let h = hash.join().unwrap_or_else(|p| std::panic::resume_unwind(p));
        (r, h)
    })
}

/// A sharded build's pass over its input, checked: runs `pass` beside the checksum of the
/// input and refuses an input whose checksum is not the plan's, whether or not the pass
/// succeeded (a changed input may well have failed it, and the change is the reason to give);
/// otherwise the pass's result.
pub(crate) fn checked<R>(
    ctx: &BuildContext,
    scope: &ShardScope,
    pass: impl FnOnce() -> Result<R, StageError>,
) -> Result<R, StageError> {
    // a plan with parts has no checksum: its shards read the map outputs, not the input
    let Some(planned) = scope.content_xxh3.clone() else {
        return pass();
    };
    let (r, hash) = beside(ctx.input, ctx.interrupt, pass);
    match hash? {
        Some(h) if hex64(h) != planned => Err(StageError::ContentChanged {
            path: ctx.input.to_path_buf(),
            plan: scope.plan_path.clone(),
            now: hex64(h),
            planned,
        }),
        Some(_) => r,
        // Ctrl-C stopped the checksum: the pass has stopped too, or its result is not checked
        None => r.and(Err(StageError::Interrupted {
            work: ctx.work.path().to_path_buf(),
        })),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streamed checksum over 4 MiB blocks equals the one-shot XXH3 of the whole bytes
    /// (another code path of the crate) and, for the empty file, the published XXH3-64 of no
    /// input; a set stop flag gives `None`.
    #[test]
    fn file_checksum_matches_one_shot_xxh3() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f");
        let go = AtomicBool::new(false);
        std::fs::write(&p, b"").unwrap();
        assert_eq!(xxh3_of_file(&p, &go).unwrap(), Some(0x2D06_8005_38D3_94C2));
        let bytes: Vec<u8> = (0..BLOCK * 2 + 12345)
            .map(|i| (i * 31 % 251) as u8)
            .collect();
        std::fs::write(&p, &bytes).unwrap();
        let want = xxhash_rust::xxh3::xxh3_64(&bytes);
        assert_eq!(xxh3_of_file(&p, &go).unwrap(), Some(want));
        assert_eq!(hex64(want).len(), 16);
        assert_eq!(xxh3_of_file(&p, &AtomicBool::new(true)).unwrap(), None);
        let (r, h) = beside(&p, &go, || 7);
        assert_eq!((r, h.unwrap()), (7, Some(want)));
        // segments: each the one-shot XXH3 of its bytes, block borders anywhere
        let ends = [0, 5, BLOCK as u64 + 3, BLOCK as u64 + 3, bytes.len() as u64];
        let got = xxh3_of_segments(&p, &ends, &go).unwrap().unwrap();
        let mut from = 0;
        for (e, g) in ends.iter().zip(&got) {
            let e = *e as usize;
            assert_eq!(*g, xxhash_rust::xxh3::xxh3_64(&bytes[from..e]), "up to {e}");
            from = e;
        }
        assert!(xxh3_of_segments(&p, &[bytes.len() as u64 + 1], &go).is_err());
    }
}
