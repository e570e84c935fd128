//! A file replaced whole or not at all: write a temporary file beside the target, fsync it,
//! rename it over the target, fsync the folder so the rename itself survives a crash.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary name a file is staged under before it is renamed to `path`: `path` with
/// `.tmp` appended to its file name (`out.voxlod` → `out.voxlod.tmp`), in the same folder so
/// the rename is atomic.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    path.with_file_name(name)
}

/// Makes a rename or a new file in `dir` durable (fsync of the folder). Errors are ignored:
/// some file systems refuse to fsync a folder, and the data itself was synced before.
pub fn sync_dir(dir: &Path) {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// Writes `bytes` to `path` atomically: [`temp_path`], fsync, rename over `path`, fsync of
/// the folder. On an error the temporary file is removed and `path` is as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_via(&temp_path(path), path, bytes)
}

/// [`write_atomic`] staged under the temporary name `tmp` (in `path`'s folder), for a caller
/// whose temporary name must differ from [`temp_path`]'s, e.g. one per process when several
/// processes may write the same file at once.
pub fn write_atomic_via(tmp: &Path, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let r = (|| {
        let mut f = File::create(tmp)?;
        f.write_all(bytes)?;
        commit(f, tmp, path)
    })();
    if r.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    r
}

/// The end of a file streamed to `tmp` (in `path`'s folder): fsync `file`, rename `tmp` over
/// `path`, fsync the folder. The caller removes `tmp` on an error (it still holds what was
/// written).
pub fn commit(file: File, tmp: &Path, path: &Path) -> std::io::Result<()> {
    file.sync_all()?;
    drop(file);
    std::fs::rename(tmp, path)?;
    sync_dir(path.parent().unwrap_or(Path::new(".")));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_old_file_and_leaves_no_temporary() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x.json");
        std::fs::write(&p, b"old").unwrap();
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        assert!(!temp_path(&p).exists());
    }

    #[test]
    fn a_streamed_file_is_committed_under_its_name() {
        let d = tempfile::tempdir().unwrap();
        let (p, tmp) = (d.path().join("out.ply"), d.path().join("out.ply.7.tmp"));
        let mut f = File::create(&tmp).unwrap();
        f.write_all(b"streamed").unwrap();
        commit(f, &tmp, &p).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"streamed");
        assert!(!tmp.exists());
        write_atomic_via(&tmp, &p, b"again").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"again");
        assert!(!tmp.exists());
    }

    #[test]
    fn a_failed_write_leaves_the_target_as_it_was() {
        let d = tempfile::tempdir().unwrap();
        // the target is a folder: the rename fails, the temporary file is removed
        let p = d.path().join("sub");
        std::fs::create_dir(&p).unwrap();
        std::fs::write(p.join("keep"), b"k").unwrap();
        assert!(write_atomic(&p, b"new").is_err());
        assert!(p.join("keep").exists());
        assert!(!temp_path(&p).exists());
    }
}
