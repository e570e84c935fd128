//! The work folder of one build: explicit on-disk intermediates (spool, bins, leaf log) and
//! the markers that say which stages are complete, so a killed or interrupted build started
//! again with the same arguments continues where it stopped.
//!
//! The folder's name is derived from everything the intermediates depend on (input file
//! identity, resolution, mode, zstd level, tool version), so a changed input or setting never
//! resumes from stale data.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{de::DeserializeOwned, Serialize};

use crate::settings::BuildSettings;
use crate::shard::plan_file::ShardScope;

/// Version of the intermediate files (spool and bins records, markers): a work folder left by a
/// build with another layout is never resumed. 2: compact records (`voxlod_tile::RecordLayout`),
/// no spool for memory-mapped inputs. 3: OBJ material ids for every used material, and in a
/// build with the material channel each leaf log record holds a second zstd frame (the
/// materials). 4: leaf log records hold the leaf's half and its encoded node's fields (the
/// LOD stage does not decode the leaves). 5: bins as blocks (`voxlod_tile::block`: a vertex
/// table and 16-bit indices per block), in pieces `[byte offset, bytes, triangles]`. 6: bins
/// of face indices for a mapped PLY of fixed-size triangle records (`bins.json`'s
/// `index_bytes`; an older build would read them as blocks).
pub const WORK_FORMAT: u32 = 6;

/// The files of a work folder: the one place that names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WorkFile {
    /// The ingest stage's triangles (only for an input that cannot be read again cheaply).
    Spool,
    /// The ingest stage's marker.
    IngestMarker,
    /// The tile stage's chunk bins.
    Bins,
    /// The tile stage's marker (the bins layout).
    BinsMarker,
    /// The voxelize stage's leaf log.
    Leaves,
    /// The voxelize stage's marker (its totals).
    LeavesMarker,
    /// The source-geometry stage's log (`--source-geometry`): one record per leaf chunk.
    Source,
    /// The source-geometry stage's marker (its totals).
    SourceMarker,
    /// The decoded textures' tiles, when they exceed their share of the memory plan
    /// (`voxlod_texture::TextureSet::load_within`; complete and checked by its own CRC).
    TextureTiles,
}

impl WorkFile {
    /// The file's name in the folder.
    pub(crate) fn name(self) -> &'static str {
        match self {
            WorkFile::Spool => "spool.tri",
            WorkFile::IngestMarker => "spool.json",
            WorkFile::Bins => "bins.tri",
            WorkFile::BinsMarker => "bins.json",
            WorkFile::Leaves => "leaves.bin",
            WorkFile::LeavesMarker => "leaves.json",
            WorkFile::Source => "source.bin",
            WorkFile::SourceMarker => "source.json",
            WorkFile::TextureTiles => "textures.tiles",
        }
    }
}

/// A stage's artifact as saved in its marker file: it exists only once the stage's data is
/// complete, and a resumed build takes the stage's result from it.
pub(crate) trait Marker: Serialize + DeserializeOwned {
    /// The marker's file.
    const FILE: WorkFile;
}

pub struct WorkDir {
    path: PathBuf,
    /// The folder's advisory lock (`lock` inside it), held while the build runs, so two
    /// builds never share one folder (same input and settings, outputs of the same name in
    /// different folders, one `--tmp`).
    _lock: Option<std::fs::File>,
}

