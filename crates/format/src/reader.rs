//! The validating reader: reads the header, the index and the manifest, checks them and every
//! index entry up front (so a corrupt file fails at `open` with a message naming what is
//! wrong), and checks each payload's checksums when a node is read. Nothing in a file can make
//! it panic.
//!
//! Payloads are read with positioned reads (`pread`), not through a memory map: a file that
//! is truncated or rewritten while it is open (by `cp`, `truncate`, or another build renaming
//! over it only changes the path, never the open file) gives an error from the next read — a
//! short read or a checksum mismatch — where a map would kill the process with SIGBUS.
//! FORMAT.md ("Files that change while they are read") states the contract.

use std::cell::RefCell;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use crate::block::unshuffle;
use crate::channel::{
    decode_material_block, material_block_size, ChannelDirectory, CHANNEL_MATERIAL,
    CHANNEL_TRIANGLES, MAX_MATERIAL_TABLE,
};
use crate::layout::{
    child_pos, order_key, Header, NodeEntry, HEADER_SIZE, MAGIC, NODE_ENTRY_SIZE, VERSION,
    VERSION_CHANNELS,
};
use crate::rules::{check_frame, check_frame_of, check_manifest};
use crate::triangles::{decode_source, SourceMesh, MAX_TRIANGLES};
use crate::voxel::Voxel;
use crate::{FileSpec, FormatError, MAX_NODE_VOXELS};

/// A voxlod file opened for reading. `Send + Sync`: threads may read nodes concurrently.
pub struct Reader {
    path: PathBuf,
    file: File,
    /// File size at `open`.
    len: u64,
    header: Header,
    nodes: Vec<NodeEntry>,
    manifest: Vec<u8>,
    /// the optional channels (version 2; empty for version 1)
    channels: ChannelDirectory,
}

impl std::fmt::Debug for Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reader")
            .field("path", &self.path)
            .field("header", &self.header)
            .finish_non_exhaustive()
    }
}

impl Reader {
    /// Opens and validates `path`: the header (magic, version, size, checksum, fields), that
    /// the index and manifest lie inside the file and the file ends with the manifest, the
    /// index and manifest checksums, and every entry (level and position inside the grid,
    /// voxel count in 1..=256³, payload range inside the payload region and right after the
    /// previous payload, bounds, reserved fields, index order, child masks exactly the stored
    /// children, every node below the root with its parent, total voxel count) and that the
    /// padding before the index is 0–7 zero bytes — so every byte of the file is checked by
    /// `open` or by the checksums [`read_node_into`](Self::read_node_into) verifies.
    ///
    /// The file may change while the reader is alive: what is read afterwards then fails with
    /// an error (a short read or a checksum mismatch), never a crash.
    pub fn open(path: &Path) -> Result<Reader, FormatError> {
        // FORMAT.md's layout, in file order.
        let io = |op: &'static str| {
            move |source| FormatError::Io {
                path: path.to_owned(),
                op,
                source,
            }
        };
        let head = |what: String| FormatError::Header {
            path: path.to_owned(),
            what,
        };
        // opened without blocking: a FIFO with no writer is refused, not waited on
        let file = match voxlod_io::open_regular(path) {
            Ok(f) => f,
            Err(voxlod_io::BoundError::Io(e)) => return Err(io("opening")(e)),
            Err(voxlod_io::BoundError::NotRegular("a folder")) => {
                return Err(head("it is a directory, not a voxlod file".into()))
            }
            Err(_) => {
                return Err(head(
                    "it is not a regular file (a device, FIFO or socket), not a voxlod file".into(),
                ))
            }
        };
        let meta = file.metadata().map_err(io("reading the file size"))?;
        let len = meta.len();
        if len < HEADER_SIZE as u64 {
            return Err(head(format!(
                "the file is {len} bytes, shorter than the {HEADER_SIZE}-byte header"
            )));
        }
        let read = |offset: u64, size: u64, what: &str| -> Result<Vec<u8>, FormatError> {
            let mut buf = vec![0u8; size as usize];
            read_at(&file, &mut buf, offset).map_err(|e| match e {
                ReadAtError::Short => head(format!(
                    "the file ended before its {what} [{offset}, +{size}): it was truncated while being opened"
                )),
                ReadAtError::Io(source) => FormatError::Io {
                    path: path.to_owned(),
                    op: "reading",
                    source,
                },
            })?;
            Ok(buf)
        };
        let h: Header = bytemuck::pod_read_unaligned(&read(0, HEADER_SIZE as u64, "header")?);
        check_header(&h, len).map_err(head)?;

