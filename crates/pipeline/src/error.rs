//! The errors of the build's stages, typed so that the caller can tell an interrupt, an input
//! that changed between passes, a failure of writing the output and bad data apart without
//! matching on text. The messages are the words the command line prints.

use std::path::PathBuf;

use voxlod_format::FormatError;
use voxlod_ingest::IngestError;
use voxlod_tile::TileError;

/// Why a stage stopped.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// Ctrl-C (or [`crate::request_interrupt`]): the work folder is kept for a resume.
    #[error("interrupted; the work done so far is kept in {}: run the same command again to resume", .work.display())]
    Interrupted {
        /// The work folder that is kept.
        work: PathBuf,
    },
    /// A pass over the memory-mapped input yielded another number of triangles than the first.
    #[error("{}: yielded {now} triangles, {first} on the first pass: the file changed during the build", .path.display())]
    InputChanged {
        /// The input file.
        path: PathBuf,
        /// Triangles of this pass.
        now: u64,
        /// Triangles of the first pass.
        first: u64,
    },
    /// An operation on a file failed.
    #[error("{what} {}", .path.display())]
    Io {
        /// What was done (`removing`, `writing`).
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// Reading the input mesh failed.
    #[error(transparent)]
    Ingest(#[from] IngestError),
    /// Tiling (spool, count, scatter, bins) failed.
    #[error(transparent)]
    Tile(#[from] TileError),
    /// Writing the octree file failed.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The mesh has nothing to voxelize.
    #[error("{}: the mesh has no (non-degenerate) triangles", .0.display())]
    NoTriangles(PathBuf),
    /// Too little disk space for the temporary files (the message says how much is needed).
    #[error("{0}")]
    TempDisk(String),
    /// Writing the output failed (I/O on it, too little space, the final rename), as opposed to
    /// bad data: the voxelized chunks are worth keeping for a second attempt.
    #[error("{0}")]
    Output(String),
    /// A voxelizer panicked on a chunk (caught on its worker, so the build ends instead of
    /// waiting for the chunk).
    #[error("voxelizing leaf chunk {chunk} {coord:?} panicked: {message}")]
    Panicked {
        /// Index of the chunk in Morton order.
        chunk: usize,
        /// Its chunk coordinates.
        coord: [u32; 3],
        /// The panic's message.
        message: String,
    },
    /// A voxelizer's lock was poisoned: a panic on another chunk left it in an unknown state.
    #[error("voxelizing leaf chunk {chunk} {coord:?}: its voxelizer was left unusable by a panic on another chunk")]
    Poisoned {
        /// Index of the chunk in Morton order.
        chunk: usize,
        /// Its chunk coordinates.
        coord: [u32; 3],
    },
    /// Any other failure, with its context.
    #[error(transparent)]
    Other(#[from] anyhow::Error),
}

impl StageError {
    /// `Io` for `what` on `path`, as a `map_err` argument.
    pub(crate) fn io(
        what: &'static str,
        path: &std::path::Path,
    ) -> impl FnOnce(std::io::Error) -> StageError {
        let path = path.to_path_buf();
        move |source| StageError::Io { what, path, source }
    }
}

/// The typed reason a callback stopped a loop that belongs to another crate (ingest's batch
/// stream, the tile passes), whose callback error is only text: the callback stores its reason
/// here and returns any error; the stage then takes the reason back ([`StopReason::lift`]).
#[derive(Default)]
pub(crate) struct StopReason(std::sync::Mutex<Option<StageError>>);

impl StopReason {
    /// Keeps `e` as the reason; returns its text for the foreign crate's callback error.
    pub(crate) fn set(&self, e: StageError) -> String {
        let text = e.to_string();
        // a poisoned lock only means a thread panicked while storing: the slot is still valid
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
        text
    }

    /// The stored reason if a callback stopped the loop, else `e` itself.
    pub(crate) fn lift(&self, e: impl Into<StageError>) -> StageError {
        self.0
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .unwrap_or_else(|| e.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reason a callback stored wins over the foreign crate's textual error, once.
    #[test]
    fn stop_reason_lifts_the_typed_error() {
        let stop = StopReason::default();
        let text = stop.set(StageError::Interrupted { work: "/w".into() });
        assert!(text.starts_with("interrupted; the work done so far is kept in /w"));
        let e = stop.lift(TileError::Callback(text));
        assert!(matches!(e, StageError::Interrupted { .. }), "{e:?}");
        let e = stop.lift(TileError::Callback("other".into()));
        assert!(matches!(e, StageError::Tile(TileError::Callback(ref m)) if m == "other"));
    }
}
