//! The build as a sequence of stages: ingest → tile → voxelize → LOD + write.
//!
//! Each stage is one file with one entry, `run(&mut BuildContext, previous artifact) →
//! artifact`. A stage's artifact is also its resume marker: it is saved in the work folder
//! (`spool.json`, `bins.json`, `leaves.json`) once the stage's data is complete, and a build
//! started again with the same arguments takes the artifact from there instead of running the
//! stage ([`run`] decides which stages a resumed build skips).

pub(crate) mod ingest;
pub(crate) mod lod_write;
pub(crate) mod source;
pub(crate) mod tile;
pub(crate) mod voxelize;

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use voxlod_ingest::MeshSource;

use crate::error::StageError;
use crate::memory::MemoryPlan;
use crate::output::OutputGuard;
use crate::work::WorkDir;
use crate::{BuildSettings, StageTime};

/// What every stage of one build shares.
pub(crate) struct BuildContext<'a> {
    /// The build's settings.
    pub settings: &'a BuildSettings,
    /// The input mesh, opened.
    pub source: &'a MeshSource,
    /// The input's path as given.
    pub input: &'a Path,
    /// The locked output (written to its staged name, renamed at the end).
    pub output: &'a OutputGuard,
    /// The worker threads.
    pub pool: rayon::ThreadPool,
    /// The work folder with the intermediates and the markers.
    pub work: &'a WorkDir,
    /// How the memory budget is split.
    pub plan: MemoryPlan,
    /// Show progress on stderr.
    pub progress: bool,
    /// Time and peak memory of each stage, in the order they ran.
    pub times: Vec<StageTime>,
    /// Warnings for the summary.
    pub warnings: Vec<String>,
    /// Set by Ctrl-C; checked between batches.
    pub interrupt: &'static AtomicBool,
}

impl BuildContext<'_> {
    /// The error to stop with once an interrupt was requested.
    pub(crate) fn interrupted(&self) -> StageError {
        StageError::Interrupted {
            work: self.work.path().to_path_buf(),
        }
    }

    /// `Err(Interrupted)` once an interrupt was requested.
    pub(crate) fn check_interrupt(&self) -> Result<(), StageError> {
        if self.interrupt.load(Ordering::SeqCst) {
            return Err(self.interrupted());
        }
        Ok(())
    }

    /// Chunk `i` of `total` is in a stage's log (leaf or source log): shows it on `bar`, and
    /// requests an interrupt once `interrupt_after_chunks` chunks are logged (the resume
    /// tests' hook).
    pub(crate) fn chunk_logged(&self, bar: &crate::progress::Stage, i: usize, total: usize) {
        bar.set(i as u64 + 1, total as u64);
        let after = self.settings.interrupt_after_chunks;
        if after.is_some_and(|n| i as u64 + 1 >= n) {
            self.interrupt.store(true, Ordering::SeqCst);
        }
    }

    /// Records a stage's time, started at `t`; `resumed` if its artifact came from the work
    /// folder.
    pub(crate) fn stage_done(&mut self, stage: &'static str, t: Instant, resumed: bool) {
        self.times.push(StageTime {
            stage,
            seconds: t.elapsed().as_secs_f64(),
            peak_rss: crate::system::peak_rss(),
            resumed,
        });
    }
}

/// What the stages produced, for the summary.
pub(crate) struct Built {
    pub ingested: ingest::Ingested,
    pub voxelized: voxelize::Voxelized,
    pub written: lod_write::Written,
    /// The source-geometry stage's totals (`--source-geometry`).
    pub source: Option<source::SourceMarker>,
}

