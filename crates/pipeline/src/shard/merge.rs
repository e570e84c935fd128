//! `voxlod merge`: the octree file of a sharded build from its plan and shard files, byte for
//! byte the file a one-machine build writes (Entwine's `merge` step, on the octree of Chajdas
//! et al.).
//!
//! The file is in post-order, so each subtree is one contiguous run of it, in Morton order of
//! the subtree roots; a shard's file holds its subtrees in that order, and the merge takes the
//! plan's ranges in Morton order, each from the shard that holds it (a cursor per shard). The
//! merge checks every shard's header and index first (missing, corrupt, from another plan,
//! wrong index), then copies each subtree's nodes below its root into the file as stored
//! (payload checksums checked, nothing decoded), decodes only the subtree roots, and builds
//! the levels above the split level by the same sort-and-compact writer as a build
//! (`octree_writer.rs`). Memory: the shards' index records, one payload at a time, and the
//! writer's pending parents above the split level (at most eight decoded children per level,
//! plus its bounded queue).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use serde::Serialize;
use voxlod_format::channel::decode_materials;
use voxlod_format::{
    EncodedChannel, EncodedNode, Voxel, Writer, CHANNEL_MATERIAL, CHANNEL_TRIANGLES,
};
use voxlod_geom::morton3;
use voxlod_lod::{halve_materials, MergeScratch};

use super::plan_file::LoadedPlan;
use super::shard_file::{ShardNode, ShardReader};
use crate::runner::{Job, Runner};
use crate::stages::lod_write::octree_writer::{file_spec, LevelStats, OctreeWriter};

/// What `voxlod merge` did.
#[derive(Clone, Debug, Serialize)]
pub struct MergeSummary {
    /// The octree file written.
    pub output: PathBuf,
    /// Shards merged.
    pub shards: u32,
    /// Level of the subtree roots.
    pub split_level: u32,
    /// Nodes copied from the shards as stored (without decoding).
    pub nodes_copied: u64,
    /// Subtree roots decoded (to build the levels above).
    pub roots_decoded: u64,
    /// Nodes and voxels per level, finest first.
    pub levels: Vec<LevelStats>,
    /// Size of the octree file, bytes.
    pub bytes: u64,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Peak resident memory of the process (bytes).
    pub peak_rss: u64,
}

/// Opens and checks every shard of `plan` (in `dir`, else beside the plan): all problems are
/// reported together, each naming its shard file.
fn open_shards(plan: &LoadedPlan, dir: Option<&Path>) -> Result<Vec<ShardReader>> {
    let p = &plan.plan;
    let n = p.shards.len() as u32;
    let mut shards = Vec::new();
    let mut problems = Vec::new();
    for i in 0..n {
        let path = plan.shard_path(i, dir);
        if !path.exists() {
            problems.push(format!(
                "shard {i}: {} is missing (run `voxlod build --plan {} --shard {i}`)",
                path.display(),
                plan.path.display()
            ));
            continue;
        }
        let r = match ShardReader::open(&path) {
            Ok(r) => r,
            Err(e) => {
                problems.push(format!("shard {i}: {}", crate::chain_text::chain_text(&e)));
                continue;
            }
        };
        let h = &r.header;
        let why = if h.plan_sha256 != plan.sha256 {
            Some(
                "it was built from another plan (or the plan changed since): build it again"
                    .to_string(),
            )
        } else if h.index != i || h.count != n {
            Some(format!(
                "it is shard {} of {}, expected shard {i} of {n}",
                h.index, h.count
            ))
        } else if h.split_level != p.split_level || h.levels != p.levels || h.channels != p.channels
        {
            Some("its split level, levels or channels differ from the plan's".to_string())
        } else {
            None
        };
        match why {
            Some(w) => problems.push(format!("shard {i}: {}: {w}", path.display())),
            None => shards.push(r),
        }
    }
    if !problems.is_empty() {
        bail!(
            "cannot merge {}:\n  {}",
            plan.path.display(),
            problems.join("\n  ")
        );
    }
    Ok(shards)
}

