//! The LOD + write stage: the leaves from the leaf log in Morton order (read on a second
//! thread, one leaf ahead; their payloads copied, not decoded), their parents by
//! sort-and-compact (`octree_writer.rs`, `voxlod_lod`; level 1 from the leaves' halves),
//! written in post-order as soon as their last child is done; then the manifest, and the
//! output renamed into place.
//!
//! Artifact: [`Written`] (the file's size and levels); no marker: the output file is the
//! result.

use std::time::Instant;

use anyhow::Context;
use voxlod_format::channel::decode_materials;
use voxlod_format::{
    EncodedChannel, EncodedNode, Voxel, Writer, CHANNEL_MATERIAL, CHANNEL_TRIANGLES,
};

use super::ingest::Ingested;
use super::voxelize::Voxelized;
use crate::context::{BuildContext, Stage};
use crate::error::StageError;
use crate::files::work::WorkFile;
use crate::progress::Bar;
use crate::shard::shard_file::{ShardHeader, ShardWriter};
use crate::size::format_size;
use crate::stages::voxelize::leaf_log;
use octree_writer::{file_spec, LevelStats, NodeSink, OctreeWriter};

pub(crate) mod octree_writer;

/// The LOD + write stage's artifact.
pub(crate) struct Written {
    /// Size of the octree file, bytes.
    pub bytes: u64,
    /// Nodes and voxels per level, finest first.
    pub levels: Vec<LevelStats>,
    /// Source triangles written (`--source-geometry`: those of the leaves with voxels) and
    /// their compressed payload bytes.
    pub source: SourceWritten,
}

/// What the file stores of the source log: chunks without voxels are not written, so these
/// are at most the source stage's totals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct SourceWritten {
    pub triangles: u64,
    pub payload_bytes: u64,
}

/// Writes the octree file from the leaf log and renames it into place.
pub(crate) fn run(
    ctx: &mut BuildContext,
    ingested: &Ingested,
    voxelized: &Voxelized,
) -> Result<Written, StageError> {
    let t = Instant::now();
    let s = ctx.settings;
    let grid = &ingested.grid;
    check_output_space(ctx, voxelized.marker.leaf_payload_bytes)?;
    let spec = file_spec(grid, grid.levels(), s.mode);
    // the material channel: its records follow each leaf's payload in the leaf log
    let materials = crate::stages::voxelize::textures::has_material_channel(ctx.source.info());
    let channels = channels(ctx);
    if let Some(scope) = ctx.scope.shard() {
        return write_shard(ctx, voxelized, scope, channels, t);
    }
    let writer = Writer::create_staged(ctx.output.staged(), spec, &channels)?;
    let mut octree = OctreeWriter::new(writer, grid.levels(), s.zstd_level, ctx.pool);
    let source = write_leaves(ctx, &mut octree, voxelized.marker.records, materials)?;
    let m = &ingested.marker;
    let manifest = manifest_fields(ctx, &ingested.grid, m.triangles, m.degenerate_skipped);
    let (bytes, levels) = octree.finish(|levels| {
        let mut m = manifest;
        m["levels"] = serde_json::json!(levels);
        m
    })?;
    committed(
        ctx,
        t,
        Written {
            bytes,
            levels,
            source,
        },
    )
}

/// The octree's optional channels: the material channel (its records follow each leaf's
/// payload in the leaf log) if the input has materials, the source triangles
/// (`--source-geometry`: the source log's records, beside the leaves).
pub(crate) fn channels(ctx: &BuildContext) -> Vec<u32> {
    let mut channels = Vec::new();
    if crate::stages::voxelize::textures::has_material_channel(ctx.source.info()) {
        channels.push(CHANNEL_MATERIAL);
    }
    if ctx.settings.source_geometry {
        channels.push(CHANNEL_TRIANGLES);
    }
    channels
}

