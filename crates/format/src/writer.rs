//! The streamed writer: payloads go to disk as nodes are finished (leaves in Morton order,
//! each parent right after its last child, so a build holds only the current Morton path);
//! only the 64-byte index entries stay in memory. The file is built under a temporary name and renamed
//! into place when complete, so `path` never holds a partial file; a caller that has a
//! temporary name of its own and renames it itself writes there directly
//! ([`Writer::create_staged`]).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use bytemuck::Zeroable;

use crate::channel::{
    ChannelDescriptor, ChannelDirectory, ChannelEntry, EncodedChannel, CHANNEL_ENTRY_SIZE,
    CHANNEL_MATERIAL, CHANNEL_TRIANGLES, MAX_CHANNELS,
};
use crate::layout::{
    child_pos, order_key, Header, NodeEntry, HEADER_SIZE, MAGIC, VERSION, VERSION_CHANNELS,
};
use crate::{EncodedNode, FileSpec, FormatError};

/// Writes one voxlod file. See the crate documentation for an example.
///
/// Nodes must come in index order (post-order, children in Morton order) with exact child
/// masks; [`write_node`](Self::write_node) refuses anything else without writing, so the
/// writer stays usable after such an error. After an I/O error it refuses everything.
/// Dropping a writer that was not finished removes its temporary file.
pub struct Writer {
    path: PathBuf,
    /// Where the bytes go: [`temp_path`]`(path)`, renamed to `path` by `finish`, or `path`
    /// itself for [`Writer::create_staged`] (no rename).
    tmp_path: PathBuf,
    file: Option<BufWriter<File>>,
    spec: FileSpec,
    entries: Vec<NodeEntry>,
    keys: Vec<u128>,
    offset: u64,
    total_voxels: u64,
    failed: bool,
    /// the optional channels' ids (empty: a version 1 file) and per channel the entries so far
    channels: Vec<u32>,
    channel_entries: Vec<Vec<ChannelEntry>>,
}

impl std::fmt::Debug for Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Writer")
            .field("path", &self.path)
            .field("nodes", &self.entries.len())
            .field("bytes_written", &self.offset)
            .finish_non_exhaustive()
    }
}

/// The temporary file a [`Writer`] for `path` builds: `path` with `.tmp` appended to its file
/// name (`out.voxlod` → `out.voxlod.tmp`), in the same directory so the final rename is atomic.
pub use voxlod_io::temp_path;

impl Writer {
    /// Creates (or truncates) [`temp_path`]`(path)` and writes the placeholder (all-zero) header.
    pub fn create(path: &Path, spec: FileSpec) -> Result<Writer, FormatError> {
        Writer::create_with_channels(path, spec, &[])
    }

    /// [`create`](Self::create) for a file with the optional channels `channels` (ids strictly
    /// increasing, at most 16; docs/FORMAT.md section 14): every node is then written with
    /// [`write_node_with`](Self::write_node_with), and the file is version 2. With no channels
    /// the file is version 1, the same bytes as [`create`](Self::create) gives.
    pub fn create_with_channels(
        path: &Path,
        spec: FileSpec,
        channels: &[u32],
    ) -> Result<Writer, FormatError> {
        Writer::open(path, temp_path(path), spec, channels)
    }

    /// [`create_with_channels`](Self::create_with_channels) writing `path` itself, for a
    /// caller whose `path` is already a temporary name of its own that it renames into place
    /// (so the file is renamed once): [`finish`](Self::finish) syncs the file and does not
    /// rename it; an unfinished writer removes it.
    pub fn create_staged(
        path: &Path,
        spec: FileSpec,
        channels: &[u32],
    ) -> Result<Writer, FormatError> {
        Writer::open(path, path.to_owned(), spec, channels)
    }

