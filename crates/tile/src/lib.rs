//! Out-of-core tiling: every triangle goes into the bin of every 256³ chunk its voxels may
//! touch, and the bins live on disk.
//!
//! Passes over the triangles after PotreeConverter 2's counting-sort chunker (Schütz et al.,
//! "Fast Out-of-Core Octree Generation for Massive Point Clouds", 2020):
//!
//! 1. the mesh's bounds are found (they fix the grid). An input that is cheap to read again
//!    (a memory-mapped binary file) is simply read again by the later passes; any other input is
//!    written once to a [`Spool`] of compact records ([`Spooler`]), parsed once whatever its
//!    format. Both are [`Passes`]: something that can hand out the same triangles any number
//!    of times, in the same order.
//! 2. [`count`]: with the grid known, each triangle's chunk range is counted per chunk.
//! 3. [`scatter`]: triangles (in world coordinates, as read) are encoded as compact records
//!    ([`RecordLayout`]: only the attributes the mesh has) into one slice per non-empty chunk
//!    of a buffer of fixed budget; a full slice is appended to the bins file as
//!    [blocks](block) (each distinct corner once, 16-bit indices, flags once), one *piece* of
//!    the chunk's bin.
//!
//! When the grid is known before the triangles are read, [`RunScatter`] bins them without
//! the counts, in the same pass that reads them for their bounds: the buffer is written in
//! runs, each sorted by chunk and encoded as blocks, and a chunk's bin is its pieces in the
//! runs (same triangles, same order for [`Bins::read_chunk`]). For an input whose triangles can
//! be found again by their face record, the runs may hold those records instead of the
//! triangles ([`RunScatter::create_indexed`]: bins of face indices, 4 or 8 bytes per binned
//! triangle, no blocks), read back through the input as a [`TriangleSource`]
//! ([`Bins::read_chunk_from`]).
//!
//! Per-triangle work that does not depend on the order (the chunk ranges as [`ChunkKeys`],
//! of the triangles moved to the grid) runs in each pass's prepare step
//! ([`Passes::for_each_prepared`]), on the threads that read the triangles; the counting and
//! binning, which need the order, on the calling thread.
//!
//! Memory is bounded by design: the passes read through fixed-size buffers, the scatter buffer
//! has a byte budget, and [`Bins::read_chunk`] hands a chunk's triangles out in fixed-size
//! batches. Only the per-chunk counters grow with the grid (8 bytes per chunk).
//!
//! ```
//! use voxlod_geom::{Grid, Triangle};
//! use voxlod_tile::{count, scatter, RecordLayout, Spooler};
//! let dir = tempfile::tempdir().unwrap();
//! let layout = RecordLayout { normals: false, colors: false, texcoords: false };
//! let mut spooler = Spooler::create(&dir.path().join("spool"), layout).unwrap();
//! spooler.push(&[Triangle::new([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])]).unwrap();
//! let spool = spooler.finish().unwrap();
//! let grid = Grid::fit(&spool.bounds, 512).unwrap();
//! let counts = count(&spool, &grid, &mut |_, _| {}).unwrap();
//! let bins = scatter(&spool, &grid, &counts, &dir.path().join("bins"), layout, 1 << 20, &mut |_, _| {}).unwrap();
//! assert_eq!(bins.chunks().len(), 8); // the triangle spans the whole cube: all 2×2×2 chunks
//! let mut n = 0;
//! bins.read_chunk(0, 1024, &mut |tris| { n += tris.len(); Ok(()) }).unwrap();
//! assert_eq!(n, 1);
//! // one block per chunk: a 16-byte header and the 40-byte record (for one triangle, a vertex
//! // table and indices would be larger)
//! assert_eq!(bins.bytes(), 8 * (16 + 40));
//! assert_eq!(std::fs::metadata(dir.path().join("bins")).unwrap().len(), bins.bytes());
//! ```

pub mod block;

mod bins;
mod record;
mod run_scatter;
mod spool;

pub use bins::{
    count, scatter, scatter_bound, Bins, ChunkBin, ChunkCounts, ChunkKeys, TriangleSource, DROPPED,
    SPANS,
};
pub use record::RecordLayout;
pub use run_scatter::{RunScatter, RUN_SCATTER_MAX_CHUNKS};
pub use spool::{Spool, Spooler};

