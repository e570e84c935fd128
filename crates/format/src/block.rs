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

use voxlod_geom::morton::{morton8_word, unmorton8_word};

use crate::voxel::{has_minus_512, Voxel};
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
        let (block_crc32, (bounds_min, bounds_max)) = BLOCK.with(|cell| {
            let block = &mut *cell.borrow_mut();
            block.clear();
            block.reserve(12 * n);
            let got = DECOMPRESSOR
                .with(|d| {
                    let mut d = d.borrow_mut();
                    if d.is_none() {
                        *d = Some(zstd::bulk::Decompressor::new()?);
                    }
                    let d = d.as_mut().expect("decompressor was just set");
                    d.decompress_to_buffer(&payload, block)
                })
                .map_err(|e| bad(format!("stored payload: zstd decompression failed: {e}")))?;
            if got != 12 * n {
                return Err(bad(format!(
                    "stored payload decompressed to {got} bytes, expected 12·{n}"
                )));
            }
            let bounds =
                unshuffle(block, n, out).map_err(|w| bad(format!("stored payload: {w}")))?;
            Ok((crc32fast::hash(block), bounds))
        })?;
        Ok(EncodedNode {
            payload_crc32,
            payload,
            voxel_count,
            block_crc32,
            bounds_min,
            bounds_max,
        })
    }
}

