//! Morton (Z-order) codes, the one copy every crate uses: [`morton3`] for grid positions (up
//! to 21 bits an axis), [`morton8`] for positions inside a 256³ chunk (the canonical order of
//! the voxels in a node, `docs/FORMAT.md`), and the forms the hot loops want for 24-bit
//! in-chunk codes: [`morton8_word`] (shifts and masks, runs in SIMD lanes over many words),
//! [`morton8_word_by_table`], [`morton8_by_table`] and [`unmorton8_word`] (a table lookup a byte).
//!
//! A position word packs a voxel position as `x | y << 8 | z << 16` (bits 24 and up are
//! ignored here), as `Voxel::pos_mask` of the format crate does.

/// Spreads the low 21 bits of `v` so there are two zero bits between each.
#[inline]
pub fn part1by2(v: u32) -> u64 {
    let mut x = v as u64 & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Inverse of [`part1by2`].
#[inline]
pub fn compact1by2(x: u64) -> u32 {
    let mut x = x & 0x1249_2492_4924_9249;
    x = (x ^ (x >> 2)) & 0x10c3_0c30_c30c_30c3;
    x = (x ^ (x >> 4)) & 0x100f_00f0_0f00_f00f;
    x = (x ^ (x >> 8)) & 0x001f_0000_ff00_00ff;
    x = (x ^ (x >> 16)) & 0x001f_0000_0000_ffff;
    x = (x ^ (x >> 32)) & 0x1f_ffff;
    x as u32
}

/// Morton (Z-order) code of a 3D point with up to 21 bits per axis: bit `3i` is bit `i` of x,
/// bit `3i+1` of y, bit `3i+2` of z.
#[inline]
pub fn morton3(x: u32, y: u32, z: u32) -> u64 {
    part1by2(x) | (part1by2(y) << 1) | (part1by2(z) << 2)
}

/// Inverse of [`morton3`].
#[inline]
pub fn demorton3(m: u64) -> [u32; 3] {
    [compact1by2(m), compact1by2(m >> 1), compact1by2(m >> 2)]
}

/// Morton code of an 8-bit-per-axis position (24 bits): bit `3i` from x, `3i+1` from y,
/// `3i+2` from z.
#[inline]
pub fn morton8(x: u8, y: u8, z: u8) -> u32 {
    spread8(x as u32) | spread8(y as u32) << 1 | spread8(z as u32) << 2
}

/// The low byte of `v` with bit `b` moved to bit `3b`: one axis of [`morton8`].
#[inline]
fn spread8(v: u32) -> u32 {
    let x = v & 0xff;
    let x = (x | (x << 8)) & 0x0000_f00f;
    let x = (x | (x << 4)) & 0x000c_30c3;
    (x | (x << 2)) & 0x0024_9249
}

/// [`morton8`] of a position word (bits 0–23: x, y, z) by bit spreading: shifts and masks
/// only, so that a loop over words runs in SIMD lanes.
#[inline]
pub fn morton8_word(w: u32) -> u32 {
    spread8(w) | spread8(w >> 8) << 1 | spread8(w >> 16) << 2
}

/// [`morton8`] of a position word (bits 0–23: x, y, z) by three table lookups: cheaper than
/// [`morton8_word`] one word at a time.
#[inline]
pub fn morton8_word_by_table(w: u32) -> u32 {
    SPREAD8[(w & 0xff) as usize]
        | SPREAD8[(w >> 8 & 0xff) as usize] << 1
        | SPREAD8[(w >> 16 & 0xff) as usize] << 2
}

/// [`morton8`] by three table lookups: cheaper than the bit spreading of [`morton8`] one
/// position at a time (the voxelizer's marking of each voxel a triangle touches).
#[inline]
pub fn morton8_by_table(x: u8, y: u8, z: u8) -> u32 {
    SPREAD8[x as usize] | SPREAD8[y as usize] << 1 | SPREAD8[z as usize] << 2
}

/// Byte `v` with its bits moved to every third bit (bit `b` → bit `3b`): one axis of
/// [`morton8`].
static SPREAD8: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut v = 0;
    while v < 256 {
        let mut b = 0;
        while b < 8 {
            t[v] |= ((v as u32 >> b) & 1) << (3 * b);
            b += 1;
        }
        v += 1;
    }
    t
};

