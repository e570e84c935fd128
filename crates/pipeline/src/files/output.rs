//! Output safety for every command that writes a file (`build`, `render`, `export`, `gen`):
//! checks made before any work starts, an advisory lock per output, a unique temporary name
//! beside the output, and the final rename.
//!
//! Checked up front ([`OutputGuard::acquire`]): the output is not a directory and its folder
//! exists; it is not one of the command's inputs (same device and inode, so links and other
//! spellings of a path are caught); an existing file there is of the kind the command writes
//! (or empty) unless `force`; the folder is writable and not full (the lock file below is
//! created and written there); no other voxlod process holds the output's lock.
//!
//! The lock is `flock(LOCK_EX | LOCK_NB)` on `.voxlod-lock-<name>` beside the output, holding the
//! pid of its owner so that a second process can name it. The file is removed when the guard
//! is dropped, while still locked; a process that locked a file that was removed meanwhile
//! sees another inode at the path and tries again, so two processes never both hold it.
//! The kernel releases the lock when its process dies (`kill -9` included).

use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::unix::fs::MetadataExt;
use std::os::unix::io::AsRawFd;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::size::format_size;

/// Below this much free space in the output's folder a command is refused at once: even the
/// smallest octree (header, one node, index, manifest) or picture would not fit.
pub const MIN_OUTPUT_FREE: u64 = 64 << 10;

/// What a command writes; an existing file of another kind is not replaced without `force`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// A voxlod octree (`build`).
    Octree,
    /// A PNG picture (`render`).
    Png,
    /// A JPEG picture (`render -o x.jpg`).
    Jpeg,
    /// A PLY mesh (`export`, `gen`).
    Ply,
    /// A glTF 2.0 binary (`export -o x.glb`).
    Glb,
    /// A sharded build's plan (`plan`, JSON).
    Plan,
    /// A shard of a sharded build (`build --plan --shard`).
    Shard,
    /// A map task's output (`map --part I`: `part-IIII.bins`, `part-IIII.json`), whose name the
    /// tool chooses beside the plan: replaced whatever is there (it has no magic of its own).
    MapOutput,
}

impl OutputKind {
    fn name(self) -> &'static str {
        match self {
            OutputKind::Octree => "a voxlod octree",
            OutputKind::Png => "a PNG image",
            OutputKind::Jpeg => "a JPEG image",
            OutputKind::Ply => "a PLY mesh",
            OutputKind::Glb => "a glTF binary",
            OutputKind::Plan => "a voxlod plan",
            OutputKind::Shard => "a voxlod shard",
            OutputKind::MapOutput => "a voxlod map output",
        }
    }

    fn of(head: &[u8]) -> Option<OutputKind> {
        if head.starts_with(&voxlod_format::MAGIC) {
            Some(OutputKind::Octree)
        } else if head.starts_with(b"\x89PNG\r\n\x1a\n") {
            Some(OutputKind::Png)
        } else if head.starts_with(b"\xff\xd8\xff") {
            Some(OutputKind::Jpeg)
        } else if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
            Some(OutputKind::Ply)
        } else if head.starts_with(b"glTF") {
            Some(OutputKind::Glb)
        } else if head.starts_with(crate::shard::shard_file::MAGIC) {
            Some(OutputKind::Shard)
        } else if head.starts_with(b"{\n  \"format\": \"v") {
            // the first 16 bytes of a plan as `plan` writes it (`"format": "voxlod-plan"`)
            Some(OutputKind::Plan)
        } else {
            None
        }
    }
}

/// What a file's first bytes say it is, for messages.
fn describe(head: &[u8]) -> &'static str {
    if let Some(k) = OutputKind::of(head) {
        return k.name();
    }
    if head.starts_with(&[0x1f, 0x8b]) {
        "gzip-compressed data"
    } else if head.starts_with(b"solid") {
        "an ASCII STL mesh"
    } else if head.iter().all(|b| b.is_ascii()) {
        "a text file"
    } else {
        "a file of unknown kind"
    }
}

/// The checks, lock and temporary name of one command's output; see the module docs.
#[derive(Debug)]
pub struct OutputGuard {
    output: PathBuf,
    staged: PathBuf,
    lock_path: PathBuf,
    lock: File,
}

