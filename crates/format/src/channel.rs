//! Optional per-node channels (docs/FORMAT.md section 14): data beside a node's voxels that a
//! renderer may use or ignore, such as the per-voxel material index of Chajdas, Reitinger &
//! Westermann, "Scalable rendering for very large meshes" (WSCG 2014), section 3.1 ("per-face
//! data such as material IDs" stored beside the voxels).
//!
//! A file with channels is format version 2: after the node index comes a *channel directory*
//! (a header of 8 bytes, one 16-byte descriptor per channel, then per channel one entry per
//! node), and each node's channel payloads follow its voxel payload in the payload region.
//! Channels are identified by number; a reader skips the payloads of a channel it does not
//! know (their placement and checksums are still checked), so a new channel (the source
//! triangles, [`CHANNEL_TRIANGLES`], `triangles.rs`) needs no new version. A file without channels is version 1, byte
//! for byte as before.
//!
//! The **material channel** ([`CHANNEL_MATERIAL`]) stores per node a table of the distinct
//! material ids of its voxels (ascending; each id indexes the manifest's `"materials"` list)
//! and per voxel a 16-bit index into that table.

use bytemuck::{Pod, Zeroable};

use crate::FormatError;

/// Channel id of the per-voxel material index (section 14.3).
pub const CHANNEL_MATERIAL: u32 = 1;
/// Channel id of a leaf chunk's source triangles (section 14.4, `triangles.rs`).
pub const CHANNEL_TRIANGLES: u32 = 2;
/// Bytes of a [`ChannelEntry`] as this version writes it (a descriptor may say more; readers
/// read the first 24 bytes of each entry).
pub const CHANNEL_ENTRY_SIZE: u32 = 24;
/// Bytes of a [`ChannelDescriptor`].
pub const CHANNEL_DESCRIPTOR_SIZE: u32 = 16;
/// Bytes before the descriptors: channel count and a reserved word.
pub const CHANNEL_DIRECTORY_HEAD: u32 = 8;
/// Most channels a file may have.
pub const MAX_CHANNELS: u32 = 16;
/// Most entries in one node's material table (the per-voxel index is 16 bits).
pub const MAX_MATERIAL_TABLE: u32 = 1 << 16;

/// One channel's descriptor in the directory (16 bytes, little-endian).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct ChannelDescriptor {
    /// The channel's id (strictly increasing over the directory).
    pub id: u32,
    /// Bytes per entry of the channel's table, ≥ 24.
    pub entry_size: u32,
    /// Reserved, 0.
    pub flags: u32,
    /// Reserved, 0.
    pub reserved: u32,
}

/// One node's entry in a channel's table (the first 24 bytes of each entry).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct ChannelEntry {
    /// Absolute offset of the node's payload in this channel (0 if it has none).
    pub payload_offset: u64,
    /// Bytes of the payload; 0: the node has no payload in this channel.
    pub payload_size: u64,
    /// CRC-32 of the payload bytes (0 if none).
    pub payload_crc32: u32,
    /// A channel-specific count (material channel: entries of the node's material table).
    pub count: u32,
}

const _: () = assert!(std::mem::size_of::<ChannelDescriptor>() == CHANNEL_DESCRIPTOR_SIZE as usize);
const _: () = assert!(std::mem::size_of::<ChannelEntry>() == CHANNEL_ENTRY_SIZE as usize);

/// One node's compressed payload in a channel, made by [`encode_materials`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodedChannel {
    /// The compressed payload: one zstd frame.
    pub payload: Vec<u8>,
    /// CRC-32 of `payload`.
    pub payload_crc32: u32,
    /// The entry's `count` (material channel: table entries).
    pub count: u32,
    /// Voxels of the node it was encoded for.
    pub voxel_count: u32,
}

/// The decompressed size of a material payload: `4·T + 2·n` bytes.
pub fn material_block_size(table: u32, voxels: u32) -> u64 {
    4 * table as u64 + 2 * voxels as u64
}

