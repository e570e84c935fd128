//! The triangle passes of the tile stage ([`voxlod_tile::Passes`]): over the input itself when
//! it is cheap to parse again, and a wrapper that stops any pass on Ctrl-C. Both stop a pass
//! with a typed reason ([`StageError::InputChanged`], [`StageError::Interrupted`]) kept in the
//! build's [`StopReason`]; the tile crate only sees its text.

use voxlod_geom::Triangle;
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::{Passes, TileError};

use crate::error::{StageError, StopReason};
use crate::stages::BuildContext;

/// Passes over a memory-mapped input (see [`MeshSource::rereadable`]): parsing it again costs
/// what reading a spool would, and saves writing one.
pub(crate) struct InputPasses<'a> {
    pub source: &'a MeshSource,
    /// Triangles of the first pass: every later pass must yield as many.
    pub count: u64,
    /// Where a changed input is reported.
    pub stop: &'a StopReason,
}

impl Passes for InputPasses<'_> {
    fn for_each_prepared(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> Vec<u32> + Sync),
        f: &mut dyn FnMut(&[Triangle], Vec<u32>) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        let mut inner: Option<TileError> = None;
        let r = self.source.stream_prepared(
            prepare,
            &mut |tris, p| {
                f(tris, p).map_err(|e| {
                    let m = e.to_string();
                    inner = Some(e);
                    IngestError::Callback(m)
                })
            },
            &mut |_, _| {},
        );
        match r {
            Ok(st) if st.triangles == self.count => Ok(()),
            Ok(st) => Err(TileError::Callback(self.stop.set(
                StageError::InputChanged {
                    path: self.source.info().path.clone(),
                    now: st.triangles,
                    first: self.count,
                },
            ))),
            Err(e) => Err(inner.take().unwrap_or(TileError::Callback(e.to_string()))),
        }
    }

    fn count(&self) -> u64 {
        self.count
    }
}

/// Any passes, stopped with [`StageError::Interrupted`] between batches once Ctrl-C was
/// pressed.
pub(crate) struct Interruptible<'a> {
    pub inner: &'a dyn Passes,
    pub ctx: &'a BuildContext<'a>,
}

impl Passes for Interruptible<'_> {
    fn for_each_prepared(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> Vec<u32> + Sync),
        f: &mut dyn FnMut(&[Triangle], Vec<u32>) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        self.inner.for_each_prepared(prepare, &mut |tris, p| {
            if let Err(e) = self.ctx.check_interrupt() {
                return Err(TileError::Callback(self.ctx.stop.set(e)));
            }
            f(tris, p)
        })
    }

    fn count(&self) -> u64 {
        self.inner.count()
    }
}