use std::path::PathBuf;

use voxlod_geom::{Grid, Triangle};

/// Triangles per read batch when passing over a spool (3.5–8.25 MiB of records).
pub const READ_BATCH: usize = 96 * 1024;

/// The same triangles, in the same order, as many times as asked: a spool, or an input that is
/// cheap to parse again.
pub trait Passes: Sync {
    /// Calls `f` with every triangle (world coordinates), in batches, in a fixed order, after
    /// `prepare` on each batch, run where the batch was read: for a source decoded on several
    /// threads, on the thread that decoded it, while `f` takes the batch before. `prepare` may
    /// change the triangles (`f` sees them changed); `f` gets the values it returns.
    fn for_each_prepared(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> Vec<u32> + Sync),
        f: &mut dyn FnMut(&[Triangle], Vec<u32>) -> Result<(), TileError>,
    ) -> Result<(), TileError>;
    /// Calls `f` with every triangle (world coordinates), in batches, in a fixed order.
    fn for_each_batch(
        &self,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        self.for_each_prepared(&|_| Vec::new(), &mut |tris, _| f(tris))
    }
    /// Triangles one pass yields (for progress).
    fn count(&self) -> u64;
}

/// The triangle with its positions in grid coordinates (normals and colours unchanged: the
/// world-to-grid map is a uniform scale plus a translation).
#[inline]
pub fn to_grid(grid: &Grid, t: &Triangle) -> Triangle {
    let mut g = *t;
    for v in &mut g.v {
        *v = grid.to_grid(*v);
    }
    g
}

/// A failure of the tiling stage; messages name the temporary file involved.
#[derive(Debug, thiserror::Error)]
pub enum TileError {
    #[error("{op} {path}: {source}")]
    /// Reading or writing a temporary file failed.
    Io {
        /// What was being done (`reading`, `writing`, …).
        op: &'static str,
        /// The file.
        path: PathBuf,
        #[source]
        /// The OS error.
        source: std::io::Error,
    },
    #[error("{path} is {len} bytes, not the expected whole number of {record}-byte triangle records (truncated temporary file?)")]
    /// A spool file is not a whole number of records.
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length, bytes.
        len: u64,
        /// Bytes per record.
        record: u64,
    },
    #[error("{path}: {problem} (a damaged temporary bins file?)")]
    /// A bins file's blocks do not match its pieces or its record layout.
    BadBins {
        /// The file.
        path: PathBuf,
        /// What does not match, and where.
        problem: String,
    },
    #[error("the grid has {0} chunks; at most 2^32 are supported")]
    /// The grid has more chunks than a `u32` index holds.
    TooManyChunks(u64),
    #[error("chunk {coord:?} received {received} triangles but {counted} were counted: the input changed between passes")]
    /// The scatter pass put more or fewer triangles into a chunk than the count pass counted
    /// for it: the passes did not yield the same triangles. (`received` is what the chunk had
    /// when the difference was found: the first triangle of a chunk counted empty, the first
    /// batch past its count, or all of them at the end of the pass.)
    CountChanged {
        /// The chunk's coordinates in the grid of chunks.
        coord: [u32; 3],
        /// Triangles the scatter pass gave it.
        received: u64,
        /// Triangles the count pass counted for it.
        counted: u64,
    },
    #[error("a triangle has {0} but the temporary records were laid out without them (ingest reported the mesh's attributes wrongly)")]
    /// A triangle carries an attribute (`vertex normals`, `texture coordinates`, `colours`)
    /// that the [`RecordLayout`] has no room for, so encoding it would lose it.
    LostAttribute(&'static str),
    #[error(transparent)]
    /// The error with which the caller's callback or its [`Passes`] stopped a pass, kept whole:
    /// the caller takes its own type back with `downcast`.
    Callback(Box<dyn std::error::Error + Send + Sync>),
}

impl TileError {
    pub(crate) fn io(
        op: &'static str,
        path: &std::path::Path,
    ) -> impl FnOnce(std::io::Error) -> TileError {
        let path = path.to_path_buf();
        move |source| TileError::Io { op, path, source }
    }
}
