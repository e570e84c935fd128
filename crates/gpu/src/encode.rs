//! Decoding the fixed-point attribute sums read back from the GPU into voxel records, with the
//! averaging and encoding rules of `voxlod_voxelize::ChunkVoxelizer::finish` (Chajdas et al.
//! 2014 voxel layout: position, face mask with border caps, 10:10:10 normal, RGBA8).

use voxlod_format::voxel::{border_caps, face_mask, pack_color, pack_normal, Voxel};

/// Bytes of one voxel slot: 16 sums of 96 bits (W, W·n, W·rgba, K, n, rgba).
pub(crate) const SLOT_BYTES: u64 = 192;
const SLOT_WORDS: usize = 48;
/// The fixed-point scale of the sums, 2^64 (voxelize.wgsl `add_fixed`).
const SCALE: f64 = 18446744073709551616.0;

/// Fixed-point sum `k` of a slot: a 96-bit two's-complement integer, least significant word first.
#[inline]
fn sum(acc: &[u32], k: usize) -> f64 {
    let w = &acc[3 * k..3 * k + 3];
    let v = (w[2] as i32 as i128) << 64 | (w[1] as i128) << 32 | w[0] as i128;
    v as f64 / SCALE
}

/// Appends the voxels whose slots are in `[lo, hi)`: `occ` is the occupancy bitset (bit `i` of
/// word `w` is local voxel `32 w + i`, index `x + 256 (y + 256 z)`), `base` the first slot of
/// each word, `acc` the accumulators of slots `lo..hi`. Returns how many occupied voxels got no
/// contribution at all (a shader invocation was cut short); those are not appended.
pub(crate) fn decode(
    occ: &[u32],
    base: &[u32],
    acc: &[u32],
    lo: u32,
    hi: u32,
    out: &mut Vec<Voxel>,
) -> usize {
    let mut empty = 0;
    debug_assert_eq!(occ.len(), base.len());
    debug_assert_eq!(acc.len(), (hi - lo) as usize * SLOT_WORDS);
    for (w, (&bits, &b)) in occ.iter().zip(base).enumerate() {
        if bits == 0 || b >= hi || b + bits.count_ones() <= lo {
            continue;
        }
        let mut rest = bits;
        let mut slot = b;
        while rest != 0 {
            let bit = rest.trailing_zeros();
            rest &= rest - 1;
            if slot >= lo && slot < hi {
                let idx = w as u32 * 32 + bit;
                let pos = [idx & 255, (idx >> 8) & 255, idx >> 16].map(|c| c as u8);
                let a = &acc[(slot - lo) as usize * SLOT_WORDS..][..SLOT_WORDS];
                match voxel(pos, a) {
                    Some(v) => out.push(v),
                    None => empty += 1,
                }
            }
            slot += 1;
        }
    }
    empty
}

/// One voxel from its sums: area-weighted means, or unweighted means if the total weight is 0;
/// None if nothing was added.
fn voxel(pos: [u8; 3], a: &[u32]) -> Option<Voxel> {
    let w = sum(a, 0);
    let (n, c) = if w > 0.0 {
        (
            [1, 2, 3].map(|k| (sum(a, k) / w) as f32),
            [4, 5, 6, 7].map(|k| sum(a, k) / w),
        )
    } else {
        let k = sum(a, 8);
        debug_assert!(k > 0.0, "occupied voxel {pos:?} without contributions");
        if k > 0.0 {
            (
                [9, 10, 11].map(|j| (sum(a, j) / k) as f32),
                [12, 13, 14, 15].map(|j| sum(a, j) / k),
            )
        } else {
            ([0.0; 3], [0.0; 4])
        }
    };
    let normal = pack_normal(n);
    let mask = face_mask(normal) | border_caps(pos);
    let rgba = c.map(|x| x.round().clamp(0.0, 255.0) as u8);
    Some(Voxel::new(pos, mask, normal, pack_color(rgba)))
}
