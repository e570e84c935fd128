//! A node's payload: the node's voxels as a structure of arrays, transformed so that zstd
//! compresses it well, in one zstd frame. The transform (measured by
//! `examples/measure_compression.rs`, specified in `docs/FORMAT.md`, "Node payload"):
//!
//! 1. Position words become Morton deltas: `(morton − previous morton) | mask << 24`, the
//!    first voxel's previous morton being 0 (Morton order makes the deltas small).
//! 2. Each of the three arrays of n words is byte-shuffled into four planes of n bytes
//!    (byte 0 of every word, then byte 1, ...).
//! 3. The four normal planes and the four colour planes are delta-coded bytewise
//!    (`b[j] − b[j−1]` wrapping, first byte kept): neighbours in Morton order have similar
//!    normals and colours.

use std::cell::RefCell;

use crate::voxel::{morton8, Voxel};
use crate::{FormatError, MAX_NODE_VOXELS};

/// One node's voxels, compressed and checksummed, ready for [`Writer::write_node`](crate::Writer::write_node).
/// Only [`encode_node`] makes one, so its contents are known to be valid.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodedNode {
    pub(crate) payload: Vec<u8>,
    pub(crate) voxel_count: u32,
    pub(crate) payload_crc32: u32,
    pub(crate) block_crc32: u32,
    pub(crate) bounds_min: [u8; 3],
    pub(crate) bounds_max: [u8; 3],
}

impl EncodedNode {
    /// The compressed payload (one zstd frame) as it will be stored.
    pub fn payload(&self) -> &[u8] {
        &self.payload
    }
    /// Number of voxels (at least 1).
    pub fn voxel_count(&self) -> u32 {
        self.voxel_count
    }
    /// CRC-32 of the payload.
    pub fn payload_crc32(&self) -> u32 {
        self.payload_crc32
    }
    /// CRC-32 of the decompressed block.
    pub fn block_crc32(&self) -> u32 {
        self.block_crc32
    }
    /// Tight inclusive bounds of the voxel positions inside the chunk: (min, max).
    pub fn bounds(&self) -> ([u8; 3], [u8; 3]) {
        (self.bounds_min, self.bounds_max)
    }
}

impl EncodedNode {
    /// Rebuilds an encoded node from a payload that [`encode_node`] made earlier and that was
    /// kept elsewhere (for example in a resumable intermediate file) with its
    /// [`payload_crc32`](Self::payload_crc32), decoding it into `out` and checking it
    /// completely: checksum, size, Morton order, reserved bits. The block checksum and bounds
    /// are recomputed, so the result equals what `encode_node` returned for those voxels.
    pub fn from_payload(
        payload: Vec<u8>,
        voxel_count: u32,
        payload_crc32: u32,
        out: &mut Vec<Voxel>,
    ) -> Result<EncodedNode, FormatError> {
        let bad = |what: String| FormatError::Voxels { what };
        if crc32fast::hash(&payload) != payload_crc32 {
            return Err(bad("stored payload: checksum mismatch".into()));
        }
        let n = voxel_count as usize;
        if n == 0 || voxel_count > MAX_NODE_VOXELS {
            return Err(bad(format!("stored payload claims {voxel_count} voxels")));
        }
        let mut block = Vec::with_capacity(12 * n);
        let got = zstd::bulk::Decompressor::new()
            .and_then(|mut d| d.decompress_to_buffer(&payload, &mut block))
            .map_err(|e| bad(format!("stored payload: zstd decompression failed: {e}")))?;
        if got != 12 * n {
            return Err(bad(format!(
                "stored payload decompressed to {got} bytes, expected 12·{n}"
            )));
        }
        let (bounds_min, bounds_max) =
            unshuffle(&block, n, out).map_err(|w| bad(format!("stored payload: {w}")))?;
        Ok(EncodedNode {
            payload_crc32,
            payload,
            voxel_count,
            block_crc32: crc32fast::hash(&block),
            bounds_min,
            bounds_max,
        })
    }
}