/// The unique staged name of output `name` in `dir`: `.voxlod-part-NAME-PID-TIME` (TIME in
/// hexadecimal nanoseconds), what [`find_output_leftovers`] recognises.
fn staged_name(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!(
        ".voxlod-part-{name}-{}-{:x}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64)
    ))
}

/// The output's folder (`.` for a bare file name).
pub fn output_dir(output: &Path) -> &Path {
    output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

fn file_name(output: &Path) -> String {
    output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into())
}

/// An OS error's text without its "(os error N)" suffix, e.g. "Is a directory".
pub(crate) fn os_text(e: &std::io::Error) -> String {
    let s = e.to_string();
    match s.find(" (os error") {
        Some(i) => s[..i].to_string(),
        None => s,
    }
}

impl OutputGuard {
    /// Runs the up-front checks for writing `output` from `inputs` and takes the output's lock.
    /// Errors name the output (or its folder) once and say what to do.
    pub fn acquire(
        output: &Path,
        inputs: &[&Path],
        kind: OutputKind,
        force: bool,
    ) -> Result<OutputGuard> {
        let dir = check_path(output, kind)?;
        check_existing(output, inputs, kind, force)?;
        let name = file_name(output);
        let lock_path = dir.join(format!(".voxlod-lock-{name}"));
        let lock = lock_file(&lock_path, output, dir)?;
        // from here on the guard owns the lock: an error below drops it, removing the lock file
        let guard = OutputGuard {
            output: output.to_path_buf(),
            staged: staged_name(dir, &name),
            lock_path,
            lock,
        };
        check_free_space(output, dir)?;
        remove_leftovers(dir, &name);
        Ok(guard)
    }

    /// The lock and staged name for an output that is a **folder** (`export --3d-tiles DIR`):
    /// `folder`'s parent must exist (the caller checks what may be replaced); the staged name
    /// `.voxlod-part-NAME-PID-TIME` is then a folder the caller creates and fills, renamed into
    /// place by [`commit_folder`](Self::commit_folder) and removed with everything in it if
    /// the guard is dropped first. A killed export leaves it (and the lock file) for
    /// `voxlod clean`, like a killed build's staged file.
    pub fn acquire_folder(folder: &Path) -> Result<OutputGuard> {
        if folder.as_os_str().is_empty() {
            bail!("the output folder path is empty");
        }
        let dir = output_dir(folder);
        if !dir.is_dir() {
            bail!(
                "{}: the folder {} does not exist",
                folder.display(),
                dir.display()
            );
        }
        let name = file_name(folder);
        let lock_path = dir.join(format!(".voxlod-lock-{name}"));
        let lock = lock_file(&lock_path, folder, dir)?;
        let guard = OutputGuard {
            output: folder.to_path_buf(),
            staged: staged_name(dir, &name),
            lock_path,
            lock,
        };
        check_free_space(folder, dir)?;
        remove_leftovers(dir, &name);
        Ok(guard)
    }

    /// Puts the staged folder in place of the output folder: created there if absent, else
    /// exchanged with the old one in one atomic `renameat2(RENAME_EXCHANGE)` (no moment without a
    /// tileset; on a file system without it, the old folder is moved aside first) and the old
    /// one, now under the staged name, removed. The folder's parent is synced.
    pub fn commit_folder(&self) -> Result<()> {
        let shown = self.output.display();
        let exists = std::fs::symlink_metadata(&self.output).is_ok();
        if !exists {
            std::fs::rename(&self.staged, &self.output).map_err(|e| {
                anyhow::anyhow!("{shown}: cannot rename into place: {}", os_text(&e))
            })?;
        } else if let Err(e) = exchange(&self.staged, &self.output) {
            // no RENAME_EXCHANGE here: aside, in, then the old one removed
            let aside = PathBuf::from(format!("{}-old", self.staged.display()));
            std::fs::rename(&self.output, &aside).map_err(|e2| {
                anyhow::anyhow!(
                    "{shown}: cannot exchange ({}) nor move aside: {}",
                    os_text(&e),
                    os_text(&e2)
                )
            })?;
            if let Err(e) = std::fs::rename(&self.staged, &self.output) {
                let _ = std::fs::rename(&aside, &self.output);
                bail!("{shown}: cannot rename into place: {}", os_text(&e));
            }
            let _ = std::fs::rename(&aside, &self.staged);
        }
        // the old folder (now at the staged name) goes with everything in it
        if exists {
            std::fs::remove_dir_all(&self.staged).map_err(|e| {
                anyhow::anyhow!(
                    "{}: cannot remove the replaced folder: {}",
                    self.staged.display(),
                    os_text(&e)
                )
            })?;
        }
        voxlod_io::sync_dir(output_dir(&self.output));
        Ok(())
    }

