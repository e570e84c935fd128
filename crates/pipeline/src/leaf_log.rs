//! The leaf log: the voxelize stage's output, one record per leaf chunk in Morton order (empty
//! chunks included, so the record count is the resume position), each with its compressed
//! payload. Records are checksummed; after a kill, reopening keeps the valid prefix and cuts
//! off a torn tail, and the build continues with the next chunk.
//!
//! Record: a 40-byte [`RecordHeader`] (little-endian) followed by `payload_len` bytes.

use std::fs::{File, OpenOptions};
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use bytemuck::{Pod, Zeroable};
use voxlod_format::EncodedNode;

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
    pub payload_crc32: u32,
    /// Triangles of this chunk the voxelizer skipped.
    pub skipped: u32,
    header_crc32: u32,
}

impl RecordHeader {
    fn crc(&self) -> u32 {
        crc32fast::hash(&bytemuck::bytes_of(self)[..36])
    }
}

pub struct LeafLog {
    path: PathBuf,
    out: BufWriter<File>,
    records: u64,
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
        {
            let mut r = BufReader::with_capacity(1 << 20, &mut f);
            let mut h = RecordHeader::zeroed();
            let mut payload = Vec::new();
            loop {
                if valid_end + 40 > len || r.read_exact(bytemuck::bytes_of_mut(&mut h)).is_err() {
                    break;
                }
                if h.magic != MAGIC
                    || h.crc() != h.header_crc32
                    || h.chunk as u64 != records
                    || valid_end + 40 + h.payload_len as u64 > len
                {
                    break;
                }
                payload.resize(h.payload_len as usize, 0);
                if r.read_exact(&mut payload).is_err()
                    || crc32fast::hash(&payload) != h.payload_crc32
                {
                    break;
                }
                valid_end += 40 + h.payload_len as u64;
                records += 1;
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
        })
    }

    /// Records already in the log: the next chunk to voxelize.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Appends chunk `chunk`'s result (`None` for a chunk without voxels).
    #[cfg(test)]
    pub fn append(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        node: Option<&EncodedNode>,
        skipped: u64,
    ) -> Result<()> {
        self.append_with(chunk, coord, node, &[], skipped)
    }

    /// [`append`](Self::append) with `extra` bytes after the node's payload, in the same
    /// checksummed record (the material channel's payload: a second zstd frame).
    pub fn append_with(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        node: Option<&EncodedNode>,
        extra: &[u8],
        skipped: u64,
    ) -> Result<()> {
        let joined;
        let payload = match node {
            Some(n) if !extra.is_empty() => {
                joined = [n.payload(), extra].concat();
                &joined[..]
            }
            _ => node.map_or(&[][..], |n| n.payload()),
        };
        let count = node.map_or(0, |n| n.voxel_count());
        self.append_record(chunk, coord, count, payload, skipped)
    }

    /// Appends a record of `count` items (voxels; triangles in the source log) with `payload`.
    pub fn append_record(
        &mut self,
        chunk: u64,
        coord: [u32; 3],
        count: u32,
        payload: &[u8],
        skipped: u64,
    ) -> Result<()> {
        if chunk != self.records {
            bail!(
                "log {}: chunk {chunk} appended after {} records",
                self.path.display(),
                self.records
            );
        }
        let mut h = RecordHeader {
            magic: MAGIC,
            chunk: chunk as u32,
            coord,
            voxel_count: count,
            payload_len: payload.len() as u32,
            payload_crc32: crc32fast::hash(payload),
            skipped: skipped.min(u32::MAX as u64) as u32,
            header_crc32: 0,
        };
        h.header_crc32 = h.crc();
        let path = &self.path;
        self.out
            .write_all(bytemuck::bytes_of(&h))
            .with_context(|| format!("writing {}", path.display()))?;
        self.out
            .write_all(payload)
            .with_context(|| format!("writing {}", path.display()))?;
        self.records += 1;
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

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_format::voxel::Voxel;

    #[test]
    fn torn_tail_is_cut_and_appending_continues() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("leaves.bin");
        let v: Vec<Voxel> = (0..100u32)
            .map(|i| Voxel::new([i as u8, 0, 0], 1, 0, i))
            .collect();
        let enc = voxlod_format::encode_node(&v, 3).unwrap();
        let mut log = LeafLog::open(&p).unwrap();
        log.append(0, [0, 0, 0], Some(&enc), 0).unwrap();
        log.append(1, [1, 0, 0], None, 2).unwrap();
        log.append(2, [0, 1, 0], Some(&enc), 0).unwrap();
        log.finish().unwrap();
        let full = std::fs::metadata(&p).unwrap().len();
        // a kill in the middle of record 2
        let f = OpenOptions::new().write(true).open(&p).unwrap();
        f.set_len(full - 7).unwrap();
        let mut log = LeafLog::open(&p).unwrap();
        assert_eq!(log.records(), 2);
        assert!(log.append(5, [0; 3], None, 0).is_err());
        log.append(2, [0, 1, 0], Some(&enc), 0).unwrap();
        log.finish().unwrap();
        assert_eq!(std::fs::metadata(&p).unwrap().len(), full);
        let mut seen = vec![];
        read_log(&p, &mut |h, pl| {
            seen.push((h.chunk, h.voxel_count, pl.len(), h.skipped));
            Ok(())
        })
        .unwrap();
        assert_eq!(
            seen,
            vec![
                (0, 100, enc.payload().len(), 0),
                (1, 0, 0, 2),
                (2, 100, enc.payload().len(), 0)
            ]
        );
        // a flipped payload byte is caught by reopening (record dropped) and by reading
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[45] ^= 1;
        std::fs::write(&p, &bytes).unwrap();
        assert!(read_log(&p, &mut |_, _| Ok(())).is_err());
        assert_eq!(LeafLog::open(&p).unwrap().records(), 0);
    }
}
