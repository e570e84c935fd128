//! The streamed octree: leaves arrive in Morton order, each parent is built (sort-and-compact;
//! at level 1 the concatenation of the leaves' halves, made where the leaves were voxelized)
//! and written as soon as its last child is done, so only the partial parents on the current
//! Morton path are held in memory (at most eight children per level).
//!
//! Parents are merged and compressed on the thread pool: when a parent's last child is done,
//! this thread waits for the merges of its children (if still running) and hands the parent's
//! merge and encode to the pool. Nodes wait in a queue in post-order and are written as soon as
//! the node at its head is encoded. The queue is bounded (node count and the bytes of the
//! children its merges hold), so memory stays bounded; the file is the same bytes as with
//! inline merges and encodes.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::{mpsc, Arc};

use anyhow::{Context, Result};
use voxlod_format::{encode_materials, encode_node, EncodedChannel, EncodedNode, Voxel, Writer};
use voxlod_lod::{halve_materials, merge_materials, MergeScratch};

/// A node's voxels and, in a build with the material channel, their materials.
type NodeVoxels = Arc<(Vec<Voxel>, Option<Vec<u32>>)>;
/// A node's encoded payloads: the voxels, and the material channel's if the build has one.
type Encoded = (EncodedNode, Option<EncodedChannel>);

/// A stored node's payloads: its voxels, its material payload and its source-triangle payload
/// (each channel only if the file has it).
pub type StoredPayloads = (EncodedNode, Option<EncodedChannel>, Option<EncodedChannel>);

/// Most nodes waiting for their encode, and most bytes they hold (voxels of merges and
/// encodes, and leaves' source-triangle payloads queued behind them), before the writer waits
/// for the oldest (the LOD stage runs after the voxelizers are gone, and this stays far inside
/// their share of the memory plan).
const QUEUE_NODES: usize = 16;
const QUEUE_BYTES: u64 = 64 << 20;

/// The octree file's header fields for a tree of `levels` levels over `grid` in `mode`: the
/// one place a build and a merge take them from, so both write the same header.
pub(crate) fn file_spec(
    grid: &voxlod_geom::Grid,
    levels: u32,
    mode: voxlod_voxelize::Mode,
) -> voxlod_format::FileSpec {
    voxlod_format::FileSpec {
        resolution: grid.resolution,
        levels,
        mode: mode.code(),
        origin: grid.origin,
        voxel_size: grid.voxel_size,
    }
}

/// Voxel and node counts of one level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LevelStats {
    /// Level, 0 = finest.
    pub level: u32,
    /// Nodes (chunks) of the level.
    pub nodes: u64,
    /// Voxels of the level.
    pub voxels: u64,
}

struct Pending {
    parent: [u32; 3],
    children: [Option<Child>; 8],
    mask: u8,
}

/// A node's voxels, as its parent's merge needs them: known (leaves) or being merged on the pool.
enum Child {
    Done(NodeVoxels),
    Merging(mpsc::Receiver<NodeVoxels>),
}

thread_local! {
    /// Merge buffers of each pool thread.
    static SCRATCH: RefCell<MergeScratch> = RefCell::new(MergeScratch::new());
}

/// A node's payload: encoded already (leaves) or being encoded on the pool.
enum Payload {
    Ready(Encoded),
    Encoding(mpsc::Receiver<Result<Encoded, voxlod_format::FormatError>>),
}

/// A node waiting in post-order for its payload.
struct Queued {
    level: u32,
    coord: [u32; 3],
    child_mask: u8,
    payload: Payload,
    /// Bytes the node holds while queued: the voxels its merge and encode hold, or a leaf's
    /// source-triangle payload (counted against `QUEUE_BYTES`, so queued source payloads
    /// stay inside the LOD share of the memory plan).
    bytes: u64,
    /// A leaf's source-triangle payload (`--source-geometry`), written after its other
    /// channels.
    source: Option<EncodedChannel>,
}

/// Where an [`OctreeWriter`] puts its nodes, in post-order: an octree file ([`Writer`]) or
/// a shard file (`shard_file.rs`).
pub trait NodeSink {
    /// Appends one node with its channel payloads (`channels[k]` for the sink's `k`-th channel).
    fn write_node_with(
        &mut self,
        level: u32,
        pos: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
        channels: &[Option<&EncodedChannel>],
    ) -> Result<()>;
    /// Bytes written so far.
    fn bytes_written(&self) -> u64;
}