/// Runs the stages in order, each from the previous one's artifact; a stage whose marker is
/// in the work folder is skipped (the voxelize stage's marker skips the tile stage too).
pub(crate) fn run(ctx: &mut BuildContext) -> Result<Built, StageError> {
    let mut ingested = ingest::run(ctx)?;
    if let Some(scope) = &ctx.settings.shard {
        // the plan's fingerprint was checked; its grid and channels must come out the same
        let channels = lod_write::channels(ctx);
        if ingested.grid != scope.grid || channels != scope.channels {
            return Err(anyhow::anyhow!(
                "{}: the input gives the grid {:?} and channels {channels:?}, the plan {:?} and {:?}: plan again",
                ctx.input.display(),
                ingested.grid,
                scope.grid,
                scope.channels
            )
            .into());
        }
    }
    let voxelized = match voxelize::Voxelized::resume(ctx) {
        Some(v) => v,
        None => {
            let tiled = tile::run(ctx, &mut ingested)?;
            // source geometry (its own stage, from the same bins) before the voxelizers exist
            if ctx.settings.source_geometry {
                source::run(ctx, &tiled)?;
            }
            voxelize::run(ctx, tiled)?
        }
    };
    if voxelized.marker.skipped > 0 {
        ctx.warnings.push(format!(
            "{} triangle/chunk pairs skipped by the voxelizer (zero area after the move to grid coordinates)",
            voxelized.marker.skipped
        ));
    }
    // after a resume from the leaf log, the source stage's marker holds its totals
    let source = if ctx.settings.source_geometry {
        let m = ctx.work.marker::<source::SourceMarker>();
        Some(m.ok_or_else(|| {
            anyhow::anyhow!(
                "the work folder has a leaf log but no complete source log (source.json)"
            )
        })?)
    } else {
        None
    };
    let written = lod_write::run(ctx, &ingested, &voxelized)?;
    Ok(Built {
        ingested,
        voxelized,
        written,
        source,
    })
}

#[cfg(test)]
mod tests {
    use std::ops::ControlFlow;
    use std::path::PathBuf;
    use std::sync::atomic::AtomicBool;

    use super::*;
    use crate::backend::{ChunkSource, ChunkVoxels, CpuVoxelizers, Voxelize};
    use crate::output::OutputKind;
    use crate::work::{Marker, WorkFile};

    /// A small mesh in a temporary folder, opened as a build would open it.
    struct Fixture {
        dir: tempfile::TempDir,
        settings: BuildSettings,
        source: MeshSource,
        guard: OutputGuard,
        work: WorkDir,
        input: PathBuf,
    }

    /// An ASCII PLY of a tetrahedron and a triangle across the unit cube: at 512³ its
    /// triangles touch several of the 2×2×2 leaf chunks.
    fn fixture() -> Fixture {
        fixture_of(false)
    }