    /// The unique temporary name to write the output under (beside it, so that
    /// [`commit`](Self::commit) is an atomic rename).
    pub fn staged(&self) -> &Path {
        &self.staged
    }

    /// The output path.
    pub fn output(&self) -> &Path {
        &self.output
    }

    /// Renames the staged file to the output (replacing an old one) and makes the rename
    /// durable (fsync of the folder).
    pub fn commit(&self) -> Result<()> {
        if let Err(e) = std::fs::rename(&self.staged, &self.output) {
            bail!(
                "{}: cannot move the finished file into place: {}",
                self.output.display(),
                os_text(&e)
            );
        }
        voxlod_io::sync_dir(output_dir(&self.output));
        Ok(())
    }

    /// Writes `bytes` as the whole output: the staged file, fsynced, then [`commit`]ted.
    ///
    /// [`commit`]: Self::commit
    pub fn write_whole(&self, bytes: &[u8]) -> Result<()> {
        let staged = self.staged();
        let mut f =
            File::create(staged).with_context(|| format!("{}: cannot create", staged.display()))?;
        f.write_all(bytes)
            .and_then(|()| f.sync_all())
            .with_context(|| format!("{}: cannot write", staged.display()))?;
        self.commit()
    }
}

impl Drop for OutputGuard {
    fn drop(&mut self) {
        remove_entry(&self.staged);
        // removed while still locked (the lock goes with the descriptor, closed after this)
        if same_inode(&self.lock, &self.lock_path) {
            let _ = std::fs::remove_file(&self.lock_path);
        }
    }
}

/// The output path names a file (not a directory) in an existing folder; returns the folder.
fn check_path(output: &Path, kind: OutputKind) -> Result<&Path> {
    let shown = output.display();
    if output.as_os_str().is_empty() {
        bail!("the output path is empty");
    }
    if output.is_dir() || output.as_os_str().to_string_lossy().ends_with('/') {
        let folder = output.to_string_lossy();
        let folder = folder.trim_end_matches('/');
        bail!(
            "{shown} is a directory: name the output file, e.g. {folder}/out.{}",
            ext(kind)
        );
    }
    let dir = output_dir(output);
    if !dir.is_dir() {
        bail!(
            "{shown}: the output's folder {} does not exist",
            dir.display()
        );
    }
    Ok(dir)
}

/// An existing file at `output` is none of the `inputs` (same device and inode), is a regular
/// file, and is empty or of `kind` unless `force`.
fn check_existing(output: &Path, inputs: &[&Path], kind: OutputKind, force: bool) -> Result<()> {
    let shown = output.display();
    let Ok(om) = std::fs::metadata(output) else {
        return Ok(());
    };
    for input in inputs {
        if let Ok(im) = std::fs::metadata(input) {
            if im.dev() == om.dev() && im.ino() == om.ino() {
                bail!(
                    "{shown} is the input {}: choose another output file",
                    input.display()
                );
            }
        }
    }
    if !om.is_file() {
        bail!("{shown} exists and is not a regular file: choose another output file");
    }
    if om.len() > 0 {
        let mut head = [0u8; 16];
        let n = File::open(output)
            .and_then(|mut f| read_head(&mut f, &mut head))
            .unwrap_or(0);
        let head = &head[..n];
        if OutputKind::of(head) != Some(kind) && !force {
            bail!(
                "{shown} exists and is {}, not {}: refusing to replace it (use --force to overwrite it)",
                describe(head),
                kind.name()
            );
        }
    }
    Ok(())
}

/// The output's folder has at least [`MIN_OUTPUT_FREE`] free (when the system tells).
fn check_free_space(output: &Path, dir: &Path) -> Result<()> {
    if let Some(free) = crate::system::free_disk(dir) {
        if free < MIN_OUTPUT_FREE {
            bail!(
                "{}: the output's folder {} has only {} free (full disk?)",
                output.display(),
                dir.display(),
                format_size(free)
            );
        }
    }
    Ok(())
}