/// Merges the shards of the plan at `plan_path` into `output`. `runtime` gives the threads,
/// `progress` and `force`.
pub fn merge(
    plan_path: &Path,
    output: &Path,
    shard_dir: Option<&Path>,
    runtime: &crate::settings::BuildSettings,
) -> Result<MergeSummary> {
    let t0 = Instant::now();
    let plan = LoadedPlan::load(plan_path)?;
    let shards = open_shards(&plan, shard_dir)?;
    let p = &plan.plan;
    // a plan with parts: the input's counts are the map outputs'
    let mut manifest = p.manifest.clone();
    if !p.parts.is_empty() {
        let hex = voxlod_io::hex(&plan.sha256);
        let markers = super::map_part::load_markers(&plan.path, &hex, &p.parts, &p.grid.into())?;
        let (triangles, degenerate, _) = super::map_part::totals(&markers);
        manifest["input"]["triangles"] = triangles.into();
        manifest["input"]["degenerate_skipped"] = degenerate.into();
    }
    let inputs: Vec<&Path> = shards.iter().map(|s| s.path()).collect();
    let runner = Runner::open(
        Job::Merge {
            shards: &inputs,
            output,
        },
        runtime,
    )?;
    let spec = file_spec(&p.grid.into(), p.levels, p.settings.mode);
    let writer = Writer::create_staged(runner.guard.staged(), spec, &p.channels)?;
    let mut octree = OctreeWriter::new(writer, p.levels, p.settings.zstd_level, &runner.pool);
    let mut m = Merger {
        octree: &mut octree,
        split: p.split_level,
        levels: p.levels,
        material: p.channels.iter().position(|&c| c == CHANNEL_MATERIAL),
        triangles: p.channels.iter().position(|&c| c == CHANNEL_TRIANGLES),
        scratch: MergeScratch::new(),
        copied: 0,
        roots: 0,
    };
    // every range in Morton order, from its shard, each shard's nodes read once in order
    let mut cursor = vec![0usize; shards.len()];
    for &(start, end, k) in &plan.owners {
        let k = k as usize;
        m.range(&shards[k], &mut cursor[k], start..end)?;
    }
    for (shard, &at) in shards.iter().zip(&cursor) {
        if let Some(node) = shard.nodes.get(at) {
            let e = &node.entry;
            bail!(
                "{}: node level {} {:?} lies outside the shard's ranges, or out of Morton order",
                shard.path().display(),
                e.level,
                e.pos()
            );
        }
    }
    let (copied, roots) = (m.copied, m.roots);
    let (bytes, levels) = octree.finish(|levels| {
        manifest["levels"] = serde_json::json!(levels);
        manifest
    })?;
    runner.guard.commit()?;
    runner.finish(&mut Vec::new())?;
    Ok(MergeSummary {
        output: output.to_path_buf(),
        shards: p.shards.len() as u32,
        split_level: p.split_level,
        nodes_copied: copied,
        roots_decoded: roots,
        levels,
        bytes,
        seconds: t0.elapsed().as_secs_f64(),
        peak_rss: crate::system::peak_rss(),
    })
}

/// The merge's state while it walks the shards.
struct Merger<'a, 'p> {
    octree: &'a mut OctreeWriter<'p, Writer>,
    split: u32,
    levels: u32,
    /// Positions of the material and source-triangle channels among the file's channels.
    material: Option<usize>,
    triangles: Option<usize>,
    scratch: MergeScratch,
    copied: u64,
    roots: u64,
}