impl EncodedNode {
    /// Rebuilds an encoded node from a payload that [`encode_node`] made earlier, with the
    /// other fields it returned ([`block_crc32`](Self::block_crc32), [`bounds`](Self::bounds)),
    /// kept by the caller under a checksum of its own (the pipeline's leaf log), *without*
    /// decompressing it: for a writer that copies stored payloads into a file. Checks the
    /// payload's checksum, the count and that the bounds are ordered; that the fields belong
    /// to the payload is the caller's promise ([`from_payload`](Self::from_payload) checks
    /// everything, at the cost of a decode).
    pub fn from_stored(
        payload: Vec<u8>,
        voxel_count: u32,
        payload_crc32: u32,
        block_crc32: u32,
        (bounds_min, bounds_max): ([u8; 3], [u8; 3]),
    ) -> Result<EncodedNode, FormatError> {
        let bad = |what: String| FormatError::Voxels { what };
        if crc32fast::hash(&payload) != payload_crc32 {
            return Err(bad("stored payload: checksum mismatch".into()));
        }
        if voxel_count == 0 || voxel_count > MAX_NODE_VOXELS {
            return Err(bad(format!("stored payload claims {voxel_count} voxels")));
        }
        if (0..3).any(|a| bounds_min[a] > bounds_max[a]) {
            return Err(bad(format!(
                "stored bounds {bounds_min:?}..{bounds_max:?} are not ordered"
            )));
        }
        Ok(EncodedNode {
            payload,
            voxel_count,
            payload_crc32,
            block_crc32,
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
    BLOCK.with(|cell| {
        let block = &mut *cell.borrow_mut();
        let Some((bounds_min, bounds_max)) = shuffle(voxels, block) else {
            return Err(bad(invalid_voxels(voxels)));
        };
        debug_assert!(voxels.len() <= MAX_NODE_VOXELS as usize); // implied by strictly increasing 24-bit codes
        let block_crc32 = crc32fast::hash(block);
        let payload = compress(block, zstd_level)
            .map_err(|e| bad(format!("zstd compression failed: {e}")))?;
        Ok(EncodedNode {
            payload_crc32: crc32fast::hash(&payload),
            payload,
            voxel_count: voxels.len() as u32,
            block_crc32,
            bounds_min,
            bounds_max,
        })
    })
}

/// What is wrong with voxels that [`shuffle`] refused: the first voxel with reserved bits set,
/// or out of Morton order.
fn invalid_voxels(voxels: &[Voxel]) -> String {
    let mut prev: Option<u32> = None;
    for (i, v) in voxels.iter().enumerate() {
        if v.pos_mask >> 30 != 0 || v.normal >> 30 != 0 {
            return format!(
                "voxel {i}: reserved bits 30-31 set (pos_mask {:#010x}, normal {:#010x})",
                v.pos_mask, v.normal
            );
        }
        if has_minus_512(v.normal) {
            return format!(
                "voxel {i}: a normal component is -512 (normal {:#010x}); components are in [-511, 511]",
                v.normal
            );
        }
        let m = v.morton();
        if prev.is_some_and(|p| m <= p) {
            let why = if Some(m) == prev {
                "duplicate position"
            } else {
                "not in Morton order"
            };
            return format!(
                "voxel {i} at {:?}: {why} (previous voxel at {:?})",
                v.pos(),
                voxels[i - 1].pos()
            );
        }
        prev = Some(m);
    }
    unreachable!("invalid_voxels called on valid voxels")
}

thread_local! {
    /// The transformed block of the node being encoded or decoded on this thread, kept so
    /// that every node does not allocate (and the kernel zero) 12 bytes per voxel afresh.
    static BLOCK: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    /// One decompression context per thread (made once, not per node).
    static DECOMPRESSOR: RefCell<Option<zstd::bulk::Decompressor<'static>>> = const { RefCell::new(None) };
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

/// Voxels transformed per step of [`shuffle`] and [`unshuffle`]: their words sit in small
/// arrays (in L1) between the word pass and the byte-plane pass.
const STEP: usize = 256;

/// Writes the transformed block (12·n bytes) of `voxels` into `out` and returns the voxels'
/// tight bounds, or `None` (with `out` unspecified) if they are not in strictly increasing
/// Morton order, have reserved bits set or a normal component of −512.
///
/// Per step of [`STEP`] voxels: the voxels' words are copied into three arrays, each holding
/// the previous step's last word in front (so that every delta reads two neighbouring array
/// elements); then word passes (Morton codes by bit spreading, Morton deltas with the masks,
/// bytewise deltas of normals and colours, the checks and bounds) and a byte-plane pass that
/// spreads the words into the twelve planes. None of these passes carries a value from one
/// voxel to the next, so the compiler runs them in SIMD lanes (a `tests` reference computes
/// the block voxel by voxel: the same bytes).
pub(crate) fn shuffle(voxels: &[Voxel], out: &mut Vec<u8>) -> Option<([u8; 3], [u8; 3])> {
    let n = voxels.len();
    // every byte is written below: no need to zero what the buffer already holds
    if out.len() < 12 * n {
        out.resize(12 * n, 0);
    }
    out.truncate(12 * n);
    let (pos, rest) = out.split_at_mut(4 * n);
    let (nor, col) = rest.split_at_mut(4 * n);
    // element 0: the previous voxel's word (the Morton code 0 and zero words before the first)
    let mut morton = [0u32; STEP + 1];
    let mut normal = [0u32; STEP + 1];
    let mut color = [0u32; STEP + 1];
    let mut pos_mask = [0u32; STEP];
    let mut words = [[0u32; STEP]; 3];
    // the first voxel has no predecessor to be greater than
    let mut ordered = 0u32;
    let mut bad = 0u32;
    let mut lo = [u32::MAX; 3];
    let mut hi = [0u32; 3];
    for (s, step) in voxels.chunks(STEP).enumerate() {
        let len = step.len();
        for (j, v) in step.iter().enumerate() {
            pos_mask[j] = v.pos_mask;
            normal[j + 1] = v.normal;
            color[j + 1] = v.color;
        }
        for j in 0..len {
            morton[j + 1] = morton8_word(pos_mask[j]);
        }
        // strictly increasing codes (from the second voxel of the node on)
        for j in usize::from(s == 0)..len {
            ordered += u32::from(morton[j + 1] <= morton[j]);
        }
        for j in 0..len {
            let p = pos_mask[j];
            words[0][j] = morton[j + 1].wrapping_sub(morton[j]) | (p & 0x3f00_0000);
            words[1][j] = byte_sub(normal[j + 1], normal[j]);
            words[2][j] = byte_sub(color[j + 1], color[j]);
            bad |= (p | normal[j + 1]) >> 30;
            bad |= u32::from(has_minus_512(normal[j + 1]));
            for a in 0..3 {
                let c = p >> (8 * a) & 0xff;
                lo[a] = lo[a].min(c);
                hi[a] = hi[a].max(c);
            }
        }
        morton[0] = morton[len];
        normal[0] = normal[len];
        color[0] = color[len];
        let at = s * STEP;
        for (w, planes) in words.iter().zip([&mut *pos, &mut *nor, &mut *col]) {
            let (p0, rest) = planes.split_at_mut(n);
            let (p1, rest) = rest.split_at_mut(n);
            let (p2, p3) = rest.split_at_mut(n);
            spread_planes(
                &w[..len],
                [
                    &mut p0[at..at + len],
                    &mut p1[at..at + len],
                    &mut p2[at..at + len],
                    &mut p3[at..at + len],
                ],
            );
        }
    }
    (ordered == 0 && bad == 0).then_some((lo.map(|c| c as u8), hi.map(|c| c as u8)))
}

/// Byte `b` of every word into plane `b`.
#[inline]
fn spread_planes(words: &[u32], planes: [&mut [u8]; 4]) {
    let [p0, p1, p2, p3] = planes;
    let len = words.len();
    let (p0, p1, p2, p3) = (
        &mut p0[..len],
        &mut p1[..len],
        &mut p2[..len],
        &mut p3[..len],
    );
    for j in 0..len {
        let w = words[j];
        p0[j] = w as u8;
        p1[j] = (w >> 8) as u8;
        p2[j] = (w >> 16) as u8;
        p3[j] = (w >> 24) as u8;
    }
}

/// The word of bytes `j` of four planes.
#[inline]
fn gather_planes(planes: [&[u8]; 4], words: &mut [u32]) {
    let len = words.len();
    let [p0, p1, p2, p3] = planes;
    let (p0, p1, p2, p3) = (&p0[..len], &p1[..len], &p2[..len], &p3[..len]);
    for j in 0..len {
        words[j] = u32::from_le_bytes([p0[j], p1[j], p2[j], p3[j]]);
    }
}

/// Inverse of [`shuffle`]: decodes the block of `n` voxels into `out` (cleared). Checks what
/// the transform cannot express in a valid node (Morton codes past 24 bits or not strictly
/// increasing, reserved bits) and returns the voxels' tight bounds.
///
/// Per step of [`STEP`] voxels, a byte-plane pass gathers the words (SIMD lanes), then a word
/// pass runs the prefix sums and rebuilds the voxels, its checks accumulated branch-free (the
/// failing voxel is looked for only when one failed).
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
    let mut lo = [u8::MAX; 3];
    let mut hi = [0u8; 3];
    let mut m = 0u32;
    let mut normal = 0u32;
    let mut color = 0u32;
    let mut words = [[0u32; STEP]; 3];
    let mut bad = false;
    for at in (0..n).step_by(STEP) {
        let len = STEP.min(n - at);
        for (a, w) in words.iter_mut().enumerate() {
            let p = |b: usize| &plane(4 * a + b)[at..at + len];
            gather_planes([p(0), p(1), p(2), p(3)], &mut w[..len]);
        }
        let first = at == 0;
        out.extend((0..len).map(|j| {
            let w = words[0][j];
            let d = w & 0x00ff_ffff;
            // a zero delta after the first voxel, a code past 24 bits, reserved bits
            bad |= d == 0 && !(first && j == 0);
            m += d; // both < 2^24: no overflow
            bad |= m >= 1 << 24;
            normal = byte_add(normal, words[1][j]);
            color = byte_add(color, words[2][j]);
            bad |= (w | normal) >> 30 != 0 || has_minus_512(normal);
            // the position as Voxel::pos_mask packs it (x | y << 8 | z << 16), by table
            let pos = unmorton8_word(m);
            for (a, (l, h)) in lo.iter_mut().zip(&mut hi).enumerate() {
                let c = (pos >> (8 * a)) as u8;
                *l = (*l).min(c);
                *h = (*h).max(c);
            }
            Voxel {
                pos_mask: pos | (w >> 24 & 0x3f) << 24,
                normal,
                color,
            }
        }));
        if bad {
            return Err(first_invalid(block, n));
        }
    }
    Ok((lo, hi))
}

/// The first problem in a block that [`unshuffle`] refused, found voxel by voxel.
fn first_invalid(block: &[u8], n: usize) -> String {
    let byte = |k: usize, j: usize| block[k * n + j];
    let word = |a: usize, j: usize| u32::from_le_bytes(std::array::from_fn(|b| byte(4 * a + b, j)));
    let mut m = 0u32;
    let mut normal = 0u32;
    for j in 0..n {
        let w = word(0, j);
        let d = w & 0x00ff_ffff;
        if j > 0 && d == 0 {
            return format!("voxel {j}: Morton delta 0 (duplicate position)");
        }
        m += d;
        if m >= 1 << 24 {
            return format!("voxel {j}: Morton code {m:#x} exceeds 24 bits");
        }
        if w >> 30 != 0 {
            return format!("voxel {j}: reserved position bits 30-31 set");
        }
        normal = byte_add(normal, word(1, j));
        if normal >> 30 != 0 {
            return format!("voxel {j}: reserved normal bits 30-31 set");
        }
        if has_minus_512(normal) {
            return format!(
                "voxel {j}: a normal component is -512 (normal {normal:#010x}); components are in [-511, 511]"
            );
        }
    }
    unreachable!("first_invalid called on a valid block")
}

/// Bytewise wrapping `a − b` of two words (each byte lane on its own; SWAR: the low seven
/// bits of each lane subtract from a lane with its top bit set, so no borrow crosses lanes,
/// and the top bit is fixed up by xor).
#[inline]
fn byte_sub(a: u32, b: u32) -> u32 {
    const H: u32 = 0x8080_8080;
    ((a | H) - (b & !H)) ^ ((a ^ !b) & H)
}

/// Bytewise wrapping `a + b` (SWAR: the low seven bits of each lane add without carrying
/// into the next lane, the top bit is their sum's top bit xor the lanes' top bits).
#[inline]
fn byte_add(a: u32, b: u32) -> u32 {
    const LOW7: u32 = 0x7f7f_7f7f;
    ((a & LOW7) + (b & LOW7)) ^ ((a ^ b) & !LOW7)
}

#[cfg(test)]
mod tests {
    #[test]
    fn byte_add_and_sub_match_their_plain_definitions() {
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
            let plain = u32::from_le_bytes(std::array::from_fn(|k| {
                a.to_le_bytes()[k].wrapping_sub(b.to_le_bytes()[k])
            }));
            assert_eq!(byte_sub(a, b), plain, "{a:#x} - {b:#x}");
        }
    }

    #[test]
    fn from_payload_rebuilds_the_same_node() {
        use crate::voxel::{pack_color, pack_normal};
        let voxels: Vec<Voxel> = (0..500u32)
            .map(|i| {
                let p = voxlod_geom::morton::unmorton8(i * 7);
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
        // without the decode: the stored fields give the same node; a flipped payload byte,
        // a bad count or unordered bounds are refused
        let (crc, block, bounds) = (enc.payload_crc32(), enc.block_crc32(), enc.bounds());
        let n = enc.voxel_count();
        let stored =
            |p: &[u8], n: u32, b| super::EncodedNode::from_stored(p.to_vec(), n, crc, block, b);
        assert_eq!(stored(enc.payload(), n, bounds).unwrap(), enc);
        let mut flipped = enc.payload().to_vec();
        flipped[k] ^= 0x40;
        assert!(stored(&flipped, n, bounds).is_err());
        assert!(stored(enc.payload(), 0, bounds).is_err());
        assert!(stored(enc.payload(), crate::MAX_NODE_VOXELS + 1, bounds).is_err());
        assert!(stored(enc.payload(), n, ([5, 0, 0], [4, 9, 9])).is_err());
    }

    use super::*;

    /// The transformed block voxel by voxel (the form before the SIMD passes of [`shuffle`]):
    /// writes the transformed block (12·n bytes) of `voxels` into `out` and returns the voxels'
    /// tight bounds, or `None` (with `out` unspecified) if they are not in strictly increasing
    /// Morton order, have reserved bits set or a normal component of −512.
    ///
    /// Per step of [`STEP`] voxels, a word pass (Morton deltas with the masks, bytewise deltas
    /// of normals and colours, the checks and bounds; branch-free) fills three word arrays, and
    /// a byte-plane pass spreads them into the twelve planes (no dependencies between voxels,
    /// so the compiler uses SIMD lanes).
    fn shuffle_reference(voxels: &[Voxel], out: &mut Vec<u8>) -> Option<([u8; 3], [u8; 3])> {
        let n = voxels.len();
        // every byte is written below: no need to zero what the buffer already holds
        if out.len() < 12 * n {
            out.resize(12 * n, 0);
        }
        out.truncate(12 * n);
        let (pos, rest) = out.split_at_mut(4 * n);
        let (nor, col) = rest.split_at_mut(4 * n);
        let mut prev_m = None;
        let (mut prev_n, mut prev_c) = (0u32, 0u32);
        let mut ok = true;
        let mut reserved = 0u32;
        let mut lo = [u8::MAX; 3];
        let mut hi = [0u8; 3];
        let mut words = [[0u32; STEP]; 3];
        for (s, step) in voxels.chunks(STEP).enumerate() {
            for (j, v) in step.iter().enumerate() {
                let m = voxlod_geom::morton::morton8_word_by_table(v.pos_mask);
                ok &= Some(m) > prev_m;
                let delta = m.wrapping_sub(prev_m.unwrap_or(0));
                prev_m = Some(m);
                words[0][j] = delta | (v.pos_mask & 0x3f00_0000);
                reserved |= v.pos_mask | v.normal;
                ok &= !has_minus_512(v.normal);
                words[1][j] = byte_sub(v.normal, prev_n);
                prev_n = v.normal;
                words[2][j] = byte_sub(v.color, prev_c);
                prev_c = v.color;
                for (a, (l, h)) in lo.iter_mut().zip(&mut hi).enumerate() {
                    let c = (v.pos_mask >> (8 * a)) as u8;
                    *l = (*l).min(c);
                    *h = (*h).max(c);
                }
            }
            let (at, len) = (s * STEP, step.len());
            for (w, planes) in words.iter().zip([&mut *pos, &mut *nor, &mut *col]) {
                let (p0, rest) = planes.split_at_mut(n);
                let (p1, rest) = rest.split_at_mut(n);
                let (p2, p3) = rest.split_at_mut(n);
                spread_planes(
                    &w[..len],
                    [
                        &mut p0[at..at + len],
                        &mut p1[at..at + len],
                        &mut p2[at..at + len],
                        &mut p3[at..at + len],
                    ],
                );
            }
        }
        (ok && reserved >> 30 == 0).then_some((lo, hi))
    }

    /// [`shuffle`] equals [`shuffle_reference`] byte for byte, bounds and refusal included: on
    /// random nodes of 1 to 700 voxels (several steps, partial last step), and on nodes with
    /// one defect each (a duplicate or an out-of-order position, reserved bits, a −512 normal
    /// component) at any place, the first voxel among them.
    #[test]
    fn shuffle_equals_the_voxel_by_voxel_reference() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for case in 0..400 {
            let n = 1 + (next() % 700) as usize;
            let mut codes: Vec<u32> = (0..n).map(|_| (next() % (1 << 24)) as u32).collect();
            codes.sort_unstable();
            codes.dedup();
            let mut voxels: Vec<Voxel> = codes
                .iter()
                .map(|&m| {
                    let r = next();
                    let p = voxlod_geom::morton::unmorton8(m);
                    let normal = (r as u32) & 0x3fff_ffff;
                    // keep −512 components out of the valid nodes
                    let normal = if has_minus_512(normal) {
                        normal ^ 1 << 4 ^ 1 << 14 ^ 1 << 24
                    } else {
                        normal
                    };
                    let normal = if has_minus_512(normal) { 0 } else { normal };
                    Voxel::new(p, (r >> 32) as u8 & 0x3f, normal, (r >> 40) as u32)
                })
                .collect();
            let at = (next() % voxels.len() as u64) as usize;
            match case % 5 {
                1 if at > 0 => {
                    voxels[at] = Voxel {
                        pos_mask: voxels[at - 1].pos_mask,
                        ..voxels[at]
                    }
                }
                2 if at > 0 => voxels.swap(at - 1, at),
                3 => voxels[at].pos_mask |= 1 << 30,
                4 => voxels[at].normal = 0x200 << (10 * (next() % 3)),
                _ => {}
            }
            let got = shuffle(&voxels, &mut a);
            let want = shuffle_reference(&voxels, &mut b);
            assert_eq!(got, want, "case {case}");
            if want.is_some() {
                assert_eq!(a, b, "case {case}");
            }
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
        // FORMAT.md section 12, "Two voxels": positions (1,0,0) → morton 1 and (0,1,0) →
        // morton 2; masks are the normal's faces plus the border caps (section 6)
        use crate::voxel::{border_caps, face_mask};
        let (na, nb) = (0x0000_01ff, 0x0007_fc00);
        let (ma, mb) = (0x29, 0x26);
        assert_eq!(face_mask(na) | border_caps([1, 0, 0]), ma); // +x | −y −z
        assert_eq!(face_mask(nb) | border_caps([0, 1, 0]), mb); // +y | −x −z
        let a = Voxel::new([1, 0, 0], ma, na, 0x1122_3344);
        let b = Voxel::new([0, 1, 0], mb, nb, 0x1122_3355);
        let mut block = Vec::new();
        assert_eq!(shuffle(&[a, b], &mut block), Some(([0, 0, 0], [1, 1, 0])));
        #[rustfmt::skip]
        let expected: [u8; 24] = [
            // position planes: deltas 1, 1; masks 0x29, 0x26
            1, 1, 0, 0, 0, 0, 0x29, 0x26,
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
