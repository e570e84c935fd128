//! The tile stage: counts the triangles per leaf chunk (unless the ingest stage did), then
//! scatters them into on-disk bins (`bins.tri`): per chunk, pieces of blocks (`voxlod_tile`).
//! Reads the spool, or the memory-mapped input again.
//!
//! Artifact: the open [`Bins`]; resume marker: their layout, [`BinsMarker`] (`bins.json`).

use std::time::Instant;

use voxlod_tile::{Bins, ChunkCounts, Passes, RecordLayout, Spool};

use super::ingest::Ingested;
use crate::context::{BuildContext, Stage};
use crate::error::StageError;
use crate::files::markers::BinsMarker;
use crate::files::work::WorkFile;
use crate::progress::Bar;
use crate::resume::Resume;
use crate::size::format_size;
use passes::{InputPasses, Interruptible};

pub(crate) mod passes;

/// The tile stage's artifact.
pub(crate) struct Tiled {
    /// The bins, open for reading (triangles in world coordinates).
    pub bins: Bins,
    /// The grid the bins are cut on.
    pub grid: voxlod_geom::Grid,
}

/// Runs the tile stage, or opens the bins its marker describes. Takes the chunk counts the
/// ingest stage left, if any. Removes the spool once the bins are complete. Bins written here
/// add their bytes to `ingested.temp_written`.
pub(crate) fn run(
    ctx: &mut BuildContext,
    resume: &Resume,
    ingested: &mut Ingested,
) -> Result<Tiled, StageError> {
    let t = Instant::now();
    let bins_path = ctx.work.file(WorkFile::Bins);
    let resumed = resume.bins.clone().and_then(|m| {
        let indexable = ctx.source.fixed_face_count().is_some();
        m.open(&bins_path, ingested.layout, indexable)
    });
    let bins = match resumed {
        Some(b) => {
            ctx.stage_done(Stage::Tile, t, true);
            b
        }
        None => {
            // written by the ingest pass, or by this stage's passes
            let bins = match ingested.early_bins.take() {
                Some(b) => b,
                None => {
                    let counts = ingested.early_counts.take();
                    let bins = tile(ctx, ingested, counts)?;
                    ingested.temp_written += bins.bytes();
                    bins
                }
            };
            // the marker describes the work folder's bins file; bins read in place (a shard's
            // map outputs) are found again from their own markers
            if bins.owned() {
                ctx.work.set_marker(&BinsMarker::of(&bins))?;
            }
            ctx.stage_done(Stage::Tile, t, false);
            bins
        }
    };
    let spool = ctx.work.file(WorkFile::Spool);
    if spool.exists() {
        std::fs::remove_file(&spool).map_err(StageError::io("removing", &spool))?;
    }
    Ok(Tiled {
        bins,
        grid: ingested.grid,
    })
}

/// The passes over the ingested triangles (the spool, or the memory-mapped input again),
/// given to `f`.
fn with_passes<R>(ctx: &BuildContext, ing: &Ingested, f: impl FnOnce(&dyn Passes) -> R) -> R {
    let count = ing.marker.count;
    let spool;
    let input;
    let src: &dyn Passes = if ing.marker.spooled {
        spool = Spool {
            path: ctx.work.file(WorkFile::Spool),
            count,
            bounds: ing.bounds(),
            layout: ing.layout,
        };
        &spool
    } else {
        input = InputPasses {
            source: ctx.source,
            count,
        };
        &input
    };
    f(&Interruptible { inner: src, ctx })
}

/// The count pass: triangles per leaf chunk (what `voxlod plan` cuts into shards).
pub(crate) fn count_pass(
    ctx: &BuildContext,
    ing: &Ingested,
    src: &dyn Passes,
) -> Result<ChunkCounts, StageError> {
    let bar = Bar::items(ctx.progress, "count", ing.marker.count);
    let c = ctx
        .pool
        .install(|| voxlod_tile::count(src, &ing.grid, &mut |d, n| bar.set(d, n)))
        .map_err(StageError::from)?;
    bar.finish();
    Ok(c)
}

/// The chunk counts of the ingested triangles: taken during ingest, else by a count pass.
pub(crate) fn counts(ctx: &BuildContext, ing: &mut Ingested) -> Result<ChunkCounts, StageError> {
    match ing.early_counts.take() {
        Some(c) => Ok(c),
        None => with_passes(ctx, ing, |src| count_pass(ctx, ing, src)),
    }
}

/// The count pass (unless `counts` are given) and the scatter pass. A sharded build keeps
/// the chunks of its own subtrees only, and checks the input's content during the pass.
fn tile(
    ctx: &BuildContext,
    ing: &Ingested,
    counts: Option<ChunkCounts>,
) -> Result<Bins, StageError> {
    with_passes(ctx, ing, |src| {
        let mut counts = match counts {
            Some(c) => c,
            None => count_pass(ctx, ing, src)?,
        };
        if ctx.scope.drops_chunks() {
            counts.retain(|c| ctx.scope.keeps(c));
        }
        ctx.check_interrupt()?;
        check_bins_space(ctx, &counts, ing.layout)?;
        let bar = Bar::items(ctx.progress, "scatter", ing.marker.count);
        let scatter = || {
            ctx.pool
                .install(|| {
                    voxlod_tile::scatter(
                        src,
                        &ing.grid,
                        &counts,
                        &ctx.work.file(WorkFile::Bins),
                        ing.layout,
                        ctx.memory.scatter_buffer,
                        &mut |d, n| bar.set(d, n),
                    )
                })
                .map_err(StageError::from)
        };
        // a shard's only pass over the input: its content must be the plan's
        let bins = match ctx.scope.shard() {
            Some(scope) => crate::shard::content_hash::checked(ctx, scope, scatter)?,
            None => scatter()?,
        };
        bar.finish();
        Ok(bins)
    })
}

/// Refuses the scatter pass if the bins, whose largest size the counts give (blocks are never
/// larger than their records), cannot fit.
fn check_bins_space(
    ctx: &BuildContext,
    counts: &ChunkCounts,
    layout: RecordLayout,
) -> Result<(), StageError> {
    let rec = layout.bytes() as u64;
    let bins_bytes = voxlod_tile::scatter_bound(counts, layout, ctx.memory.scatter_buffer);
    let work = ctx.work.path();
    if let Some(free) = crate::system::free_disk(work) {
        if bins_bytes > free {
            return Err(StageError::TempDisk(format!(
                "not enough disk space for the chunk bins: up to {} needed in {} ({} records of {} bytes), {} free (choose another folder with --tmp)",
                format_size(bins_bytes),
                work.display(),
                counts.total(),
                rec,
                format_size(free)
            )));
        }
    }
    if ctx.progress {
        eprintln!(
            "chunk bins: at most {} ({} triangle records)",
            format_size(bins_bytes),
            counts.total()
        );
    }
    Ok(())
}