    /// The fixture's mesh, as ASCII PLY (spooled) or binary PLY (memory-mapped, binned during
    /// the ingest pass).
    fn fixture_of(binary: bool) -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("t.ply");
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ];
        let f = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3], [1, 2, 4]];
        let mut text = format!(
            "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            v.len(),
            f.len()
        );
        if binary {
            let mut bytes = text
                .replace("format ascii", "format binary_little_endian")
                .into_bytes();
            for p in v {
                p.iter()
                    .for_each(|&c: &f32| bytes.extend_from_slice(&c.to_le_bytes()));
            }
            for t in f {
                bytes.push(3);
                t.iter()
                    .for_each(|&i: &i32| bytes.extend_from_slice(&i.to_le_bytes()));
            }
            std::fs::write(&input, bytes).unwrap();
        } else {
            for p in v {
                text += &format!("{} {} {}\n", p[0], p[1], p[2]);
            }
            for t in f {
                text += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
            }
            std::fs::write(&input, text).unwrap();
        }
        let settings = BuildSettings {
            resolution: 512,
            backend: crate::Backend::Cpu,
            ..Default::default()
        };
        let output = dir.path().join("t.voxlod");
        let guard = OutputGuard::acquire(&output, &[&input], OutputKind::Octree, false).unwrap();
        let source = MeshSource::open(&input).unwrap();
        let key = WorkDir::key(&input, &settings).unwrap();
        let (work, _) = WorkDir::open(dir.path(), &output, &key).unwrap();
        Fixture {
            dir,
            settings,
            source,
            guard,
            work,
            input,
        }
    }

    impl Fixture {
        fn ctx(&self, interrupt: &'static AtomicBool) -> BuildContext<'_> {
            BuildContext {
                settings: &self.settings,
                source: &self.source,
                input: &self.input,
                output: &self.guard,
                pool: rayon::ThreadPoolBuilder::new()
                    .num_threads(2)
                    .build()
                    .unwrap(),
                work: &self.work,
                plan: MemoryPlan::new(2 << 30, 2).unwrap(),
                progress: false,
                times: Vec::new(),
                warnings: Vec::new(),
                interrupt,
            }
        }
    }

    fn flag() -> &'static AtomicBool {
        Box::leak(Box::new(AtomicBool::new(false)))
    }

    /// Each stage's artifact, saved as its marker, is what a resumed build takes back: the
    /// markers round-trip, the bins marker reopens the same bins, and a second run of each
    /// stage reports itself resumed instead of running again.
    /// `temp_written` (the summary's `temp_bytes_written`) is the size of the spool and bins
    /// files the build wrote, spooled or binned during the ingest pass; a resumed build wrote
    /// none.
    #[test]
    fn temp_bytes_written_are_the_sizes_of_the_files_written() {
        for binary in [false, true] {
            let fx = fixture_of(binary);
            let mut ctx = fx.ctx(flag());
            let mut ingested = ingest::run(&mut ctx).unwrap();
            assert_eq!(ingested.binned_during_ingest, binary);
            let len = |f: WorkFile| std::fs::metadata(ctx.work.file(f)).map_or(0, |m| m.len());
            let spool = len(WorkFile::Spool);
            assert_eq!(spool > 0, !binary);
            let early_bins = len(WorkFile::Bins);
            assert_eq!(
                ingested.temp_written,
                spool + early_bins,
                "binary: {binary}"
            );
            let tiled = tile::run(&mut ctx, &mut ingested).unwrap();
            let bins = len(WorkFile::Bins);
            assert!(bins > 0);
            assert_eq!(tiled.bins.bytes(), bins);
            assert_eq!(ingested.temp_written, spool + bins, "binary: {binary}");
            drop(tiled);
            let mut again = fx.ctx(flag());
            let mut resumed = ingest::run(&mut again).unwrap();
            let _ = tile::run(&mut again, &mut resumed).unwrap();
            assert_eq!(resumed.temp_written, 0);
        }
    }

    #[test]
    fn stage_artifacts_round_trip_as_resume_markers() {
        let fx = fixture();
        let mut ctx = fx.ctx(flag());
        let mut ingested = ingest::run(&mut ctx).unwrap();
        assert_eq!(ingested.marker.count, 5);
        assert_eq!(
            ctx.work.marker::<ingest::SpoolMarker>(),
            Some(ingested.marker.clone())
        );
        let tiled = tile::run(&mut ctx, &mut ingested).unwrap();
        let chunks = tiled.bins.chunks().to_vec();
        assert!(chunks.len() > 1, "{} chunks", chunks.len());
        let bins_marker = ctx.work.marker::<tile::BinsMarker>().unwrap();
        assert_eq!(bins_marker, tile::BinsMarker::of(&tiled.bins));
        let back = bins_marker.chunks().unwrap();
        assert_eq!(back.len(), chunks.len());
        for (a, b) in back.iter().zip(&chunks) {
            assert_eq!(
                (a.coord, a.morton, a.start, a.count),
                (b.coord, b.morton, b.start, b.count)
            );
        }
        drop(tiled);
        // a second build on the same folder takes both artifacts from the markers
        let mut again = fx.ctx(flag());
        let mut ingested2 = ingest::run(&mut again).unwrap();
        assert_eq!(ingested2.marker, ingested.marker);
        assert_eq!(ingested2.grid, ingested.grid);
        let tiled2 = tile::run(&mut again, &mut ingested2).unwrap();
        assert_eq!(
            tiled2.bins.total(),
            chunks.iter().map(|c| c.count).sum::<u64>()
        );
        let resumed: Vec<_> = again.times.iter().map(|t| (t.stage, t.resumed)).collect();
        assert_eq!(resumed, [("ingest", true), ("tile", true)]);
        // the voxelize stage's marker is its artifact, and skips tile and voxelize
        let v = voxelize::run(&mut again, tiled2).unwrap();
        assert_eq!(v.marker.records, chunks.len() as u64);
        assert_eq!(
            again.work.marker::<voxelize::LeavesMarker>(),
            Some(v.marker.clone())
        );
        let mut third = fx.ctx(flag());
        let r = voxelize::Voxelized::resume(&mut third).unwrap();
        assert_eq!(r.marker, v.marker);
        // a marker whose chunk coordinates no u32 holds is not taken
        let bad: tile::BinsMarker =
            serde_json::from_str(r#"{"chunks":[[4294967296,0,0,0,1]]}"#).unwrap();
        assert!(bad.chunks().is_none());
        assert_eq!(tile::BinsMarker::FILE.name(), "bins.json");
        drop(fx.dir);
    }

    /// A voxelizer that panics on one chunk.
    struct PanicsOn(usize);

    impl Voxelize for PanicsOn {
        fn voxelize(&self, chunk: &dyn ChunkSource) -> Result<ChunkVoxels, StageError> {
            assert!(chunk.index() != self.0, "test panic on chunk {}", self.0);
            let mut n = 0;
            chunk.replay(&mut |t| {
                n += t.len();
                ControlFlow::Continue(())
            })?;
            Ok(ChunkVoxels {
                voxels: Vec::new(),
                skipped: n as u64,
                materials: None,
            })
        }
    }

    /// A panic in a worker of the voxelize stage ends the stage with an error naming the
    /// chunk (a watchdog aborts the test if it hangs instead), the chunks before it are in the
    /// leaf log, and no marker is written; with the real voxelizer the stage then completes.
    #[test]
    fn worker_panic_in_voxelize_stage_is_an_error_naming_the_chunk() {
        let (done, watch) = std::sync::mpsc::channel::<()>();
        std::thread::spawn(move || {
            if watch
                .recv_timeout(std::time::Duration::from_secs(120))
                .is_err()
            {
                eprintln!("the voxelize stage hung after a worker panic");
                std::process::abort();
            }
        });
        let fx = fixture();
        let mut ctx = fx.ctx(flag());
        let mut ingested = ingest::run(&mut ctx).unwrap();
        let tiled = tile::run(&mut ctx, &mut ingested).unwrap();
        let n = tiled.bins.chunks().len();
        assert!(n > 2);
        let e = voxelize::run_with(&mut ctx, &tiled, Box::new(PanicsOn(1)))
            .expect_err("a panic must fail the stage");
        let coord = tiled.bins.chunks()[1].coord;
        match &e {
            StageError::Panicked {
                chunk,
                coord: c,
                message,
            } => {
                assert_eq!((*chunk, *c), (1, coord));
                assert!(message.contains("test panic on chunk 1"), "{message}");
            }
            other => panic!("expected Panicked, got {other:?}"),
        }
        assert!(e
            .to_string()
            .starts_with(&format!("voxelizing leaf chunk 1 {coord:?} panicked")));
        assert!(ctx.work.marker::<voxelize::LeavesMarker>().is_none());
        // the log holds chunk 0 only; the real voxelizer continues from there
        let cpu = Box::new(CpuVoxelizers::new(&fx.settings, 2, None, false));
        let (m, gpu) = voxelize::run_with(&mut ctx, &tiled, cpu).unwrap();
        assert_eq!((m.records, gpu), (n as u64, None));
        assert_eq!(
            ctx.times.last().map(|t| (t.stage, t.resumed)),
            Some(("voxelize", true))
        );
        done.send(()).unwrap();
    }

    /// An interrupt stops each stage with the typed error naming the work folder, also where
    /// it is noticed inside another crate's loop: ingest's batch stream, the tile passes
    /// (`Interruptible`), the leaf log reader of the LOD + write stage.
    #[test]
    fn interrupt_is_a_typed_error() {
        let fx = fixture();
        let stop = flag();
        let interrupted = |e: StageError| {
            assert!(
                matches!(&e, StageError::Interrupted { work } if work == fx.work.path()),
                "{e:?}"
            );
        };
        let mut ctx = fx.ctx(stop);
        stop.store(true, Ordering::SeqCst);
        interrupted(ingest::run(&mut ctx).err().expect("ingest interrupted"));
        stop.store(false, Ordering::SeqCst);
        let mut ingested = ingest::run(&mut ctx).unwrap();
        // the spooled fixture has no chunk counts yet: the count pass is interrupted
        assert!(ingested.marker.spooled && ingested.early_counts.is_none());
        stop.store(true, Ordering::SeqCst);
        interrupted(
            tile::run(&mut ctx, &mut ingested)
                .err()
                .expect("tile interrupted"),
        );
        stop.store(false, Ordering::SeqCst);
        let tiled = tile::run(&mut ctx, &mut ingested).unwrap();
        let voxelized = voxelize::run(&mut ctx, tiled).unwrap();
        stop.store(true, Ordering::SeqCst);
        let e = lod_write::run(&mut ctx, &ingested, &voxelized).err();
        interrupted(e.expect("lod + write interrupted"));
        stop.store(false, Ordering::SeqCst);
        lod_write::run(&mut ctx, &ingested, &voxelized).unwrap();
    }
}
