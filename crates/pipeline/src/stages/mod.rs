//! The build as a sequence of stages: ingest → tile → (source) → voxelize → LOD + write.
//!
//! Each stage is a file or folder (with its helpers) and one entry, `run(&mut BuildContext,
//! ...) → artifact`. A stage's result is saved as its marker in the work folder
//! (`files/markers.rs`) once its data is complete; [`Resume`] reads the markers once and a
//! stage takes its result from there instead of running again ([`run`] skips tile and voxelize
//! when every chunk is voxelized).

pub(crate) mod ingest;
pub(crate) mod lod_write;
pub(crate) mod source;
pub(crate) mod tile;
pub(crate) mod voxelize;

use crate::context::BuildContext;
use crate::error::StageError;
use crate::files::markers::SourceMarker;
use crate::resume::Resume;

/// What the stages produced, for the summary.
pub(crate) struct Built {
    pub ingested: ingest::Ingested,
    pub voxelized: voxelize::Voxelized,
    pub written: lod_write::Written,
    /// The source-geometry stage's totals (`--source-geometry`).
    pub source: Option<SourceMarker>,
}

/// A grid as a message shows it: origin, voxel size and resolution in plain numbers.
fn grid_words(g: &voxlod_geom::Grid) -> String {
    let [x, y, z] = g.origin;
    format!(
        "origin ({x}, {y}, {z}), voxel size {}, resolution {}",
        g.voxel_size, g.resolution
    )
}

