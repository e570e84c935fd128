//! The shard file (`shard-IIII.vlshard`, docs/FORMAT.md "Shard files"): the LOD stage's
//! artifact restricted to one shard's Morton range of subtrees. It holds the subtrees' nodes
//! in post-order, each payload encoded exactly as the octree file stores it, and their index
//! entries, under a header naming the plan (its SHA-256) and the shard; the merge copies the
//! payloads into the octree file without decoding them (only the subtree roots are decoded).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use voxlod_format::channel::ChannelEntry;
use voxlod_format::{EncodedChannel, EncodedNode, NodeEntry};

use crate::stages::lod_write::octree_writer::NodeSink;

/// The first 8 bytes of a shard file.
pub const MAGIC: &[u8; 8] = b"VLSHARD\0";
/// Version of the shard file layout.
pub const SHARD_VERSION: u32 = 1;
/// Bytes of the header.
const HEADER_SIZE: u64 = 128;
/// At most this many channels (the format defines fewer: room for new kinds without a new
/// shard file version).
const MAX_CHANNELS: usize = 4;
/// Bytes of one channel entry.
const CHANNEL_ENTRY: usize = 24;

/// What a shard file says about itself (its header).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShardHeader {
    /// 0-based shard index.
    pub index: u32,
    /// Shards in the plan.
    pub count: u32,
    /// Level of the subtree roots.
    pub split_level: u32,
    /// Levels of the octree.
    pub levels: u32,
    /// SHA-256 of the plan file.
    pub plan_sha256: [u8; 32],
    /// The octree's channel ids, increasing.
    pub channels: Vec<u32>,
}

impl ShardHeader {
    /// The 128 header bytes, for `node_count` nodes whose index starts at `index_offset`.
    fn to_bytes(&self, node_count: u64, index_offset: u64, total_voxels: u64, crc: u32) -> Vec<u8> {
        let mut h = Vec::with_capacity(HEADER_SIZE as usize);
        h.extend_from_slice(MAGIC);
        for v in [SHARD_VERSION, HEADER_SIZE as u32, self.index, self.count] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        for v in [self.split_level, self.levels] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.extend_from_slice(&self.plan_sha256);
        h.extend_from_slice(&(self.channels.len() as u32).to_le_bytes());
        for k in 0..MAX_CHANNELS {
            h.extend_from_slice(&self.channels.get(k).copied().unwrap_or(0).to_le_bytes());
        }
        h.extend_from_slice(&0u32.to_le_bytes());
        let index_size = node_count * self.record_size();
        for v in [node_count, index_offset, index_size, total_voxels] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.extend_from_slice(&crc.to_le_bytes());
        let header_crc = crc32fast::hash(&h);
        h.extend_from_slice(&header_crc.to_le_bytes());
        debug_assert_eq!(h.len() as u64, HEADER_SIZE);
        h
    }

    /// Bytes of one index record: the node entry and one entry per channel.
    fn record_size(&self) -> u64 {
        64 + (CHANNEL_ENTRY * self.channels.len()) as u64
    }
}

/// Writes a shard file at a path (the build's staged name; the caller renames it).
pub struct ShardWriter {
    path: PathBuf,
    file: BufWriter<File>,
    header: ShardHeader,
    index: Vec<u8>,
    nodes: u64,
    offset: u64,
    total_voxels: u64,
}

impl ShardWriter {
    /// Creates the file and writes a zero header (an unfinished shard has a bad magic).
    pub fn create(path: &Path, header: ShardHeader) -> Result<ShardWriter> {
        assert!(header.channels.len() <= MAX_CHANNELS, "too many channels");
        let mut file = BufWriter::with_capacity(
            1 << 20,
            File::create(path).with_context(|| format!("{}: cannot create", path.display()))?,
        );
        file.write_all(&[0; HEADER_SIZE as usize])
            .with_context(|| format!("{}: writing the header", path.display()))?;
        Ok(ShardWriter {
            path: path.to_path_buf(),
            file,
            header,
            index: Vec::new(),
            nodes: 0,
            offset: HEADER_SIZE,
            total_voxels: 0,
        })
    }