/// Removes the leftovers of killed runs (their unique temporary names `.voxlod-part-NAME-…`):
/// nobody else writes them while we hold the output's lock.
fn remove_leftovers(dir: &Path, name: &str) {
    let prefix = format!(".voxlod-part-{name}-");
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().starts_with(&prefix) {
                remove_entry(&e.path());
            }
        }
    }
}

/// Removes a file, or a folder with everything in it (a staged tileset); errors ignored.
fn remove_entry(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            let _ = std::fs::remove_dir_all(path);
        }
        Ok(_) => {
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
}

/// The bytes of a file, or of every file under a folder (symlinks not followed).
fn entry_bytes(path: &Path) -> u64 {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => std::fs::read_dir(path).map_or(0, |rd| {
            rd.flatten().map(|e| entry_bytes(&e.path())).sum::<u64>()
        }),
        Ok(m) => m.len(),
        Err(_) => 0,
    }
}

/// Exchanges the two paths atomically (`renameat2` with `RENAME_EXCHANGE`, Linux ≥ 3.15 on
/// most local file systems).
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let ca = CString::new(a.as_os_str().as_bytes())?;
    let cb = CString::new(b.as_os_str().as_bytes())?;
    // SAFETY: two NUL-terminated paths relative to the working directory.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// What a run killed while writing an output left beside it (`voxlod clean` lists and removes
/// it): the output's lock file `.voxlod-lock-NAME` and staged parts `.voxlod-part-NAME-PID-TIME`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutputLeftovers {
    /// The output's file name (`NAME`).
    pub name: String,
    /// The files, sorted: the lock file (when there is one) and the staged parts.
    pub files: Vec<PathBuf>,
    /// Bytes of the files.
    pub bytes: u64,
    /// The pid of the running process that holds the output's lock, if one does (then nothing
    /// is removed); `None` when nobody holds it.
    pub in_use_by: Option<Option<u32>>,
}

/// The output name a leftover file of `dir` belongs to, if it is one.
fn leftover_name(file: &str) -> Option<String> {
    if let Some(name) = file.strip_prefix(".voxlod-lock-") {
        return (!name.is_empty()).then(|| name.to_string());
    }
    if let Some(name) = legacy_map_leftover(file) {
        return Some(name);
    }
    // .voxlod-part-NAME-PID-HEXTIME (NAME may itself contain '-')
    let rest = file.strip_prefix(".voxlod-part-")?;
    let mut it = rest.rsplitn(3, '-');
    let (time, pid, name) = (it.next()?, it.next()?, it.next()?);
    let ok = !name.is_empty()
        && !pid.is_empty()
        && pid.bytes().all(|b| b.is_ascii_digit())
        && !time.is_empty()
        && time.bytes().all(|b| b.is_ascii_hexdigit());
    ok.then(|| name.to_string())
}

/// The map output a file left by a map task of an earlier voxlod belongs to, if it is one:
/// `part-IIII.bins.PID.partial` (its bins being written) or `part-IIII.json.tmp` (its marker
/// being written), which a killed task of those versions left beside the plan.
pub(crate) fn legacy_map_leftover(file: &str) -> Option<String> {
    let part = |name: &str, ext: &str| {
        name.strip_prefix("part-")
            .and_then(|r| r.strip_suffix(ext))
            .is_some_and(|d| d.len() >= 4 && d.bytes().all(|b| b.is_ascii_digit()))
    };
    if let Some(name) = file.strip_suffix(".tmp") {
        return part(name, ".json").then(|| name.to_string());
    }
    let rest = file.strip_suffix(".partial")?;
    let (name, pid) = rest.rsplit_once('.')?;
    (part(name, ".bins") && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
        .then(|| name.to_string())
}

/// The leftovers of outputs in `dir` (see [`OutputLeftovers`]), grouped by output name, each
/// probed for a holder without creating anything: a lock file is opened, never created.
pub fn find_output_leftovers(dir: &Path) -> Result<Vec<OutputLeftovers>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot list it: {}", dir.display(), os_text(&e)))?;
    let mut by_name = std::collections::BTreeMap::<String, OutputLeftovers>::new();
    for e in entries.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        let Some(name) = leftover_name(&file) else {
            continue;
        };
        // files, and the staged folders of tileset exports
        if !e.file_type().is_ok_and(|t| t.is_file() || t.is_dir()) {
            continue;
        }
        let l = by_name.entry(name.clone()).or_insert(OutputLeftovers {
            name,
            files: Vec::new(),
            bytes: 0,
            in_use_by: None,
        });
        l.bytes += entry_bytes(&e.path());
        l.files.push(e.path());
    }
    let mut found: Vec<OutputLeftovers> = by_name.into_values().collect();
    for l in &mut found {
        l.files.sort();
        l.in_use_by = lock_holder(&dir.join(format!(".voxlod-lock-{}", l.name)));
    }
    Ok(found)
}