/// Encodes the per-voxel material ids of a node (`materials[j]` for its voxel `j`, in the
/// node's voxel order) as a material payload: the ascending table of the distinct ids, then
/// each voxel's index into it as two byte planes (low bytes, then high bytes), compressed as
/// one zstd frame with its content size.
pub fn encode_materials(materials: &[u32], zstd_level: i32) -> Result<EncodedChannel, FormatError> {
    let bad = |what: String| FormatError::Voxels { what };
    if materials.is_empty() {
        return Err(bad("a material payload needs at least one voxel".into()));
    }
    let mut table = materials.to_vec();
    table.sort_unstable();
    table.dedup();
    if table.len() > MAX_MATERIAL_TABLE as usize {
        return Err(bad(format!(
            "{} distinct materials in one node, more than {MAX_MATERIAL_TABLE}",
            table.len()
        )));
    }
    let n = materials.len();
    let mut block = Vec::with_capacity(4 * table.len() + 2 * n);
    for m in &table {
        block.extend_from_slice(&m.to_le_bytes());
    }
    let start = block.len();
    block.resize(start + 2 * n, 0);
    let (lo, hi) = block[start..].split_at_mut(n);
    // consecutive voxels mostly share a material: remember the last lookup
    let mut last = (table[0], 0u16);
    for (j, m) in materials.iter().enumerate() {
        if *m != last.0 {
            let i = table.binary_search(m).expect("every id is in the table");
            last = (*m, i as u16);
        }
        lo[j] = last.1 as u8;
        hi[j] = (last.1 >> 8) as u8;
    }
    let payload = zstd::bulk::compress(&block, zstd_level)
        .map_err(|e| bad(format!("zstd compression failed: {e}")))?;
    Ok(EncodedChannel {
        payload_crc32: crc32fast::hash(&payload),
        payload,
        count: table.len() as u32,
        voxel_count: n as u32,
    })
}

/// Decodes a decompressed material block of a node of `n` voxels with a table of `t` entries
/// into the per-voxel material ids. Checks (section 14.3): the size is `4t + 2n`, the table is
/// strictly increasing, every index is below `t` and every table entry is used.
pub fn decode_material_block(block: &[u8], t: u32, n: u32) -> Result<Vec<u32>, String> {
    let (t, n) = (t as usize, n as usize);
    if block.len() as u64 != material_block_size(t as u32, n as u32) {
        return Err(format!(
            "material block is {} bytes, expected 4·{t} + 2·{n}",
            block.len()
        ));
    }
    let table: Vec<u32> = block[..4 * t]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    if table.windows(2).any(|w| w[0] >= w[1]) {
        return Err("material table is not strictly increasing".into());
    }
    let (lo, hi) = block[4 * t..].split_at(n);
    let mut used = vec![false; t];
    let mut out = Vec::with_capacity(n);
    for j in 0..n {
        let i = lo[j] as usize | (hi[j] as usize) << 8;
        let Some(&m) = table.get(i) else {
            return Err(format!(
                "voxel {j} has material index {i}, but the table has {t} entries"
            ));
        };
        used[i] = true;
        out.push(m);
    }
    if let Some(i) = used.iter().position(|u| !u) {
        return Err(format!(
            "material table entry {i} (id {}) is used by no voxel",
            table[i]
        ));
    }
    Ok(out)
}

/// Bytes of the first zstd frame of `bytes` (to split a payload from what follows it in a
/// build's intermediate files).
pub fn first_frame_len(bytes: &[u8]) -> Result<usize, String> {
    zstd::zstd_safe::find_frame_compressed_size(bytes).map_err(|code| {
        format!(
            "not a zstd frame: {}",
            zstd::zstd_safe::get_error_name(code)
        )
    })
}

/// Decodes a material payload of a node of `n` voxels when its table length is not at hand
/// (a build's intermediate files): `T` from the frame's content size `4T + 2n`, then the checks
/// of [`decode_material_block`]. Returns the per-voxel ids and the payload as written.
pub fn decode_materials(payload: Vec<u8>, n: u32) -> Result<(Vec<u32>, EncodedChannel), String> {
    let size = match zstd::zstd_safe::get_frame_content_size(&payload) {
        Ok(Some(size)) => size,
        _ => return Err("the material payload's frame has no content size".into()),
    };
    let t = size
        .checked_sub(2 * n as u64)
        .filter(|r| r % 4 == 0 && *r / 4 >= 1 && *r / 4 <= MAX_MATERIAL_TABLE as u64)
        .ok_or_else(|| format!("a material block of {size} bytes does not fit {n} voxels"))?
        / 4;
    crate::rules::check_frame_of(&payload, size, &format!("4·{t} + 2·{n}"))?;
    let block = zstd::bulk::decompress(&payload, size as usize)
        .map_err(|e| format!("zstd decompression failed: {e}"))?;
    let mats = decode_material_block(&block, t as u32, n)?;
    Ok((
        mats,
        EncodedChannel {
            payload_crc32: crc32fast::hash(&payload),
            payload,
            count: t as u32,
            voxel_count: n,
        },
    ))
}