impl Merger<'_, '_> {
    /// Copies the subtrees of `shard` whose roots lie in `range` (level-split Morton codes):
    /// its nodes from `*at` on while they do, `*at` left at the first node that does not.
    fn range(
        &mut self,
        shard: &ShardReader,
        at: &mut usize,
        range: std::ops::Range<u64>,
    ) -> Result<()> {
        let mut open = false;
        while let Some(node) = shard.nodes.get(*at) {
            let e = &node.entry;
            let shift = self.split - e.level;
            let root = e.pos().map(|c| c >> shift);
            let inside = range.contains(&morton3(root[0], root[1], root[2]));
            ensure!(
                inside || !open,
                "{}: node level {} {:?} lies outside the subtree before it (a damaged shard)",
                shard.path().display(),
                e.level,
                e.pos()
            );
            if !inside {
                break;
            }
            *at += 1;
            if !open {
                self.octree.begin_subtree(self.split, root)?;
                open = true;
            }
            let (enc, channels) = self.read(shard, node)?;
            if e.level < self.split {
                let refs: Vec<Option<&EncodedChannel>> =
                    channels.iter().map(Option::as_ref).collect();
                self.octree
                    .write_stored(e.level, e.pos(), e.child_mask as u8, &enc, &refs)?;
                self.copied += 1;
            } else {
                self.root(node, enc, channels)
                    .with_context(|| format!("{}", shard.path().display()))?;
                open = false;
            }
        }
        ensure!(
            !open,
            "{}: the last subtree has no root (a truncated shard)",
            shard.path().display()
        );
        Ok(())
    }

    /// A node's payloads from the shard as stored, their checksums checked.
    fn read(
        &self,
        shard: &ShardReader,
        node: &ShardNode,
    ) -> Result<(EncodedNode, Vec<Option<EncodedChannel>>)> {
        let e = &node.entry;
        let payload = shard.payload(e.payload_offset, e.payload_size, e.payload_crc32)?;
        let enc = EncodedNode::from_stored(
            payload,
            e.voxel_count,
            e.payload_crc32,
            e.block_crc32,
            e.bounds(),
        )
        .with_context(|| {
            format!(
                "{}: node level {} {:?}",
                shard.path().display(),
                e.level,
                e.pos()
            )
        })?;
        let mut channels = Vec::with_capacity(node.channels.len());
        for c in &node.channels {
            channels.push(if c.payload_size == 0 {
                None
            } else {
                Some(EncodedChannel {
                    payload: shard.payload(c.payload_offset, c.payload_size, c.payload_crc32)?,
                    payload_crc32: c.payload_crc32,
                    count: c.count,
                    voxel_count: e.voxel_count,
                })
            });
        }
        Ok((enc, channels))
    }

    /// A subtree root: decoded (its voxels and materials) for the levels above, then written
    /// as stored.
    fn root(
        &mut self,
        node: &ShardNode,
        enc: EncodedNode,
        mut channels: Vec<Option<EncodedChannel>>,
    ) -> Result<()> {
        let e = &node.entry;
        let take =
            |k: Option<usize>, ch: &mut Vec<Option<EncodedChannel>>| k.and_then(|k| ch[k].take());
        let material = take(self.material, &mut channels);
        let source = take(self.triangles, &mut channels);
        let mut voxels = Vec::new();
        let mut mats = None;
        if e.level + 1 < self.levels {
            // the root's voxels, for its parent (the only nodes the merge decodes)
            let back = EncodedNode::from_payload(
                enc.payload().to_vec(),
                e.voxel_count,
                e.payload_crc32,
                &mut voxels,
            )?;
            ensure!(
                back.block_crc32() == e.block_crc32 && back.bounds() == e.bounds(),
                "node level {} {:?}: its block checksum or bounds differ from the index",
                e.level,
                e.pos()
            );
            if let Some(m) = &material {
                let (ids, _) = decode_materials(m.payload.clone(), e.voxel_count)
                    .map_err(anyhow::Error::msg)?;
                mats = Some(ids);
            }
            self.roots += 1;
        }
        let (parent_voxels, parent_mats) = if e.level == 0 && self.levels > 1 {
            // a leaf's parent is made from its half, as in a build
            let c = e.pos();
            let octant = (c[0] & 1 | (c[1] & 1) << 1 | (c[2] & 1) << 2) as usize;
            let mut half: Vec<Voxel> = Vec::new();
            self.scratch.halve(&voxels, octant, &mut half);
            let half_mats = mats.map(|m| halve_materials(&voxels, &m));
            (half, half_mats)
        } else {
            (voxels, mats)
        };
        self.octree.push_stored_root(
            e.level,
            e.pos(),
            e.child_mask as u8,
            (enc, material, source),
            (parent_voxels, parent_mats),
        )
    }
}