    fn write(&mut self, bytes: &[u8]) -> Result<u64> {
        let at = self.offset;
        self.file
            .write_all(bytes)
            .with_context(|| format!("{}: writing a payload", self.path.display()))?;
        self.offset += bytes.len() as u64;
        Ok(at)
    }

    /// Writes the index and the header, and syncs the file.
    pub fn finish(mut self) -> Result<u64> {
        let index = std::mem::take(&mut self.index);
        let index_offset = self.write(&index)?;
        let head = self.header.to_bytes(
            self.nodes,
            index_offset,
            self.total_voxels,
            crc32fast::hash(&index),
        );
        let mut f = self
            .file
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("{}: writing", self.path.display()))?;
        f.seek(SeekFrom::Start(0))
            .and_then(|_| f.write_all(&head))
            .and_then(|()| f.sync_all())
            .with_context(|| format!("{}: writing the header", self.path.display()))?;
        Ok(self.offset)
    }
}

impl NodeSink for ShardWriter {
    fn write_node_with(
        &mut self,
        level: u32,
        pos: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
        channels: &[Option<&EncodedChannel>],
    ) -> Result<()> {
        ensure!(
            level <= self.header.split_level,
            "shard node level {level} above the split level {}",
            self.header.split_level
        );
        let (bounds_min, bounds_max) = node.bounds();
        let entry = NodeEntry {
            level,
            x: pos[0],
            y: pos[1],
            z: pos[2],
            voxel_count: node.voxel_count(),
            child_mask: child_mask as u32,
            payload_offset: self.write(node.payload())?,
            payload_size: node.payload().len() as u64,
            payload_crc32: node.payload_crc32(),
            block_crc32: node.block_crc32(),
            bounds_min: [bounds_min[0], bounds_min[1], bounds_min[2], 0],
            bounds_max: [bounds_max[0], bounds_max[1], bounds_max[2], 0],
            reserved: [0; 2],
        };
        let mut record = bytemuck::bytes_of(&entry).to_vec();
        for k in 0..self.header.channels.len() {
            let e = match channels.get(k).copied().flatten() {
                Some(c) => ChannelEntry {
                    payload_offset: self.write(&c.payload)?,
                    payload_size: c.payload.len() as u64,
                    payload_crc32: c.payload_crc32,
                    count: c.count,
                },
                None => ChannelEntry::default(),
            };
            record.extend_from_slice(bytemuck::bytes_of(&e));
        }
        self.index.extend_from_slice(&record);
        self.nodes += 1;
        self.total_voxels += node.voxel_count() as u64;
        Ok(())
    }

    fn bytes_written(&self) -> u64 {
        self.offset
    }
}

/// One node of a shard: its index entry and its channel entries.
#[derive(Clone, Debug)]
pub struct ShardNode {
    /// The node entry (payload offset within the shard file).
    pub entry: NodeEntry,
    /// One entry per channel of the header.
    pub channels: Vec<ChannelEntry>,
}

/// A shard file opened and checked (header, index checksum, sizes, payload placement).
pub struct ShardReader {
    path: PathBuf,
    file: File,
    /// Its header.
    pub header: ShardHeader,
    /// Its nodes, in post-order.
    pub nodes: Vec<ShardNode>,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

impl ShardReader {
    /// Opens `path`; any damage to the header or the index is an error naming the file.
    pub fn open(path: &Path) -> Result<ShardReader> {
        // only a regular file: a FIFO would block the merge forever
        let file = voxlod_io::open_regular(path)
            .with_context(|| format!("{}: cannot open", path.display()))?;
        let r = Self::read(path, file);
        r.with_context(|| format!("{}: not a complete shard file", path.display()))
    }