impl NodeSink for Writer {
    fn write_node_with(
        &mut self,
        level: u32,
        pos: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
        channels: &[Option<&EncodedChannel>],
    ) -> Result<()> {
        Ok(Writer::write_node_with(
            self, level, pos, child_mask, node, channels,
        )?)
    }

    fn bytes_written(&self) -> u64 {
        Writer::bytes_written(self)
    }
}

/// Receives leaf chunks in Morton order and writes leaves and parents in post-order.
pub struct OctreeWriter<'p, W: NodeSink = Writer> {
    writer: W,
    levels: u32,
    /// The highest level built: the root's (`levels − 1`), or a shard's split level.
    top: u32,
    zstd_level: i32,
    pool: &'p rayon::ThreadPool,
    pending: Vec<Option<Pending>>,
    queue: VecDeque<Queued>,
    queued_bytes: u64,
    last_leaf: Option<u64>,
    /// Nodes and voxels per level written so far.
    pub stats: Vec<LevelStats>,
}

impl<'p, W: NodeSink> OctreeWriter<'p, W> {
    /// Parents are merged and compressed on `pool`. Precondition: the caller is not one of
    /// `pool`'s threads (it waits for merges running there).
    pub fn new(writer: W, levels: u32, zstd_level: i32, pool: &'p rayon::ThreadPool) -> Self {
        assert!(
            pool.current_thread_index().is_none(),
            "OctreeWriter must not run on a thread of the pool it hands merges to"
        );
        OctreeWriter {
            writer,
            levels,
            top: levels - 1,
            zstd_level,
            pool,
            pending: (0..levels).map(|_| None).collect(),
            queue: VecDeque::new(),
            queued_bytes: 0,
            last_leaf: None,
            stats: (0..levels)
                .map(|level| LevelStats {
                    level,
                    ..Default::default()
                })
                .collect(),
        }
    }

    /// Builds the levels up to `top` only (a shard's split level): nodes at `top` get no
    /// parent. Precondition: `top < levels`.
    pub fn with_top(mut self, top: u32) -> Self {
        assert!(
            top < self.levels,
            "top level {top} of {} levels",
            self.levels
        );
        self.top = top;
        self
    }

    /// Writes a leaf whose payload is already encoded (leaves are compressed in parallel) and
    /// schedules it for its parent. Leaves must come in strictly increasing Morton order.
    /// `encoded` is `None` exactly when the chunk has no voxels (then nothing is stored).
    /// In a build with the material channel, `materials` holds the leaf's per-voxel materials
    /// and their encoded payload (and the writer was made with that channel).
    /// Makes the leaf's half on this thread; [`push_halved`](Self::push_halved) takes one made
    /// elsewhere.
    pub fn push_leaf(
        &mut self,
        coord: [u32; 3],
        voxels: Vec<Voxel>,
        encoded: Option<EncodedNode>,
        materials: Option<(Vec<u32>, EncodedChannel)>,
    ) -> Result<()> {
        anyhow::ensure!(
            voxels.is_empty() == encoded.is_none(),
            "leaf {coord:?}: voxels and encoded payload disagree"
        );
        let (mats, menc) = materials.unzip();
        let mut half = Vec::new();
        if self.levels > 1 {
            let octant = (coord[0] & 1 | (coord[1] & 1) << 1 | (coord[2] & 1) << 2) as usize;
            SCRATCH.with(|s| s.borrow_mut().halve(&voxels, octant, &mut half));
        }
        let half_mats = mats.map(|m| halve_materials(&voxels, &m));
        self.push_halved(coord, half, half_mats, encoded, menc, None)
    }