/// The position word (`x | y << 8 | z << 16`) of an in-chunk Morton code (its low 24 bits),
/// by three table lookups.
#[inline]
pub fn unmorton8_word(m: u32) -> u32 {
    UNMORTON8[0][(m & 0xff) as usize]
        | UNMORTON8[1][(m >> 8 & 0xff) as usize]
        | UNMORTON8[2][(m >> 16 & 0xff) as usize]
}

/// Inverse of [`morton8`] (of the code's low 24 bits), by [`unmorton8_word`].
#[inline]
pub fn unmorton8(m: u32) -> [u8; 3] {
    let w = unmorton8_word(m);
    [w as u8, (w >> 8) as u8, (w >> 16) as u8]
}

/// For byte `b` of a 24-bit Morton code (`b` = 0, 1, 2) and each of its 256 values, the
/// coordinate bits it holds, packed as `x | y << 8 | z << 16`: Morton bit `i` (bit `j` of byte
/// `b`, `i = 8b + j`) is bit `i / 3` of axis `i % 3`.
static UNMORTON8: [[u32; 256]; 3] = {
    let mut t = [[0u32; 256]; 3];
    let mut b = 0;
    while b < 3 {
        let mut v = 0;
        while v < 256 {
            let mut j = 0;
            while j < 8 {
                if v >> j & 1 == 1 {
                    let i = 8 * b + j;
                    t[b][v] |= 1 << ((i % 3) * 8 + i / 3);
                }
                j += 1;
            }
            v += 1;
        }
        b += 1;
    }
    t
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_roundtrip_and_order() {
        for &(x, y, z) in &[
            (0, 0, 0),
            (1, 2, 3),
            (255, 255, 255),
            (65535, 1, 40000),
            (12345, 54321, 7),
        ] {
            assert_eq!(demorton3(morton3(x, y, z)), [x, y, z]);
        }
        // brute-force bit interleave
        for x in 0..8u32 {
            for y in 0..8u32 {
                for z in 0..8u32 {
                    let mut m = 0u64;
                    for b in 0..3 {
                        m |= (((x >> b) & 1) as u64) << (3 * b);
                        m |= (((y >> b) & 1) as u64) << (3 * b + 1);
                        m |= (((z >> b) & 1) as u64) << (3 * b + 2);
                    }
                    assert_eq!(morton3(x, y, z), m);
                }
            }
        }
    }

    #[test]
    fn the_in_chunk_forms_agree_with_morton3_everywhere() {
        for m in 0..1u32 << 24 {
            let p = demorton3(m as u64);
            let (x, y, z) = (p[0] as u8, p[1] as u8, p[2] as u8);
            let word = p[0] | p[1] << 8 | p[2] << 16;
            assert_eq!(unmorton8(m), [x, y, z]);
            assert_eq!(unmorton8_word(m | 0xff00_0000), word);
            assert_eq!(morton8(x, y, z), m);
            assert_eq!(morton8_word(word | 0x3f00_0000), m);
            assert_eq!(morton8_word_by_table(word | 0x3f00_0000), m);
            assert_eq!(morton8_by_table(x, y, z), m);
        }
        // brute-force bit interleave of a few positions
        for &(x, y, z) in &[(3u8, 200u8, 17u8), (255, 0, 1), (0, 255, 128)] {
            let mut m = 0u32;
            for b in 0..8 {
                m |= ((x as u32 >> b) & 1) << (3 * b);
                m |= ((y as u32 >> b) & 1) << (3 * b + 1);
                m |= ((z as u32 >> b) & 1) << (3 * b + 2);
            }
            assert_eq!(morton8(x, y, z), m);
        }
    }
}