/// Whether a live process holds the lock file at `path` (opened without creating it): `None`
/// when it is missing or nobody holds it, else `Some` of the holder's pid when written.
fn lock_holder(path: &Path) -> Option<Option<u32>> {
    let f = File::open(path).ok()?;
    // SAFETY: flock on a descriptor we own; released when `f` is dropped.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return None;
    }
    Some(
        std::fs::read_to_string(path)
            .ok()
            .and_then(|s| s.trim().parse::<u32>().ok()),
    )
}

/// Removes the leftovers of the output `name` in `dir` while holding that output's lock (so a
/// run starting to write it meanwhile is refused rather than losing its file); refused when a
/// running process holds the lock. Returns the bytes removed.
pub fn remove_output_leftovers(dir: &Path, name: &str) -> Result<u64> {
    let lock_path = dir.join(format!(".voxlod-lock-{name}"));
    let lock = match lock_or_name_holder(&lock_path) {
        Ok(f) => f,
        Err(LockError::Held(pid)) => bail!(
            "{} is being written by a running voxlod process ({}): its files are kept",
            dir.join(name).display(),
            pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"))
        ),
        Err(LockError::Io(e)) => bail!("locking {}: {}", lock_path.display(), os_text(&e)),
    };
    let mut bytes = 0;
    let entries = std::fs::read_dir(dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot list it: {}", dir.display(), os_text(&e)))?;
    for e in entries.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        // the staged parts (and an earlier map task's files), not the lock: that goes last
        if !file.starts_with(".voxlod-lock-") && leftover_name(&file).as_deref() == Some(name) {
            let len = entry_bytes(&e.path());
            let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
            let removed = if is_dir {
                std::fs::remove_dir_all(e.path())
            } else {
                std::fs::remove_file(e.path())
            };
            removed.map_err(|err| {
                anyhow::anyhow!("removing {}: {}", e.path().display(), os_text(&err))
            })?;
            bytes += len;
        }
    }
    // the lock file last, while still locked (the protocol of the module docs)
    if same_inode(&lock, &lock_path) {
        bytes += lock.metadata().map_or(0, |m| m.len());
        let _ = std::fs::remove_file(&lock_path);
    }
    Ok(bytes)
}

fn ext(kind: OutputKind) -> &'static str {
    match kind {
        OutputKind::Octree => "voxlod",
        OutputKind::Png => "png",
        OutputKind::Jpeg => "jpg",
        OutputKind::Ply => "ply",
        OutputKind::Glb => "glb",
        OutputKind::Plan => "json",
        OutputKind::Shard => "vlshard",
        OutputKind::MapOutput => "bins",
    }
}

