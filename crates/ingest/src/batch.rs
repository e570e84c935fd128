//! Batching of triangles for the caller: every reader pushes triangles here one by one;
//! degenerate ones are counted and dropped, the rest are handed on in batches of
//! [`BATCH`] triangles, with a progress report per batch. The parallel PLY reader hands on
//! each worker's share as a batch of its own instead, prepared on the worker.
//!
//! Each batch goes through the caller's `prepare` step first (see
//! [`MeshSource::stream_prepared`](crate::MeshSource::stream_prepared)), then to its callback
//! with what `prepare` returned.

use std::any::Any;

use crate::{IngestError, IngestStats};
use voxlod_geom::Triangle;

/// What the caller's `prepare` step made of one batch, type-erased inside the readers.
pub(crate) type Prepared = Box<dyn Any + Send>;
/// The caller's `prepare` step, type-erased.
pub(crate) type Prepare<'a> = &'a (dyn Fn(&mut [Triangle]) -> Prepared + Sync);
/// The caller's callback, type-erased: the batch, each triangle's face record (empty unless
/// the reader tracks them: [`LocalBatch::faces`]) and what `prepare` made of the batch.
pub(crate) type Callback<'a> =
    &'a mut dyn FnMut(&[Triangle], &[u64], Prepared) -> Result<(), IngestError>;

/// Triangles per batch handed to the caller's callback (64 Ki triangles = 5.5 MiB).
pub const BATCH: usize = 1 << 16;

/// Triangles between two calls of the release hook: bounds the pages of a memory-mapped
/// input that can be resident at once (at most 3 vertex pages per triangle, plus the faces).
pub const RELEASE_EVERY: u32 = 8192;

pub(crate) struct Emitter<'a> {
    batch: Vec<Triangle>,
    /// Run on each batch before `f`: on the worker that decoded it, for a parallel reader.
    pub prepare: Prepare<'a>,
    f: Callback<'a>,
    progress: &'a mut dyn FnMut(u64, u64),
    pub stats: IngestStats,
    /// Input bytes consumed so far; readers update it, the emitter reports it.
    pub bytes_done: u64,
    pub bytes_total: u64,
    /// Called every [`RELEASE_EVERY`] triangles: drops the resident pages of a memory-mapped
    /// input, so that the process's resident memory stays bounded whatever the file size.
    release: Option<&'a dyn Fn()>,
    since_release: u32,
}

impl<'a> Emitter<'a> {
    pub fn new(
        prepare: Prepare<'a>,
        f: Callback<'a>,
        progress: &'a mut dyn FnMut(u64, u64),
        bytes_total: u64,
    ) -> Self {
        Emitter {
            batch: Vec::with_capacity(BATCH),
            prepare,
            f,
            progress,
            stats: IngestStats::default(),
            bytes_done: 0,
            bytes_total,
            release: None,
            since_release: 0,
        }
    }

    /// Installs the release hook (see the field).
    pub fn with_release(mut self, release: Option<&'a dyn Fn()>) -> Self {
        self.release = release;
        self
    }

    /// A triangle whose corners repeat a vertex index: zero area, skipped and counted.
    #[inline]
    pub fn repeated_index(&mut self) {
        self.stats.degenerate_skipped += 1;
        self.stats.repeated_index += 1;
    }

    /// Reports progress at input byte `bytes` without emitting anything.
    pub fn report(&mut self, bytes: u64) {
        self.bytes_done = bytes;
        (self.progress)(bytes.min(self.bytes_total), self.bytes_total);
    }

    /// Takes one triangle; drops it if it has exactly zero area.
    #[inline]
    pub fn push(&mut self, t: Triangle) -> Result<(), IngestError> {
        debug_assert!(
            t.is_finite(),
            "readers refuse non-finite vertices before emitting"
        );
        if t.is_degenerate() {
            self.stats.degenerate_skipped += 1;
            return Ok(());
        }
        self.batch.push(t);
        self.stats.triangles += 1;
        self.added(1);
        if self.batch.len() == BATCH {
            self.flush()?;
        }
        Ok(())
    }

