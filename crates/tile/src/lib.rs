//! Out-of-core tiling: every triangle goes into the bin of every 256³ chunk its voxels may
//! touch, and the bins live on disk.
//!
//! Three passes over explicit on-disk intermediates, after PotreeConverter 2's counting-sort
//! chunker (Schütz et al., "Fast Out-of-Core Octree Generation for Massive Point Clouds", 2020):
//!
//! 1. [`Spooler`]: the input triangles (world coordinates) are appended to a *spool* file while
//!    their bounds are accumulated, so the input is parsed once, whatever its format.
//! 2. [`Spool::count`]: with the grid known, each triangle's chunk range is counted per chunk.
//! 3. [`Spool::scatter`]: the bins file is laid out as one pre-sized region per non-empty chunk,
//!    in Morton order of the chunks; triangles (now in grid coordinates) are buffered in memory
//!    up to a fixed budget and flushed to their regions with positioned writes.
//!
//! Memory is bounded by design: the passes read the spool through a fixed-size buffer, the
//! scatter buffer has a byte budget, and [`Bins::read_chunk`] hands a chunk's triangles out in
//! fixed-size batches. Only the per-chunk counters grow with the grid (8 bytes per chunk).
//!
//! ```
//! use voxlod_geom::{Grid, Triangle};
//! use voxlod_tile::Spooler;
//! let dir = tempfile::tempdir().unwrap();
//! let mut spooler = Spooler::create(&dir.path().join("spool")).unwrap();
//! spooler.push(&[Triangle::new([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])]).unwrap();
//! let spool = spooler.finish().unwrap();
//! let grid = Grid::fit(&spool.bounds, 512).unwrap();
//! let counts = spool.count(&grid, &mut |_, _| {}).unwrap();
//! let bins = spool.scatter(&grid, &counts, &dir.path().join("bins"), 1 << 20, &mut |_, _| {}).unwrap();
//! assert_eq!(bins.chunks().len(), 8); // the triangle spans the whole cube: all 2×2×2 chunks
//! let mut n = 0;
//! bins.read_chunk(0, 1024, &mut |tris| { n += tris.len(); Ok(()) }).unwrap();
//! assert_eq!(n, 1);
//! ```

mod bins;
mod spool;

pub use bins::{Bins, ChunkBin, ChunkCounts};
pub use spool::{to_grid, Spool, Spooler};

use std::path::PathBuf;

/// Bytes of one triangle record in the spool and the bins.
pub const TRIANGLE_BYTES: u64 = std::mem::size_of::<voxlod_geom::Triangle>() as u64;

/// Triangles per read batch when passing over the spool (8.25 MiB of records).
pub const READ_BATCH: usize = 96 * 1024;

/// A failure of the tiling stage; messages name the temporary file involved.
#[derive(Debug, thiserror::Error)]
pub enum TileError {
    #[error("{op} {path}: {source}")]
    Io {
        op: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is {len} bytes, not a whole number of {TRIANGLE_BYTES}-byte triangle records (truncated temporary file?)")]
    Truncated { path: PathBuf, len: u64 },
    #[error("the grid has {0} chunks; at most 2^32 are supported")]
    TooManyChunks(u64),
    #[error("{0}")]
    Callback(String),
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