        let index_err = |what: String| FormatError::Index {
            path: path.to_owned(),
            what,
        };
        // the header check bounded both ranges by the file size
        let index = read(h.index_offset, h.index_size, "node index")?;
        let crc = crc32fast::hash(&index);
        if crc != h.index_crc32 {
            return Err(index_err(format!(
                "checksum mismatch (header says {:08x}, index has {crc:08x})",
                h.index_crc32
            )));
        }
        let manifest = read(h.manifest_offset, h.manifest_size, "manifest")?;
        let crc = crc32fast::hash(&manifest);
        if crc != h.manifest_crc32 {
            return Err(FormatError::Manifest {
                path: path.to_owned(),
                what: format!(
                    "checksum mismatch (header says {:08x}, manifest has {crc:08x})",
                    h.manifest_crc32
                ),
            });
        }
        // FORMAT.md 11.2: the manifest rules every reader applies
        check_manifest(&manifest).map_err(|what| FormatError::Manifest {
            path: path.to_owned(),
            what,
        })?;
        let nodes: Vec<NodeEntry> = index
            .chunks_exact(NODE_ENTRY_SIZE as usize)
            .map(bytemuck::pod_read_unaligned)
            .collect();
        // version 2: the channel directory between the index and the manifest (FORMAT.md 14.1)
        let mut channels = ChannelDirectory::default();
        if h.version == VERSION_CHANNELS {
            let start = h.index_offset + h.index_size;
            let bytes = read(start, h.manifest_offset - start, "channel directory")?;
            let crc = crc32fast::hash(&bytes);
            if crc != h.channels_crc32 {
                return Err(index_err(format!(
                    "channel directory checksum mismatch (header says {:08x}, directory has {crc:08x})",
                    h.channels_crc32
                )));
            }
            channels = ChannelDirectory::parse(&bytes, h.node_count).map_err(index_err)?;
        }
        let reader = Reader {
            path: path.to_owned(),
            file,
            len,
            header: h,
            nodes,
            manifest,
            channels,
        };
        reader.check_entries()?;
        Ok(reader)
    }

    fn node_error(&self, index: usize, what: String) -> FormatError {
        let e = &self.nodes[index];
        FormatError::Node {
            path: self.path.clone(),
            index,
            level: e.level,
            pos: e.pos(),
            what,
        }
    }

    /// Per-entry checks, then the tree structure (child masks, parents).
    fn check_entries(&self) -> Result<(), FormatError> {
        // FORMAT.md's index rules, in the order the document lists them.
        let spec = self.spec();
        let h = &self.header;
        let mut prev_end = HEADER_SIZE as u64;
        let mut total = 0u64;
        let mut prev_key = None;
        for (i, e) in self.nodes.iter().enumerate() {
            let bad = |what: String| Err(self.node_error(i, what));
            if e.level >= h.levels {
                return bad(format!(
                    "level {} but the file has {} levels",
                    e.level, h.levels
                ));
            }
            if !spec.contains_node(e.level, e.pos()) {
                return bad(format!(
                    "position outside the level's grid of {} chunks per axis",
                    spec.chunks_per_axis(e.level)
                ));
            }
            if e.voxel_count == 0 || e.voxel_count > MAX_NODE_VOXELS {
                return bad(format!(
                    "voxel count {} is outside 1..={MAX_NODE_VOXELS}",
                    e.voxel_count
                ));
            }
            if e.child_mask > 0xff || (e.level == 0 && e.child_mask != 0) {
                return bad(format!(
                    "child mask {:#x} is invalid at level {}",
                    e.child_mask, e.level
                ));
            }
            // payloads are back to back in index order, so every byte of the file is checked
            let end = e.payload_offset.checked_add(e.payload_size);
            match end {
                Some(end) if e.payload_size > 0 && e.payload_offset == prev_end && end <= h.index_offset => prev_end = end,
                _ => {
                    return bad(format!(
                        "payload at {} of {} bytes is not inside the payload region [{HEADER_SIZE}, {}) right after the previous payload (at {prev_end})",
                        e.payload_offset, e.payload_size, h.index_offset
                    ))
                }
            }
            // then the node's channel payloads, in directory order (FORMAT.md 14.2)
            for (d, table) in self.channels.descriptors.iter().zip(&self.channels.entries) {
                let c = table[i];
                if c.payload_size == 0 {
                    if c.payload_offset != 0 || c.payload_crc32 != 0 || c.count != 0 {
                        return bad(format!(
                            "channel {}: an entry without payload has non-zero fields",
                            d.id
                        ));
                    }
                    if d.id == CHANNEL_MATERIAL {
                        return bad(
                            "no material payload (the material channel has one for every node)"
                                .into(),
                        );
                    }
                    continue;
                }
                match c.payload_offset.checked_add(c.payload_size) {
                    Some(end) if c.payload_offset == prev_end && end <= h.index_offset => prev_end = end,
                    _ => {
                        return bad(format!(
                            "channel {} payload at {} of {} bytes is not inside the payload region right after the previous payload (at {prev_end})",
                            d.id, c.payload_offset, c.payload_size
                        ))
                    }
                }
                if d.id == CHANNEL_TRIANGLES
                    && (e.level != 0 || c.count == 0 || c.count > MAX_TRIANGLES)
                {
                    return bad(format!(
                        "source triangles ({} of them) at level {} (leaf chunks only, 1..={MAX_TRIANGLES} triangles)",
                        c.count, e.level
                    ));
                }
                if d.id == CHANNEL_MATERIAL
                    && (c.count == 0 || c.count > MAX_MATERIAL_TABLE || c.count > e.voxel_count)
                {
                    return bad(format!(
                        "material table of {} entries for {} voxels (1..=min(n, {MAX_MATERIAL_TABLE}))",
                        c.count, e.voxel_count
                    ));
                }
            }
            let (lo, hi) = (e.bounds_min, e.bounds_max);
            if lo[3] != 0 || hi[3] != 0 || (0..3).any(|a| lo[a] > hi[a]) {
                return bad(format!("bounds {lo:?}..={hi:?} are invalid"));
            }
            if e.reserved != [0, 0] {
                return bad("reserved fields are not zero".into());
            }
            let key = order_key(e.level, e.pos());
            if prev_key.is_some_and(|p| key <= p) {
                return bad(
                    "out of index order (post-order, children in Morton order) or a duplicate node"
                        .into(),
                );
            }
            prev_key = Some(key);
            total += e.voxel_count as u64;
        }
        let pad_len = h.index_offset - prev_end;
        let mut pad = [0u8; 8];
        let pad_ok = pad_len < 8 && {
            let pad = &mut pad[..pad_len as usize];
            self.read_at(pad, prev_end, "the padding before the index")?;
            pad.iter().all(|&b| b == 0)
        };
        if !pad_ok {
            return Err(FormatError::Index {
                path: self.path.clone(),
                what: format!("the {pad_len} bytes between the last payload and the index are not 0–7 zero bytes of padding"),
            });
        }
        if total != h.total_voxels {
            return Err(FormatError::Index {
                path: self.path.clone(),
                what: format!(
                    "the nodes hold {total} voxels but the header says {}",
                    h.total_voxels
                ),
            });
        }
        let top = h.levels - 1;
        for (i, e) in self.nodes.iter().enumerate() {
            let mut present = 0u32;
            if e.level > 0 {
                for o in 0..8 {
                    if self.find(e.level - 1, child_pos(e.pos(), o)).is_some() {
                        present |= 1 << o;
                    }
                }
            }
            if present != e.child_mask {
                return Err(self.node_error(
                    i,
                    format!(
                        "child mask {:#010b} but the stored children are {present:#010b}",
                        e.child_mask
                    ),
                ));
            }
            if e.level < top
                && self
                    .find(e.level + 1, [e.x / 2, e.y / 2, e.z / 2])
                    .is_none()
            {
                return Err(self.node_error(i, "its parent is missing".into()));
            }
        }
        Ok(())
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// The validated header.
    pub fn header(&self) -> &Header {
        &self.header
    }
    /// The grid the file covers.
    pub fn spec(&self) -> FileSpec {
        let h = &self.header;
        FileSpec {
            resolution: h.resolution,
            levels: h.levels,
            mode: h.mode,
            origin: h.origin,
            voxel_size: h.voxel_size,
        }
    }
    /// File size in bytes (when it was opened).
    pub fn file_size(&self) -> u64 {
        self.len
    }
    /// Sum of the voxel counts of all nodes.
    pub fn total_voxels(&self) -> u64 {
        self.header.total_voxels
    }
    /// The node index, in index order.
    pub fn nodes(&self) -> &[NodeEntry] {
        &self.nodes
    }
    /// The index of the root node (the last entry), or `None` for a file without voxels.
    pub fn root(&self) -> Option<usize> {
        self.find(self.header.levels - 1, [0, 0, 0])
    }
    /// Index of each child (octant `i = dx | dy<<1 | dz<<2`) of node `index`.
    pub fn children(&self, index: usize) -> [Option<usize>; 8] {
        let Some(e) = self.nodes.get(index) else {
            return [None; 8];
        };
        std::array::from_fn(|o| {
            if e.child_mask >> o & 1 == 0 {
                return None;
            }
            self.find(e.level - 1, child_pos(e.pos(), o as u32))
        })
    }

    /// The ids of the file's optional channels (empty for a version 1 file), ascending;
    /// ids this crate does not know are listed too (their payloads are only checked for
    /// placement and checksum).
    pub fn channel_ids(&self) -> Vec<u32> {
        self.channels.descriptors.iter().map(|d| d.id).collect()
    }

    /// Compressed payload bytes of channel `id` summed over all nodes (0 if the file has no
    /// such channel).
    pub fn channel_payload_bytes(&self, id: u32) -> u64 {
        self.channels.position(id).map_or(0, |k| {
            self.channels.entries[k]
                .iter()
                .map(|c| c.payload_size)
                .sum()
        })
    }

    /// True if the file has the per-voxel material channel.
    pub fn has_materials(&self) -> bool {
        self.channels.position(CHANNEL_MATERIAL).is_some()
    }

    /// The compressed payload of node `index` in channel `id`, its checksum checked; `None` if
    /// the file has no such channel or the node has no payload in it.
    pub fn read_channel_payload(
        &self,
        index: usize,
        id: u32,
    ) -> Result<Option<Vec<u8>>, FormatError> {
        if index >= self.nodes.len() {
            return Err(FormatError::NoSuchNode {
                path: self.path.clone(),
                index,
                count: self.nodes.len(),
            });
        }
        let Some(k) = self.channels.position(id) else {
            return Ok(None);
        };
        let c = self.channels.entries[k][index];
        if c.payload_size == 0 {
            return Ok(None);
        }
        let mut out = vec![0u8; c.payload_size as usize];
        read_at(&self.file, &mut out, c.payload_offset).map_err(|err| match err {
            ReadAtError::Short => self.node_error(
                index,
                format!("the file ends before its channel {id} payload: it was truncated after it was opened"),
            ),
            ReadAtError::Io(source) => FormatError::Io {
                path: self.path.clone(),
                op: "reading a channel payload",
                source,
            },
        })?;
        let crc = crc32fast::hash(&out);
        if crc != c.payload_crc32 {
            return Err(self.node_error(
                index,
                format!(
                    "channel {id} payload checksum mismatch (directory says {:08x}, payload has {crc:08x})",
                    c.payload_crc32
                ),
            ));
        }
        Ok(Some(out))
    }

    /// The material id of each voxel of node `index`, in the node's voxel order (ids index the
    /// manifest's `"materials"` list), checked as FORMAT.md 14.3 says; `None` for a file
    /// without the material channel.
    pub fn read_materials(&self, index: usize) -> Result<Option<Vec<u32>>, FormatError> {
        let Some(payload) = self.read_channel_payload(index, CHANNEL_MATERIAL)? else {
            return Ok(None);
        };
        let k = self
            .channels
            .position(CHANNEL_MATERIAL)
            .expect("has the channel");
        let t = self.channels.entries[k][index].count;
        let n = self.nodes[index].voxel_count;
        let want = material_block_size(t, n);
        let bad = |what: String| self.node_error(index, format!("material payload: {what}"));
        check_frame_of(&payload, want, &format!("4·{t} + 2·{n}")).map_err(bad)?;
        let block = zstd::bulk::decompress(&payload, want as usize)
            .map_err(|e| bad(format!("zstd decompression failed: {e}")))?;
        decode_material_block(&block, t, n).map(Some).map_err(bad)
    }

    /// True if the file has the source-geometry channel (FORMAT.md 14.4).
    pub fn has_source_triangles(&self) -> bool {
        self.channels.position(CHANNEL_TRIANGLES).is_some()
    }

    /// The source triangles stored beside leaf node `index` (FORMAT.md 14.4), checked: the
    /// payload's CRC, the frame rules, the block's size and every index. `None` if the file has
    /// no source-geometry channel or the node has no triangles in it. Positions are in the
    /// chunk's frame ([`SourceMesh::position`]); the node's chunk origin in leaf voxels is
    /// `256·(x, y, z)`.
    pub fn source_triangles(&self, index: usize) -> Result<Option<SourceMesh>, FormatError> {
        let Some(payload) = self.read_channel_payload(index, CHANNEL_TRIANGLES)? else {
            return Ok(None);
        };
        let k = self
            .channels
            .position(CHANNEL_TRIANGLES)
            .expect("has the channel");
        let t = self.channels.entries[k][index].count;
        decode_source(&payload, t)
            .map(Some)
            .map_err(|what| self.node_error(index, format!("source triangles: {what}")))
    }

    /// Triangles stored beside node `index` in the source-geometry channel, from the node
    /// index alone (nothing is read; 0 without the channel or for a node without triangles).
    pub fn node_source_triangle_count(&self, index: usize) -> u32 {
        self.channels
            .position(CHANNEL_TRIANGLES)
            .map_or(0, |k| self.channels.entries[k][index].count)
    }

    /// Triangles stored in the source-geometry channel over all nodes (0 without it).
    pub fn source_triangle_count(&self) -> u64 {
        self.channels.position(CHANNEL_TRIANGLES).map_or(0, |k| {
            self.channels.entries[k]
                .iter()
                .map(|e| e.count as u64)
                .sum()
        })
    }

    /// The raw manifest bytes (UTF-8 JSON).
    pub fn manifest_bytes(&self) -> &[u8] {
        &self.manifest
    }
    /// The manifest, parsed.
    pub fn manifest(&self) -> Result<serde_json::Value, FormatError> {
        serde_json::from_slice(self.manifest_bytes()).map_err(|e| FormatError::Manifest {
            path: self.path.clone(),
            what: format!("not valid JSON: {e}"),
        })
    }

    /// Index of the node at `level`, `pos`, if stored (binary search in the index order).
    pub fn find(&self, level: u32, pos: [u32; 3]) -> Option<usize> {
        if !self.spec().contains_node(level, pos) {
            return None;
        }
        let key = order_key(level, pos);
        self.nodes
            .binary_search_by_key(&key, |e| order_key(e.level, e.pos()))
            .ok()
    }

    /// Reads the compressed payload of node `index` (its range was validated by `open`) into
    /// `out` (replacing its contents). Not checked against the checksums: see
    /// [`read_node_into`](Self::read_node_into).
    pub fn read_payload_into(&self, index: usize, out: &mut Vec<u8>) -> Result<(), FormatError> {
        let Some(e) = self.nodes.get(index) else {
            return Err(FormatError::NoSuchNode {
                path: self.path.clone(),
                index,
                count: self.nodes.len(),
            });
        };
        out.clear();
        out.resize(e.payload_size as usize, 0);
        let r = read_at(&self.file, out, e.payload_offset);
        r.map_err(|err| {
            out.clear();
            match err {
                ReadAtError::Short => self.node_error(
                    index,
                    format!(
                        "the file ends before this payload [{}, +{}): it was truncated after it was opened ({} bytes then)",
                        e.payload_offset, e.payload_size, self.len
                    ),
                ),
                ReadAtError::Io(source) => FormatError::Io {
                    path: self.path.clone(),
                    op: "reading a payload",
                    source,
                },
            }
        })
    }

    /// The compressed payload of node `index`, read from the file.
    pub fn payload(&self, index: usize) -> Result<Vec<u8>, FormatError> {
        let mut out = Vec::new();
        self.read_payload_into(index, &mut out)?;
        Ok(out)
    }

    /// `read_at` for the checks of `open`: a short read is an index error.
    fn read_at(&self, buf: &mut [u8], offset: u64, what: &str) -> Result<(), FormatError> {
        read_at(&self.file, buf, offset).map_err(|e| match e {
            ReadAtError::Short => FormatError::Index {
                path: self.path.clone(),
                what: format!(
                    "the file ended before {what} at {offset}: it was truncated while being opened"
                ),
            },
            ReadAtError::Io(source) => FormatError::Io {
                path: self.path.clone(),
                op: "reading",
                source,
            },
        })
    }

    /// Reads node `index` into `out` (cleared first; reuse it across calls to avoid
    /// allocation): checks the payload checksum, decompresses, checks the size and block
    /// checksum, undoes the transform, checks Morton order and the bounds. Errors name the node.
    pub fn read_node_into(&self, index: usize, out: &mut Vec<Voxel>) -> Result<(), FormatError> {
        out.clear();
        let mut payload = PAYLOAD.with(|p| std::mem::take(&mut *p.borrow_mut()));
        let r = self
            .read_payload_into(index, &mut payload)
            .and_then(|()| self.decode_payload(index, &payload, out));
        if payload.capacity() <= 64 << 20 {
            PAYLOAD.with(|p| *p.borrow_mut() = payload); // reused by the next read
        }
        r
    }

    /// Checks and decodes a payload read by [`read_payload_into`](Self::read_payload_into).
    fn decode_payload(
        &self,
        index: usize,
        payload: &[u8],
        out: &mut Vec<Voxel>,
    ) -> Result<(), FormatError> {
        let e = self.nodes[index];
        let crc = crc32fast::hash(payload);
        if crc != e.payload_crc32 {
            return Err(self.node_error(
                index,
                format!(
                    "payload checksum mismatch (index says {:08x}, payload has {crc:08x})",
                    e.payload_crc32
                ),
            ));
        }
        let n = e.voxel_count as usize;
        // FORMAT.md 11.2: exactly one zstd frame declaring 12·n bytes, before decompressing
        check_frame(payload, n).map_err(|what| self.node_error(index, what))?;
        let result = SCRATCH.with(|cell| -> Result<(), String> {
            let mut scratch = cell.borrow_mut();
            let (dctx, block) = &mut *scratch;
            if dctx.is_none() {
                *dctx = Some(zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?);
            }
            let d = dctx.as_mut().expect("decompressor was just set");
            block.clear();
            block.reserve(12 * n);
            let got = d
                .decompress_to_buffer(payload, block)
                .map_err(|e| format!("zstd decompression failed: {e}"))?;
            if got != 12 * n {
                return Err(format!(
                    "decompressed to {got} bytes, expected 12·{n} = {}",
                    12 * n
                ));
            }
            let crc = crc32fast::hash(block);
            if crc != e.block_crc32 {
                return Err(format!(
                    "block checksum mismatch (index says {:08x}, block has {crc:08x})",
                    e.block_crc32
                ));
            }
            let bounds = unshuffle(block, n, out)?;
            if bounds != e.bounds() {
                return Err(format!(
                    "voxel bounds {:?} differ from the index's {:?}",
                    bounds,
                    e.bounds()
                ));
            }
            if block.capacity() > 64 << 20 {
                *block = Vec::new(); // don't keep a huge buffer per thread
            }
            Ok(())
        });
        result.map_err(|what| {
            out.clear();
            self.node_error(index, what)
        })
    }

    /// Reads node `index` into a new vector (see [`read_node_into`](Self::read_node_into)).
    pub fn read_node(&self, index: usize) -> Result<Vec<Voxel>, FormatError> {
        let mut out = Vec::new();
        self.read_node_into(index, &mut out)?;
        Ok(out)
    }
}