/// A sharded build's LOD + write: its subtrees up to the split level, into the shard file.
fn write_shard(
    ctx: &mut BuildContext,
    voxelized: &Voxelized,
    scope: &crate::shard::plan_file::ShardScope,
    channels: Vec<u32>,
    t: Instant,
) -> Result<Written, StageError> {
    let header = ShardHeader {
        index: scope.index,
        count: scope.count,
        split_level: scope.split_level,
        levels: scope.levels,
        plan_sha256: scope.plan_sha256,
        channels,
    };
    let materials = header.channels.contains(&CHANNEL_MATERIAL);
    let sink = ShardWriter::create(ctx.output.staged(), header)?;
    let mut octree = OctreeWriter::new(sink, scope.levels, ctx.settings.zstd_level, ctx.pool)
        .with_top(scope.split_level);
    let source = write_leaves(ctx, &mut octree, voxelized.marker.records, materials)?;
    let (sink, levels) = octree.finish_sink()?;
    let bytes = sink.finish()?;
    committed(
        ctx,
        t,
        Written {
            bytes,
            levels,
            source,
        },
    )
}

/// Renames the written file (octree or shard) into place and ends the stage.
fn committed(ctx: &mut BuildContext, t: Instant, written: Written) -> Result<Written, StageError> {
    ctx.output
        .commit()
        .map_err(|e| StageError::Output(crate::chain_text::chain_text(&e)))?;
    ctx.stage_done(Stage::LodWrite, t, false);
    Ok(written)
}

/// The file holds every leaf payload: refuses before writing if the output's folder cannot
/// hold even those (the work folder is kept, see `build`), warns if it may not hold the rest.
fn check_output_space(ctx: &mut BuildContext, leaf_payloads: u64) -> Result<(), StageError> {
    let output = ctx.output.output();
    let out_dir = crate::files::output::output_dir(output);
    let Some(free) = crate::system::free_disk(out_dir) else {
        return Ok(());
    };
    if free < leaf_payloads {
        return Err(StageError::Output(format!(
            "not enough disk space for {}: it holds at least {} of leaf chunks, {} free in {}",
            output.display(),
            format_size(leaf_payloads),
            format_size(free),
            out_dir.display()
        )));
    }
    if free < leaf_payloads / 3 * 4 {
        ctx.warnings.push(format!(
            "{} free in {} may not hold {} (at least {} of leaf chunks, about a third more with the coarser levels)",
            format_size(free),
            out_dir.display(),
            output.display(),
            format_size(leaf_payloads)
        ));
    }
    Ok(())
}

/// A leaf from the log, as the octree writer takes it.
struct Leaf {
    /// Chunk coordinates.
    coord: [u32; 3],
    /// Its voxels merged alone to its parent's resolution.
    half: Vec<Voxel>,
    /// The half's materials (with the material channel).
    half_materials: Option<Vec<u32>>,
    /// Its encoded payload; None when it has no voxel.
    node: Option<EncodedNode>,
    /// Its encoded material payload (with the material channel).
    materials: Option<EncodedChannel>,
    /// Its source-triangle payload (with source geometry; None when no triangle touches it).
    source: Option<EncodedChannel>,
}

