//! The streamed octree: leaves arrive in Morton order, each parent is built (sort-and-compact)
//! and written as soon as its last child is done, so only the partial parents on the current
//! Morton path are held in memory (at most eight children per level).

use anyhow::{Context, Result};
use voxlod_format::{encode_node, Voxel, Writer};
use voxlod_lod::MergeScratch;

/// Voxel and node counts of one level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LevelStats {
    pub level: u32,
    pub nodes: u64,
    pub voxels: u64,
}

struct Pending {
    parent: [u32; 3],
    children: [Vec<Voxel>; 8],
    mask: u8,
}

/// Receives leaf chunks in Morton order and writes leaves and parents in post-order.
pub struct OctreeWriter {
    writer: Writer,
    levels: u32,
    zstd_level: i32,
    pending: Vec<Option<Pending>>,
    scratch: MergeScratch,
    last_leaf: Option<u64>,
    pub stats: Vec<LevelStats>,
}

impl OctreeWriter {
    pub fn new(writer: Writer, levels: u32, zstd_level: i32) -> Self {
        OctreeWriter {
            writer,
            levels,
            zstd_level,
            pending: (0..levels).map(|_| None).collect(),
            scratch: MergeScratch::new(),
            last_leaf: None,
            stats: (0..levels)
                .map(|level| LevelStats {
                    level,
                    ..Default::default()
                })
                .collect(),
        }
    }

    /// Writes a leaf whose payload is already encoded (leaves are compressed in parallel) and
    /// schedules it for its parent. Leaves must come in strictly increasing Morton order.
    /// `encoded` is `None` exactly when the chunk has no voxels (then nothing is stored).
    pub fn push_leaf(
        &mut self,
        coord: [u32; 3],
        voxels: Vec<Voxel>,
        encoded: Option<&voxlod_format::EncodedNode>,
    ) -> Result<()> {
        let m = voxlod_geom::morton3(coord[0], coord[1], coord[2]);
        anyhow::ensure!(
            self.last_leaf.map_or(true, |l| l < m),
            "leaf chunks out of Morton order at {coord:?}"
        );
        self.last_leaf = Some(m);
        match encoded {
            Some(enc) if !voxels.is_empty() => self.emit(0, coord, 0, voxels, enc),
            None if voxels.is_empty() => Ok(()),
            _ => anyhow::bail!("leaf {coord:?}: voxels and encoded payload disagree"),
        }
    }

    /// Post-order: before node (level, coord) is written, every pending parent of an earlier
    /// subtree is completed and written; then the node itself; then it waits for its parent.
    fn emit(
        &mut self,
        level: u32,
        coord: [u32; 3],
        child_mask: u8,
        voxels: Vec<Voxel>,
        enc: &voxlod_format::EncodedNode,
    ) -> Result<()> {
        for l in level..self.levels.saturating_sub(1) {
            let shift = l + 1 - level;
            let ancestor = [coord[0] >> shift, coord[1] >> shift, coord[2] >> shift];
            if self.pending[l as usize]
                .as_ref()
                .is_some_and(|p| p.parent != ancestor)
            {
                self.flush(l)?;
            }
        }
        self.writer
            .write_node(level, coord, child_mask, enc)
            .with_context(|| format!("writing node level {level} {coord:?}"))?;
        self.stats[level as usize].nodes += 1;
        self.stats[level as usize].voxels += voxels.len() as u64;
        if level + 1 < self.levels {
            let parent = [coord[0] >> 1, coord[1] >> 1, coord[2] >> 1];
            let octant = (coord[0] & 1 | (coord[1] & 1) << 1 | (coord[2] & 1) << 2) as usize;
            let p = self.pending[level as usize].get_or_insert_with(|| Pending {
                parent,
                children: Default::default(),
                mask: 0,
            });
            debug_assert!(
                p.parent == parent && p.mask & (1 << octant) == 0,
                "child pushed twice"
            );
            p.children[octant] = voxels;
            p.mask |= 1 << octant;
        }
        Ok(())
    }

    /// Builds and writes the pending parent of `level`'s nodes.
    fn flush(&mut self, level: u32) -> Result<()> {
        let Some(p) = self.pending[level as usize].take() else {
            return Ok(());
        };
        let refs: [&[Voxel]; 8] = std::array::from_fn(|o| p.children[o].as_slice());
        let mut merged = Vec::new();
        self.scratch.merge(&refs, &mut merged);
        drop(p.children);
        let enc = encode_node(&merged, self.zstd_level)
            .with_context(|| format!("encoding node level {} {:?}", level + 1, p.parent))?;
        self.emit(level + 1, p.parent, p.mask, merged, &enc)
    }

    /// Completes every pending parent up to the root and finishes the file.
    /// `manifest` receives the final per-level statistics.
    pub fn finish(
        mut self,
        manifest: impl FnOnce(&[LevelStats]) -> serde_json::Value,
    ) -> Result<(u64, Vec<LevelStats>)> {
        for level in 0..self.levels {
            self.flush(level)?;
        }
        let stats = self.stats.clone();
        let size = self
            .writer
            .finish(&manifest(&stats))
            .context("finishing the output file")?;
        Ok((size, stats))
    }

    pub fn bytes_written(&self) -> u64 {
        self.writer.bytes_written()
    }
}
