//! The fixed-size records of the file: the 128-byte [`Header`] and the 64-byte [`NodeEntry`]
//! of the node index, and the order of the index (post-order over the octree, children in
//! Morton order), which [`order_key`] turns into one sortable number.
//! Byte offsets are in `docs/FORMAT.md`; the size asserts below pin them.

use bytemuck::{Pod, Zeroable};

/// The 8 magic bytes that start every voxlod file (the last byte is the major layout number).
pub const MAGIC: [u8; 8] = *b"VOXLOD\0\x01";
/// The format version of files without optional channels (written byte for byte as before
/// channels existed, so readers of version 1 keep reading them).
pub const VERSION: u32 = 1;
/// The format version of files with optional channels (a channel directory after the node
/// index; docs/FORMAT.md section 14). This crate reads both and writes this one only for a
/// file with at least one channel.
pub const VERSION_CHANNELS: u32 = 2;
/// Size of [`Header`] in bytes.
pub const HEADER_SIZE: u32 = 128;
/// Size of [`NodeEntry`] in bytes.
pub const NODE_ENTRY_SIZE: u32 = 64;

/// The file header at offset 0 (128 bytes, little-endian). Written as zeros first and patched
/// when the file is finished.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Header {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`VERSION`].
    pub version: u32,
    /// [`HEADER_SIZE`].
    pub header_size: u32,
    /// Leaf voxels per axis, `R = 256·2^k`.
    pub resolution: u32,
    /// Number of levels, `k + 1`; level `levels − 1` is the single root chunk.
    pub levels: u32,
    /// Voxelization mode: [`MODE_CONSERVATIVE`](crate::MODE_CONSERVATIVE) or [`MODE_THIN`](crate::MODE_THIN).
    pub mode: u32,
    /// Reserved, 0.
    pub flags: u32,
    /// World coordinates of the grid corner (the minimum corner of leaf voxel (0,0,0)).
    pub origin: [f64; 3],
    /// World units per leaf voxel.
    pub voxel_size: f64,
    /// Number of entries in the node index.
    pub node_count: u64,
    /// Byte offset of the node index (a multiple of 8).
    pub index_offset: u64,
    /// Byte size of the node index, `node_count · 64`.
    pub index_size: u64,
    /// Byte offset of the manifest, `index_offset + index_size` (version 2: plus the size of the
    /// channel directory, which lies between them).
    pub manifest_offset: u64,
    /// Byte size of the manifest; the file ends at `manifest_offset + manifest_size`.
    pub manifest_size: u64,
    /// Sum of `voxel_count` over all nodes (all levels).
    pub total_voxels: u64,
    /// CRC-32 (IEEE, zlib's) of the node index bytes.
    pub index_crc32: u32,
    /// CRC-32 of the manifest bytes.
    pub manifest_crc32: u32,
    /// Version 2: CRC-32 of the channel directory; version 1: reserved, 0.
    pub channels_crc32: u32,
    /// CRC-32 of the first 124 bytes of the header.
    pub header_crc32: u32,
}

/// One entry of the node index (64 bytes, little-endian).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Pod, Zeroable)]
pub struct NodeEntry {
    /// Level, 0 = leaves.
    pub level: u32,
    /// Node position in chunks at its level: `0 ≤ x < (R/256) >> level`.
    pub x: u32,
    /// See `x`.
    pub y: u32,
    /// See `x`.
    pub z: u32,
    /// Number of voxels, `1 ..= 256³`.
    pub voxel_count: u32,
    /// Bit `i` set when child octant `i = dx | dy<<1 | dz<<2` is stored; 0 at level 0.
    pub child_mask: u32,
    /// Byte offset of the payload (a zstd frame).
    pub payload_offset: u64,
    /// Byte size of the payload.
    pub payload_size: u64,
    /// CRC-32 of the payload (compressed) bytes.
    pub payload_crc32: u32,
    /// CRC-32 of the decompressed block (12·voxel_count bytes).
    pub block_crc32: u32,
    /// Tight inclusive minimum of the voxel positions inside the chunk; 4th byte 0.
    pub bounds_min: [u8; 4],
    /// Tight inclusive maximum; 4th byte 0.
    pub bounds_max: [u8; 4],
    /// Reserved, 0.
    pub reserved: [u32; 2],
}