    fn open(
        path: &Path,
        tmp_path: PathBuf,
        spec: FileSpec,
        channels: &[u32],
    ) -> Result<Writer, FormatError> {
        if channels.len() > MAX_CHANNELS as usize || channels.windows(2).any(|w| w[0] >= w[1]) {
            return Err(FormatError::Spec {
                path: path.to_owned(),
                what: format!(
                    "channel ids {channels:?} are not strictly increasing or more than {MAX_CHANNELS}"
                ),
            });
        }
        spec.validate().map_err(|what| FormatError::Spec {
            path: path.to_owned(),
            what,
        })?;
        let file = File::create(&tmp_path).map_err(|source| FormatError::Io {
            path: tmp_path.clone(),
            op: "creating the temporary file",
            source,
        })?;
        let mut w = Writer {
            path: path.to_owned(),
            tmp_path,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            spec,
            entries: Vec::new(),
            keys: Vec::new(),
            offset: 0,
            total_voxels: 0,
            failed: false,
            channels: channels.to_vec(),
            channel_entries: vec![Vec::new(); channels.len()],
        };
        w.write(
            &[0u8; HEADER_SIZE as usize],
            "writing the placeholder header",
        )?;
        Ok(w)
    }

    /// The spec the file is written with.
    pub fn spec(&self) -> &FileSpec {
        &self.spec
    }

    /// Number of nodes written so far.
    pub fn node_count(&self) -> usize {
        self.entries.len()
    }

    /// Appends one node. `level` and `pos` must lie in the grid; the node must come after
    /// every node written so far in index order (post-order over the octree, children in
    /// Morton order — so no node twice); `child_mask` must be 0 at level 0 and otherwise have
    /// exactly the bits of the children already written. Violations are errors that write
    /// nothing.
    pub fn write_node(
        &mut self,
        level: u32,
        pos: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
    ) -> Result<(), FormatError> {
        self.write_node_with(level, pos, child_mask, node, &[])
    }

    /// [`write_node`](Self::write_node) with the node's payloads in the file's channels:
    /// `channels[k]` for the `k`-th id given to
    /// [`create_with_channels`](Self::create_with_channels) (`None` or missing: the node has
    /// no payload there). The material channel needs a payload for every node, encoded for
    /// the node's voxel count.
    pub fn write_node_with(
        &mut self,
        level: u32,
        pos: [u32; 3],
        child_mask: u8,
        node: &EncodedNode,
        channels: &[Option<&EncodedChannel>],
    ) -> Result<(), FormatError> {
        self.check_usable()?;
        let bad = |what: String| FormatError::Tree {
            path: self.path.clone(),
            level,
            pos,
            what,
        };
        if channels.len() > self.channels.len() {
            return Err(bad(format!(
                "{} channel payloads for a file of {} channels",
                channels.len(),
                self.channels.len()
            )));
        }
        for (k, &id) in self.channels.iter().enumerate() {
            let c = channels.get(k).copied().flatten();
            match c {
                Some(c) if id == CHANNEL_MATERIAL && c.voxel_count != node.voxel_count => {
                    return Err(bad(format!(
                        "channel {id}'s payload was encoded for {} voxels, the node has {}",
                        c.voxel_count, node.voxel_count
                    )))
                }
                Some(_) if id == CHANNEL_TRIANGLES && level != 0 => {
                    return Err(bad(
                        "source triangles are stored for leaf chunks (level 0) only".into(),
                    ))
                }
                None if id == CHANNEL_MATERIAL => {
                    return Err(bad(
                        "no material payload (the material channel has one for every node)".into(),
                    ))
                }
                _ => {}
            }
        }
        if !self.spec.contains_node(level, pos) {
            return Err(bad(format!(
                "outside the grid ({} levels; level {level} has {} chunks per axis)",
                self.spec.levels,
                self.spec.chunks_per_axis(level)
            )));
        }
        let key = order_key(level, pos);
        if let (Some(&last_key), Some(last)) = (self.keys.last(), self.entries.last()) {
            if key <= last_key {
                let why = if key == last_key {
                    "written twice"
                } else {
                    "out of order"
                };
                return Err(bad(format!(
                    "{why}: nodes must be written in post-order with children in Morton order; the previous node was level {} at {:?}",
                    last.level,
                    last.pos()
                )));
            }
        }
        let mut present = 0u8;
        if level > 0 {
            for i in 0..8 {
                if self.find(level - 1, child_pos(pos, i)).is_some() {
                    present |= 1 << i;
                }
            }
        }
        if child_mask != present {
            return Err(bad(format!(
                "child mask {child_mask:#010b} but the children written are {present:#010b} (a parent comes right after its last child)"
            )));
        }
        let entry = NodeEntry {
            level,
            x: pos[0],
            y: pos[1],
            z: pos[2],
            voxel_count: node.voxel_count,
            child_mask: child_mask as u32,
            payload_offset: self.offset,
            payload_size: node.payload.len() as u64,
            payload_crc32: node.payload_crc32,
            block_crc32: node.block_crc32,
            bounds_min: [
                node.bounds_min[0],
                node.bounds_min[1],
                node.bounds_min[2],
                0,
            ],
            bounds_max: [
                node.bounds_max[0],
                node.bounds_max[1],
                node.bounds_max[2],
                0,
            ],
            reserved: [0; 2],
        };
        self.write(&node.payload, "writing a node payload")?;
        for k in 0..self.channels.len() {
            let e = match channels.get(k).copied().flatten() {
                Some(c) => {
                    let e = ChannelEntry {
                        payload_offset: self.offset,
                        payload_size: c.payload.len() as u64,
                        payload_crc32: c.payload_crc32,
                        count: c.count,
                    };
                    self.write(&c.payload, "writing a channel payload")?;
                    e
                }
                None => ChannelEntry::default(),
            };
            self.channel_entries[k].push(e);
        }
        self.entries.push(entry);
        self.keys.push(key);
        self.total_voxels += node.voxel_count as u64;
        Ok(())
    }