/// The directory of a file's channels, parsed and checked against the node count.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChannelDirectory {
    /// The descriptors, ids strictly increasing.
    pub descriptors: Vec<ChannelDescriptor>,
    /// Per channel (same order), one entry per node in index order.
    pub entries: Vec<Vec<ChannelEntry>>,
}

impl ChannelDirectory {
    /// Bytes of the directory of `channels` channels over `nodes` nodes, each entry
    /// [`CHANNEL_ENTRY_SIZE`] bytes.
    pub fn size(channels: usize, nodes: u64) -> u64 {
        CHANNEL_DIRECTORY_HEAD as u64
            + channels as u64 * (CHANNEL_DESCRIPTOR_SIZE as u64 + nodes * CHANNEL_ENTRY_SIZE as u64)
    }

    /// The directory's bytes (section 14.1).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(&(self.descriptors.len() as u32).to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        for d in &self.descriptors {
            out.extend_from_slice(bytemuck::bytes_of(d));
        }
        for table in &self.entries {
            out.extend_from_slice(bytemuck::cast_slice(table));
        }
        out
    }

    /// Parses and checks the directory's bytes for a file of `nodes` nodes: at least one and
    /// at most [`MAX_CHANNELS`] channels, the reserved word 0, ids strictly increasing,
    /// entry sizes ≥ 24 and multiples of 8, reserved descriptor fields 0, and the size exactly
    /// that of the tables. Entry placement is checked by the reader with the payloads.
    pub fn parse(bytes: &[u8], nodes: u64) -> Result<ChannelDirectory, String> {
        let word = |at: usize| -> Option<u32> {
            Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
        };
        let (Some(count), Some(reserved)) = (word(0), word(4)) else {
            return Err(format!(
                "the channel directory is {} bytes, shorter than its 8-byte head",
                bytes.len()
            ));
        };
        if count == 0 || count > MAX_CHANNELS || reserved != 0 {
            return Err(format!(
                "the channel directory's head is invalid ({count} channels, reserved {reserved:#x}; 1..={MAX_CHANNELS} channels and 0 expected)"
            ));
        }
        let desc_end = 8 + count as usize * CHANNEL_DESCRIPTOR_SIZE as usize;
        let Some(desc_bytes) = bytes.get(8..desc_end) else {
            return Err(format!(
                "the channel directory ({} bytes) is too short for {count} descriptors",
                bytes.len()
            ));
        };
        let descriptors: Vec<ChannelDescriptor> = desc_bytes
            .chunks_exact(CHANNEL_DESCRIPTOR_SIZE as usize)
            .map(bytemuck::pod_read_unaligned)
            .collect();
        let mut want = desc_end as u64;
        for (k, d) in descriptors.iter().enumerate() {
            if k > 0 && d.id <= descriptors[k - 1].id {
                return Err("channel ids are not strictly increasing".into());
            }
            if d.entry_size < CHANNEL_ENTRY_SIZE || d.entry_size % 8 != 0 {
                return Err(format!(
                    "channel {} has entries of {} bytes (at least {CHANNEL_ENTRY_SIZE}, a multiple of 8)",
                    d.id, d.entry_size
                ));
            }
            if d.flags != 0 || d.reserved != 0 {
                return Err(format!("channel {}'s reserved fields are not zero", d.id));
            }
            want = nodes
                .checked_mul(d.entry_size as u64)
                .and_then(|s| s.checked_add(want))
                .ok_or("the channel tables' size overflows")?;
        }
        if want != bytes.len() as u64 {
            return Err(format!(
                "the channel directory is {} bytes, but its {count} tables over {nodes} nodes take {want}",
                bytes.len()
            ));
        }
        let mut at = desc_end;
        let mut entries = Vec::with_capacity(descriptors.len());
        for d in &descriptors {
            let size = d.entry_size as usize;
            let table = (0..nodes as usize)
                .map(|i| {
                    let e = at + i * size;
                    bytemuck::pod_read_unaligned(&bytes[e..e + CHANNEL_ENTRY_SIZE as usize])
                })
                .collect();
            at += nodes as usize * size;
            entries.push(table);
        }
        Ok(ChannelDirectory {
            descriptors,
            entries,
        })
    }

    /// The position of channel `id` in the directory.
    pub fn position(&self, id: u32) -> Option<usize> {
        self.descriptors.iter().position(|d| d.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn material_block_roundtrip_and_layout() {
        let mats = [7u32, 7, 300, 7, 2];
        let enc = encode_materials(&mats, 3).unwrap();
        assert_eq!(enc.count, 3);
        let block = zstd::bulk::decompress(&enc.payload, 1 << 10).unwrap();
        // table 2, 7, 300; indices 1 1 2 1 0 as low plane then high plane
        let want: Vec<u8> = [2u32, 7, 300]
            .iter()
            .flat_map(|m| m.to_le_bytes())
            .chain([1, 1, 2, 1, 0, 0, 0, 0, 0, 0])
            .collect();
        assert_eq!(block, want);
        assert_eq!(decode_material_block(&block, 3, 5).unwrap(), mats);
        // an index past the table, an unused entry, an unsorted table, a wrong size
        let mut b = block.clone();
        b[12] = 3;
        assert!(decode_material_block(&b, 3, 5)
            .unwrap_err()
            .contains("index 3"));
        let mut b = block.clone();
        b[12 + 2] = 1;
        assert!(decode_material_block(&b, 3, 5)
            .unwrap_err()
            .contains("used by no voxel"));
        let mut b = block.clone();
        b[0] = 9;
        assert!(decode_material_block(&b, 3, 5)
            .unwrap_err()
            .contains("increasing"));
        assert!(decode_material_block(&block, 3, 4).is_err());
        assert!(encode_materials(&[], 3).is_err());
    }

    #[test]
    fn decode_without_the_table_length() {
        let mats = [4u32, 4, 1, 9];
        let enc = encode_materials(&mats, 1).unwrap();
        let both = [enc.payload.clone(), vec![1, 2, 3]].concat();
        assert_eq!(first_frame_len(&both).unwrap(), enc.payload.len());
        let (got, again) = decode_materials(enc.payload.clone(), 4).unwrap();
        assert_eq!((got.as_slice(), &again), (&mats[..], &enc));
        assert!(decode_materials(enc.payload, 5).is_err());
    }

    #[test]
    fn wide_tables_use_the_high_plane() {
        let mats: Vec<u32> = (0..1000).rev().collect();
        let enc = encode_materials(&mats, 3).unwrap();
        let block = zstd::bulk::decompress(&enc.payload, 1 << 20).unwrap();
        assert_eq!(decode_material_block(&block, 1000, 1000).unwrap(), mats);
        assert_eq!(block[4000 + 1000], (999 >> 8) as u8);
    }

    #[test]
    fn directory_roundtrip_and_rejects() {
        let dir = ChannelDirectory {
            descriptors: vec![ChannelDescriptor {
                id: CHANNEL_MATERIAL,
                entry_size: CHANNEL_ENTRY_SIZE,
                ..Default::default()
            }],
            entries: vec![vec![
                ChannelEntry {
                    payload_offset: 200,
                    payload_size: 17,
                    payload_crc32: 5,
                    count: 1,
                };
                2
            ]],
        };
        let bytes = dir.to_bytes();
        assert_eq!(bytes.len() as u64, ChannelDirectory::size(1, 2));
        assert_eq!(ChannelDirectory::parse(&bytes, 2).unwrap(), dir);
        assert!(ChannelDirectory::parse(&bytes, 3).is_err());
        assert!(ChannelDirectory::parse(&bytes[..7], 2).is_err());
        let mut b = bytes.clone();
        b[0] = 0;
        assert!(ChannelDirectory::parse(&b, 2).is_err());
        let mut b = bytes.clone();
        b[12] = 8; // entry size 8
        assert!(ChannelDirectory::parse(&b, 2)
            .unwrap_err()
            .contains("entries of 8"));
    }
}
