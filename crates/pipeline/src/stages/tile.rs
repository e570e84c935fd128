//! The tile stage: counts the triangles per leaf chunk (unless the ingest stage did), then
//! scatters them into on-disk bins (`bins.tri`): per chunk, pieces of blocks (`voxlod_tile`).
//! Reads the spool, or the memory-mapped input again.
//!
//! Artifact: the open [`Bins`]; resume marker: their layout, [`BinsMarker`] (`bins.json`).

use std::time::Instant;

use serde::{Deserialize, Serialize};
use voxlod_tile::{Bins, ChunkBin, ChunkCounts, Passes, RecordLayout, Spool};

use super::ingest::Ingested;
use super::BuildContext;
use crate::error::StageError;
use crate::passes::{InputPasses, Interruptible};
use crate::progress::Stage;
use crate::size::format_size;
use crate::work::{Marker, WorkFile};

/// The bins layout (`bins.json`): `[x, y, z, start, count]` per non-empty chunk (`start`: the
/// byte offset of its first piece) and each chunk's pieces `[byte offset, bytes, triangles]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct BinsMarker {
    chunks: Vec<[u64; 5]>,
    #[serde(default)]
    pieces: Vec<Vec<[u64; 3]>>,
}

impl Marker for BinsMarker {
    const FILE: WorkFile = WorkFile::BinsMarker;
}

impl BinsMarker {
    /// The layout of `bins`.
    pub(crate) fn of(bins: &Bins) -> BinsMarker {
        let chunks = bins
            .chunks()
            .iter()
            .map(|c| {
                let [x, y, z] = c.coord.map(u64::from);
                [x, y, z, c.start, c.count]
            })
            .collect();
        BinsMarker {
            chunks,
            pieces: bins.pieces().to_vec(),
        }
    }

    /// The bins this marker describes, opened (None if the file does not match it).
    pub(crate) fn open(self, path: &std::path::Path, layout: RecordLayout) -> Option<Bins> {
        let chunks = self.chunks()?;
        Bins::open_pieces(path, chunks, layout, self.pieces).ok()
    }

    /// The chunks of the layout (None if a coordinate is out of range: the marker is not ours).
    pub(crate) fn chunks(&self) -> Option<Vec<ChunkBin>> {
        self.chunks
            .iter()
            .map(|c| {
                let coord = [
                    u32::try_from(c[0]).ok()?,
                    u32::try_from(c[1]).ok()?,
                    u32::try_from(c[2]).ok()?,
                ];
                Some(ChunkBin {
                    coord,
                    morton: voxlod_geom::morton3(coord[0], coord[1], coord[2]),
                    start: c[3],
                    count: c[4],
                })
            })
            .collect()
    }
}

/// The tile stage's artifact.
pub(crate) struct Tiled {
    /// The bins, open for reading.
    pub bins: Bins,
}

/// Runs the tile stage, or opens the bins its marker describes. Takes the chunk counts the
/// ingest stage left, if any. Removes the spool once the bins are complete. Bins written here
/// add their bytes to `ingested.temp_written`.
pub(crate) fn run(ctx: &mut BuildContext, ingested: &mut Ingested) -> Result<Tiled, StageError> {
    let t = Instant::now();
    let bins_path = ctx.work.file(WorkFile::Bins);
    let resumed = ctx
        .work
        .marker::<BinsMarker>()
        .and_then(|m| m.open(&bins_path, ingested.layout));
    let bins = match resumed {
        Some(b) => {
            ctx.stage_done("tile", t, true);
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
            ctx.work.set_marker(&BinsMarker::of(&bins))?;
            ctx.stage_done("tile", t, false);
            bins
        }
    };
    let spool = ctx.work.file(WorkFile::Spool);
    if spool.exists() {
        std::fs::remove_file(&spool).map_err(StageError::io("removing", &spool))?;
    }
    Ok(Tiled { bins })
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
    let bar = Stage::items(ctx.progress, "count", ing.marker.count);
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
        if let Some(scope) = &ctx.settings.shard {
            counts.retain(|c| scope.contains_chunk(c));
        }
        ctx.check_interrupt()?;
        check_bins_space(ctx, &counts, ing.layout)?;
        let bar = Stage::items(ctx.progress, "scatter", ing.marker.count);
        let scatter = || {
            ctx.pool
                .install(|| {
                    voxlod_tile::scatter(
                        src,
                        &ing.grid,
                        &counts,
                        &ctx.work.file(WorkFile::Bins),
                        ing.layout,
                        ctx.plan.scatter_buffer,
                        &mut |d, n| bar.set(d, n),
                    )
                })
                .map_err(StageError::from)
        };
        // a shard's only pass over the input: its content must be the plan's
        let bins = match &ctx.settings.shard {
            Some(scope) => crate::content_hash::checked(ctx, scope, scatter)?,
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
    let bins_bytes = voxlod_tile::scatter_bound(counts, layout, ctx.plan.scatter_buffer);
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
