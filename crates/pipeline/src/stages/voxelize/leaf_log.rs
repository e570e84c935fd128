//! The leaf log: the voxelize stage's output, one record per leaf chunk in Morton order (empty
//! chunks included, so the record count is the resume position), each with its compressed
//! payload and its *half*: the leaf's voxels merged to its parent's resolution on the worker
//! that voxelized it (`voxlod_lod::MergeScratch::halve`), so that the LOD stage builds the
//! level-1 parents by concatenation and copies the leaf payloads into the file without
//! decoding them. Records are checksummed; after a kill, reopening keeps the valid prefix and
//! cuts off a torn tail, and the build continues with the next chunk.
//!
//! Record: a 64-byte [`RecordHeader`] (little-endian) followed by `payload_len` bytes: the
//! leaf's zstd frames (`frames_len` bytes: the voxels, then in a build with the material
//! channel the materials), then its half as `half_count` 12-byte voxel records
//! (`voxlod_format::Voxel`, three little-endian u32) and, with the material channel,
//! `half_count` little-endian u32 material ids.

use std::fs::{File, OpenOptions};
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use bytemuck::{Pod, Zeroable};
use voxlod_format::{EncodedNode, Voxel};

const MAGIC: u32 = u32::from_le_bytes(*b"LEAF");

/// Bytes of a [`RecordHeader`] on disk.
pub const RECORD_HEADER_BYTES: u64 = std::mem::size_of::<RecordHeader>() as u64;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RecordHeader {
    magic: u32,
    /// Index of the chunk in the bins layout (records are consecutive: 0, 1, 2, …).
    pub chunk: u32,
    pub coord: [u32; 3],
    pub voxel_count: u32,
    pub payload_len: u32,
    /// CRC-32 of the whole payload (frames and half).
    pub payload_crc32: u32,
    /// Triangles of this chunk the voxelizer skipped.
    pub skipped: u32,
    /// Bytes of the zstd frames at the start of the payload; the half follows.
    pub frames_len: u32,
    /// Voxels of the half (0 for an empty leaf, or when the leaf is the root).
    pub half_count: u32,
    /// The leaf's `EncodedNode` fields: CRC-32 of its voxel frame, of its decompressed block,
    /// and its bounds (min x y z, max x y z, two zero bytes).
    pub node_crc32: u32,
    pub block_crc32: u32,
    pub bounds: [u8; 8],
    header_crc32: u32,
}

const _: () = assert!(RECORD_HEADER_BYTES == 64);

impl RecordHeader {
    fn crc(&self) -> u32 {
        crc32fast::hash(&bytemuck::bytes_of(self)[..RECORD_HEADER_BYTES as usize - 4])
    }

    /// The leaf's bounds (min, max).
    pub fn bounds(&self) -> ([u8; 3], [u8; 3]) {
        let b = self.bounds;
        ([b[0], b[1], b[2]], [b[3], b[4], b[5]])
    }
}

/// One non-empty leaf as the voxelize stage appends it.
pub struct LeafRecord<'a> {
    /// The leaf's voxels, encoded.
    pub node: &'a EncodedNode,
    /// The material channel's payload (a second zstd frame; empty without the channel).
    pub materials: &'a [u8],
    /// The leaf's half (empty when the leaf is the root).
    pub half: &'a [Voxel],
    /// The half's materials, one per half voxel (empty without the material channel).
    pub half_materials: &'a [u32],
}

pub struct LeafLog {
    path: PathBuf,
    out: BufWriter<File>,
    records: u64,
    /// Totals over the records: skipped triangles, bytes of the leaves' zstd frames.
    skipped: u64,
    frame_bytes: u64,
}

