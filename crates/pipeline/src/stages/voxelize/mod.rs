//! The voxelize stage: every leaf chunk's triangles through a [`Voxelize`] implementation (the
//! CPU chunk voxelizers or the GPU one, `backend.rs`), each chunk's voxels encoded and halved
//! (merged alone to its parent's resolution, for the LOD stage) on its worker and appended
//! strictly in Morton order to the leaf log (`leaves.bin`), which resumes at chunk granularity.
//! Workers run at most a window of chunks ahead of the log (`window.rs`); a worker's panic
//! becomes an error naming its chunk.
//!
//! Artifact and resume marker: [`LeavesMarker`] (`leaves.json`), written once every chunk is
//! in the log; the bins are removed then.

use std::cell::RefCell;
use std::time::Instant;

use anyhow::Context;
use voxlod_format::{encode_materials, encode_node, EncodedNode, Voxel};
use voxlod_lod::MergeScratch;
use voxlod_tile::Bins;

use crate::stages::tile::passes::InputTriangles;

use super::tile::Tiled;
use crate::context::{BuildContext, Stage};
use crate::error::StageError;
use crate::files::markers::LeavesMarker;
use crate::files::work::WorkFile;
use crate::progress::Bar;
use crate::resume::Resume;
use backend::{BinChunk, GpuStats, Voxelize};
use leaf_log::{LeafLog, LeafRecord};

pub(crate) mod backend;
pub(crate) mod leaf_log;
pub(crate) mod textures;
pub(crate) mod window;

/// The voxelize stage's artifact.
pub(crate) struct Voxelized {
    pub marker: LeavesMarker,
    /// The voxelizer that ran (backend, adapter, method, cutoff).
    pub backend: String,
    /// What the GPU backend did; None on the CPU or when resumed.
    pub gpu_stats: Option<GpuStats>,
    /// The textures' tile cache, if they were read by tile; None when resumed.
    pub texture_cache: Option<textures::TextureCacheSummary>,
}

impl Voxelized {
    /// The artifact of an interrupted run that voxelized every chunk (the tile and voxelize
    /// stages are then skipped).
    pub(crate) fn resume(ctx: &mut BuildContext, resume: &Resume) -> Option<Voxelized> {
        let marker = resume.leaves.clone()?;
        ctx.stage_done(Stage::Tile, Instant::now(), true);
        ctx.stage_done(Stage::Voxelize, Instant::now(), true);
        Some(Voxelized {
            marker,
            backend: "(voxelized by the interrupted run)".into(),
            gpu_stats: None,
            texture_cache: None,
        })
    }
}

/// Runs the voxelize stage with the voxelizer the settings choose.
pub(crate) fn run(ctx: &mut BuildContext, tiled: Tiled) -> Result<Voxelized, StageError> {
    let threads = ctx.pool.current_num_threads();
    let t = Instant::now();
    let textures = textures::load(ctx)?;
    let tiles = textures.clone().filter(|t| t.tiles().is_some());
    if textures.is_some() {
        // decoding (and tiling) the textures, before the voxelizers start
        let reused = tiles
            .as_ref()
            .and_then(|t| t.tiles())
            .is_some_and(|t| t.reused);
        ctx.stage_done(Stage::Textures, t, reused);
    }
    let materials = textures::has_material_channel(ctx.source.info());
    let (vz, backend) = backend::select(
        ctx.settings,
        ctx.memory.voxelizers,
        threads,
        &tiled.bins,
        Some(&InputTriangles(ctx.source)),
        &tiled.grid,
        textures,
        materials,
    )?;
    let (marker, gpu_stats) = run_with(ctx, &tiled, vz)?;
    tiled.bins.remove()?;
    let texture_cache = tiles.as_ref().and_then(|t| t.tiles()).map(|t| {
        let st = t.stats();
        textures::TextureCacheSummary {
            decoded_bytes: t.decoded_bytes,
            capacity: st.capacity,
            peak_resident: st.peak_resident,
            tile_reads: st.tile_reads,
            file_bytes: t.file_bytes,
            reused: t.reused,
        }
    });
    Ok(Voxelized {
        marker,
        backend,
        gpu_stats,
        texture_cache,
    })
}