    /// [`push_leaf`](Self::push_leaf) with the leaf's half instead of its voxels: its voxels
    /// merged alone into its parent (`voxlod_lod::MergeScratch::halve` for the leaf's octant;
    /// empty when the leaf is the root) and, with the material channel, the half's materials
    /// (`voxlod_lod::halve_materials`) and the leaf's encoded material payload. The level-1
    /// parents are then the concatenations of their children's halves. In a build with source
    /// geometry, `source` is the leaf's source-triangle payload (the writer's last channel).
    pub fn push_halved(
        &mut self,
        coord: [u32; 3],
        half: Vec<Voxel>,
        half_materials: Option<Vec<u32>>,
        encoded: Option<EncodedNode>,
        materials: Option<EncodedChannel>,
        source: Option<EncodedChannel>,
    ) -> Result<()> {
        let m = voxlod_geom::morton3(coord[0], coord[1], coord[2]);
        anyhow::ensure!(
            self.last_leaf.map_or(true, |l| l < m),
            "leaf chunks out of Morton order at {coord:?}"
        );
        self.last_leaf = Some(m);
        let Some(enc) = encoded else {
            anyhow::ensure!(half.is_empty(), "leaf {coord:?}: a half without voxels");
            return Ok(());
        };
        anyhow::ensure!(
            half.is_empty() == (self.levels == 1)
                && half_materials
                    .as_ref()
                    .is_none_or(|m| m.len() == half.len()),
            "leaf {coord:?}: a half of {} voxels in a tree of {} levels",
            half.len(),
            self.levels
        );
        let half = Child::Done(Arc::new((half, half_materials)));
        let node = Queued {
            level: 0,
            coord,
            child_mask: 0,
            payload: Payload::Ready((enc, materials)),
            bytes: source.as_ref().map_or(0, |s| s.payload.len() as u64),
            source,
        };
        self.emit(node, half)
    }

    /// Post-order: before node (level, coord) is written, every pending parent of an earlier
    /// subtree is completed and written; then the node itself; then it waits for its parent.
    fn emit(&mut self, node: Queued, voxels: Child) -> Result<()> {
        let (level, coord) = (node.level, node.coord);
        self.flush_before(level, coord)?;
        self.enqueue(node)?;
        if level < self.top {
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
            p.children[octant] = Some(voxels);
            p.mask |= 1 << octant;
        }
        Ok(())
    }

    /// Post-order before node (level, coord): completes every pending parent of an earlier
    /// subtree.
    fn flush_before(&mut self, level: u32, coord: [u32; 3]) -> Result<()> {
        for l in level..self.top {
            let shift = l + 1 - level;
            let ancestor = [coord[0] >> shift, coord[1] >> shift, coord[2] >> shift];
            if self.pending[l as usize]
                .as_ref()
                .is_some_and(|p| p.parent != ancestor)
            {
                self.flush(l)?;
            }
        }
        Ok(())
    }

    /// Builds and writes the pending parent of `level`'s nodes.
    fn flush(&mut self, level: u32) -> Result<()> {
        let Some(p) = self.pending[level as usize].take() else {
            return Ok(());
        };
        // the children's voxels: wait for merges still running (this thread is not in the
        // pool, and pool tasks never wait, so this cannot deadlock)
        let mut kids: [NodeVoxels; 8] = Default::default();
        for (kid, child) in kids.iter_mut().zip(p.children) {
            *kid = match child {
                None => continue,
                Some(Child::Done(v)) => v,
                Some(Child::Merging(rx)) => rx.recv().map_err(|_| {
                    anyhow::anyhow!("a merge below level {} {:?} stopped", level + 1, p.parent)
                })?,
            };
        }
        let bytes = kids
            .iter()
            .map(|k| k.0.len() * std::mem::size_of::<Voxel>())
            .sum::<usize>();
        let (vtx, vrx) = mpsc::sync_channel(1);
        let (etx, erx) = mpsc::sync_channel(1);
        let zstd_level = self.zstd_level;
        self.pool.spawn(move || {
            let refs: [&[Voxel]; 8] = std::array::from_fn(|o| kids[o].0.as_slice());
            let any_mats = kids.iter().any(|k| k.1.is_some());
            let m: [&[u32]; 8] = std::array::from_fn(|o| kids[o].1.as_deref().unwrap_or(&[]));
            let (merged, mats) = if level == 0 {
                // the leaves' halves: a level-1 parent is their concatenation
                (refs.concat(), any_mats.then(|| m.concat()))
            } else {
                let mut merged = Vec::new();
                SCRATCH.with(|s| s.borrow_mut().merge(&refs, &mut merged));
                // the material LOD rule, where the children have materials (FORMAT.md 14.3)
                let mats = any_mats.then(|| merge_materials(&refs, &m));
                (merged, mats)
            };
            drop(kids);
            let merged = Arc::new((merged, mats));
            // a receiver is gone only if the build already failed
            let _ = vtx.send(Arc::clone(&merged));
            let enc = encode_node(&merged.0, zstd_level).and_then(|e| {
                let m = merged
                    .1
                    .as_ref()
                    .map(|m| encode_materials(m, zstd_level))
                    .transpose()?;
                Ok((e, m))
            });
            let _ = etx.send(enc);
        });
        let (voxels, payload) = (Child::Merging(vrx), Payload::Encoding(erx));
        let node = Queued {
            level: level + 1,
            coord: p.parent,
            child_mask: p.mask,
            payload,
            bytes: bytes as u64,
            source: None,
        };
        self.emit(node, voxels)
    }