/// Compresses one node's voxels at zstd level `zstd_level` (see
/// [`DEFAULT_ZSTD_LEVEL`](crate::DEFAULT_ZSTD_LEVEL)). The voxels must be non-empty, sorted by
/// strictly increasing Morton code of their position (no two at one position), with bits
/// 30–31 of the position and normal words zero; anything else is an error.
///
/// Pure and thread-safe, so callers can compress nodes in parallel; the output depends only
/// on the voxels and the level.
pub fn encode_node(voxels: &[Voxel], zstd_level: i32) -> Result<EncodedNode, FormatError> {
    let bad = |what: String| FormatError::Voxels { what };
    if voxels.is_empty() {
        return Err(bad(
            "a node needs at least one voxel (empty nodes are not stored)".into(),
        ));
    }
    if !zstd::compression_level_range().contains(&zstd_level) {
        return Err(bad(format!(
            "zstd level {zstd_level} is outside {:?}",
            zstd::compression_level_range()
        )));
    }
    let mut lo = [u8::MAX; 3];
    let mut hi = [0u8; 3];
    let mut prev: Option<u32> = None;
    for (i, v) in voxels.iter().enumerate() {
        if v.pos_mask >> 30 != 0 || v.normal >> 30 != 0 {
            return Err(bad(format!(
                "voxel {i}: reserved bits 30-31 set (pos_mask {:#010x}, normal {:#010x})",
                v.pos_mask, v.normal
            )));
        }
        let m = v.morton();
        if let Some(p) = prev {
            if m <= p {
                let why = if m == p {
                    "duplicate position"
                } else {
                    "not in Morton order"
                };
                return Err(bad(format!(
                    "voxel {i} at {:?}: {why} (previous voxel at {:?})",
                    v.pos(),
                    voxels[i - 1].pos()
                )));
            }
        }
        prev = Some(m);
        let p = v.pos();
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    debug_assert!(voxels.len() <= MAX_NODE_VOXELS as usize); // implied by strictly increasing 24-bit codes

    let mut block = Vec::new();
    shuffle(voxels, &mut block);
    let block_crc32 = crc32fast::hash(&block);
    let payload =
        compress(&block, zstd_level).map_err(|e| bad(format!("zstd compression failed: {e}")))?;
    Ok(EncodedNode {
        payload_crc32: crc32fast::hash(&payload),
        payload,
        voxel_count: voxels.len() as u32,
        block_crc32,
        bounds_min: lo,
        bounds_max: hi,
    })
}

thread_local! {
    // One compression context per thread, re-made when the level changes (contexts are
    // expensive to set up and not Sync).
    static COMPRESSOR: RefCell<Option<(i32, zstd::bulk::Compressor<'static>)>> = const { RefCell::new(None) };
}

fn compress(block: &[u8], level: i32) -> std::io::Result<Vec<u8>> {
    COMPRESSOR.with(|cell| {
        let mut slot = cell.borrow_mut();
        if slot.as_ref().map(|(l, _)| *l) != Some(level) {
            let mut c = zstd::bulk::Compressor::new(level)?;
            c.set_parameter(zstd::zstd_safe::CParameter::ContentSizeFlag(true))?;
            c.set_parameter(zstd::zstd_safe::CParameter::ChecksumFlag(false))?;
            *slot = Some((level, c));
        }
        let (_, c) = slot.as_mut().expect("compressor was just set");
        c.compress(block)
    })
}

/// Writes the transformed block (12·n bytes) of `voxels` into `out` (cleared).
/// Preconditions (checked by [`encode_node`]): strictly increasing Morton codes.
pub(crate) fn shuffle(voxels: &[Voxel], out: &mut Vec<u8>) {
    let n = voxels.len();
    out.clear();
    out.resize(12 * n, 0);
    let (pos, rest) = out.split_at_mut(4 * n);
    let (nor, col) = rest.split_at_mut(4 * n);
    let mut prev_m = 0u32;
    let mut prev_n = 0u32;
    let mut prev_c = 0u32;
    for (j, v) in voxels.iter().enumerate() {
        let m = v.morton();
        debug_assert!(j == 0 || m > prev_m);
        let w = (m - prev_m) | (v.mask() as u32) << 24;
        prev_m = m;
        let dn = byte_sub(v.normal, prev_n);
        prev_n = v.normal;
        let dc = byte_sub(v.color, prev_c);
        prev_c = v.color;
        for k in 0..4 {
            pos[k * n + j] = (w >> (8 * k)) as u8;
            nor[k * n + j] = (dn >> (8 * k)) as u8;
            col[k * n + j] = (dc >> (8 * k)) as u8;
        }
    }
}

/// Inverse of [`shuffle`]: decodes the block of `n` voxels into `out` (cleared). Checks what
/// the transform cannot express in a valid node (Morton codes past 24 bits or not strictly
/// increasing, reserved bits) and returns the voxels' tight bounds.
pub(crate) fn unshuffle(
    block: &[u8],
    n: usize,
    out: &mut Vec<Voxel>,
) -> Result<([u8; 3], [u8; 3]), String> {
    if block.len() != 12 * n {
        return Err(format!(
            "block is {} bytes, expected 12·{n} = {}",
            block.len(),
            12 * n
        ));
    }
    out.clear();
    out.reserve(n);
    // the twelve byte planes, each n long
    let plane = |k: usize| &block[k * n..(k + 1) * n];
    let (p0, p1, p2, p3) = (plane(0), plane(1), plane(2), plane(3));
    let (n0, n1, n2, n3) = (plane(4), plane(5), plane(6), plane(7));
    let (c0, c1, c2, c3) = (plane(8), plane(9), plane(10), plane(11));
    let mut lo = [u8::MAX; 3];
    let mut hi = [0u8; 3];
    let mut m = 0u32;
    let mut normal = 0u32;
    let mut color = 0u32;
    for j in 0..n {
        let w = u32::from_le_bytes([p0[j], p1[j], p2[j], p3[j]]);
        let d = w & 0x00ff_ffff;
        if j > 0 && d == 0 {
            return Err(format!("voxel {j}: Morton delta 0 (duplicate position)"));
        }
        m += d; // both < 2^24: no overflow
        if m >= 1 << 24 {
            return Err(format!("voxel {j}: Morton code {m:#x} exceeds 24 bits"));
        }
        if w >> 30 != 0 {
            return Err(format!("voxel {j}: reserved position bits 30-31 set"));
        }
        normal = byte_add(normal, u32::from_le_bytes([n0[j], n1[j], n2[j], n3[j]]));
        if normal >> 30 != 0 {
            return Err(format!("voxel {j}: reserved normal bits 30-31 set"));
        }
        color = byte_add(color, u32::from_le_bytes([c0[j], c1[j], c2[j], c3[j]]));
        // the position as Voxel::pos_mask packs it (x | y << 8 | z << 16), by table
        let pos = UNMORTON[0][(m & 0xff) as usize]
            | UNMORTON[1][(m >> 8 & 0xff) as usize]
            | UNMORTON[2][(m >> 16) as usize];
        let p = pos.to_le_bytes();
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
        debug_assert_eq!([p[0], p[1], p[2]], unmorton8(m));
        out.push(Voxel {
            pos_mask: pos | (w >> 24 & 0x3f) << 24,
            normal,
            color,
        });
    }
    Ok((lo, hi))
}

/// Bytewise wrapping `a − b` of two words (each byte lane on its own).
#[inline]
fn byte_sub(a: u32, b: u32) -> u32 {
    u32::from_le_bytes(std::array::from_fn(|k| {
        a.to_le_bytes()[k].wrapping_sub(b.to_le_bytes()[k])
    }))
}

/// Bytewise wrapping `a + b` (SWAR: the low seven bits of each lane add without carrying
/// into the next lane, the top bit is their sum's top bit xor the lanes' top bits).
#[inline]
fn byte_add(a: u32, b: u32) -> u32 {
    const LOW7: u32 = 0x7f7f_7f7f;
    ((a & LOW7) + (b & LOW7)) ^ ((a ^ b) & !LOW7)
}

/// For byte `b` of a 24-bit Morton code (`b` = 0, 1, 2) and each of its 256 values, the
/// coordinate bits it holds, packed as `x | y << 8 | z << 16`: Morton bit `i` is bit `i / 3` of
/// axis `i % 3` ([`crate::voxel::morton8`]).
static UNMORTON: [[u32; 256]; 3] = unmorton_tables();

const fn unmorton_tables() -> [[u32; 256]; 3] {
    let mut t = [[0u32; 256]; 3];
    let mut b = 0;
    while b < 3 {
        let mut v = 0;
        while v < 256 {
            let mut w = 0u32;
            let mut j = 0;
            while j < 8 {
                if v >> j & 1 == 1 {
                    let i = 8 * b + j;
                    w |= 1 << ((i % 3) * 8 + i / 3);
                }
                j += 1;
            }
            t[b][v] = w;
            v += 1;
        }
        b += 1;
    }
    t
}

/// Inverse of [`morton8`].
#[inline]
pub(crate) fn unmorton8(m: u32) -> [u8; 3] {
    #[inline]
    fn compact(v: u32) -> u8 {
        let mut x = v & 0x0024_9249;
        x = (x | (x >> 2)) & 0x000c_30c3;
        x = (x | (x >> 4)) & 0x0000_f00f;
        x = (x | (x >> 8)) & 0x0000_00ff;
        x as u8
    }
    let p = [compact(m), compact(m >> 1), compact(m >> 2)];
    debug_assert_eq!(morton8(p[0], p[1], p[2]), m & 0x00ff_ffff);
    p
}

#[cfg(test)]
mod tests {
    #[test]
    fn byte_add_and_unmorton_tables_match_their_plain_definitions() {
        use super::*;
        let mut s = 0x1234_5678_9abc_def1u64;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let (a, b) = (s as u32, (s >> 32) as u32);
            let plain = u32::from_le_bytes(std::array::from_fn(|k| {
                a.to_le_bytes()[k].wrapping_add(b.to_le_bytes()[k])
            }));
            assert_eq!(byte_add(a, b), plain, "{a:#x} + {b:#x}");
        }
        for m in (0..1u32 << 24).step_by(7) {
            let pos = UNMORTON[0][(m & 0xff) as usize]
                | UNMORTON[1][(m >> 8 & 0xff) as usize]
                | UNMORTON[2][(m >> 16) as usize];
            let p = unmorton8(m);
            assert_eq!(pos, p[0] as u32 | (p[1] as u32) << 8 | (p[2] as u32) << 16);
            assert_eq!(crate::voxel::morton8(p[0], p[1], p[2]), m);
        }
    }

    #[test]
    fn from_payload_rebuilds_the_same_node() {
        use crate::voxel::{pack_color, pack_normal};
        let voxels: Vec<Voxel> = (0..500u32)
            .map(|i| {
                let p = crate::block::unmorton8(i * 7);
                Voxel::new(
                    p,
                    (i % 64) as u8,
                    pack_normal([1.0, i as f32, 0.5]),
                    pack_color([i as u8, 2, 3, 255]),
                )
            })
            .collect();
        let enc = super::encode_node(&voxels, 3).unwrap();
        let mut out = Vec::new();
        let again = super::EncodedNode::from_payload(
            enc.payload().to_vec(),
            enc.voxel_count(),
            enc.payload_crc32(),
            &mut out,
        )
        .unwrap();
        assert_eq!(again, enc);
        assert_eq!(out, voxels);
        let mut bad = enc.payload().to_vec();
        let k = bad.len() / 2;
        bad[k] ^= 0x40;
        assert!(super::EncodedNode::from_payload(
            bad,
            enc.voxel_count(),
            enc.payload_crc32(),
            &mut out
        )
        .is_err());
        assert!(super::EncodedNode::from_payload(
            enc.payload().to_vec(),
            enc.voxel_count() + 1,
            enc.payload_crc32(),
            &mut out
        )
        .is_err());
    }

    use super::*;

    #[test]
    fn unmorton_inverts_morton() {
        for m in (0..1u32 << 24).step_by(997).chain([0, 1, (1 << 24) - 1]) {
            let p = unmorton8(m);
            assert_eq!(morton8(p[0], p[1], p[2]), m);
        }
    }

    #[test]
    fn byte_delta_inverts() {
        for (a, b) in [
            (0u32, 0u32),
            (0x3fff_ffff, 1),
            (0x0102_0304, 0xff00_ff00),
            (7, 0xffff_ffff),
        ] {
            assert_eq!(byte_add(b, byte_sub(a, b)), a);
        }
    }

    #[test]
    fn shuffle_layout_of_two_voxels() {
        // two voxels: positions (1,0,0) → morton 1 and (0,1,0) → morton 2
        let a = Voxel::new([1, 0, 0], 0x01, 0x0000_01ff, 0x1122_3344);
        let b = Voxel::new([0, 1, 0], 0x04, 0x0007_fc00, 0x1122_3355);
        let mut block = Vec::new();
        shuffle(&[a, b], &mut block);
        #[rustfmt::skip]
        let expected: [u8; 24] = [
            // position planes: deltas 1, 1; masks 0x01, 0x04
            1, 1, 0, 0, 0, 0, 0x01, 0x04,
            // normal planes: words 0x000001ff, then bytewise delta 0x0007fc00 − 0x000001ff
            0xff, 0x01, 0x01, 0xfb, 0x00, 0x07, 0x00, 0x00,
            // colour planes: 0x11223344, then delta 0x00000011
            0x44, 0x11, 0x33, 0x00, 0x22, 0x00, 0x11, 0x00,
        ];
        assert_eq!(block, expected);
        let mut out = Vec::new();
        let bounds = unshuffle(&block, 2, &mut out).unwrap();
        assert_eq!(out, vec![a, b]);
        assert_eq!(bounds, ([0, 0, 0], [1, 1, 0]));
    }
}