/// Runs the stages in order, each from the previous one's artifact; a stage whose marker is
/// in the work folder is skipped (the voxelize stage's marker skips the tile stage too).
pub(crate) fn run(ctx: &mut BuildContext) -> Result<Built, StageError> {
    let resume = Resume::read(ctx.work);
    let mut ingested = ingest::run(ctx, &resume)?;
    if let Some(scope) = ctx.scope.shard() {
        // the plan's fingerprint was checked; its grid and channels must come out the same
        let channels = lod_write::channels(ctx);
        // the input is unchanged since planning (its fingerprint matched), so a difference
        // means the plan file was edited or damaged: the message names the plan, in words
        let what = if ingested.grid != scope.grid {
            format!(
                "its grid is {}, but {} gives {}",
                grid_words(&scope.grid),
                ctx.input.display(),
                grid_words(&ingested.grid)
            )
        } else if channels != scope.channels {
            format!(
                "its channels are {:?}, but the build settings give {channels:?}",
                scope.channels
            )
        } else {
            String::new()
        };
        if !what.is_empty() {
            return Err(anyhow::anyhow!(
                "{}: {what}, though the input has not changed since it was planned: the plan file was edited or damaged; plan again",
                scope.plan_path.display(),
            )
            .into());
        }
    }
    let (voxelized, source) = match voxelize::Voxelized::resume(ctx, &resume) {
        // the source stage ran before the voxelize stage: its marker holds its totals
        Some(v) => {
            let source = match (ctx.settings.source_geometry, resume.source) {
                (false, _) => None,
                (true, Some(m)) => Some(m),
                (true, None) => {
                    return Err(anyhow::anyhow!(
                        "the work folder has a leaf log but no complete source log (source.json)"
                    )
                    .into())
                }
            };
            (v, source)
        }
        None => {
            let tiled = tile::run(ctx, &resume, &mut ingested)?;
            // source geometry (its own stage, from the same bins) before the voxelizers exist
            let source = if ctx.settings.source_geometry {
                Some(source::run(ctx, &resume, &tiled)?)
            } else {
                None
            };
            (voxelize::run(ctx, tiled)?, source)
        }
    };
    if voxelized.marker.skipped > 0 {
        ctx.warnings.push(format!(
            "{} triangle/chunk pairs skipped by the voxelizer (zero area after the move to grid coordinates)",
            voxelized.marker.skipped
        ));
    }
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
    use crate::context::Scope;
    use crate::files::markers::{BinsMarker, IngestMarker, LeavesMarker};
    use crate::files::output::{OutputGuard, OutputKind};
    use crate::files::work::{Marker, WorkDir, WorkFile};
    use crate::memory::MemoryPlan;
    use crate::settings::BuildSettings;
    use crate::stages::voxelize::backend::{ChunkSource, ChunkVoxels, CpuVoxelizers, Voxelize};
    use std::sync::atomic::Ordering;
    use voxlod_ingest::MeshSource;

    /// A small mesh in a temporary folder, opened as a build would open it.
    struct Fixture {
        dir: tempfile::TempDir,
        settings: BuildSettings,
        source: MeshSource,
        guard: OutputGuard,
        work: WorkDir,
        input: PathBuf,
        pool: rayon::ThreadPool,
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
            backend: crate::settings::Backend::Cpu,
            ..Default::default()
        };
        let output = dir.path().join("t.voxlod");
        let guard = OutputGuard::acquire(&output, &[&input], OutputKind::Octree, false).unwrap();
        let source = MeshSource::open(&input).unwrap();
        let key = WorkDir::key(&input, &settings, None).unwrap();
        let (work, _) = WorkDir::open(dir.path(), &output, &key).unwrap();
        Fixture {
            dir,
            settings,
            source,
            guard,
            work,
            input,
            pool: rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .unwrap(),
        }
    }

    impl Fixture {
        fn resume(&self) -> Resume {
            Resume::read(&self.work)
        }

        fn ctx(&self, interrupt: &'static AtomicBool) -> BuildContext<'_> {
            BuildContext {
                settings: &self.settings,
                scope: &Scope::Whole,
                source: &self.source,
                input: &self.input,
                output: &self.guard,
                pool: &self.pool,
                work: &self.work,
                memory: MemoryPlan::new(2 << 30, 2).unwrap(),
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
            let mut ingested = ingest::run(&mut ctx, &fx.resume()).unwrap();
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
            let tiled = tile::run(&mut ctx, &fx.resume(), &mut ingested).unwrap();
            let bins = len(WorkFile::Bins);
            assert!(bins > 0);
            assert_eq!(tiled.bins.bytes(), bins);
            assert_eq!(ingested.temp_written, spool + bins, "binary: {binary}");
            drop(tiled);
            let mut again = fx.ctx(flag());
            let mut resumed = ingest::run(&mut again, &fx.resume()).unwrap();
            let _ = tile::run(&mut again, &fx.resume(), &mut resumed).unwrap();
            assert_eq!(resumed.temp_written, 0);
        }
    }

    #[test]
    fn stage_artifacts_round_trip_as_resume_markers() {
        let fx = fixture();
        let mut ctx = fx.ctx(flag());
        let mut ingested = ingest::run(&mut ctx, &fx.resume()).unwrap();
        assert_eq!(ingested.marker.count, 5);
        assert_eq!(
            ctx.work.marker::<IngestMarker>(),
            Some(ingested.marker.clone())
        );
        let tiled = tile::run(&mut ctx, &fx.resume(), &mut ingested).unwrap();
        let chunks = tiled.bins.chunks().to_vec();
        assert!(chunks.len() > 1, "{} chunks", chunks.len());
        let bins_marker = ctx.work.marker::<BinsMarker>().unwrap();
        assert_eq!(bins_marker, BinsMarker::of(&tiled.bins));
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
        let mut ingested2 = ingest::run(&mut again, &fx.resume()).unwrap();
        assert_eq!(ingested2.marker, ingested.marker);
        assert_eq!(ingested2.grid, ingested.grid);
        let tiled2 = tile::run(&mut again, &fx.resume(), &mut ingested2).unwrap();
        assert_eq!(
            tiled2.bins.total(),
            chunks.iter().map(|c| c.count).sum::<u64>()
        );
        let resumed: Vec<_> = again.times.iter().map(|t| (t.stage, t.resumed)).collect();
        assert_eq!(resumed, [("ingest", true), ("tile", true)]);
        // the voxelize stage's marker is its artifact, and skips tile and voxelize
        let v = voxelize::run(&mut again, tiled2).unwrap();
        assert_eq!(v.marker.records, chunks.len() as u64);
        assert_eq!(again.work.marker::<LeavesMarker>(), Some(v.marker.clone()));
        let mut third = fx.ctx(flag());
        let r = voxelize::Voxelized::resume(&mut third, &fx.resume()).unwrap();
        assert_eq!(r.marker, v.marker);
        // a marker whose chunk coordinates no u32 holds is not taken
        let bad: BinsMarker = serde_json::from_str(r#"{"chunks":[[4294967296,0,0,0,1]]}"#).unwrap();
        assert!(bad.chunks().is_none());
        assert_eq!(BinsMarker::FILE.name(), "bins.json");
        drop(fx.dir);
    }

    /// A voxelizer that panics on one chunk.
    struct PanicsOn(usize);

    impl Voxelize for PanicsOn {
        fn voxelize(&self, chunk: &dyn ChunkSource) -> Result<ChunkVoxels, StageError> {
            assert!(chunk.index() != self.0, "test panic on chunk {}", self.0);
            let mut n = 0;
            chunk.replay_world(&mut |t| {
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
        let mut ingested = ingest::run(&mut ctx, &fx.resume()).unwrap();
        let tiled = tile::run(&mut ctx, &fx.resume(), &mut ingested).unwrap();
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
        assert!(ctx.work.marker::<LeavesMarker>().is_none());
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
        interrupted(
            ingest::run(&mut ctx, &fx.resume())
                .err()
                .expect("ingest interrupted"),
        );
        stop.store(false, Ordering::SeqCst);
        let mut ingested = ingest::run(&mut ctx, &fx.resume()).unwrap();
        // the spooled fixture has no chunk counts yet: the count pass is interrupted
        assert!(ingested.marker.spooled && ingested.early_counts.is_none());
        stop.store(true, Ordering::SeqCst);
        interrupted(
            tile::run(&mut ctx, &fx.resume(), &mut ingested)
                .err()
                .expect("tile interrupted"),
        );
        stop.store(false, Ordering::SeqCst);
        let tiled = tile::run(&mut ctx, &fx.resume(), &mut ingested).unwrap();
        let voxelized = voxelize::run(&mut ctx, tiled).unwrap();
        stop.store(true, Ordering::SeqCst);
        let e = lod_write::run(&mut ctx, &ingested, &voxelized).err();
        interrupted(e.expect("lod + write interrupted"));
        stop.store(false, Ordering::SeqCst);
        lod_write::run(&mut ctx, &ingested, &voxelized).unwrap();
    }
}
