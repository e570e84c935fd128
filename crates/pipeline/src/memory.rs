//! The memory plan: how the `--memory` budget is split between the stages, stated before the
//! build starts, and refused early when it cannot work.

use anyhow::{bail, Result};
use serde::Serialize;

use crate::size::format_size;

/// Bytes one chunk voxelizer needs: its two-level slot index (a 128 KiB table of the 32³
/// bricks plus 2 KiB per touched brick: at most 64 MiB, far less for a surface), the
/// accumulators of the occupied voxels of one chunk (a dense surface of a 256³ chunk has a few
/// hundred thousand voxels) and its (triangle, voxel) pairs, at most 32 MiB
/// (`voxelize/src/single.rs`).
pub const VOXELIZER_BYTES: u64 = 128 << 20;
/// Held by the LOD stage: up to eight children per level on the current Morton path, plus
/// compressed payloads in flight (the write queue's 64 MiB bound counts the voxels of queued
/// merges and the source-triangle payloads of leaves queued behind them).
pub const LOD_BYTES: u64 = 128 << 20;
/// Fixed overhead: code, the thread pool, read buffers of the tile passes.
pub const BASE_BYTES: u64 = 64 << 20;

/// The largest buffer of a run scatter (`voxlod_tile::RunScatter`: the ingest pass's bins and
/// the map tasks'). Each run is sorted by chunk and written whole, so a larger buffer only adds
/// first-touch page faults and cache misses, and a smaller one more pieces. Measured on gen 1e8
/// at 2048³ (docs/journal/benchmarks-experiments.md, "Sharded build with a map phase"): a
/// 16 MiB buffer instead of the 1 GiB share of a 2 GiB budget takes about 2 CPU-s less in the
/// one-machine build and 0.25 CPU-s less per map task.
pub const RUN_BUFFER_MAX: u64 = 16 << 20;

/// Memory an input's reader holds ([`voxlod_ingest::MeshInfo::held`]: a glTF file's document
/// and buffers) that is counted within the base, as the read buffers of the other formats are.
/// A reader holding more has the excess planned beside the stages ([`MemoryPlan::with_input`]).
pub const INPUT_IN_BASE: u64 = 8 << 20;

/// How the budget is spent.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MemoryPlan {
    /// The `--memory` budget, bytes.
    pub budget: u64,
    /// Triangles buffered by the scatter pass between flushes (a run scatter uses at most
    /// [`RUN_BUFFER_MAX`] of it: [`MemoryPlan::run_buffer`]).
    pub scatter_buffer: u64,
    /// Chunk voxelizers running at once (≤ threads).
    pub voxelizers: usize,
    /// Bytes planned in total.
    pub planned: u64,
    /// Decoded textures during the voxelize stage (0 for a mesh without textures): their
    /// pyramids whole when they fit [`MemoryPlan::texture_share`], otherwise a tile cache of
    /// that share ([`MemoryPlan::with_textures`]).
    pub textures: u64,
    /// Memory the input's reader holds beyond [`INPUT_IN_BASE`], for the whole build (0 for a
    /// mapped or streamed input).
    pub input: u64,
}

impl MemoryPlan {
    /// Splits `budget` for `threads` workers; an error if even one chunk voxelizer cannot fit.
    pub fn new(budget: u64, threads: usize) -> Result<MemoryPlan> {
        let minimum = BASE_BYTES + LOD_BYTES + VOXELIZER_BYTES + (16 << 20);
        if budget < minimum {
            bail!(
                "memory budget {} is too small: a build needs at least {} (one chunk voxelizer {}, LOD {}, base {}, scatter buffer 16 MiB)",
                format_size(budget),
                format_size(minimum),
                format_size(VOXELIZER_BYTES),
                format_size(LOD_BYTES),
                format_size(BASE_BYTES)
            );
        }
        let free = budget - BASE_BYTES - LOD_BYTES;
        let voxelizers = (threads.max(1) as u64)
            .min((free - (16 << 20)) / VOXELIZER_BYTES)
            .max(1) as usize;
        // The scatter pass runs before the voxelizers exist, so it may use what they will need.
        let scatter_buffer = (free / 2).min(1 << 30);
        let planned =
            BASE_BYTES + LOD_BYTES + (voxelizers as u64 * VOXELIZER_BYTES).max(scatter_buffer);
        Ok(MemoryPlan {
            budget,
            scatter_buffer,
            voxelizers,
            planned,
            textures: 0,
            input: 0,
        })
    }

    /// What the input's reader may hold ([`voxlod_ingest::ReadOptions::memory`]): what the
    /// least plan (one chunk voxelizer, a 16 MiB scatter buffer) leaves of the budget, and
    /// [`INPUT_IN_BASE`] within the base.
    pub fn input_share(&self) -> u64 {
        let least = BASE_BYTES + LOD_BYTES + VOXELIZER_BYTES + (16 << 20);
        self.budget.saturating_sub(least) + INPUT_IN_BASE
    }

