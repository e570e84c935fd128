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
    /// Ctrl-C (or [`crate::system::request_interrupt`]): the work folder is kept for a resume.
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
    /// A sharded build's input has other bytes than when its plan was made (the XXH3-64 of
    /// its content differs), though its size, time and first and last MiB may be the same.
    #[error("{}: its content changed since {} was planned (XXH3-64 {now}, the plan has {planned}): plan again", .path.display(), .plan.display())]
    ContentChanged {
        /// The input file.
        path: PathBuf,
        /// The plan file.
        plan: PathBuf,
        /// The checksum now, hex.
        now: String,
        /// The plan's checksum, hex.
        planned: String,
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
    Ingest(IngestError),
    /// Tiling (spool, count, scatter, bins) failed.
    #[error(transparent)]
    Tile(TileError),
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

/// A callback's error boxed by another crate's loop (ingest's batch stream, the tile passes)
/// as the error the build stopped with: a `StageError` the callback
/// stopped with comes back as itself, an ingest or tile error (one pass's reading of the input,
/// the spool's writing) as its own variant, so an interrupt stays `Interrupted` and a changed
/// input `InputChanged` however deep the loops were nested. `Err` gives back anything else.
fn unbox(
    e: Box<dyn std::error::Error + Send + Sync>,
) -> Result<StageError, Box<dyn std::error::Error + Send + Sync>> {
    let e = match e.downcast::<StageError>() {
        Ok(e) => return Ok(*e),
        Err(e) => e,
    };
    let e = match e.downcast::<TileError>() {
        Ok(e) => return Ok((*e).into()),
        Err(e) => e,
    };
    match e.downcast::<IngestError>() {
        Ok(e) => Ok((*e).into()),
        Err(e) => Err(e),
    }
}

impl From<IngestError> for StageError {
    fn from(e: IngestError) -> Self {
        match e {
            IngestError::Callback(e) => {
                unbox(e).unwrap_or_else(|e| Self::Ingest(IngestError::Callback(e)))
            }
            e => Self::Ingest(e),
        }
    }
}

impl From<TileError> for StageError {
    fn from(e: TileError) -> Self {
        match e {
            TileError::Callback(e) => {
                unbox(e).unwrap_or_else(|e| Self::Tile(TileError::Callback(e)))
            }
            e => Self::Tile(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxed(
        e: impl std::error::Error + Send + Sync + 'static,
    ) -> Box<dyn std::error::Error + Send + Sync> {
        Box::new(e)
    }

    /// A stage error that stopped a foreign loop comes back typed, through any nesting of the
    /// loops (a tile pass over the input: tile callback inside ingest's stream), with its
    /// message unchanged; a foreign error stays what it was.
    #[test]
    fn callback_errors_come_back_typed() {
        let interrupted = || StageError::Interrupted { work: "/w".into() };
        let text = interrupted().to_string();
        assert!(text.starts_with("interrupted; the work done so far is kept in /w"));
        let e = StageError::from(TileError::Callback(boxed(interrupted())));
        assert!(matches!(e, StageError::Interrupted { .. }), "{e:?}");
        assert_eq!(e.to_string(), text);
        let e = StageError::from(IngestError::Callback(boxed(interrupted())));
        assert!(matches!(e, StageError::Interrupted { .. }), "{e:?}");
        // the InputPasses nesting: ingest's stream around the tile pass's callback
        let changed = StageError::InputChanged {
            path: "/m.ply".into(),
            now: 3,
            first: 4,
        };
        let nested = TileError::Callback(boxed(IngestError::Callback(boxed(TileError::Callback(
            boxed(changed),
        )))));
        let e = StageError::from(nested);
        assert!(
            matches!(
                e,
                StageError::InputChanged {
                    now: 3,
                    first: 4,
                    ..
                }
            ),
            "{e:?}"
        );
        assert_eq!(
            e.to_string(),
            "/m.ply: yielded 3 triangles, 4 on the first pass: the file changed during the build"
        );
        // a tile error inside ingest's callback (the spool's write) is a tile error
        let io = TileError::Io {
            op: "write",
            path: "/w/spool.tri".into(),
            source: std::io::Error::other("disk full"),
        };
        let e = StageError::from(IngestError::Callback(boxed(io)));
        assert!(
            matches!(e, StageError::Tile(TileError::Io { op: "write", .. })),
            "{e:?}"
        );
        // an ingest error inside a tile pass (a second pass's read) is an ingest error
        let obj = IngestError::Obj {
            path: "/m.obj".into(),
            message: "bad".into(),
        };
        let e = StageError::from(TileError::Callback(boxed(obj)));
        assert!(
            matches!(e, StageError::Ingest(IngestError::Obj { .. })),
            "{e:?}"
        );
        // anything else stays in its variant, whole
        let e = StageError::from(TileError::Callback(boxed(std::io::Error::other("other"))));
        let StageError::Tile(TileError::Callback(inner)) = e else {
            panic!("{e:?}")
        };
        assert_eq!(
            inner
                .downcast::<std::io::Error>()
                .expect("whole")
                .to_string(),
            "other"
        );
        let e = StageError::from(TileError::TooManyChunks(5));
        assert!(
            matches!(e, StageError::Tile(TileError::TooManyChunks(5))),
            "{e:?}"
        );
    }
}