    /// Takes the triangles of a [`LocalBatch`] (already checked for zero area, and prepared if
    /// its `prepared` is set) and its counts, and hands them on as one batch, without copying
    /// them (after any partial batch of [`Emitter::push`], so the order is kept). Batch
    /// boundaries carry no meaning for the callers: only the order of the triangles does.
    pub fn push_local(&mut self, mut lb: LocalBatch) -> Result<(), IngestError> {
        self.stats.polygons += lb.polygons;
        self.stats.degenerate_skipped += lb.degenerate + lb.repeated;
        self.stats.repeated_index += lb.repeated;
        if lb.tris.is_empty() {
            return Ok(());
        }
        if !self.batch.is_empty() {
            self.flush()?;
        }
        let n = lb.tris.len();
        self.stats.triangles += n as u64;
        let prepared = match lb.prepared.take() {
            Some(p) => p,
            None => (self.prepare)(&mut lb.tris),
        };
        let faces = lb.faces.as_deref().unwrap_or(&[]);
        debug_assert!(faces.is_empty() || faces.len() == n);
        (self.f)(&lb.tris, faces, prepared)?;
        (self.progress)(self.bytes_done.min(self.bytes_total), self.bytes_total);
        self.added(n.min(u32::MAX as usize) as u32);
        Ok(())
    }

    /// Counts `n` triangles towards the next call of the release hook.
    #[inline]
    fn added(&mut self, n: u32) {
        self.since_release += n;
        if self.since_release >= RELEASE_EVERY {
            self.since_release = 0;
            if let Some(r) = self.release {
                r();
            }
        }
    }

    fn flush(&mut self) -> Result<(), IngestError> {
        if !self.batch.is_empty() {
            let prepared = (self.prepare)(&mut self.batch);
            (self.f)(&self.batch, &[], prepared)?;
            self.batch.clear();
        }
        (self.progress)(self.bytes_done.min(self.bytes_total), self.bytes_total);
        Ok(())
    }

    /// Hands on the last partial batch and reports completion.
    pub fn finish(mut self) -> Result<IngestStats, IngestError> {
        self.bytes_done = self.bytes_total;
        self.flush()?;
        Ok(self.stats)
    }
}

/// Where decoded triangles go: the [`Emitter`] (sequential reading) or a [`LocalBatch`] (one
/// worker's share of a parallel PLY read).
pub(crate) trait Sink {
    fn polygon(&mut self);
    fn repeated_index(&mut self);
    fn push(&mut self, t: Triangle) -> Result<(), IngestError>;
    fn bytes_done(&mut self, bytes: u64);
}

impl Sink for Emitter<'_> {
    #[inline]
    fn polygon(&mut self) {
        self.stats.polygons += 1;
    }
    #[inline]
    fn repeated_index(&mut self) {
        Emitter::repeated_index(self)
    }
    #[inline]
    fn push(&mut self, t: Triangle) -> Result<(), IngestError> {
        Emitter::push(self, t)
    }
    #[inline]
    fn bytes_done(&mut self, bytes: u64) {
        self.bytes_done = bytes;
    }
}

/// Triangles and counts of a range of face records decoded by one worker, handed to the
/// emitter in record order afterwards ([`Emitter::push_local`]).
#[derive(Default)]
pub(crate) struct LocalBatch {
    pub tris: Vec<Triangle>,
    pub polygons: u64,
    pub degenerate: u64,
    pub repeated: u64,
    /// The emitter's `prepare` step run on `tris` by the worker, once they are complete.
    pub prepared: Option<Prepared>,
    /// If set, the face record of each triangle of `tris` (for bins of face indices): the
    /// record the batch starts at (`first`) plus the records taken before this one. Every
    /// record counts once in `polygons` before its triangle is added, so the record of a
    /// triangle is `first + polygons - 1` when it is added.
    pub faces: Option<Vec<u64>>,
    /// The face record this batch starts at (with `faces`).
    pub first: u64,
}

impl Sink for LocalBatch {
    #[inline]
    fn polygon(&mut self) {
        self.polygons += 1;
    }
    #[inline]
    fn repeated_index(&mut self) {
        self.repeated += 1;
    }
    #[inline]
    fn push(&mut self, t: Triangle) -> Result<(), IngestError> {
        self.add(t);
        Ok(())
    }
    #[inline]
    fn bytes_done(&mut self, _: u64) {}
}

impl LocalBatch {
    /// Keeps `t` unless it has zero area (the same test as `Emitter::push`).
    #[inline]
    pub(crate) fn add(&mut self, t: Triangle) {
        if t.is_degenerate() {
            self.degenerate += 1;
        } else {
            self.tris.push(t);
            if let Some(f) = &mut self.faces {
                debug_assert!(self.polygons > 0, "a record is counted before its triangle");
                f.push(self.first + self.polygons - 1);
            }
        }
    }
}

/// A corner index repeated: the triangle has zero area.
#[inline]
pub(crate) fn repeats(tri: [usize; 3]) -> bool {
    tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]
}