impl WorkDir {
    /// The key of a build: input identity (canonical path, size, modification time), the
    /// settings that change the intermediates (the voxelizer method too: the leaf log of
    /// `scanline-ilv` differs), the tool version and [`WORK_FORMAT`].
    pub fn key(input: &Path, s: &BuildSettings, shard: Option<&ShardScope>) -> Result<String> {
        let canon = input
            .canonicalize()
            .with_context(|| format!("{}: cannot resolve the path", input.display()))?;
        let meta = std::fs::metadata(&canon)
            .with_context(|| format!("{}: cannot read its metadata", input.display()))?;
        let mtime = voxlod_io::mtime_ns(&meta);
        let text = format!(
            "{}\n{}\n{}\n{}\n{}\n{}\n{}\n{}\n{}\n{}",
            canon.display(),
            meta.len(),
            mtime,
            s.resolution,
            s.mode,
            s.voxelizer,
            s.zstd_level,
            s.backend,
            env!("CARGO_PKG_VERSION"),
            WORK_FORMAT
        );
        // a build with source geometry has a source log; one without never resumes from it
        let text = if s.source_geometry {
            text + "\nsource_geometry"
        } else {
            text
        };
        // a shard's intermediates hold its own chunks only
        let text = match shard {
            Some(sc) => format!(
                "{text}\nshard {} of {}, plan {}",
                sc.index,
                sc.count,
                voxlod_io::hex(&sc.plan_sha256)
            ),
            None => text,
        };
        // FNV-1a: stable across Rust releases, so the same build finds its folder again
        Ok(format!(
            "{:016x}",
            voxlod_io::fnv1a(text.as_bytes(), voxlod_io::FNV1A_OFFSET)
        ))
    }

    /// Opens (resuming) or creates the work folder for `output` under `parent`. Returns whether
    /// it existed.
    pub fn open(parent: &Path, output: &Path, key: &str) -> Result<(WorkDir, bool)> {
        let name = output
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let path = parent.join(format!(".voxlod-work-{name}-{key}"));
        let existed = path.is_dir();
        if !existed {
            std::fs::create_dir_all(&path).map_err(|e| {
                anyhow::anyhow!(
                    "creating the work folder {}: {}",
                    path.display(),
                    crate::files::output::os_text(&e)
                )
            })?;
        }
        let lock = match crate::files::output::lock_or_name_holder(&path.join("lock")) {
            Ok(f) => f,
            Err(crate::files::output::LockError::Held(pid)) => bail!(
                "the work folder {} is in use by another voxlod build ({}): wait for it to finish",
                path.display(),
                pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"))
            ),
            Err(crate::files::output::LockError::Io(e)) => bail!(
                "locking the work folder {}: {}",
                path.display(),
                crate::files::output::os_text(&e)
            ),
        };
        Ok((
            WorkDir {
                path,
                _lock: Some(lock),
            },
            existed,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The path of one of the folder's files.
    pub(crate) fn file(&self, f: WorkFile) -> PathBuf {
        self.path.join(f.name())
    }

    /// A stage's marker, or None when it is missing or unreadable (then the stage runs again).
    pub(crate) fn marker<M: Marker>(&self) -> Option<M> {
        self.read_json(M::FILE.name())
    }

    /// Writes a stage's marker (see [`WorkDir::write_json`]).
    pub(crate) fn set_marker<M: Marker>(&self, m: &M) -> Result<()> {
        self.write_json(M::FILE.name(), m)
    }

    fn read_json<T: DeserializeOwned>(&self, name: &str) -> Option<T> {
        let bytes = std::fs::read(self.path.join(name)).ok()?;
        serde_json::from_slice(&bytes).ok()
    }

    /// Writes a JSON file atomically ([`voxlod_io::write_atomic`]), so a marker exists only
    /// once its stage's data is complete.
    fn write_json<T: Serialize>(&self, name: &str, value: &T) -> Result<()> {
        let fin = self.path.join(name);
        let bytes = serde_json::to_vec(value)?;
        voxlod_io::write_atomic(&fin, &bytes).with_context(|| format!("writing {}", fin.display()))
    }

    /// Removes the folder and everything in it.
    ///
    /// `remove_dir_all` lists the folder and then removes what it listed; a file created
    /// meanwhile makes the final rmdir fail with "Directory not empty". A few retries remove
    /// such a late file; a folder that still cannot be removed is an error naming it.
    pub(crate) fn remove(self) -> Result<()> {
        let mut tries = 0;
        loop {
            match std::fs::remove_dir_all(&self.path) {
                Ok(()) => return Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound && tries > 0 => return Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::DirectoryNotEmpty && tries < 5 => {
                    tries += 1;
                    std::thread::sleep(std::time::Duration::from_millis(20 * tries));
                }
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!("removing the work folder {}", self.path.display())
                    })
                }
            }
        }
    }
}

