//! The mip pyramid of a texture: every level the **exact box filter of level 0 in linear
//! light** (Williams, "Pyramidal Parametrics", SIGGRAPH 1983, with box-filtered levels): level
//! `k` is `max(1, W >> k) × max(1, H >> k)` down to 1×1, and its texel `(i, j)` is the mean, in
//! f64 and linear light, of the level-0 texels `(x, y)` with `⌊x·w_k/W⌋ = i` and
//! `⌊y·h_k/H⌋ = j`, rounded to sRGB8 once. One level at a time from level 0, so that the tile
//! file ([`crate::tile_file`]) and the in-memory texture build the same bytes with the same
//! arithmetic, and the tile file never holds more than level 0 and one other level — or, for
//! a texture decoded row by row ([`LevelRows`]), one row of sums per level.

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
/// box filter above, row by row of level `k` ([`LevelRows`] fed every level-0 row).
pub(crate) fn box_level(base: &[[u8; 4]], w: u32, h: u32, k: u32) -> Vec<[u8; 4]> {
    assert!(k >= 1 && base.len() as u64 == w as u64 * h as u64);
    let mut level = LevelRows::new(w, h, k);
    let mut out = Vec::with_capacity(level.width() as usize * level.height() as usize);
    let mut row = Vec::new();
    for y in 0..h {
        if level.push(&base[(y * w) as usize..((y + 1) * w) as usize], &mut row) {
            out.extend_from_slice(&row);
        }
    }
    out
}

/// Level `k ≥ 1` of a `w × h` texture built as its level-0 rows arrive, top to bottom: each
/// level-`k` row is the box filter above, its blocks summed in level-0 row order, finished when
/// the last level-0 row it covers arrives. Holds one row of sums, so a texture can be filtered
/// while it is decoded row by row (the tile file's streamed path) with the same arithmetic, in
/// the same order, as the whole-image path.
pub(crate) struct LevelRows {
    w: u32,
    h: u32,
    wk: u32,
    hk: u32,
    /// The level-`k` column of each level-0 column.
    col: Vec<u32>,
    sums: Vec<[f64; 4]>,
    counts: Vec<u64>,
    /// The level-`k` row being summed, and the level-0 rows pushed so far.
    j: u32,
    y: u32,
}

impl LevelRows {
    pub(crate) fn new(w: u32, h: u32, k: u32) -> LevelRows {
        assert!(k >= 1 && w > 0 && h > 0);
        let (wk, hk) = ((w >> k).max(1), (h >> k).max(1));
        LevelRows {
            w,
            h,
            wk,
            hk,
            col: (0..w)
                .map(|x| (x as u64 * wk as u64 / w as u64) as u32)
                .collect(),
            sums: vec![[0.0; 4]; wk as usize],
            counts: vec![0; wk as usize],
            j: 0,
            y: 0,
        }
    }

    pub(crate) fn width(&self) -> u32 {
        self.wk
    }

    pub(crate) fn height(&self) -> u32 {
        self.hk
    }

    /// Adds the next level-0 row; when it is the last one of level-`k` row `j`, writes that
    /// row to `out` (`width()` texels) and returns true.
    pub(crate) fn push(&mut self, row: &[[u8; 4]], out: &mut Vec<[u8; 4]>) -> bool {
        assert!(
            row.len() == self.w as usize && self.y < self.h,
            "rows in order, each w wide"
        );
        let lut = lut();
        for (x, t) in row.iter().enumerate() {
            let i = self.col[x] as usize;
            let s = &mut self.sums[i];
            s[0] += lut[t[0] as usize] as f64;
            s[1] += lut[t[1] as usize] as f64;
            s[2] += lut[t[2] as usize] as f64;
            s[3] += t[3] as f64;
            self.counts[i] += 1;
        }
        self.y += 1;
        // level-k row j covers level-0 rows ⌈j·h/h_k⌉ .. ⌈(j+1)·h/h_k⌉ (never empty: h_k ≤ h)
        let end = ((self.j as u64 + 1) * self.h as u64).div_ceil(self.hk as u64) as u32;
        if self.y < end {
            return false;
        }
        out.clear();
        for (s, n) in self.sums.iter_mut().zip(self.counts.iter_mut()) {
            let inv = 1.0 / (*n).max(1) as f64;
            out.push([
                linear_to_srgb8((s[0] * inv) as f32),
                linear_to_srgb8((s[1] * inv) as f32),
                linear_to_srgb8((s[2] * inv) as f32),
                (s[3] * inv).round() as u8,
            ]);
            *s = [0.0; 4];
            *n = 0;
        }
        self.j += 1;
        true
    }
}