/// Feeds the leaf log to `octree`. The log is read and split on a second thread, one leaf
/// ahead of the merges and parent encodes of this one (two leaves in flight at most). The
/// leaves' payloads are not decoded: they go into the file as the voxelize stage encoded
/// them, and their parents are made from their halves. Returns the source triangles written.
fn write_leaves<W: NodeSink>(
    ctx: &BuildContext,
    octree: &mut OctreeWriter<W>,
    records: u64,
    materials: bool,
) -> Result<SourceWritten, StageError> {
    let leaves = ctx.work.file(WorkFile::Leaves);
    let mut sources = ctx
        .settings
        .source_geometry
        .then(|| leaf_log::LogReader::open(&ctx.work.file(WorkFile::Source)))
        .transpose()?;
    let bar = Bar::items(ctx.progress, Stage::LodWrite.name(), records);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Leaf, StageError>>(1);
    let mut written = SourceWritten::default();
    std::thread::scope(|scope| -> Result<(), StageError> {
        scope.spawn(|| {
            let r = leaf_log::read_log(&leaves, &mut |h, payload| {
                ctx.check_interrupt()?;
                let mut leaf = split_leaf(h, payload, materials)?;
                if let Some(log) = &mut sources {
                    leaf.source = crate::stages::source::leaf_channel(log, h)?;
                }
                // a closed channel means the writer failed: stop reading
                tx.send(Ok(leaf))
                    .map_err(|_| anyhow::anyhow!("the octree writer stopped"))
            });
            if let Err(e) = r {
                // an interrupt comes back as itself
                let e = e.downcast::<StageError>().unwrap_or_else(StageError::Other);
                let _ = tx.send(Err(e));
            }
            drop(tx);
        });
        // owned here, so that an early return closes the channel and stops the reader
        let rx = rx;
        let mut n = 0u64;
        for leaf in rx.iter() {
            let Leaf {
                coord,
                half,
                half_materials,
                node,
                materials,
                source,
            } = leaf?;
            if let Some(s) = &source {
                written.triangles += s.count as u64;
                written.payload_bytes += s.payload.len() as u64;
            }
            octree.push_halved(coord, half, half_materials, node, materials, source)?;
            n += 1;
            bar.set(n, records);
        }
        Ok(())
    })?;
    bar.finish();
    Ok(written)
}

/// A leaf log record split into its parts. With `materials`, the material frame is checked
/// (decoded) and kept encoded.
fn split_leaf(
    h: &leaf_log::RecordHeader,
    payload: Vec<u8>,
    materials: bool,
) -> anyhow::Result<Leaf> {
    if h.voxel_count == 0 {
        return Ok(Leaf {
            coord: h.coord,
            half: Vec::new(),
            half_materials: None,
            node: None,
            materials: None,
            source: None,
        });
    }
    let leaf = leaf_log::StoredLeaf::split(h, payload, materials)?;
    let menc = if materials {
        let (_, m) = decode_materials(leaf.materials, h.voxel_count)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("leaf log record {}", h.chunk))?;
        Some(m)
    } else {
        None
    };
    Ok(Leaf {
        coord: h.coord,
        half: leaf.half,
        half_materials: leaf.half_materials,
        node: Some(leaf.node),
        materials: menc,
        source: None,
    })
}

/// The manifest without its `levels` (known once the file is written).
pub(crate) fn manifest_fields(
    ctx: &BuildContext,
    grid: &voxlod_geom::Grid,
    triangles: u64,
    degenerate_skipped: u64,
) -> serde_json::Value {
    let s = ctx.settings;
    let mut settings = serde_json::json!({
        "resolution": s.resolution,
        "mode": s.mode.to_string(),
        "zstd_level": s.zstd_level,
    });
    // the exact methods write the same bytes; the approximate one says so in the file
    if !s.voxelizer.is_exact() {
        settings["voxelizer"] = s.voxelizer.to_string().into();
    }
    let input_name = ctx
        .input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut manifest = serde_json::json!({
        "tool": "voxlod",
        "tool_version": env!("CARGO_PKG_VERSION"),
        "input": { "file": input_name, "format": ctx.source.info().format, "triangles": triangles,
                   "degenerate_skipped": degenerate_skipped },
        "settings": settings,
        "grid": {
            "origin": grid.origin,
            "voxel_size": grid.voxel_size,
            "resolution": grid.resolution,
            "levels": grid.levels(),
        },
        "levels": serde_json::Value::Null,
    });
    // the source material names, indexed by material id (FORMAT.md 14.3)
    let info = ctx.source.info();
    if crate::stages::voxelize::textures::has_material_channel(info) {
        let names: Vec<&str> = info.materials.iter().map(|m| m.name.as_str()).collect();
        manifest["materials"] = serde_json::json!(names);
    }
    // the up axis the input format defines (glTF: +Y), for `render`
    if let Some(up) = info.up {
        manifest["input"]["up"] = serde_json::json!(up);
    }
    manifest
}
