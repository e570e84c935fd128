//! The source-geometry stage (`--source-geometry`, docs/FORMAT.md 14.4): for every leaf
//! chunk, the triangles of its bin (the records the voxelizer reads) that touch the chunk, as
//! the source-triangle channel's payload (`source_mesh.rs`: quantized, indexed, compressed).
//! Chunks are built on the workers, at most a window ahead, and appended strictly in Morton
//! order to the source log (`source.bin`, the leaf log's record format: the record's count is
//! the triangles stored, its payload the chunk's kept and clipped counts as two u32 then the
//! channel payload, empty when no triangle touches the chunk), so the log's bytes do not depend on the thread count and a killed
//! build resumes at the next chunk. Runs between the tile and voxelize stages, while the
//! voxelizers do not exist yet, and uses their memory.
//!
//! Artifact and resume marker: [`SourceMarker`] (`source.json`), written once every chunk is
//! in the log.

use std::time::Instant;

use anyhow::Context;
use voxlod_format::{encode_source, EncodedChannel};
use voxlod_tile::Bins;

use super::tile::Tiled;
use super::voxelize::backend::READ_BATCH;
use super::voxelize::leaf_log::{LeafLog, LogReader, RecordHeader};
use super::voxelize::textures;
use crate::context::{BuildContext, Stage};
use crate::error::StageError;
use crate::files::markers::SourceMarker;
use crate::files::work::WorkFile;
use crate::memory::VOXELIZER_BYTES;
use crate::progress::Bar;
use crate::resume::Resume;
use crate::size::format_size;
use mesh::{SourceAttributes, SourceBuilder, SourceCounts};

pub(crate) mod clip;
pub(crate) mod mesh;

/// Bytes a chunk's source mesh may take while it is built, per triangle of its bin: up to
/// three vertex-index entries (hash map slots included) and vertices, the triangle, the
/// uncompressed block and the compressed payload, with the slack of growing vectors.
pub(crate) const BYTES_PER_TRIANGLE: u64 = 512;

/// Runs the stage (or takes its marker from an earlier run).
pub(crate) fn run(
    ctx: &mut BuildContext,
    resume: &Resume,
    tiled: &Tiled,
) -> Result<SourceMarker, StageError> {
    let t = Instant::now();
    if let Some(m) = resume.source.clone() {
        ctx.stage_done(Stage::Source, t, true);
        return Ok(m);
    }
    let bins = &tiled.bins;
    let info = ctx.source.info();
    let attrs = SourceAttributes {
        normals: bins.layout().normals,
        colors: bins.layout().colors,
        materials: textures::has_material_channel(info),
    };
    let workers = workers(ctx, bins)?;
    let path = ctx.work.file(WorkFile::Source);
    let mut log = LeafLog::open(&path)?;
    let resumed = log.records() > 0;
    let r = append_chunks(ctx, bins, &tiled.grid, attrs, workers, &mut log);
    log.finish()?;
    r?;
    let mut m = SourceMarker::default();
    super::voxelize::leaf_log::read_log(&path, &mut |h, payload| {
        m.records += 1;
        m.counts.stored += h.voxel_count as u64;
        let (kept, clipped, frame) = split_record(&payload)?;
        m.counts.kept += kept as u64;
        m.counts.clipped += clipped as u64;
        m.payload_bytes += frame.len() as u64;
        Ok(())
    })?;
    ctx.work.set_marker(&m)?;
    ctx.stage_done(Stage::Source, t, resumed);
    Ok(m)
}

/// Workers building chunks at once: at most the voxelizers the plan allows, fewer when the
/// largest chunk's mesh would not fit their memory beside the others; an error naming the
/// chunk when it does not fit alone.
fn workers(ctx: &BuildContext, bins: &Bins) -> Result<usize, StageError> {
    let share = (ctx.memory.voxelizers as u64 * VOXELIZER_BYTES).max(ctx.memory.scatter_buffer);
    let Some(big) = bins.chunks().iter().max_by_key(|c| c.count) else {
        return Ok(1);
    };
    let need = big.count * BYTES_PER_TRIANGLE;
    if need > share {
        return Err(StageError::Other(anyhow::anyhow!(
            "leaf chunk {:?} holds {} triangles: its source geometry needs about {}, more than the {} the memory plan leaves for it (raise --memory, or the resolution to spread the triangles over more chunks)",
            big.coord,
            big.count,
            format_size(need),
            format_size(share)
        )));
    }
    Ok(((share / need.max(1)) as usize).clamp(1, ctx.memory.voxelizers))
}