impl LeafLog {
    /// Opens the log at `path`, keeping every valid record of an earlier run and truncating a
    /// torn or corrupt tail; creates it if missing.
    pub fn open(path: &Path) -> Result<LeafLog> {
        let mut f = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .with_context(|| format!("opening {}", path.display()))?;
        let len = f
            .metadata()
            .with_context(|| format!("reading {}", path.display()))?
            .len();
        let mut valid_end = 0u64;
        let mut records = 0u64;
        let (mut skipped, mut frame_bytes) = (0u64, 0u64);
        const HEAD: u64 = RECORD_HEADER_BYTES;
        {
            let mut r = BufReader::with_capacity(1 << 20, &mut f);
            let mut h = RecordHeader::zeroed();
            let mut payload = Vec::new();
            loop {
                if valid_end + HEAD > len || r.read_exact(bytemuck::bytes_of_mut(&mut h)).is_err() {
                    break;
                }
                if h.magic != MAGIC
                    || h.crc() != h.header_crc32
                    || h.chunk as u64 != records
                    || valid_end + HEAD + h.payload_len as u64 > len
                {
                    break;
                }
                payload.resize(h.payload_len as usize, 0);
                if r.read_exact(&mut payload).is_err()
                    || crc32fast::hash(&payload) != h.payload_crc32
                {
                    break;
                }
                valid_end += HEAD + h.payload_len as u64;
                records += 1;
                skipped += h.skipped as u64;
                frame_bytes += h.frames_len as u64;
            }
        }
        f.set_len(valid_end)
            .with_context(|| format!("truncating {}", path.display()))?;
        f.seek(SeekFrom::Start(valid_end))
            .with_context(|| format!("seeking in {}", path.display()))?;
        Ok(LeafLog {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(4 << 20, f),
            records,
            skipped,
            frame_bytes,
        })
    }

    /// Records already in the log: the next chunk to voxelize.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Triangles the voxelizer skipped, over the records in the log.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Bytes of the leaves' zstd frames in the log: what the octree file will hold of them.
    pub fn frame_bytes(&self) -> u64 {
        self.frame_bytes
    }

    /// Appends chunk `chunk`'s result (`None` for a chunk without voxels).
    pub fn append(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        leaf: Option<&LeafRecord>,
        skipped: u64,
    ) -> Result<()> {
        let mut parts: [&[u8]; 4] = [&[]; 4];
        let mut h = RecordHeader::zeroed();
        if let Some(r) = leaf {
            assert!(
                r.half_materials.is_empty() || r.half_materials.len() == r.half.len(),
                "one material per half voxel"
            );
            parts = [
                r.node.payload(),
                r.materials,
                bytemuck::cast_slice(r.half),
                bytemuck::cast_slice(r.half_materials),
            ];
            let (min, max) = r.node.bounds();
            h.bounds = [min[0], min[1], min[2], max[0], max[1], max[2], 0, 0];
            (h.node_crc32, h.block_crc32) = (r.node.payload_crc32(), r.node.block_crc32());
            h.voxel_count = r.node.voxel_count();
            h.half_count = r.half.len() as u32;
        }
        h.frames_len = (parts[0].len() + parts[1].len()) as u32;
        self.write_record(chunk, coord, h, &parts, skipped)
    }

    /// Appends a record of `count` items (triangles in the source log) whose payload is one
    /// frame, `payload` (no half, no node fields).
    pub fn append_record(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        count: u32,
        payload: &[u8],
        skipped: u64,
    ) -> Result<()> {
        let mut h = RecordHeader::zeroed();
        h.voxel_count = count;
        h.frames_len = payload.len() as u32;
        self.write_record(chunk, coord, h, &[payload], skipped)
    }

    /// Completes `h` (position, lengths, checksums) and writes it and `parts`, the payload.
    fn write_record(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        mut h: RecordHeader,
        parts: &[&[u8]],
        skipped: u64,
    ) -> Result<()> {
        if chunk != self.records {
            bail!(
                "log {}: chunk {chunk} appended after {} records",
                self.path.display(),
                self.records
            );
        }
        let mut crc = crc32fast::Hasher::new();
        parts.iter().for_each(|p| crc.update(p));
        h.magic = MAGIC;
        h.chunk = chunk as u32;
        h.coord = coord;
        h.payload_len = parts.iter().map(|p| p.len()).sum::<usize>() as u32;
        h.payload_crc32 = crc.finalize();
        h.skipped = skipped.min(u32::MAX as u64) as u32;
        h.header_crc32 = h.crc();
        let path = &self.path;
        for bytes in [bytemuck::bytes_of(&h)]
            .into_iter()
            .chain(parts.iter().copied())
        {
            self.out
                .write_all(bytes)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        self.records += 1;
        self.skipped += h.skipped as u64;
        self.frame_bytes += h.frames_len as u64;
        Ok(())
    }

    /// Flushes buffered records to the file (done at every batch, so a kill loses at most the
    /// batch in flight).
    pub fn flush(&mut self) -> Result<()> {
        self.out
            .flush()
            .with_context(|| format!("writing {}", self.path.display()))
    }

    /// Flushes and syncs the log.
    pub fn finish(mut self) -> Result<()> {
        self.flush()?;
        self.out
            .get_ref()
            .sync_all()
            .with_context(|| format!("syncing {}", self.path.display()))
    }
}

/// Reads a finished log record by record, checking each (the source log is read beside the
/// leaf log this way).
pub struct LogReader {
    path: PathBuf,
    r: BufReader<File>,
    expect: u64,
}

impl LogReader {
    /// Opens the log at `path` for reading from its first record.
    pub fn open(path: &Path) -> Result<LogReader> {
        let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
        Ok(LogReader {
            path: path.to_path_buf(),
            r: BufReader::with_capacity(4 << 20, file),
            expect: 0,
        })
    }