    fn read(path: &Path, file: File) -> Result<ShardReader> {
        let size = file.metadata()?.len();
        let mut h = [0u8; HEADER_SIZE as usize];
        file.read_exact_at(&mut h, 0)
            .context("shorter than a header (128 bytes)")?;
        ensure!(
            &h[..8] == MAGIC,
            "bad magic (an unfinished or foreign file)"
        );
        ensure!(
            u32_at(&h, 124) == crc32fast::hash(&h[..124]),
            "header checksum mismatch"
        );
        let version = u32_at(&h, 8);
        ensure!(
            version == SHARD_VERSION && u32_at(&h, 12) == HEADER_SIZE as u32,
            "shard version {version}, this tool reads {SHARD_VERSION}"
        );
        let channel_count = u32_at(&h, 64) as usize;
        ensure!(channel_count <= MAX_CHANNELS, "{channel_count} channels");
        let header = ShardHeader {
            index: u32_at(&h, 16),
            count: u32_at(&h, 20),
            split_level: u32_at(&h, 24),
            levels: u32_at(&h, 28),
            plan_sha256: h[32..64].try_into().expect("32 bytes"),
            channels: (0..channel_count).map(|k| u32_at(&h, 68 + 4 * k)).collect(),
        };
        let (nodes, index_offset, index_size) = (u64_at(&h, 88), u64_at(&h, 96), u64_at(&h, 104));
        ensure!(
            index_size == nodes.saturating_mul(header.record_size())
                && index_offset >= HEADER_SIZE
                && index_offset.checked_add(index_size) == Some(size),
            "index of {nodes} nodes at {index_offset} does not end the file of {size} bytes"
        );
        let mut index = vec![0u8; index_size as usize];
        file.read_exact_at(&mut index, index_offset)
            .context("reading the index")?;
        ensure!(
            crc32fast::hash(&index) == u32_at(&h, 120),
            "index checksum mismatch"
        );
        let nodes = parse_index(&index, &header, index_offset)?;
        ensure!(
            nodes
                .iter()
                .map(|n| n.entry.voxel_count as u64)
                .sum::<u64>()
                == u64_at(&h, 112),
            "total voxel count differs from the index"
        );
        Ok(ShardReader {
            path: path.to_path_buf(),
            file,
            header,
            nodes,
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Reads `size` bytes at `offset` and checks their CRC-32.
    pub fn payload(&self, offset: u64, size: u64, crc: u32) -> Result<Vec<u8>> {
        let mut b = vec![0u8; size as usize];
        self.file
            .read_exact_at(&mut b, offset)
            .with_context(|| format!("{}: reading a payload", self.path.display()))?;
        if crc32fast::hash(&b) != crc {
            bail!(
                "{}: payload checksum mismatch at offset {offset} (a corrupt shard)",
                self.path.display()
            );
        }
        Ok(b)
    }
}

/// The index records, checked: payloads back to back from the header to the index, levels at
/// most the split level.
fn parse_index(index: &[u8], h: &ShardHeader, index_offset: u64) -> Result<Vec<ShardNode>> {
    let rec = h.record_size() as usize;
    let mut at = HEADER_SIZE;
    let mut nodes = Vec::with_capacity(index.len() / rec.max(1));
    for r in index.chunks_exact(rec) {
        let entry: NodeEntry = bytemuck::pod_read_unaligned(&r[..64]);
        let channels: Vec<ChannelEntry> = r[64..]
            .chunks_exact(CHANNEL_ENTRY)
            .map(bytemuck::pod_read_unaligned)
            .collect();
        ensure!(
            entry.level <= h.split_level && entry.payload_offset == at && entry.voxel_count > 0,
            "node {} (level {} {:?}) is out of place",
            nodes.len(),
            entry.level,
            entry.pos()
        );
        at += entry.payload_size;
        for c in &channels {
            if c.payload_size > 0 {
                ensure!(c.payload_offset == at, "a channel payload is out of place");
                at += c.payload_size;
            }
        }
        nodes.push(ShardNode { entry, channels });
    }
    ensure!(at == index_offset, "the payloads do not end at the index");
    Ok(nodes)
}
