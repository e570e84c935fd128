//! Pass 1 of tiling: the spool, a flat file of `Triangle` records in world coordinates, and
//! the passes over it (count, scatter) that need the mesh's bounds first.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use voxlod_geom::{Bounds, Grid, Triangle};

use crate::bins::{self, Bins, ChunkCounts};
use crate::{TileError, READ_BATCH, TRIANGLE_BYTES};

/// Appends triangles to a spool file and accumulates their bounds.
pub struct Spooler {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    count: u64,
    bounds: Bounds,
}

impl Spooler {
    pub fn create(path: &Path) -> Result<Spooler, TileError> {
        let f = File::create(path).map_err(TileError::io("create", path))?;
        Ok(Spooler {
            path: path.to_path_buf(),
            out: Some(BufWriter::with_capacity(4 << 20, f)),
            count: 0,
            bounds: Bounds::default(),
        })
    }

    /// Appends a batch. Triangles must be finite (ingest guarantees it).
    pub fn push(&mut self, tris: &[Triangle]) -> Result<(), TileError> {
        for t in tris {
            debug_assert!(t.is_finite());
            self.bounds.add_triangle(t);
        }
        self.count += tris.len() as u64;
        let out = self.out.as_mut().expect("spooler used after finish");
        out.write_all(bytemuck::cast_slice(tris))
            .map_err(TileError::io("write", &self.path))
    }

    /// Flushes the file and returns the spool.
    pub fn finish(mut self) -> Result<Spool, TileError> {
        let out = self.out.take().expect("spooler finished twice");
        let f = out.into_inner().map_err(|e| TileError::Io {
            op: "write",
            path: self.path.clone(),
            source: e.into_error(),
        })?;
        f.sync_data().map_err(TileError::io("sync", &self.path))?;
        Ok(Spool {
            path: std::mem::take(&mut self.path),
            count: self.count,
            bounds: self.bounds,
        })
    }
}

impl Drop for Spooler {
    fn drop(&mut self) {
        // An unfinished spool is useless: remove it.
        if self.out.is_some() {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// A finished spool file: `count` triangles with world-space `bounds`.
#[derive(Debug)]
pub struct Spool {
    pub path: PathBuf,
    pub count: u64,
    pub bounds: Bounds,
}

impl Spool {
    /// Reopens an existing spool (e.g. to resume), recomputing its count and bounds.
    pub fn open(path: &Path) -> Result<Spool, TileError> {
        let mut s = Spool {
            path: path.to_path_buf(),
            count: 0,
            bounds: Bounds::default(),
        };
        let len = std::fs::metadata(path)
            .map_err(TileError::io("stat", path))?
            .len();
        if len % TRIANGLE_BYTES != 0 {
            return Err(TileError::Truncated {
                path: path.to_path_buf(),
                len,
            });
        }
        let mut bounds = Bounds::default();
        s.for_each_batch(&mut |tris| {
            for t in tris {
                bounds.add_triangle(t);
            }
            Ok(())
        })?;
        s.count = len / TRIANGLE_BYTES;
        s.bounds = bounds;
        Ok(s)
    }

    /// Reads the spool sequentially through a fixed buffer of [`READ_BATCH`] triangles.
    pub fn for_each_batch(
        &self,
        f: &mut dyn FnMut(&[Triangle]) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        let mut file = File::open(&self.path).map_err(TileError::io("open", &self.path))?;
        let len = file
            .metadata()
            .map_err(TileError::io("stat", &self.path))?
            .len();
        if len % TRIANGLE_BYTES != 0 || len / TRIANGLE_BYTES != self.count && self.count != 0 {
            return Err(TileError::Truncated {
                path: self.path.clone(),
                len,
            });
        }
        let mut buf = vec![Triangle::new([[0.0; 3]; 3]); READ_BATCH];
        let mut left = len / TRIANGLE_BYTES;
        while left > 0 {
            let n = left.min(READ_BATCH as u64) as usize;
            file.read_exact(bytemuck::cast_slice_mut(&mut buf[..n]))
                .map_err(TileError::io("read", &self.path))?;
            f(&buf[..n])?;
            left -= n as u64;
        }
        Ok(())
    }

    /// Pass 2: counts, per leaf chunk, the triangles whose chunk range (see
    /// [`Grid::chunk_range`]) includes it. `progress(done, total)` is in triangles.
    pub fn count(
        &self,
        grid: &Grid,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<ChunkCounts, TileError> {
        let mut counts = ChunkCounts::new(grid)?;
        let mut done = 0u64;
        self.for_each_batch(&mut |tris| {
            for t in tris {
                let g = to_grid(grid, t);
                if let Some((lo, hi)) = grid.chunk_range(&g) {
                    counts.add_range(lo, hi);
                }
            }
            done += tris.len() as u64;
            progress(done, self.count);
            Ok(())
        })?;
        Ok(counts)
    }

    /// Pass 3: writes the bins file at `path` (grid coordinates), buffering at most
    /// `buffer_bytes` of triangles in memory between flushes.
    pub fn scatter(
        &self,
        grid: &Grid,
        counts: &ChunkCounts,
        path: &Path,
        buffer_bytes: u64,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<Bins, TileError> {
        let mut sc = bins::Scatter::create(grid, counts, path, buffer_bytes)?;
        let mut done = 0u64;
        let mut gtris = Vec::with_capacity(READ_BATCH);
        self.for_each_batch(&mut |tris| {
            gtris.clear();
            gtris.extend(tris.iter().map(|t| to_grid(grid, t)));
            sc.push(&gtris)?;
            done += tris.len() as u64;
            progress(done, self.count);
            Ok(())
        })?;
        sc.finish()
    }

    /// Removes the spool file.
    pub fn remove(self) -> Result<(), TileError> {
        std::fs::remove_file(&self.path).map_err(TileError::io("remove", &self.path))
    }
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