/// The stage with the voxelizer `vz`: continues the leaf log where it ends, writes the marker.
/// The voxelizer is dropped (its memory freed) before the stage's peak memory is taken.
pub(crate) fn run_with(
    ctx: &mut BuildContext,
    tiled: &Tiled,
    vz: Box<dyn Voxelize>,
) -> Result<(LeavesMarker, Option<GpuStats>), StageError> {
    let t = Instant::now();
    let leaves_path = ctx.work.file(WorkFile::Leaves);
    let mut log = LeafLog::open(&leaves_path)?;
    let start = log.records() as usize;
    if let Err(e) = append_chunks(ctx, &tiled.bins, &tiled.grid, &*vz, &mut log) {
        log.finish()?;
        return Err(e);
    }
    let gpu_stats = vz.gpu_stats()?;
    drop(vz);
    let m = LeavesMarker {
        records: log.records(),
        skipped: log.skipped(),
        binned_triangles: tiled.bins.total(),
        bin_index_bytes: tiled.bins.index_bytes().unwrap_or(0),
        leaf_payload_bytes: log.frame_bytes(),
    };
    log.finish()?;
    ctx.work.set_marker(&m)?;
    ctx.stage_done(Stage::Voxelize, t, start > 0);
    Ok((m, gpu_stats))
}

/// A leaf chunk's result, as its worker leaves it for the leaf log (`leaf_log::LeafRecord`).
#[derive(Default)]
struct Encoded {
    node: Option<EncodedNode>,
    materials: Vec<u8>,
    half: Vec<Voxel>,
    half_materials: Vec<u32>,
    skipped: u64,
}

thread_local! {
    /// The halving buffers of each worker.
    static HALVE: RefCell<MergeScratch> = RefCell::new(MergeScratch::new());
}

/// Voxelizes and encodes the chunks after those in `log` on the workers, at most a window
/// ahead of the log, and appends them to it in Morton order (deterministic output).
fn append_chunks(
    ctx: &BuildContext,
    bins: &Bins,
    grid: &voxlod_geom::Grid,
    vz: &dyn Voxelize,
    log: &mut LeafLog,
) -> Result<(), StageError> {
    let chunks = bins.chunks();
    let input = InputTriangles(ctx.source);
    let start = log.records() as usize;
    let bar = Bar::items(ctx.progress, Stage::Voxelize.name(), chunks.len() as u64);
    bar.set(start as u64, chunks.len() as u64);
    let zstd_level = ctx.settings.zstd_level;
    // a leaf that is not the root gets its half (its share of its parent) here, on its worker
    let halves = ctx.settings.resolution > voxlod_geom::CHUNK;
    let voxelize_one = |i: usize| -> Result<Encoded, StageError> {
        let r = vz.voxelize(&BinChunk {
            bins,
            input: Some(&input),
            index: i,
            grid,
        })?;
        if r.voxels.is_empty() {
            return Ok(Encoded {
                skipped: r.skipped,
                ..Encoded::default()
            });
        }
        let what = || format!("encoding leaf chunk {:?}", chunks[i].coord);
        let node = Some(encode_node(&r.voxels, zstd_level).with_context(what)?);
        // the material channel's payload goes after the voxels' in the leaf log record
        let materials = match &r.materials {
            Some(m) => encode_materials(m, zstd_level).with_context(what)?.payload,
            None => Vec::new(),
        };
        let mut half = Vec::new();
        let mut half_materials = Vec::new();
        if halves {
            let c = chunks[i].coord;
            let octant = (c[0] & 1 | (c[1] & 1) << 1 | (c[2] & 1) << 2) as usize;
            HALVE.with(|s| s.borrow_mut().halve(&r.voxels, octant, &mut half));
            if let Some(m) = &r.materials {
                half_materials = voxlod_lod::halve_materials(&r.voxels, m);
            }
        }
        Ok(Encoded {
            node,
            materials,
            half,
            half_materials,
            skipped: r.skipped,
        })
    };
    window::ordered(
        ctx.pool,
        ctx.memory.voxelizers,
        ctx.memory.voxelizers * 4,
        start..chunks.len(),
        &voxelize_one,
        &mut |i, r| {
            ctx.check_interrupt()?;
            let e = r?;
            let leaf = e.node.as_ref().map(|node| LeafRecord {
                node,
                materials: &e.materials,
                half: &e.half,
                half_materials: &e.half_materials,
            });
            log.append(i as u64, chunks[i].coord, leaf.as_ref(), e.skipped)?;
            log.flush()?;
            ctx.chunk_logged(&bar, i, chunks.len());
            Ok(())
        },
        &|i, message| StageError::Panicked {
            chunk: i,
            coord: chunks[i].coord,
            message: message.to_string(),
        },
    )?;
    bar.finish();
    Ok(())
}