    /// The plan with a reader holding `held` bytes for the whole build: what exceeds
    /// [`INPUT_IN_BASE`] is taken from the budget before it is split (fewer chunk voxelizers,
    /// a smaller scatter buffer); an error if even the least plan no longer fits.
    pub fn with_input(self, held: u64, threads: usize) -> Result<MemoryPlan> {
        let input = held.saturating_sub(INPUT_IN_BASE);
        if input == 0 {
            return Ok(self);
        }
        if input > self.input_share() - INPUT_IN_BASE {
            bail!(
                "memory budget {}: reading the input holds {}, and the build needs {} beside it",
                format_size(self.budget),
                format_size(held),
                format_size(self.budget - self.input_share() + INPUT_IN_BASE)
            );
        }
        let mut p = MemoryPlan::new(self.budget - input, threads)?;
        p.budget = self.budget;
        p.input = input;
        p.planned += input;
        Ok(p)
    }

    /// The buffer of a run scatter: the scatter buffer, at most [`RUN_BUFFER_MAX`].
    pub fn run_buffer(&self) -> u64 {
        self.scatter_buffer.min(RUN_BUFFER_MAX)
    }

    /// What the voxelize stage leaves for decoded textures: the budget less the base, the LOD
    /// stage and the chunk voxelizers (at least 16 MiB, as [`MemoryPlan::new`] keeps 16 MiB
    /// beside the voxelizers). The scatter buffer is gone by then.
    pub fn texture_share(&self) -> u64 {
        self.budget - self.input - BASE_BYTES - LOD_BYTES - self.voxelizers as u64 * VOXELIZER_BYTES
    }

    /// The plan with `decoded` bytes of decoded textures: held whole if they fit the texture
    /// share, else a tile cache of the whole share.
    pub fn with_textures(mut self, decoded: u64) -> MemoryPlan {
        self.textures = decoded.min(self.texture_share());
        let voxelize = self.voxelizers as u64 * VOXELIZER_BYTES + self.textures;
        self.planned = BASE_BYTES + LOD_BYTES + self.input + voxelize.max(self.scatter_buffer);
        self
    }

    /// The plan in words, its parts adding up to its total: base + LOD + the larger of the
    /// voxelizers (with the decoded textures, if any) and the scatter buffer (the scatter pass
    /// runs before the voxelizers exist, so the two share their memory).
    pub fn describe(&self) -> String {
        let mut voxelize = format!(
            "{} chunk voxelizer(s) × {}",
            self.voxelizers,
            format_size(VOXELIZER_BYTES)
        );
        if self.textures > 0 {
            voxelize += &format!(" + textures {}", format_size(self.textures));
        }
        let scatter = format_size(self.scatter_buffer);
        let (shared, other) =
            if self.voxelizers as u64 * VOXELIZER_BYTES + self.textures >= self.scatter_buffer {
                (
                    voxelize,
                    format!("before them the scatter buffer, {scatter}"),
                )
            } else {
                (
                    format!("scatter buffer {scatter}"),
                    format!("after it {voxelize}"),
                )
            };
        let input = if self.input > 0 {
            format!(" + input reader {}", format_size(self.input))
        } else {
            String::new()
        };
        format!(
            "memory plan: {} of {} budget = base {} + LOD {}{input} + {shared} (in the same memory, {other})",
            format_size(self.planned),
            format_size(self.budget),
            format_size(BASE_BYTES),
            format_size(LOD_BYTES),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plan_fits_budget_or_refuses() {
        assert!(MemoryPlan::new(100 << 20, 2).is_err());
        for budget in [512u64 << 20, 1 << 30, 2 << 30, 24 << 30] {
            for threads in [1, 2, 16] {
                let p = MemoryPlan::new(budget, threads).unwrap();
                assert!(p.planned <= budget, "{p:?}");
                assert!(p.voxelizers >= 1 && p.voxelizers <= threads);
                // the parts the description adds up give the total
                let shared = (p.voxelizers as u64 * VOXELIZER_BYTES).max(p.scatter_buffer);
                assert_eq!(BASE_BYTES + LOD_BYTES + shared, p.planned);
                assert!(p.texture_share() >= 16 << 20, "{p:?}");
                // textures of any size stay inside the budget: whole, or a cache of the share
                for decoded in [1u64 << 20, p.texture_share(), 64 << 30] {
                    let t = p.with_textures(decoded);
                    assert_eq!(t.textures, decoded.min(p.texture_share()));
                    assert!(t.planned <= budget, "{t:?}");
                    let voxelize = t.voxelizers as u64 * VOXELIZER_BYTES + t.textures;
                    assert_eq!(
                        t.planned,
                        BASE_BYTES + LOD_BYTES + voxelize.max(t.scatter_buffer)
                    );
                    assert!(t
                        .describe()
                        .contains(&format!("+ textures {}", format_size(t.textures))));
                }
                // an input reader's memory is planned beside the stages, inside the budget
                for held in [1u64 << 20, p.input_share() / 2, p.input_share()] {
                    let q = p.with_input(held, threads).unwrap();
                    assert!(q.planned <= budget, "{q:?}");
                    assert_eq!(q.input, held.saturating_sub(INPUT_IN_BASE));
                    assert!(q.with_textures(64 << 30).planned <= budget);
                }
                assert!(p.with_input(p.input_share() + 1, threads).is_err());
                let d = p.describe();
                assert!(
                    d.contains(&format!(
                        "= base {} + LOD {} + ",
                        format_size(BASE_BYTES),
                        format_size(LOD_BYTES)
                    )),
                    "{d}"
                );
            }
        }
    }
}
