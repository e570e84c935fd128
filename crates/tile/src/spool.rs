//! Pass 1 of tiling: the spool, a flat file of compact triangle records ([`RecordLayout`]) in
//! world coordinates, for inputs that are expensive to parse twice (ASCII, gzip, OBJ).

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use voxlod_geom::{Bounds, Triangle};

use crate::{Passes, RecordLayout, TileError, READ_BATCH};

/// Appends triangles to a spool file and accumulates their bounds.
pub struct Spooler {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    layout: RecordLayout,
    buf: Vec<u8>,
    count: u64,
    bounds: Bounds,
}

impl Spooler {
    /// Creates the spool file at `path` for records of `layout`.
    pub fn create(path: &Path, layout: RecordLayout) -> Result<Spooler, TileError> {
        let f = File::create(path).map_err(TileError::io("create", path))?;
        Ok(Spooler {
            path: path.to_path_buf(),
            out: Some(BufWriter::with_capacity(4 << 20, f)),
            layout,
            buf: Vec::new(),
            count: 0,
            bounds: Bounds::default(),
        })
    }

    /// Appends a batch. Triangles must be finite (ingest guarantees it).
    pub fn push(&mut self, tris: &[Triangle]) -> Result<(), TileError> {
        self.buf.clear();
        for t in tris {
            debug_assert!(t.is_finite());
            self.bounds.add_triangle(t);
            self.layout.encode(t, &mut self.buf)?;
        }
        self.count += tris.len() as u64;
        let out = self.out.as_mut().expect("spooler used after finish");
        out.write_all(&self.buf)
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
            layout: self.layout,
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

/// A finished spool file: `count` triangles with world-space `bounds`, records laid out by
/// `layout`.
#[derive(Debug)]
pub struct Spool {
    /// The spool file.
    pub path: PathBuf,
    /// Triangle records in it.
    pub count: u64,
    /// Bounds of the triangles' corners.
    pub bounds: Bounds,
    /// The record layout.
    pub layout: RecordLayout,
}

impl Spool {
    /// Reopens an existing spool (e.g. to resume), recomputing its count and bounds.
    pub fn open(path: &Path, layout: RecordLayout) -> Result<Spool, TileError> {
        let len = std::fs::metadata(path)
            .map_err(TileError::io("stat", path))?
            .len();
        let rec = layout.bytes() as u64;
        if len % rec != 0 {
            return Err(TileError::Truncated {
                path: path.to_path_buf(),
                len,
                record: rec,
            });
        }
        let mut s = Spool {
            path: path.to_path_buf(),
            count: len / rec,
            bounds: Bounds::default(),
            layout,
        };
        let mut bounds = Bounds::default();
        s.for_each_batch(&mut |tris| {
            tris.iter().for_each(|t| bounds.add_triangle(t));
            Ok(())
        })?;
        s.bounds = bounds;
        Ok(s)
    }

    /// Removes the spool file.
    pub fn remove(self) -> Result<(), TileError> {
        std::fs::remove_file(&self.path).map_err(TileError::io("remove", &self.path))
    }
}

impl Passes for Spool {
    /// Reads the spool sequentially through a fixed buffer of [`READ_BATCH`] records (and
    /// prepares each batch on the calling thread).
    fn for_each_prepared(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> Vec<u32> + Sync),
        f: &mut dyn FnMut(&[Triangle], Vec<u32>) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        let mut file = File::open(&self.path).map_err(TileError::io("open", &self.path))?;
        let len = file
            .metadata()
            .map_err(TileError::io("stat", &self.path))?
            .len();
        let rec = self.layout.bytes();
        if len != self.count * rec as u64 {
            return Err(TileError::Truncated {
                path: self.path.clone(),
                len,
                record: rec as u64,
            });
        }
        let mut raw = vec![0u8; READ_BATCH * rec];
        let mut tris = Vec::with_capacity(READ_BATCH);
        let mut left = self.count;
        while left > 0 {
            let n = left.min(READ_BATCH as u64) as usize;
            file.read_exact(&mut raw[..n * rec])
                .map_err(TileError::io("read", &self.path))?;
            self.layout.decode_all(&raw[..n * rec], &mut tris);
            let p = prepare(&mut tris);
            f(&tris, p)?;
            left -= n as u64;
        }
        Ok(())
    }

    fn count(&self) -> u64 {
        self.count
    }
}