    /// The next record and its payload, checksums checked; `None` at the end.
    pub fn next_record(&mut self) -> Result<Option<(RecordHeader, Vec<u8>)>> {
        let (path, expect) = (&self.path, self.expect);
        let mut h = RecordHeader::zeroed();
        match self.r.read_exact(bytemuck::bytes_of_mut(&mut h)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(None),
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        }
        if h.magic != MAGIC || h.crc() != h.header_crc32 || h.chunk as u64 != expect {
            bail!("{}: record {expect} is corrupt", path.display());
        }
        let mut payload = vec![0u8; h.payload_len as usize];
        self.r
            .read_exact(&mut payload)
            .with_context(|| format!("{}: record {expect} is truncated", path.display()))?;
        if crc32fast::hash(&payload) != h.payload_crc32 {
            bail!("{}: record {expect}'s payload is corrupt", path.display());
        }
        self.expect += 1;
        Ok(Some((h, payload)))
    }
}

/// Reads a finished log in order, handing each record and its payload to `f`.
pub fn read_log(
    path: &Path,
    f: &mut dyn FnMut(&RecordHeader, Vec<u8>) -> Result<()>,
) -> Result<()> {
    let mut r = LogReader::open(path)?;
    while let Some((h, payload)) = r.next_record()? {
        f(&h, payload)?;
    }
    Ok(())
}

/// A non-empty leaf read back from the log.
pub struct StoredLeaf {
    /// The leaf's voxels, encoded, as the voxelize stage's `encode_node` made them.
    pub node: EncodedNode,
    /// The material channel's frame (empty without the channel).
    pub materials: Vec<u8>,
    /// The leaf's half, and its materials in a build with the material channel.
    pub half: Vec<Voxel>,
    pub half_materials: Option<Vec<u32>>,
}

impl StoredLeaf {
    /// Splits the payload of a non-empty leaf's record (as [`read_log`] hands it on, its
    /// checksum checked) into its parts; `materials`: the build has the material channel.
    pub fn split(h: &RecordHeader, mut payload: Vec<u8>, materials: bool) -> Result<StoredLeaf> {
        let what = || format!("leaf log record {}", h.chunk);
        let (frames, half) = (h.frames_len as usize, h.half_count as usize);
        let per_voxel = std::mem::size_of::<Voxel>() + if materials { 4 } else { 0 };
        if h.voxel_count == 0 || frames + half * per_voxel != payload.len() {
            bail!(
                "{}: {} payload bytes do not hold {frames} bytes of frames and a half of {half} voxels",
                what(),
                payload.len()
            );
        }
        let rest = payload.split_off(frames);
        let (voxel_bytes, mat_bytes) = rest.split_at(half * std::mem::size_of::<Voxel>());
        let mut voxels = vec![Voxel::zeroed(); half];
        bytemuck::cast_slice_mut(&mut voxels).copy_from_slice(voxel_bytes);
        let half_materials = materials.then(|| {
            mat_bytes
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()
        });
        // the voxel frame, then (with the channel) the material frame
        let voxel_frame = if materials {
            voxlod_format::channel::first_frame_len(&payload)
                .map_err(anyhow::Error::msg)
                .with_context(what)?
        } else {
            payload.len()
        };
        let materials = payload.split_off(voxel_frame);
        let node = EncodedNode::from_stored(
            payload,
            h.voxel_count,
            h.node_crc32,
            h.block_crc32,
            h.bounds(),
        )
        .with_context(what)?;
        Ok(StoredLeaf {
            node,
            materials,
            half: voxels,
            half_materials,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torn_tail_is_cut_and_appending_continues() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("leaves.bin");
        let v: Vec<Voxel> = (0..100u32)
            .map(|i| Voxel::new([i as u8, 0, 0], 1, 0, i))
            .collect();
        let enc = voxlod_format::encode_node(&v, 3).unwrap();
        let mut half = Vec::new();
        voxlod_lod::MergeScratch::new().halve(&v, 0, &mut half);
        let leaf = LeafRecord {
            node: &enc,
            materials: &[],
            half: &half,
            half_materials: &[],
        };
        let record_bytes = enc.payload().len() + 12 * half.len();
        let mut log = LeafLog::open(&p).unwrap();
        log.append(0, [0, 0, 0], Some(&leaf), 0).unwrap();
        log.append(1, [1, 0, 0], None, 2).unwrap();
        log.append(2, [0, 1, 0], Some(&leaf), 0).unwrap();
        log.finish().unwrap();
        let full = std::fs::metadata(&p).unwrap().len();
        assert_eq!(full, 3 * RECORD_HEADER_BYTES + 2 * record_bytes as u64);
        // a kill in the middle of record 2
        let f = OpenOptions::new().write(true).open(&p).unwrap();
        f.set_len(full - 7).unwrap();
        let mut log = LeafLog::open(&p).unwrap();
        assert_eq!(log.records(), 2);
        // the totals of the kept records
        assert_eq!(
            (log.skipped(), log.frame_bytes()),
            (2, enc.payload().len() as u64)
        );
        assert!(log.append(5, [0; 3], None, 0).is_err());
        log.append(2, [0, 1, 0], Some(&leaf), 0).unwrap();
        log.finish().unwrap();
        assert_eq!(std::fs::metadata(&p).unwrap().len(), full);
        let mut seen = vec![];
        read_log(&p, &mut |h, pl| {
            seen.push((h.chunk, h.voxel_count, pl.len(), h.skipped));
            if h.voxel_count > 0 {
                // the parts come back as they went in: the same encoded node, the same half
                let back = StoredLeaf::split(h, pl, false)?;
                assert_eq!(back.node, enc);
                assert_eq!(back.half, half);
                assert!(back.materials.is_empty() && back.half_materials.is_none());
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(
            seen,
            vec![
                (0, 100, record_bytes, 0),
                (1, 0, 0, 2),
                (2, 100, record_bytes, 0)
            ]
        );
        // a flipped payload byte is caught by reopening (record dropped) and by reading
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[RECORD_HEADER_BYTES as usize + 5] ^= 1;
        std::fs::write(&p, &bytes).unwrap();
        assert!(read_log(&p, &mut |_, _| Ok(())).is_err());
        assert_eq!(LeafLog::open(&p).unwrap().records(), 0);
    }

    /// With the material channel: the voxel frame, the material frame, the half and its
    /// materials come back apart; a record whose sizes do not add up is an error.
    #[test]
    fn material_leaf_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("leaves.bin");
        let v: Vec<Voxel> = (0..64u32)
            .map(|i| Voxel::new([i as u8, i as u8 % 4, 0], 2, 0, i))
            .collect();
        let enc = voxlod_format::encode_node(&v, 1).unwrap();
        let mats: Vec<u32> = (0..64).map(|i| i % 3).collect();
        let menc = voxlod_format::encode_materials(&mats, 1).unwrap();
        let mut half = Vec::new();
        voxlod_lod::MergeScratch::new().halve(&v, 5, &mut half);
        let half_mats = voxlod_lod::halve_materials(&v, &mats);
        let mut log = LeafLog::open(&p).unwrap();
        let leaf = LeafRecord {
            node: &enc,
            materials: &menc.payload,
            half: &half,
            half_materials: &half_mats,
        };
        log.append(0, [1, 0, 1], Some(&leaf), 0).unwrap();
        log.finish().unwrap();
        let mut n = 0;
        read_log(&p, &mut |h, pl| {
            assert!(StoredLeaf::split(h, pl.clone(), false).is_err());
            let back = StoredLeaf::split(h, pl, true)?;
            assert_eq!(back.node, enc);
            assert_eq!(back.materials, menc.payload);
            assert_eq!(back.half, half);
            assert_eq!(back.half_materials.as_ref(), Some(&half_mats));
            n += 1;
            Ok(())
        })
        .unwrap();
        assert_eq!(n, 1);
    }
}