    /// Appends a node to the write queue, then writes what is ready at its head (waiting for
    /// the head while the queue is over its bounds).
    fn enqueue(&mut self, q: Queued) -> Result<()> {
        self.queued_bytes += q.bytes;
        self.queue.push_back(q);
        self.drain(false)
    }

    /// Writes queued nodes in order: those already encoded, all of them if `all`, and while
    /// the queue is over its bounds.
    fn drain(&mut self, all: bool) -> Result<()> {
        loop {
            let over = self.queue.len() > QUEUE_NODES || self.queued_bytes > QUEUE_BYTES;
            let Some(head) = self.queue.front_mut() else {
                break;
            };
            let enc = match &mut head.payload {
                Payload::Ready(_) => None,
                Payload::Encoding(rx) if all || over => Some(rx.recv().map_err(|_| {
                    anyhow::anyhow!(
                        "the encoder of node level {} {:?} stopped",
                        head.level,
                        head.coord
                    )
                })?),
                Payload::Encoding(rx) => match rx.try_recv() {
                    Ok(r) => Some(r),
                    Err(mpsc::TryRecvError::Empty) => return Ok(()),
                    Err(mpsc::TryRecvError::Disconnected) => anyhow::bail!(
                        "the encoder of node level {} {:?} stopped",
                        head.level,
                        head.coord
                    ),
                },
            };
            if let Some(r) = enc {
                let enc = r.with_context(|| {
                    format!("encoding node level {} {:?}", head.level, head.coord)
                })?;
                head.payload = Payload::Ready(enc);
            }
            let q = self.queue.pop_front().expect("head exists");
            self.queued_bytes -= q.bytes;
            let Payload::Ready((enc, mat)) = &q.payload else {
                unreachable!("the head was made ready above")
            };
            self.stats[q.level as usize].nodes += 1;
            self.stats[q.level as usize].voxels += enc.voxel_count() as u64;
            // the file's channels in id order: material (1) if the build has it, then the
            // source triangles (2), which only leaves carry
            let mut channels: Vec<Option<&EncodedChannel>> = mat.iter().map(Some).collect();
            if q.source.is_some() {
                channels.push(q.source.as_ref());
            }
            self.writer
                .write_node_with(q.level, q.coord, q.child_mask, enc, &channels)
                .with_context(|| format!("writing node level {} {:?}", q.level, q.coord))?;
        }
        Ok(())
    }

    /// Completes every pending parent up to the top level and writes every queued node;
    /// returns the sink and the per-level statistics.
    pub fn finish_sink(mut self) -> Result<(W, Vec<LevelStats>)> {
        for level in 0..self.levels {
            self.flush(level)?;
        }
        self.drain(true)?;
        Ok((self.writer, self.stats))
    }

    /// Bytes of the file written so far.
    pub fn bytes_written(&self) -> u64 {
        self.writer.bytes_written()
    }

    /// Starts a stored subtree whose root is (level, coord) (the merge of a sharded build):
    /// completes and writes every earlier node, so that the subtree's nodes below its root
    /// can follow with [`write_stored`](Self::write_stored), then its root with
    /// [`push_stored_root`](Self::push_stored_root).
    pub fn begin_subtree(&mut self, level: u32, coord: [u32; 3]) -> Result<()> {
        anyhow::ensure!(
            self.pending[..level as usize].iter().all(Option::is_none),
            "subtree level {level} {coord:?} begun inside another one"
        );
        self.flush_before(level, coord)?;
        self.drain(true)
    }