/// Prefix of every work folder's name (`.voxlod-work-<output name>-<key>`).
pub const WORK_PREFIX: &str = ".voxlod-work-";

/// How long a work folder without a lock file counts as in use (a build creating it, or one
/// removing it as it finishes, changes it all the time); after that it is stale.
pub const UNLOCKED_GRACE: std::time::Duration = std::time::Duration::from_secs(60);

/// A work folder found by [`find_work_folders`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct WorkFolder {
    /// The folder.
    pub path: PathBuf,
    /// Bytes of the files in it.
    pub bytes: u64,
    /// Seconds since it was last modified.
    pub age_seconds: u64,
    /// The pid of the running build that holds its lock, if one does; a folder without a
    /// holder is stale: its build was killed and was not run again with the same arguments
    /// (running it again resumes from the folder; `voxlod clean` removes it).
    pub in_use_by: Option<Option<u32>>,
}

impl WorkFolder {
    /// True if no running build holds it.
    pub fn is_stale(&self) -> bool {
        self.in_use_by.is_none()
    }
}

/// The voxlod work folders directly inside `dir` (the folder of the outputs, or a `--tmp`),
/// sorted by name, each with its size and whether a running build holds its lock (tested by
/// taking the lock and releasing it at once).
pub fn find_work_folders(dir: &Path) -> Result<Vec<WorkFolder>> {
    let entries = std::fs::read_dir(dir).map_err(|e| {
        anyhow::anyhow!(
            "{}: cannot list it: {}",
            dir.display(),
            crate::files::output::os_text(&e)
        )
    })?;
    let mut found = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
        if !is_dir || !name.to_string_lossy().starts_with(WORK_PREFIX) {
            continue;
        }
        let path = entry.path();
        let in_use_by = holder(&path);
        let age_seconds = entry
            .metadata()
            .ok()
            .and_then(|m| m.modified().ok())
            .and_then(|t| t.elapsed().ok())
            .map_or(0, |d| d.as_secs());
        found.push(WorkFolder {
            bytes: tree_bytes(&path),
            path,
            age_seconds,
            in_use_by,
        });
    }
    found.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(found)
}

/// Whether a running build holds the lock of the work folder at `path`: `None` if none does
/// (stale), else `Some` of its pid when it has written it. Probed with a non-blocking `flock`
/// on the lock file opened *without creating it*: a build that finished removes its folder
/// while others in the same parent look for stale folders (two shards of one plan ending
/// together), and a lock file created by the probe inside a folder being removed made that
/// removal fail with "Directory not empty". A folder without a lock file is being created or
/// removed (in use) while it changed within the last [`UNLOCKED_GRACE`]; one unchanged for
/// longer was left so by a killed run (stale: removing it takes the lock first). A lock file
/// that cannot be opened for another reason counts as in use (never removed).
fn holder(path: &Path) -> Option<Option<u32>> {
    use std::os::fd::AsRawFd;
    let lock = path.join("lock");
    let f = match std::fs::OpenOptions::new().read(true).open(&lock) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let unchanged = std::fs::metadata(path)
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok());
            return match unchanged {
                Some(d) if d >= UNLOCKED_GRACE => None,
                _ => Some(None),
            };
        }
        Err(_) => return Some(None),
    };
    // SAFETY: flock on a descriptor we own; the lock is released when `f` is dropped.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return None;
    }
    let pid = std::fs::read_to_string(&lock)
        .ok()
        .and_then(|s| s.trim().parse::<u32>().ok());
    Some(pid)
}

/// Removes a stale work folder, holding its lock while it does so that a build starting on
/// it meanwhile is refused instead of losing its files; a folder in use is refused.
pub fn remove_stale_work_folder(path: &Path) -> Result<()> {
    match crate::files::output::lock_or_name_holder(&path.join("lock")) {
        Ok(_lock) => std::fs::remove_dir_all(path).map_err(|e| {
            anyhow::anyhow!(
                "removing {}: {}",
                path.display(),
                crate::files::output::os_text(&e)
            )
        }),
        Err(crate::files::output::LockError::Held(pid)) => bail!(
            "{} is in use by a running voxlod build ({}): not removed",
            path.display(),
            pid.map_or("pid unknown".to_string(), |p| format!("pid {p}"))
        ),
        Err(crate::files::output::LockError::Io(e)) => bail!(
            "locking {}: {}: not removed",
            path.display(),
            crate::files::output::os_text(&e)
        ),
    }
}

