//! The voxelize stage: every leaf chunk's triangles through a [`Voxelize`] implementation (the
//! CPU chunk voxelizers or the GPU one, `backend.rs`), each chunk's voxels encoded on its
//! worker and appended strictly in Morton order to the leaf log (`leaves.bin`), which resumes
//! at chunk granularity. Workers run at most a window of chunks ahead of the log
//! (`window.rs`); a worker's panic becomes an error naming its chunk.
//!
//! Artifact and resume marker: [`LeavesMarker`] (`leaves.json`), written once every chunk is
//! in the log; the bins are removed then.

use std::time::Instant;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use voxlod_format::{encode_materials, encode_node, EncodedNode};
use voxlod_tile::Bins;

use super::tile::Tiled;
use super::BuildContext;
use crate::backend::{BinChunk, GpuStats, Voxelize};
use crate::error::StageError;
use crate::leaf_log::{self, LeafLog};
use crate::progress::Stage;
use crate::work::{Marker, WorkFile};

/// The voxelize stage's totals (`leaves.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct LeavesMarker {
    /// Leaf chunks in the log (one per non-empty bin).
    pub records: u64,
    /// Triangle/chunk pairs the voxelizer skipped.
    pub skipped: u64,
    /// Triangle records in the bins.
    pub binned_triangles: u64,
}

impl Marker for LeavesMarker {
    const FILE: WorkFile = WorkFile::LeavesMarker;
}

/// The voxelize stage's artifact.
pub(crate) struct Voxelized {
    pub marker: LeavesMarker,
    /// The voxelizer that ran (backend, adapter, method, cutoff).
    pub backend: String,
    /// What the GPU backend did; None on the CPU or when resumed.
    pub gpu_stats: Option<GpuStats>,
}

impl Voxelized {
    /// The artifact of an interrupted run that voxelized every chunk (the tile and voxelize
    /// stages are then skipped).
    pub(crate) fn resume(ctx: &mut BuildContext) -> Option<Voxelized> {
        let marker = ctx.work.marker::<LeavesMarker>()?;
        ctx.stage_done("tile", Instant::now(), true);
        ctx.stage_done("voxelize", Instant::now(), true);
        Some(Voxelized {
            marker,
            backend: "(voxelized by the interrupted run)".into(),
            gpu_stats: None,
        })
    }
}

/// Runs the voxelize stage with the voxelizer the settings choose.
pub(crate) fn run(ctx: &mut BuildContext, tiled: Tiled) -> Result<Voxelized, StageError> {
    let threads = ctx.pool.current_num_threads();
    let textures = crate::textures::load(
        ctx.source.info(),
        ctx.input,
        ctx.settings.memory,
        &mut ctx.warnings,
    );
    let materials = crate::textures::has_material_channel(ctx.source.info());
    let (vz, backend) = crate::backend::select(
        ctx.settings,
        ctx.plan.voxelizers,
        threads,
        &tiled.bins,
        textures,
        materials,
    )?;
    let (marker, gpu_stats) = run_with(ctx, &tiled, vz)?;
    tiled.bins.remove()?;
    Ok(Voxelized {
        marker,
        backend,
        gpu_stats,
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
    if let Err(e) = append_chunks(ctx, &tiled.bins, &*vz, &mut log) {
        log.finish()?;
        return Err(e);
    }
    let gpu_stats = vz.gpu_stats()?;
    drop(vz);
    let records = log.records();
    log.finish()?;
    let mut skipped = 0u64;
    leaf_log::read_log(&leaves_path, &mut |h, _| {
        skipped += h.skipped as u64;
        Ok(())
    })?;
    let m = LeavesMarker {
        records,
        skipped,
        binned_triangles: tiled.bins.total(),
    };
    ctx.work.set_marker(&m)?;
    ctx.stage_done("voxelize", t, start > 0);
    Ok((m, gpu_stats))
}

/// Voxelizes and encodes the chunks after those in `log` on the workers, at most a window
/// ahead of the log, and appends them to it in Morton order (deterministic output).
fn append_chunks(
    ctx: &BuildContext,
    bins: &Bins,
    vz: &dyn Voxelize,
    log: &mut LeafLog,
) -> Result<(), StageError> {
    let chunks = bins.chunks();
    let start = log.records() as usize;
    let bar = Stage::items(ctx.progress, "voxelize", chunks.len() as u64);
    bar.set(start as u64, chunks.len() as u64);
    let zstd_level = ctx.settings.zstd_level;
    type Encoded = (Option<EncodedNode>, Vec<u8>, u64);
    let voxelize_one = |i: usize| -> Result<Encoded, StageError> {
        let r = vz.voxelize(&BinChunk { bins, index: i })?;
        let what = || format!("encoding leaf chunk {:?}", chunks[i].coord);
        let enc = if r.voxels.is_empty() {
            None
        } else {
            Some(encode_node(&r.voxels, zstd_level).with_context(what)?)
        };
        // the material channel's payload goes after the voxels' in the leaf log record
        let mats = match &r.materials {
            Some(m) if !m.is_empty() => encode_materials(m, zstd_level).with_context(what)?.payload,
            _ => Vec::new(),
        };
        Ok((enc, mats, r.skipped))
    };
    let interrupt_after = ctx.settings.interrupt_after_chunks;
    crate::window::ordered(
        &ctx.pool,
        ctx.plan.voxelizers,
        ctx.plan.voxelizers * 4,
        start..chunks.len(),
        &voxelize_one,
        &mut |i, r| {
            ctx.check_interrupt()?;
            let (enc, mats, skipped) = r?;
            log.append_with(i as u64, chunks[i].coord, enc.as_ref(), &mats, skipped)?;
            log.flush()?;
            bar.set(i as u64 + 1, chunks.len() as u64);
            if interrupt_after.is_some_and(|n| i as u64 + 1 >= n) {
                ctx.interrupt
                    .store(true, std::sync::atomic::Ordering::SeqCst);
            }
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
