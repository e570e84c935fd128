//! Regular files only, read with a bound. A path that names a FIFO would block a reader
//! forever, `/dev/zero` would fill memory, a folder gives an OS error that names nothing:
//! each is refused before a byte is read, with an error that says what the path is instead.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Why [`read_bounded`] or [`open_regular`] refused a path.
#[derive(Debug)]
pub enum BoundError {
    /// The path could not be opened or read.
    Io(std::io::Error),
    /// The path is not a regular file; the text says what it is ("a FIFO", "a folder", ...).
    NotRegular(&'static str),
    /// The file is larger than the caller allows.
    TooLarge {
        /// Its size in bytes.
        size: u64,
        /// The bound.
        limit: u64,
    },
}

impl std::fmt::Display for BoundError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BoundError::Io(e) => write!(f, "{e}"),
            BoundError::NotRegular(what) => write!(f, "not a regular file but {what}"),
            BoundError::TooLarge { size, limit } => {
                write!(f, "{size} bytes, more than the {limit} allowed")
            }
        }
    }
}

impl std::error::Error for BoundError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            BoundError::Io(e) => Some(e),
            _ => None,
        }
    }
}

impl From<std::io::Error> for BoundError {
    fn from(e: std::io::Error) -> Self {
        BoundError::Io(e)
    }
}

fn kind_of(ft: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_dir() {
        "a folder"
    } else if ft.is_fifo() {
        "a FIFO"
    } else if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_socket() {
        "a socket"
    } else {
        "not a file"
    }
}

/// Opens `path` for reading if it is a regular file (symlinks followed). Opened without
/// blocking, so a FIFO with no writer is refused instead of waiting forever; the type is
/// checked on the open descriptor, so a path swapped after a check cannot slip through.
pub fn open_regular(path: &Path) -> Result<File, BoundError> {
    use std::os::unix::fs::OpenOptionsExt;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc_o_nonblock())
        .open(path)?;
    let ft = f.metadata()?.file_type();
    if !ft.is_file() {
        return Err(BoundError::NotRegular(kind_of(ft)));
    }
    Ok(f)
}

/// `O_NONBLOCK` on Linux (every architecture Rust supports there uses 0o4000 except alpha,
/// mips, parisc and sparc, which voxlod does not target). On a regular file it changes nothing.
const fn libc_o_nonblock() -> i32 {
    if cfg!(any(
        target_arch = "mips",
        target_arch = "mips64",
        target_arch = "sparc64"
    )) {
        0x80
    } else {
        0o4000
    }
}

/// Reads the whole of the regular file `path`, refusing one larger than `limit` bytes
/// (checked from its size first, and again while reading, in case it grows).
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>, BoundError> {
    let f = open_regular(path)?;
    let size = f.metadata()?.len();
    if size > limit {
        return Err(BoundError::TooLarge { size, limit });
    }
    let mut out = Vec::with_capacity(size as usize);
    f.take(limit.saturating_add(1)).read_to_end(&mut out)?;
    if out.len() as u64 > limit {
        return Err(BoundError::TooLarge {
            size: out.len() as u64,
            limit,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_what_is_not_a_regular_file() {
        let d = tempfile::tempdir().unwrap();
        assert!(matches!(
            read_bounded(d.path(), 10),
            Err(BoundError::NotRegular("a folder"))
        ));
        assert!(matches!(
            read_bounded(Path::new("/dev/zero"), 10),
            Err(BoundError::NotRegular("a character device"))
        ));
        // a FIFO with no writer: refused at once, not waited on
        let fifo = d.path().join("f");
        let st = std::process::Command::new("mkfifo").arg(&fifo).status();
        if st.map_or(false, |s| s.success()) {
            assert!(matches!(
                read_bounded(&fifo, 10),
                Err(BoundError::NotRegular("a FIFO"))
            ));
        }
    }

    #[test]
    fn reads_up_to_the_bound_and_refuses_past_it() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_bounded(&p, 10).unwrap(), b"0123456789");
        assert!(matches!(
            read_bounded(&p, 9),
            Err(BoundError::TooLarge { size: 10, limit: 9 })
        ));
        // a symlink to a regular file is followed
        let l = d.path().join("l");
        std::os::unix::fs::symlink(&p, &l).unwrap();
        assert_eq!(read_bounded(&l, 10).unwrap().len(), 10);
    }
}