    /// Writes a node of a stored subtree below its root, its payloads as stored (material
    /// channel, then the source triangles, each only if the file has the channel).
    pub fn write_stored(
        &mut self,
        level: u32,
        coord: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
        channels: &[Option<&EncodedChannel>],
    ) -> Result<()> {
        anyhow::ensure!(self.queue.is_empty(), "write_stored outside a subtree");
        self.stats[level as usize].nodes += 1;
        self.stats[level as usize].voxels += node.voxel_count() as u64;
        self.writer
            .write_node_with(level, coord, child_mask, node, channels)
            .with_context(|| format!("writing node level {level} {coord:?}"))
    }

    /// The root of a stored subtree: written as stored (`materials`, `source`: its channel
    /// payloads), and its parent built from `voxels` (at level 0 the leaf's half, as
    /// [`push_halved`](Self::push_halved) takes it; above, the node's voxels) and their
    /// materials.
    pub fn push_stored_root(
        &mut self,
        level: u32,
        coord: [u32; 3],
        child_mask: u8,
        payloads: StoredPayloads,
        voxels: (Vec<Voxel>, Option<Vec<u32>>),
    ) -> Result<()> {
        let (node, materials, source) = payloads;
        let q = Queued {
            level,
            coord,
            child_mask,
            payload: Payload::Ready((node, materials)),
            bytes: 0,
            source,
        };
        self.emit(q, Child::Done(Arc::new(voxels)))
    }
}