fn read_head(f: &mut File, head: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < head.len() {
        match f.read(&mut head[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// True if `path` still names the file open as `f`.
fn same_inode(f: &File, path: &Path) -> bool {
    match (f.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// Opens and locks `lock_path` (exclusive, non-blocking) and writes our pid into it. Refuses,
/// naming the holder's pid, when another process holds it.
fn lock_file(lock_path: &Path, output: &Path, dir: &Path) -> Result<File> {
    lock_or_name_holder(lock_path).map_err(|e| match e {
        LockError::Held(pid) => anyhow::anyhow!(
            "{} is being written by another voxlod process ({}): wait for it to finish or choose another output file",
            output.display(),
            pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"))
        ),
        LockError::Io(e) if matches!(e.raw_os_error(), Some(libc::ENOSPC | libc::EDQUOT)) => {
            anyhow::anyhow!(
                "{}: the output's folder {} is full: {}",
                output.display(),
                dir.display(),
                os_text(&e)
            )
        }
        LockError::Io(e) => anyhow::anyhow!(
            "{}: the output's folder {} is not writable: {}",
            output.display(),
            dir.display(),
            os_text(&e)
        ),
    })
}

/// Why a lock was not taken.
#[derive(Debug)]
pub(crate) enum LockError {
    /// Another process holds it (its pid, when it has written it yet).
    Held(Option<u32>),
    /// Creating, locking or writing the lock file failed.
    Io(std::io::Error),
}

/// Takes the exclusive advisory lock on `path` (created if missing) and writes our pid into it;
/// see the module docs for the protocol.
pub(crate) fn lock_or_name_holder(path: &Path) -> std::result::Result<File, LockError> {
    for _ in 0..100 {
        let mut f = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(LockError::Io)?;
        // SAFETY: flock on a descriptor we own.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = std::io::Error::last_os_error();
            if e.raw_os_error() != Some(libc::EWOULDBLOCK) {
                return Err(LockError::Io(e));
            }
            // the holder writes its pid right after locking: give it a moment
            let mut pid = None;
            for _ in 0..20 {
                let mut s = String::new();
                if File::open(path)
                    .and_then(|mut g| g.read_to_string(&mut s))
                    .is_ok()
                {
                    pid = s.trim().parse::<u32>().ok();
                }
                if pid.is_some() {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            return Err(LockError::Held(pid));
        }
        if !same_inode(&f, path) {
            continue; // removed by its last holder after we opened it: lock the new one
        }
        let write = |f: &mut File| -> std::io::Result<()> {
            f.set_len(0)?;
            f.write_all(format!("{}\n", std::process::id()).as_bytes())?;
            f.sync_all()
        };
        if let Err(e) = write(&mut f) {
            let _ = std::fs::remove_file(path);
            return Err(LockError::Io(e));
        }
        return Ok(f);
    }
    Err(LockError::Io(std::io::Error::other(
        "the lock file keeps being replaced",
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_names_the_holder() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("l");
        let f = lock_or_name_holder(&p).unwrap();
        // flock locks belong to the open file description: a second open in this process
        // conflicts like another process would
        match lock_or_name_holder(&p) {
            Err(LockError::Held(Some(pid))) => assert_eq!(pid, std::process::id()),
            other => panic!("expected the lock to be held, got {other:?}"),
        }
        drop(f);
        assert!(lock_or_name_holder(&p).is_ok());
    }

    /// A killed run's lock file and staged part are found and removed; a held output's are
    /// listed as in use and kept; other files (the output itself, look-alike names) are not
    /// touched; a part without its lock file is found too.
    #[test]
    fn leftovers_of_killed_runs_are_found_and_removed() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let w = |name: &str, len: usize| std::fs::write(d.join(name), vec![7u8; len]).unwrap();
        // a killed run of "a-b.ply": its lock (nobody holds it) and its part
        drop(lock_or_name_holder(&d.join(".voxlod-lock-a-b.ply")).unwrap());
        w(".voxlod-part-a-b.ply-4242-17f3a9", 1000);
        // a running one of "c.png": held here
        let held = lock_or_name_holder(&d.join(".voxlod-lock-c.png")).unwrap();
        w(".voxlod-part-c.png-77-abc", 500);
        // a part whose lock file is gone
        w(".voxlod-part-d.voxlod-9-ff", 300);
        // not leftovers
        w("a-b.ply", 10);
        w(".voxlod-part-e.ply-x-ff", 10);
        w(".voxlod-partial", 10);
        w("part-0001.bins", 10);
        w("part-x.bins.12.partial", 10);
        w("part-0001.bins.12x.partial", 10);
        w("plan.json.tmp", 10);
        // a map task of an earlier version killed while writing part 1's bins, another its
        // marker
        w("part-0001.bins.4242.partial", 200);
        w("part-0002.json.tmp", 20);
        let found = find_output_leftovers(d).unwrap();
        let names: Vec<_> = found
            .iter()
            .map(|l| (l.name.as_str(), l.files.len()))
            .collect();
        assert_eq!(
            names,
            vec![
                ("a-b.ply", 2),
                ("c.png", 2),
                ("d.voxlod", 1),
                ("part-0001.bins", 1),
                ("part-0002.json", 1)
            ]
        );
        assert_eq!(found[0].in_use_by, None);
        assert_eq!(found[1].in_use_by, Some(Some(std::process::id())));
        assert_eq!(found[2].in_use_by, None);
        assert!(found[0].bytes >= 1000 && found[2].bytes == 300);
        assert!(remove_output_leftovers(d, "part-0001.bins").unwrap() >= 200);
        assert!(remove_output_leftovers(d, "part-0002.json").unwrap() >= 20);
        // the probe created no lock file for "d.voxlod"
        assert!(!d.join(".voxlod-lock-d.voxlod").exists());

        assert!(remove_output_leftovers(d, "a-b.ply").unwrap() >= 1000);
        assert!(remove_output_leftovers(d, "d.voxlod").unwrap() >= 300);
        let e = remove_output_leftovers(d, "c.png").unwrap_err().to_string();
        assert!(e.contains("c.png") && e.contains("running"), "{e}");
        let left = find_output_leftovers(d).unwrap();
        assert_eq!(left.len(), 1, "{left:?}");
        assert_eq!(left[0].name, "c.png");
        for f in [
            "a-b.ply",
            ".voxlod-part-e.ply-x-ff",
            ".voxlod-partial",
            "part-0001.bins",
            "part-x.bins.12.partial",
            "part-0001.bins.12x.partial",
            "plan.json.tmp",
        ] {
            assert!(d.join(f).exists(), "{f} was removed");
        }
        drop(held);
    }

    /// A staged folder (a tileset export's) is a leftover like a staged file: found with the
    /// bytes of the files inside, removed with them; `acquire_folder` stages a folder name,
    /// `commit_folder` exchanges it with an existing folder and removes the old one, and a guard
    /// dropped before its commit removes its staged folder.
    #[test]
    fn staged_folders_are_leftovers_and_commit_exchanges() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let staged = d.join(".voxlod-part-t-12-ab");
        std::fs::create_dir_all(staged.join("sub")).unwrap();
        std::fs::write(staged.join("sub/x"), vec![0u8; 700]).unwrap();
        std::fs::write(staged.join("y"), vec![0u8; 300]).unwrap();
        let found = find_output_leftovers(d).unwrap();
        assert_eq!(found.len(), 1);
        assert_eq!((found[0].name.as_str(), found[0].bytes), ("t", 1000));
        // and the lock file it took, with our pid in it
        assert!(remove_output_leftovers(d, "t").unwrap() >= 1000);
        assert!(!staged.exists());

        let out = d.join("t");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("old"), b"old").unwrap();
        let g = OutputGuard::acquire_folder(&out).unwrap();
        assert!(g
            .staged()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with(".voxlod-part-t-"));
        std::fs::create_dir(g.staged()).unwrap();
        std::fs::write(g.staged().join("new"), b"new").unwrap();
        g.commit_folder().unwrap();
        drop(g);
        assert!(out.join("new").is_file() && !out.join("old").exists());
        let names: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("t")]);

        let g = OutputGuard::acquire_folder(&out).unwrap();
        std::fs::create_dir(g.staged()).unwrap();
        std::fs::write(g.staged().join("half"), b"h").unwrap();
        let staged = g.staged().to_path_buf();
        drop(g);
        assert!(!staged.exists() && out.join("new").is_file());
    }

    #[test]
    fn kinds_are_recognized() {
        assert_eq!(OutputKind::of(b"ply\nformat"), Some(OutputKind::Ply));
        assert_eq!(
            OutputKind::of(b"\xff\xd8\xff\xe0.."),
            Some(OutputKind::Jpeg)
        );
        assert_eq!(
            OutputKind::of(b"\x89PNG\r\n\x1a\n.."),
            Some(OutputKind::Png)
        );
        assert_eq!(
            OutputKind::of(b"VOXLOD\0\x01...."),
            Some(OutputKind::Octree)
        );
        assert_eq!(OutputKind::of(b"solid x"), None);
        assert_eq!(describe(b"solid x"), "an ASCII STL mesh");
    }
}