/// Bytes of the regular files under `path` (symbolic links not followed; unreadable parts
/// count 0).
fn tree_bytes(path: &Path) -> u64 {
    let mut total = 0;
    let mut stack = vec![path.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            match e.file_type() {
                Ok(t) if t.is_dir() => stack.push(e.path()),
                Ok(t) if t.is_file() => total += e.metadata().map_or(0, |m| m.len()),
                _ => {}
            }
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Looking for stale folders creates nothing inside a folder whose lock file is gone (a
    /// build removing its folder at that moment), and counts it as in use while it is fresh; a
    /// folder whose lock a live handle holds is in use, one whose lock nobody holds is stale,
    /// and so is one without a lock file left unchanged past the grace period.
    #[test]
    fn probing_for_stale_folders_creates_no_lock_file() {
        let dir = tempfile::tempdir().unwrap();
        let removing = dir.path().join(format!("{WORK_PREFIX}a-1"));
        std::fs::create_dir(&removing).unwrap();
        std::fs::write(removing.join("leaves.json"), b"{}").unwrap();
        let held = dir.path().join(format!("{WORK_PREFIX}b-2"));
        std::fs::create_dir(&held).unwrap();
        let _lock = crate::files::output::lock_or_name_holder(&held.join("lock")).unwrap();
        let stale = dir.path().join(format!("{WORK_PREFIX}c-3"));
        std::fs::create_dir(&stale).unwrap();
        drop(crate::files::output::lock_or_name_holder(&stale.join("lock")).unwrap());
        // a folder without a lock file that nobody changed for longer than the grace period:
        // a run killed between creating it and locking it (stale, not "in use" forever)
        let abandoned = dir.path().join(format!("{WORK_PREFIX}d-4"));
        std::fs::create_dir(&abandoned).unwrap();
        let long_ago = std::time::SystemTime::now() - UNLOCKED_GRACE * 2;
        std::fs::File::open(&abandoned)
            .unwrap()
            .set_times(std::fs::FileTimes::new().set_modified(long_ago))
            .unwrap();
        let found = find_work_folders(dir.path()).unwrap();
        let state: Vec<_> = found.iter().map(|f| f.in_use_by).collect();
        assert_eq!(
            state,
            vec![Some(None), Some(Some(std::process::id())), None, None]
        );
        assert!(
            !removing.join("lock").exists() && !abandoned.join("lock").exists(),
            "the probe created a lock file"
        );
        remove_stale_work_folder(&abandoned).unwrap();
        assert!(!abandoned.exists());
        std::fs::remove_dir_all(&removing).unwrap();
    }

    /// A resumed build recomputes its grid from the bounds in a marker, so the marker must give
    /// back every f64 bit for bit (serde_json's default float parser is off by one ulp on some
    /// values, e.g. -0.9728269577026367, the bounds of a generated mesh, which moved the origin
    /// of a resumed build's header).
    #[test]
    fn markers_round_trip_floats_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let w = WorkDir {
            path: dir.path().to_path_buf(),
            _lock: None,
        };
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut vals: Vec<f64> = vec![-0.9728269577026367, 0.1 + 0.2, f64::MIN_POSITIVE, 1e300];
        for _ in 0..20_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let v = f64::from_bits(seed);
            if v.is_finite() {
                vals.push(v);
            }
            vals.push((seed >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0);
            vals.push(f32::from_bits((seed >> 32) as u32) as f64);
        }
        vals.retain(|v| v.is_finite());
        w.write_json("floats.json", &vals).unwrap();
        let back: Vec<f64> = w.read_json("floats.json").unwrap();
        assert_eq!(back.len(), vals.len());
        for (a, b) in vals.iter().zip(&back) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a:e} came back as {b:e}");
        }
    }
}