impl OctreeWriter<'_, Writer> {
    /// Completes every pending parent up to the root and finishes the file.
    /// `manifest` receives the final per-level statistics.
    pub fn finish(
        self,
        manifest: impl FnOnce(&[LevelStats]) -> serde_json::Value,
    ) -> Result<(u64, Vec<LevelStats>)> {
        let (writer, stats) = self.finish_sink()?;
        let size = writer
            .finish(&manifest(&stats))
            .context("finishing the output file")?;
        Ok((size, stats))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use std::path::Path;
    use voxlod_format::voxel::pack_color;
    use voxlod_format::FileSpec;
    use voxlod_geom::morton3;
    use voxlod_lod::merge_children;

    fn spec(levels: u32) -> FileSpec {
        FileSpec {
            resolution: 256 << (levels - 1),
            levels,
            mode: 0,
            origin: [0.0; 3],
            voxel_size: 1.0,
        }
    }

    /// Reference: the whole tree in memory, parents merged and encoded inline, nodes written
    /// by a recursive post-order walk.
    fn reference(path: &Path, levels: u32, leaves: &BTreeMap<u64, ([u32; 3], Vec<Voxel>)>) {
        fn walk(
            w: &mut Writer,
            level: u32,
            coord: [u32; 3],
            leaves: &BTreeMap<u64, ([u32; 3], Vec<Voxel>)>,
        ) -> Option<Vec<Voxel>> {
            let (voxels, mask) = if level == 0 {
                let (_, v) = leaves.get(&morton3(coord[0], coord[1], coord[2]))?;
                (v.clone(), 0u8)
            } else {
                let mut kids: [Vec<Voxel>; 8] = Default::default();
                let mut mask = 0u8;
                for (o, kid) in kids.iter_mut().enumerate() {
                    let o = o as u32;
                    let c = [
                        2 * coord[0] + (o & 1),
                        2 * coord[1] + (o >> 1 & 1),
                        2 * coord[2] + (o >> 2),
                    ];
                    if let Some(v) = walk(w, level - 1, c, leaves) {
                        *kid = v;
                        mask |= 1 << o;
                    }
                }
                if mask == 0 {
                    return None;
                }
                let refs: [&[Voxel]; 8] = std::array::from_fn(|o| kids[o].as_slice());
                (merge_children(&refs), mask)
            };
            w.write_node(level, coord, mask, &encode_node(&voxels, 3).unwrap())
                .unwrap();
            Some(voxels)
        }
        let mut w = Writer::create(path, spec(levels)).unwrap();
        walk(&mut w, levels - 1, [0; 3], leaves);
        w.finish(&serde_json::json!({})).unwrap();
    }

    impl OctreeWriter<'_> {
        /// A leaf with its half made here and, optionally, a source-triangle payload.
        fn push_leaf_with_source(
            &mut self,
            coord: [u32; 3],
            voxels: Vec<Voxel>,
            enc: EncodedNode,
            source: Option<EncodedChannel>,
        ) {
            let octant = (coord[0] & 1 | (coord[1] & 1) << 1 | (coord[2] & 1) << 2) as usize;
            let mut half = Vec::new();
            SCRATCH.with(|s| s.borrow_mut().halve(&voxels, octant, &mut half));
            self.push_halved(coord, half, None, Some(enc), None, source)
                .unwrap();
        }
    }

    /// Many parents (far more than the queue holds), some large enough to pass its byte bound:
    /// the pooled, queued writer gives the reference's bytes on 1 and 3 threads.
    #[test]
    fn pooled_encodes_write_the_reference_bytes() {
        let levels = 4; // 8³ leaf chunks
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rng = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let mut leaves = BTreeMap::new();
        for x in 0..8u32 {
            for y in 0..8u32 {
                for z in 0..8u32 {
                    if rng() % 3 == 0 {
                        continue;
                    }
                    // mostly small chunks, a few of ~1M voxels (12 MiB) to pass QUEUE_BYTES
                    let n = if rng() % 40 == 0 {
                        1 << 20
                    } else {
                        (rng() % 3000) as usize + 1
                    };
                    let mut codes: Vec<u32> = (0..n).map(|_| (rng() % (1 << 24)) as u32).collect();
                    codes.sort_unstable();
                    codes.dedup();
                    let v: Vec<Voxel> = codes
                        .iter()
                        .map(|&m| {
                            let p = voxlod_geom::demorton3(m as u64).map(|c| c as u8);
                            let r = rng();
                            Voxel::new(
                                p,
                                (r & 63) as u8,
                                // no −512 component (FORMAT.md section 6)
                                ((r >> 8) as u32 & 0x3fff_ffff) & !0x2008_0200,
                                pack_color([r as u8, (r >> 8) as u8, 7, 255]),
                            )
                        })
                        .collect();
                    leaves.insert(morton3(x, y, z), ([x, y, z], v));
                }
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let want = dir.path().join("reference.voxlod");
        reference(&want, levels, &leaves);
        let want = std::fs::read(want).unwrap();
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let path = dir.path().join(format!("t{threads}.voxlod"));
            let mut ow = OctreeWriter::new(
                Writer::create(&path, spec(levels)).unwrap(),
                levels,
                3,
                &pool,
            );
            for (coord, v) in leaves.values() {
                let enc = encode_node(v, 3).unwrap();
                ow.push_leaf(*coord, v.clone(), Some(enc), None).unwrap();
            }
            ow.finish(|_| serde_json::json!({})).unwrap();
            assert!(
                std::fs::read(&path).unwrap() == want,
                "{threads} threads: bytes differ from the reference"
            );
        }
    }

    /// Leaves with large source-triangle payloads queued behind parents whose encodes cannot
    /// run yet (the only pool thread is busy): the payloads the queue holds, recounted from
    /// its entries, never pass `QUEUE_BYTES`, so they stay inside the LOD share of the plan.
    #[test]
    fn queued_source_payloads_stay_within_the_queue_bound() {
        let levels = 3; // 4³ leaf chunks: leaves of a second subtree wait behind a parent
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("source.voxlod");
        let writer =
            Writer::create_with_channels(&path, spec(levels), &[voxlod_format::CHANNEL_TRIANGLES])
                .unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        pool.spawn(|| std::thread::sleep(std::time::Duration::from_millis(400)));
        let mut ow = OctreeWriter::new(writer, levels, 1, &pool);
        let payload = vec![7u8; 5 << 20];
        let source = EncodedChannel {
            payload_crc32: crc32fast::hash(&payload),
            payload,
            count: 1,
            voxel_count: 0,
        };
        let mut most = 0u64;
        for m in 0..24u64 {
            let coord = voxlod_geom::demorton3(m);
            let v = vec![Voxel::new([1, 2, 3], 1, 0, pack_color([9, 9, 9, 255]))];
            let enc = encode_node(&v, 1).unwrap();
            let src = (m >= 8).then(|| source.clone());
            ow.push_leaf_with_source(coord, v, enc, src);
            let held: u64 = ow
                .queue
                .iter()
                .filter_map(|q| q.source.as_ref())
                .map(|s| s.payload.len() as u64)
                .sum();
            assert!(
                held <= QUEUE_BYTES,
                "leaf {m}: {held} bytes of source payloads queued"
            );
            most = most.max(held);
        }
        assert!(most > QUEUE_BYTES / 2, "the queue never held much: {most}");
        ow.finish(|_| serde_json::json!({})).unwrap();
    }
}