/// Builds the chunks after those in `log` on `workers` workers and appends them in order.
fn append_chunks(
    ctx: &BuildContext,
    bins: &Bins,
    grid: &voxlod_geom::Grid,
    attrs: SourceAttributes,
    workers: usize,
    log: &mut LeafLog,
) -> Result<(), StageError> {
    let chunks = bins.chunks();
    let input = crate::stages::tile::passes::InputTriangles(ctx.source);
    let start = log.records() as usize;
    let bar = Bar::items(ctx.progress, Stage::Source.name(), chunks.len() as u64);
    bar.set(start as u64, chunks.len() as u64);
    let zstd_level = ctx.settings.zstd_level;
    type Built = (Vec<u8>, SourceCounts);
    let build_one = |i: usize| -> Result<Built, StageError> {
        let mut b = SourceBuilder::new(chunks[i].coord, attrs);
        bins.read_chunk_from(i, READ_BATCH, Some(&input), &mut |tris| {
            // the bins hold world coordinates; the source geometry is in grid units
            tris.iter()
                .for_each(|t| b.add(&voxlod_tile::to_grid(grid, t)));
            Ok(())
        })?;
        let counts = b.counts;
        let mut record = [counts.kept as u32, counts.clipped as u32]
            .map(u32::to_le_bytes)
            .concat();
        if let Some(mesh) = b.finish() {
            let what = || {
                format!(
                    "encoding the source triangles of leaf chunk {:?}",
                    chunks[i].coord
                )
            };
            record.extend(encode_source(&mesh, zstd_level).with_context(what)?.payload);
        }
        Ok((record, counts))
    };
    super::voxelize::window::ordered(
        ctx.pool,
        workers,
        workers * 4,
        start..chunks.len(),
        &build_one,
        &mut |i, r| {
            ctx.check_interrupt()?;
            let (payload, c) = r?;
            log.append_record(i as u64, chunks[i].coord, c.stored as u32, &payload, 0)?;
            log.flush()?;
            ctx.chunk_logged(&bar, i, chunks.len());
            Ok(())
        },
        &|i, message| {
            StageError::Other(anyhow::anyhow!(
                "building the source geometry of leaf chunk {i} {:?} panicked: {message}",
                chunks[i].coord
            ))
        },
    )?;
    bar.finish();
    Ok(())
}

/// A source log record's payload: the chunk's kept and clipped triangle counts and its
/// channel payload (empty when no triangle touches the chunk).
pub(crate) fn split_record(payload: &[u8]) -> anyhow::Result<(u32, u32, &[u8])> {
    anyhow::ensure!(
        payload.len() >= 8,
        "a source log record of {} bytes has no counts",
        payload.len()
    );
    let word = |at: usize| u32::from_le_bytes(payload[at..at + 4].try_into().expect("4 bytes"));
    Ok((word(0), word(4), &payload[8..]))
}

/// The source-triangle payload of the leaf whose leaf log record is `leaf`, read from the
/// source log beside it (one record per chunk in both). `None` when no triangle touches the
/// chunk or the chunk has no voxels (it is not stored).
pub(crate) fn leaf_channel(
    log: &mut LogReader,
    leaf: &RecordHeader,
) -> anyhow::Result<Option<EncodedChannel>> {
    let Some((h, payload)) = log.next_record()? else {
        anyhow::bail!("the source log ends before leaf chunk {}", leaf.chunk);
    };
    anyhow::ensure!(
        h.chunk == leaf.chunk && h.coord == leaf.coord,
        "source log record {} is for chunk {:?}, the leaf log's for {:?}",
        h.chunk,
        h.coord,
        leaf.coord
    );
    let (_, _, frame) = split_record(&payload)?;
    if leaf.voxel_count == 0 || frame.is_empty() {
        return Ok(None);
    }
    Ok(Some(EncodedChannel {
        payload_crc32: crc32fast::hash(frame),
        payload: frame.to_vec(),
        count: h.voxel_count,
        voxel_count: 0,
    }))
}