const _: () = assert!(std::mem::size_of::<Header>() == HEADER_SIZE as usize);
const _: () = assert!(std::mem::size_of::<NodeEntry>() == NODE_ENTRY_SIZE as usize);

impl Header {
    /// CRC-32 of the first 124 bytes, the value `header_crc32` must have.
    pub fn compute_crc(&self) -> u32 {
        crc32fast::hash(&bytemuck::bytes_of(self)[..HEADER_SIZE as usize - 4])
    }
}

impl NodeEntry {
    /// Node position `[x, y, z]` in chunks at its level.
    pub fn pos(&self) -> [u32; 3] {
        [self.x, self.y, self.z]
    }
    /// Bounds as 3-vectors: (min, max), inclusive.
    pub fn bounds(&self) -> ([u8; 3], [u8; 3]) {
        let (a, b) = (self.bounds_min, self.bounds_max);
        ([a[0], a[1], a[2]], [b[0], b[1], b[2]])
    }
    /// The child position of octant `i` (`i = dx | dy<<1 | dz<<2`), one level down.
    pub fn child_pos(&self, octant: u32) -> [u32; 3] {
        child_pos(self.pos(), octant)
    }
}

/// Position of the child in octant `i` of the node at `pos`: `2·pos + (i&1, i>>1&1, i>>2&1)`.
pub fn child_pos(pos: [u32; 3], octant: u32) -> [u32; 3] {
    debug_assert!(octant < 8);
    [
        2 * pos[0] + (octant & 1),
        2 * pos[1] + (octant >> 1 & 1),
        2 * pos[2] + (octant >> 2 & 1),
    ]
}

/// Sort key of a node in the index order: post-order over the octree, children in Morton
/// order. A node is emitted when its subtree ends, so the key is the end of its range of
/// level-0 Morton codes, `(morton(pos) + 1) << 3·level`, ties (a node and its descendants
/// ending together) broken by level. Precondition: `pos` lies inside the level's grid of a
/// file with at most 24 levels (then the key fits in 3·23 + 5 bits).
pub fn order_key(level: u32, pos: [u32; 3]) -> u128 {
    debug_assert!(level < 32);
    let mut m = 0u128;
    for b in 0..32 {
        for (a, &p) in pos.iter().enumerate() {
            m |= (((p >> b) & 1) as u128) << (3 * b + a);
        }
    }
    ((m + 1) << (3 * level)) << 5 | level as u128
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Post-order of a full octree of `levels` levels, children in Morton order, by recursion.
    fn post_order(level: u32, pos: [u32; 3], out: &mut Vec<(u32, [u32; 3])>) {
        if level > 0 {
            for i in 0..8 {
                post_order(level - 1, child_pos(pos, i), out);
            }
        }
        out.push((level, pos));
    }

    #[test]
    fn order_key_sorts_like_recursive_post_order() {
        let mut nodes = Vec::new();
        post_order(3, [0, 0, 0], &mut nodes);
        assert_eq!(nodes.len(), 1 + 8 + 64 + 512);
        let keys: Vec<u128> = nodes.iter().map(|&(l, p)| order_key(l, p)).collect();
        assert!(
            keys.windows(2).all(|w| w[0] < w[1]),
            "keys must increase along the post-order"
        );
    }

    #[test]
    fn header_field_offsets() {
        let mut h = Header::zeroed();
        h.total_voxels = 0x0102_0304_0506_0708;
        h.header_crc32 = 0xaabb_ccdd;
        h.index_crc32 = 0x1122_3344;
        let b = bytemuck::bytes_of(&h);
        assert_eq!(&b[104..112], &0x0102_0304_0506_0708u64.to_le_bytes());
        assert_eq!(&b[112..116], &0x1122_3344u32.to_le_bytes());
        assert_eq!(&b[124..128], &0xaabb_ccddu32.to_le_bytes());
        let mut e = NodeEntry::zeroed();
        e.payload_offset = 7;
        e.bounds_max = [1, 2, 3, 0];
        let b = bytemuck::bytes_of(&e);
        assert_eq!(b[24], 7);
        assert_eq!(&b[52..56], &[1, 2, 3, 0]);
    }
}