    /// Bytes written so far (header placeholder and payloads).
    pub fn bytes_written(&self) -> u64 {
        self.offset
    }

    /// Completes the file: checks that every node below the root has its parent, writes the
    /// node index and `manifest` (serialized as compact JSON, stored verbatim), patches the
    /// header, fsyncs, renames [`temp_path`]`(path)` to `path` (replacing any old file) and
    /// fsyncs the directory. Only then does `path` exist. Returns the file size. (A writer of
    /// [`create_staged`](Self::create_staged) stops after the fsync.)
    pub fn finish(mut self, manifest: &serde_json::Value) -> Result<u64, FormatError> {
        self.check_usable()?;
        let top = self.spec.levels - 1;
        for e in &self.entries {
            if e.level < top
                && self
                    .find(e.level + 1, [e.x / 2, e.y / 2, e.z / 2])
                    .is_none()
            {
                return Err(FormatError::Tree {
                    path: self.path.clone(),
                    level: e.level,
                    pos: e.pos(),
                    what: "its parent was never written (every node below the root needs one)"
                        .into(),
                });
            }
        }
        let manifest_bytes = serde_json::to_vec(manifest).map_err(|e| FormatError::Manifest {
            path: self.path.clone(),
            what: format!("cannot serialize: {e}"),
        })?;
        // refuse what every reader would reject (FORMAT.md 11.2)
        crate::rules::check_manifest(&manifest_bytes).map_err(|what| FormatError::Manifest {
            path: self.path.clone(),
            what: format!("cannot write it: {what}"),
        })?;
        let pad = (8 - self.offset % 8) % 8;
        self.write(&[0u8; 8][..pad as usize], "padding before the index")?;
        let index_offset = self.offset;
        let entries = std::mem::take(&mut self.entries);
        let index: &[u8] = bytemuck::cast_slice(&entries);
        self.write(index, "writing the node index")?;
        // version 2: the channel directory between the index and the manifest
        let mut channels_crc32 = 0;
        if !self.channels.is_empty() {
            let dir = ChannelDirectory {
                descriptors: self
                    .channels
                    .iter()
                    .map(|&id| ChannelDescriptor {
                        id,
                        entry_size: CHANNEL_ENTRY_SIZE,
                        ..Default::default()
                    })
                    .collect(),
                entries: std::mem::take(&mut self.channel_entries),
            };
            let bytes = dir.to_bytes();
            channels_crc32 = crc32fast::hash(&bytes);
            self.write(&bytes, "writing the channel directory")?;
        }
        let manifest_offset = self.offset;
        self.write(&manifest_bytes, "writing the manifest")?;

        let mut h = Header::zeroed();
        h.magic = MAGIC;
        h.version = if self.channels.is_empty() {
            VERSION
        } else {
            VERSION_CHANNELS
        };
        h.channels_crc32 = channels_crc32;
        h.header_size = HEADER_SIZE;
        h.resolution = self.spec.resolution;
        h.levels = self.spec.levels;
        h.mode = self.spec.mode;
        h.origin = self.spec.origin;
        h.voxel_size = self.spec.voxel_size;
        h.node_count = entries.len() as u64;
        h.index_offset = index_offset;
        h.index_size = index.len() as u64;
        h.manifest_offset = manifest_offset;
        h.manifest_size = manifest_bytes.len() as u64;
        h.total_voxels = self.total_voxels;
        h.index_crc32 = crc32fast::hash(index);
        h.manifest_crc32 = crc32fast::hash(&manifest_bytes);
        h.header_crc32 = h.compute_crc();
        let size = self.offset;

        let tmp = &self.tmp_path.clone();
        let io = |op: &'static str| {
            move |source| FormatError::Io {
                path: tmp.clone(),
                op,
                source,
            }
        };
        let mut buf = self.file.take().ok_or_else(|| FormatError::Poisoned {
            path: self.path.clone(),
        })?;
        self.failed = true; // until the rename succeeds, any exit below leaves the file to Drop
        buf.flush().map_err(io("flushing"))?;
        let mut file = buf
            .into_inner()
            .map_err(|e| io("flushing")(e.into_error()))?;
        file.seek(SeekFrom::Start(0))
            .map_err(io("seeking to the header"))?;
        file.write_all(bytemuck::bytes_of(&h))
            .map_err(io("writing the header"))?;
        file.sync_all().map_err(io("syncing to disk"))?;
        drop(file);
        if self.tmp_path != self.path {
            std::fs::rename(&self.tmp_path, &self.path).map_err(|source| FormatError::Io {
                path: self.path.clone(),
                op: "renaming the temporary file into place",
                source,
            })?;
            voxlod_io::sync_dir(self.path.parent().unwrap_or(Path::new(".")));
        }
        self.failed = false; // finished: nothing left for Drop to remove
        Ok(size)
    }

    fn check_usable(&self) -> Result<(), FormatError> {
        if self.failed || self.file.is_none() {
            return Err(FormatError::Poisoned {
                path: self.path.clone(),
            });
        }
        Ok(())
    }

    fn find(&self, level: u32, pos: [u32; 3]) -> Option<usize> {
        self.keys.binary_search(&order_key(level, pos)).ok()
    }

    fn write(&mut self, bytes: &[u8], op: &'static str) -> Result<(), FormatError> {
        let Some(f) = self.file.as_mut() else {
            return Err(FormatError::Poisoned {
                path: self.path.clone(),
            });
        };
        if let Err(source) = f.write_all(bytes) {
            self.failed = true;
            return Err(FormatError::Io {
                path: self.tmp_path.clone(),
                op,
                source,
            });
        }
        self.offset += bytes.len() as u64;
        Ok(())
    }
}

impl Drop for Writer {
    /// An unfinished writer (dropped, or finish failed) removes its temporary file.
    fn drop(&mut self) {
        let finished = self.file.is_none() && !self.failed;
        drop(self.file.take());
        if !finished {
            let _ = std::fs::remove_file(&self.tmp_path);
        }
    }
}