/// Why a positioned read failed.
enum ReadAtError {
    /// The file ends before the range.
    Short,
    Io(std::io::Error),
}

/// Reads exactly `buf.len()` bytes at `offset` (retrying on EINTR).
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> Result<(), ReadAtError> {
    file.read_exact_at(buf, offset).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            ReadAtError::Short
        } else {
            ReadAtError::Io(e)
        }
    })
}

thread_local! {
    // Per-thread buffer for the compressed payload of the node being read.
    static PAYLOAD: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    // Per-thread zstd context and decompression buffer, reused across reads.
    static SCRATCH: RefCell<(Option<zstd::bulk::Decompressor<'static>>, Vec<u8>)> = const { RefCell::new((None, Vec::new())) };
}

/// Header checks in the order that gives the most useful message first.
fn check_header(h: &Header, len: u64) -> Result<(), String> {
    // The header checks in order, the most useful message first.
    if h.magic != MAGIC {
        let hex = |b: &[u8]| {
            b.iter()
                .map(|x| format!("{x:02x}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        return Err(format!(
            "magic bytes are {}, expected {} (\"VOXLOD\\0\\x01\"): not a voxlod file",
            hex(&h.magic),
            hex(&MAGIC)
        ));
    }
    if h.version != VERSION && h.version != VERSION_CHANNELS {
        return Err(format!(
            "format version {} is not supported (this reader reads versions {VERSION} and {VERSION_CHANNELS})",
            h.version
        ));
    }
    if h.header_size != HEADER_SIZE {
        return Err(format!(
            "header size is {}, expected {HEADER_SIZE}",
            h.header_size
        ));
    }
    let crc = h.compute_crc();
    if crc != h.header_crc32 {
        return Err(format!(
            "checksum mismatch (stored {:08x}, computed {crc:08x}): corrupt or unfinished file",
            h.header_crc32
        ));
    }
    let spec = FileSpec {
        resolution: h.resolution,
        levels: h.levels,
        mode: h.mode,
        origin: h.origin,
        voxel_size: h.voxel_size,
    };
    spec.validate()?;
    if h.flags != 0 || (h.version == VERSION && h.channels_crc32 != 0) {
        return Err(format!(
            "reserved fields are not zero (flags {:#x}, reserved {:#x})",
            h.flags, h.channels_crc32
        ));
    }
    if h.index_offset < HEADER_SIZE as u64 || h.index_offset % 8 != 0 {
        return Err(format!(
            "index offset {} is not a multiple of 8 after the header",
            h.index_offset
        ));
    }
    if h.node_count.checked_mul(NODE_ENTRY_SIZE as u64) != Some(h.index_size) {
        return Err(format!(
            "index size {} is not node count {} · {NODE_ENTRY_SIZE}",
            h.index_size, h.node_count
        ));
    }
    let index_end = h
        .index_offset
        .checked_add(h.index_size)
        .filter(|&e| e <= len);
    let Some(index_end) = index_end else {
        return Err(format!(
            "the node index [{}, +{}) extends past the end of the {len}-byte file (truncated?)",
            h.index_offset, h.index_size
        ));
    };
    // version 2: the channel directory (at least its 8-byte head) lies between them
    if h.version == VERSION && h.manifest_offset != index_end {
        return Err(format!(
            "manifest offset {} does not follow the index (ends at {index_end})",
            h.manifest_offset
        ));
    }
    if h.version == VERSION_CHANNELS
        && !(h.manifest_offset >= index_end + 8 && h.manifest_offset <= len)
    {
        return Err(format!(
            "manifest offset {} does not leave room for a channel directory after the index (ends at {index_end}) in the {len}-byte file",
            h.manifest_offset
        ));
    }
    let Some(end) = h
        .manifest_offset
        .checked_add(h.manifest_size)
        .filter(|&e| e <= len)
    else {
        return Err(format!(
            "the manifest [{}, +{}) extends past the end of the {len}-byte file (truncated?)",
            h.manifest_offset, h.manifest_size
        ));
    };
    if end != len {
        return Err(format!(
            "the file is {len} bytes but should end with the manifest at {end}"
        ));
    }
    Ok(())
}
