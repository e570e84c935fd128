//! The triangle passes of the tile stage ([`voxlod_tile::Passes`]): over the input itself when
//! it is cheap to parse again, and a wrapper that stops any pass on Ctrl-C. Both stop a pass
//! with a typed reason ([`StageError::InputChanged`], [`StageError::Interrupted`]) carried
//! whole in [`TileError::Callback`]; `StageError::from` takes it back out.

use voxlod_geom::Triangle;
use voxlod_ingest::{IngestError, MeshSource};
use voxlod_tile::{Passes, TileError, TriangleSource};

use crate::context::BuildContext;
use crate::error::StageError;

/// Passes over a memory-mapped input (see [`MeshSource::rereadable`]): parsing it again costs
/// what reading a spool would, and saves writing one.
pub(crate) struct InputPasses<'a> {
    pub source: &'a MeshSource,
    /// Triangles of the first pass: every later pass must yield as many.
    pub count: u64,
}

impl Passes for InputPasses<'_> {
    fn for_each_prepared(
        &self,
        prepare: &(dyn Fn(&mut [Triangle]) -> Vec<u32> + Sync),
        f: &mut dyn FnMut(&[Triangle], Vec<u32>) -> Result<(), TileError>,
    ) -> Result<(), TileError> {
        let r = self.source.stream_prepared(
            prepare,
            &mut |tris, p| f(tris, p).map_err(|e| IngestError::Callback(Box::new(e))),
            &mut |_, _| {},
        );
        match r {
            Ok(st) if st.triangles == self.count => Ok(()),
            Ok(st) => Err(TileError::Callback(Box::new(StageError::InputChanged {
                path: self.source.info().path.clone(),
                now: st.triangles,
                first: self.count,
            }))),
            // the pass's own callback error, as it was
            Err(IngestError::Callback(e)) => match e.downcast::<TileError>() {
                Ok(e) => Err(*e),
                Err(e) => Err(TileError::Callback(e)),
            },
            // reading the input again failed
            Err(e) => Err(TileError::Callback(Box::new(e))),
        }
    }

    fn count(&self) -> u64 {
        self.count
    }
}

/// The input as the source of the triangles of bins of face indices
/// ([`MeshSource::triangles_at`]): a record that no longer holds its triangle is the input
/// changed during the build ([`voxlod_ingest::IngestError::FaceChanged`], naming the file).
pub(crate) struct InputTriangles<'a>(pub &'a MeshSource);

impl TriangleSource for InputTriangles<'_> {
    fn triangles_at(&self, faces: &[u64], out: &mut Vec<Triangle>) -> Result<(), TileError> {
        self.0
            .triangles_at(faces, out)
            .map_err(|e| TileError::Callback(Box::new(e)))
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
                return Err(TileError::Callback(Box::new(e)));
            }
            f(tris, p)
        })
    }

    fn count(&self) -> u64 {
        self.inner.count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary PLY icosphere (mapped, so [`InputPasses`] reads it again per pass).
    fn sphere(dir: &std::path::Path) -> (MeshSource, u64) {
        let m = voxlod_testkit::mesh::icosphere(2);
        let path = dir.join("s.ply");
        voxlod_testkit::mesh::write_ply(&path, &m);
        let source = MeshSource::open(&path).unwrap();
        assert!(source.rereadable());
        (source, m.1.len() as u64)
    }

    /// A pass that yields another number of triangles than the first ends with the typed
    /// `InputChanged` naming the file and both counts; the tile pass's own error (its callback
    /// stopping the pass) comes back out of ingest's stream as itself.
    #[test]
    fn input_passes_stop_with_typed_errors() {
        let dir = tempfile::tempdir().unwrap();
        let (source, n) = sphere(dir.path());
        let same = InputPasses {
            source: &source,
            count: n,
        };
        let mut seen = 0u64;
        same.for_each_batch(&mut |t| {
            seen += t.len() as u64;
            Ok(())
        })
        .unwrap();
        assert_eq!(seen, n);
        let changed = InputPasses {
            source: &source,
            count: n + 1,
        };
        let e = StageError::from(changed.for_each_batch(&mut |_| Ok(())).unwrap_err());
        match &e {
            StageError::InputChanged { path, now, first } => {
                assert_eq!((path, *now, *first), (&source.info().path, n, n + 1));
            }
            other => panic!("expected InputChanged, got {other:?}"),
        }
        assert!(e.to_string().ends_with(&format!(
            "yielded {n} triangles, {} on the first pass: the file changed during the build",
            n + 1
        )));
        let e = same
            .for_each_batch(&mut |_| Err(TileError::TooManyChunks(7)))
            .unwrap_err();
        assert!(matches!(e, TileError::TooManyChunks(7)), "{e:?}");
    }
}
