//! The mip pyramid of a texture: every level the **exact box filter of level 0 in linear
//! light** (Williams, "Pyramidal Parametrics", SIGGRAPH 1983, with box-filtered levels): level
//! `k` is `max(1, W >> k) × max(1, H >> k)` down to 1×1, and its texel `(i, j)` is the mean, in
//! f64 and linear light, of the level-0 texels `(x, y)` with `⌊x·w_k/W⌋ = i` and
//! `⌊y·h_k/H⌋ = j`, rounded to sRGB8 once. One level at a time from level 0, so that the tile
//! file ([`crate::tile_file`]) and the in-memory texture build the same bytes with the same
//! arithmetic, and the tile file never holds more than level 0 and one other level.

use crate::{linear_to_srgb8, lut};

/// The sizes of the levels of a `w × h` texture, level 0 first, down to 1×1.
pub(crate) fn level_sizes(w: u32, h: u32) -> Vec<(u32, u32)> {
    assert!(w > 0 && h > 0, "a texture has texels");
    let mut sizes = vec![(w, h)];
    let mut k = 1;
    while sizes.last().is_some_and(|&(a, b)| a > 1 || b > 1) {
        sizes.push(((w >> k).max(1), (h >> k).max(1)));
        k += 1;
    }
    sizes
}

/// Bytes of the decoded pyramid of a `w × h` texture (RGBA8, every level).
pub(crate) fn pyramid_bytes(w: u32, h: u32) -> u64 {
    level_sizes(w, h)
        .iter()
        .map(|&(a, b)| a as u64 * b as u64 * 4)
        .sum()
}

/// Level `k ≥ 1` of the pyramid of the `w × h` level-0 texels `base` (row 0 at the top): the
/// box filter above, row by row of level `k`, each row's blocks summed in level-0 row order.
pub(crate) fn box_level(base: &[[u8; 4]], w: u32, h: u32, k: u32) -> Vec<[u8; 4]> {
    assert!(k >= 1 && base.len() as u64 == w as u64 * h as u64);
    let lut = lut();
    let (wk, hk) = ((w >> k).max(1), (h >> k).max(1));
    let mut out = Vec::with_capacity(wk as usize * hk as usize);
    // column block of each level-0 column
    let col: Vec<u32> = (0..w)
        .map(|x| (x as u64 * wk as u64 / w as u64) as u32)
        .collect();
    let mut sums = vec![[0f64; 4]; wk as usize];
    let mut counts = vec![0u64; wk as usize];
    for j in 0..hk {
        let y0 = (j as u64 * h as u64).div_ceil(hk as u64) as u32;
        let y1 = ((j as u64 + 1) * h as u64).div_ceil(hk as u64) as u32;
        sums.iter_mut().for_each(|s| *s = [0.0; 4]);
        counts.iter_mut().for_each(|c| *c = 0);
        for y in y0..y1 {
            let row = &base[(y * w) as usize..((y + 1) * w) as usize];
            for (x, t) in row.iter().enumerate() {
                let i = col[x] as usize;
                let s = &mut sums[i];
                s[0] += lut[t[0] as usize] as f64;
                s[1] += lut[t[1] as usize] as f64;
                s[2] += lut[t[2] as usize] as f64;
                s[3] += t[3] as f64;
                counts[i] += 1;
            }
        }
        for (s, &n) in sums.iter().zip(&counts) {
            let inv = 1.0 / n.max(1) as f64;
            out.push([
                linear_to_srgb8((s[0] * inv) as f32),
                linear_to_srgb8((s[1] * inv) as f32),
                linear_to_srgb8((s[2] * inv) as f32),
                (s[3] * inv).round() as u8,
            ]);
        }
    }
    out
}
