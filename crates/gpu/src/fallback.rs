//! The per-triangle exact fallback of the GPU voxelizer: the triangles the
//! shaders could not certify are decided here, on the host, with the CPU's exact overlap test
//! (`voxlod_voxelize::voxelize_triangle`: the f64 filter of Rauwendaal & Bailey's factored test
//! with Shewchuk's adaptive predicates inside its bands; `voxelize_world_triangle` for
//! triangles fed in world coordinates, exact for those), and their attribute
//! contributions are computed as the shaders compute them (voxelize.wgsl `accumulate`). The
//! flags the shaders need per triangle are computed here too: the certificates of dyadic
//! coordinates ([`exact_flags`]) and what the move to the grid rounded ([`world_flags`]).
//!
//! A triangle is *listed* by the shaders when one of its decisions lies inside its rounding
//! band, or a normal component's sign is in doubt (voxelize.wgsl `note_uncertain`). Such a
//! triangle marks on the GPU only voxels it certainly overlaps (uncertain decisions count as
//! outside), a subset of its exact set, and nothing in the accumulation phase (the host
//! overwrites it with a degenerate triangle in the triangle buffer). The host then
//! 1. sets the bits of the listed triangles' exact voxels in the occupancy bitset, before
//!    compaction, so the union is the exact set of the chunk ([`Listed::new`], [`Listed::mark`]);
//! 2. adds their contributions to the voxels' sums in the 2⁶⁴ fixed point of the GPU's sums
//!    ([`Listed::add_to`]): integer additions, so the result does not depend on their order.

use voxlod_geom::{Grid, Triangle, CHUNK, TRI_HAS_NORMALS};
use voxlod_voxelize::{clipped_area, voxelize_triangle, voxelize_world_triangle, Mode};

/// Flags of a triangle sent to f64 shaders (voxelize.wgsl): its edge functions and normal /
/// also its depth predicates are computed without rounding ([`exact_flags`]).
pub(crate) const TRI_EXACT_EDGES: u32 = 1 << 8;
pub(crate) const TRI_EXACT_DEPTH: u32 = 1 << 9;
/// Flags of a triangle fed in world coordinates ([`world_flags`]): some f32 grid coordinate is
/// not the exact image of its world value / two grid coordinates are equal where the world
/// values are not.
pub(crate) const TRI_ROUNDED: u32 = 1 << 10;
pub(crate) const TRI_TIES_BROKEN: u32 = 1 << 11;
/// Every flag bit the host sets (cleared on the caller's triangles first).
pub(crate) const HOST_FLAGS: u32 =
    TRI_EXACT_EDGES | TRI_EXACT_DEPTH | TRI_ROUNDED | TRI_TIES_BROKEN;

/// What voxelize.wgsl must know of a triangle fed in world coordinates `world` whose f32 grid
/// coordinates on `grid` are `g` (`grid.to_grid` of each vertex), so that the sets are exact for
/// the world values:
/// * [`TRI_ROUNDED`] unless every grid coordinate `c` is exactly the image of its world value
///   `p`, `origin + c·voxel_size = p` (checked exactly: the product with a fused multiply-add,
///   the sum with Knuth's two-sum, both error terms zero; a nonzero term counts as rounded,
///   which only widens the bands). Without it the grid coordinates are the exact image, every
///   decision on them is the world's (a translation and a positive scale), and the shaders
///   decide as for grid input, certificates included.
/// * [`TRI_TIES_BROKEN`] when two vertices share a grid coordinate but not the world value
///   (the rounding made a difference zero; the shaders then list the triangle: a normal
///   component whose products are all zero must be zero in the world too).
pub(crate) fn world_flags(world: &[[f32; 3]; 3], g: &[[f32; 3]; 3], grid: &Grid) -> u32 {
    let mut f = 0;
    for k in 0..3 {
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            if g[i][k] == g[j][k] && world[i][k] != world[j][k] {
                f |= TRI_TIES_BROKEN;
            }
        }
        for i in 0..3 {
            if !exact_image(
                world[i][k] as f64,
                g[i][k] as f64,
                grid.origin[k],
                grid.voxel_size,
            ) {
                f |= TRI_ROUNDED;
            }
        }
    }
    f
}

/// Whether `o + c·s = p` exactly (`false` may also mean "not provable in two f64 steps").
#[inline]
fn exact_image(p: f64, c: f64, o: f64, s: f64) -> bool {
    let h = c * s;
    if c.mul_add(s, -h) != 0.0 {
        return false;
    }
    let w = o + h;
    let bb = w - o;
    let err = (o - (w - bb)) + (h - bb);
    err == 0.0 && w == p
}

/// The certification of voxelize.wgsl (the crate docs, "Exactness"): with every
/// coordinate a multiple of 2⁻q (q ≥ 0, the finest fraction bit of the f32 values) and
/// `B = (max|v| + 2)·2^q`, f64 computes the edge functions and the normal exactly when
/// `B < 2²⁴`, and the depth predicates too when `B < 2¹⁴`. Computed on the host, once per
/// triangle and batch, so the shaders pay nothing for it.
pub(crate) fn exact_flags(t: &Triangle) -> u32 {
    let mut low = i32::MAX;
    let mut top = 0.0f64;
    for &c in t.v.iter().flatten() {
        let b = c.to_bits();
        let e = ((b >> 23) & 255) as i32;
        let m = (b & 0x7f_ffff) | if e != 0 { 0x80_0000 } else { 0 };
        if m != 0 {
            // c = ±m·2^(max(e,1) − 150)
            low = low.min(e.max(1) - 150 + m.trailing_zeros() as i32);
        }
        top = top.max((c as f64).abs());
    }
    let q = if low == i32::MAX { 0 } else { (-low).max(0) };
    let b = (top + 2.0) * 2f64.powi(q);
    if b < (1u32 << 14) as f64 {
        TRI_EXACT_EDGES | TRI_EXACT_DEPTH
    } else if b < (1u32 << 24) as f64 {
        TRI_EXACT_EDGES
    } else {
        0
    }
}

/// The fixed-point scale of the GPU's sums, 2⁶⁴ (voxelize.wgsl `add_fixed`).
const SCALE: f64 = 18446744073709551616.0;
/// Accumulator words per voxel slot (encode.rs `SLOT_WORDS`).
const SLOT_WORDS: usize = 48;

/// The (triangle, voxel) pairs of a chunk's listed triangles.
pub(crate) struct Listed {
    /// (local voxel index `x + 256 (y + 256 z)`, index into `tris`)
    pairs: Vec<(u32, u32)>,
    /// in grid coordinates (the attributes are computed from them, as on the CPU)
    tris: Vec<Triangle>,
    /// per pair, after [`Listed::slots`]: the voxel's slot, weighted or not, the 8 values
    contrib: Vec<(u32, bool, [f64; 8])>,
}

impl Listed {
    /// The exact voxels of each triangle of `tris` in the chunk at `origin` (grid coordinates,
    /// multiples of 256), under `mode`. With `world`, `tris` came in world coordinates of that
    /// grid: each is decided exactly for them (`voxlod_voxelize::voxelize_world_triangle`, the
    /// set `ChunkVoxelizer::add_world` marks) and kept moved to the grid; without, `tris` are
    /// grid coordinates and decided exactly for those (`voxelize_triangle`, as
    /// `ChunkVoxelizer::add`).
    pub(crate) fn new(
        mut tris: Vec<Triangle>,
        world: Option<&Grid>,
        origin: [u32; 3],
        mode: Mode,
    ) -> Listed {
        let o = origin.map(|c| c as i32);
        let hi = o.map(|c| c + CHUNK as i32 - 1);
        let mut pairs = Vec::new();
        for (i, t) in tris.iter_mut().enumerate() {
            let mut add = |p: [i32; 3]| {
                let l = [0, 1, 2].map(|k| (p[k] - o[k]) as u32);
                debug_assert!(l.iter().all(|&c| c < CHUNK));
                pairs.push((l[0] + CHUNK * (l[1] + CHUNK * l[2]), i as u32));
            };
            match world {
                Some(grid) => {
                    voxelize_world_triangle(grid, &t.v, o, hi, mode, &mut add);
                    t.v = t.v.map(|p| grid.to_grid(p));
                }
                None => voxelize_triangle(&t.v, o, hi, mode, &mut add),
            }
        }
        Listed {
            pairs,
            tris,
            contrib: Vec::new(),
        }
    }

    /// Sets the pairs' voxels in the occupancy bitset `occ` (bit `i & 31` of word `i >> 5`);
    /// whether a bit was new.
    pub(crate) fn mark(&self, occ: &mut [u32]) -> bool {
        let mut new = false;
        for &(i, _) in &self.pairs {
            let (w, bit) = ((i >> 5) as usize, 1u32 << (i & 31));
            new |= occ[w] & bit == 0;
            occ[w] |= bit;
        }
        new
    }

    /// Computes each pair's slot (from the final bitset and the compaction's slot bases) and
    /// its contribution.
    pub(crate) fn slots(&mut self, occ: &[u32], base: &[u32], origin: [u32; 3]) {
        self.contrib = self
            .pairs
            .iter()
            .map(|&(i, t)| {
                let (w, bit) = ((i >> 5) as usize, 1u32 << (i & 31));
                debug_assert!(occ[w] & bit != 0);
                let slot = base[w] + (occ[w] & (bit - 1)).count_ones();
                let l = [i % CHUNK, (i / CHUNK) % CHUNK, i / (CHUNK * CHUNK)];
                let p = [0, 1, 2].map(|k| (origin[k] + l[k]) as i32);
                let (weighted, x) = contribution(&self.tris[t as usize], p);
                (slot, weighted, x)
            })
            .collect();
    }

    /// Adds the contributions of the pairs whose slot is in `[lo, hi)` to `acc`, the
    /// accumulators of those slots (48 words each).
    pub(crate) fn add_to(&self, acc: &mut [u32], lo: u32, hi: u32) {
        for &(slot, weighted, x) in &self.contrib {
            if slot < lo || slot >= hi {
                continue;
            }
            let off = (slot - lo) as usize * SLOT_WORDS;
            let first = if weighted { 0 } else { 8 };
            for (k, v) in x.into_iter().enumerate() {
                add_fixed(&mut acc[off + 3 * (first + k)..][..3], v);
            }
        }
    }
}

/// Adds `value · 2⁶⁴`, rounded down, to the 96-bit two's-complement integer `w` (least
/// significant word first), modulo 2⁹⁶ as the shader's carries do.
fn add_fixed(w: &mut [u32], value: f64) {
    let old = (w[2] as i32 as i128) << 64 | (w[1] as i128) << 32 | w[0] as i128;
    let v = old + (value * SCALE).floor() as i128;
    w[0] = v as u32;
    w[1] = (v >> 32) as u32;
    w[2] = (v >> 64) as u32;
}

/// The contribution of triangle `t` to voxel `p` (grid coordinates), as voxelize.wgsl
/// `accumulate` computes it: the clipped area `w`, the normal and colour interpolated at the
/// clipped polygon's centroid; `(true, [w, w·n, w·rgba])` when `w·2⁶⁴ ≥ 1`, else
/// `(false, [1, n, rgba])` (a voxel the triangle only touches; unweighted sums).
fn contribution(t: &Triangle, p: [i32; 3]) -> (bool, [f64; 8]) {
    let (w, q) = clipped_area(&t.v, p);
    let o = t.v.map(|v| v.map(f64::from));
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // barycentrics at q
    let (e1, e2) = (sub(o[1], o[0]), sub(o[2], o[0]));
    let n = cross(e1, e2);
    let nn = dot(n, n);
    let d = sub(q, o[0]);
    let l1 = dot(cross(d, e2), n) / nn;
    let l2 = dot(cross(e1, d), n) / nn;
    let l = [1.0 - l1 - l2, l1, l2];
    let len = nn.sqrt();
    let mut normal = n.map(|c| c / len);
    if t.flags & TRI_HAS_NORMALS != 0 {
        let m: [f64; 3] =
            std::array::from_fn(|k| (0..3).map(|i| l[i] * t.n[i][k] as f64).sum::<f64>());
        let len = dot(m, m).sqrt();
        if len > 0.0 && len < 3.0e38 {
            normal = m.map(|c| c / len);
        }
    }
    let colour: [f64; 4] =
        std::array::from_fn(|k| (0..3).map(|i| l[i] * t.c[i][k] as f64).sum::<f64>());
    let x = [
        normal[0], normal[1], normal[2], colour[0], colour[1], colour[2], colour[3],
    ];
    if (w * SCALE).floor() > 0.0 {
        (
            true,
            [
                w,
                w * x[0],
                w * x[1],
                w * x[2],
                w * x[3],
                w * x[4],
                w * x[5],
                w * x[6],
            ],
        )
    } else {
        (false, [1.0, x[0], x[1], x[2], x[3], x[4], x[5], x[6]])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn certification_levels() {
        let t = |v: [[f32; 3]; 3]| exact_flags(&Triangle::new(v));
        let all = TRI_EXACT_EDGES | TRI_EXACT_DEPTH;
        // integers and quarters below 2^14 - 2
        assert_eq!(
            t([[0.0, 1.0, 2.0], [16381.0, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            all
        );
        assert_eq!(
            t([[0.25, 1.0, 2.0], [4000.5, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            all
        );
        assert_eq!(
            t([[0.25, 1.0, 2.0], [4094.0, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            TRI_EXACT_EDGES
        );
        // 16382 + 2 = 2^14: no longer exact in the depth predicates
        assert_eq!(
            t([[0.0, 1.0, 2.0], [16382.0, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            TRI_EXACT_EDGES
        );
        // full f32 mantissas in the binade of the largest coordinate: (500 + 2) · 2^15 < 2^24
        assert_eq!(
            t([[0.0, 1.0, 2.0], [500.00003, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            TRI_EXACT_EDGES
        );
        // a fine mantissa far below the largest coordinate: 2^22 · 502 ≥ 2^24
        assert_eq!(t([[3.7, 1.0, 2.0], [500.0, 3.0, 0.0], [5.0, 6.0, 7.0]]), 0);
        // a tiny coordinate
        assert_eq!(t([[1e-30, 1.0, 2.0], [5.0, 3.0, 0.0], [5.0, 6.0, 7.0]]), 0);
        assert_eq!(
            t([[-8.0, -1.5, 2.0], [5.0, 3.0, 0.0], [5.0, 6.0, 7.0]]),
            all
        );
    }

    #[test]
    fn world_flags_tell_exact_images_and_broken_ties() {
        let flags =
            |grid: &Grid, w: [[f32; 3]; 3]| world_flags(&w, &w.map(|p| grid.to_grid(p)), grid);
        let w = [[1.0, 2.0, 3.0], [4.0, 2.0, 5.5], [-1.25, 7.0, 3.0]];
        // voxel size ½, origin on a quarter: every grid coordinate is the exact image
        let dyadic = Grid::new([-3.0, 0.25, -8.0], 128.0, 256).unwrap();
        assert_eq!(flags(&dyadic, w), 0);
        // voxel size 0.3 (not a binary fraction): rounded
        let odd = Grid::new([-3.0, 0.25, -8.0], 0.3 * 256.0, 256).unwrap();
        assert_eq!(flags(&odd, w), TRI_ROUNDED);
        // the grid's own corners are exact images even there: x = origin, 0 in grid units
        let on = [[-3.0, 0.25, -8.0], [-3.0, 0.25, -8.0], [-3.0, 0.25, -8.0]];
        assert_eq!(flags(&odd, on), 0);
        // two world values one ulp apart that round to one grid value (the origin far away:
        // the grid coordinates' ulp is coarser than the world values')
        let x = 1.0f32;
        let y = f32::from_bits(x.to_bits() + 1);
        let big = Grid::new([-1000.0; 3], 256.0, 256).unwrap();
        assert_eq!(big.to_grid([x, 0.0, 0.0])[0], big.to_grid([y, 0.0, 0.0])[0]);
        let f = flags(&big, [[x, 0.0, 1.0], [y, 1.0, 0.0], [x, 2.0, 0.5]]);
        assert_eq!(f & TRI_TIES_BROKEN, TRI_TIES_BROKEN);
        assert!(exact_image(5.0, 2.0, 1.0, 2.0));
        assert!(!exact_image(5.0, 2.0, 1.0, 2.0000000000000004));
    }

    #[test]
    fn fixed_point_adds_with_carries_and_sign() {
        let mut w = [u32::MAX, u32::MAX, 0];
        add_fixed(&mut w, 2.0f64.powi(-64));
        assert_eq!(w, [0, 0, 1]);
        add_fixed(&mut w, -1.0);
        assert_eq!(w, [0, 0, 0]);
        add_fixed(&mut w, -0.5);
        let v = (w[2] as i32 as i128) << 64 | (w[1] as i128) << 32 | w[0] as i128;
        assert_eq!(v as f64 / SCALE, -0.5);
    }

    #[test]
    fn exact_pairs_of_a_grid_triangle() {
        // the triangle of the crate docs' example: columns (0,0) (1,0) (0,1) (1,1) (2,0) (0,2)
        let t = Triangle::new([[0.0, 0.0, 2.5], [2.0, 0.0, 2.5], [0.0, 2.0, 2.5]]);
        let mut l = Listed::new(vec![t], None, [0; 3], Mode::Conservative);
        assert_eq!(l.tris.len(), 1);
        let mut occ = vec![0u32; (CHUNK * CHUNK * CHUNK / 32) as usize];
        assert!(l.mark(&mut occ));
        assert_eq!(occ.iter().map(|w| w.count_ones()).sum::<u32>(), 6);
        assert!(!l.mark(&mut occ));
        // slot bases as the compaction pass gives them
        let mut base = vec![0u32; occ.len()];
        let mut next = 0;
        for (b, w) in base.iter_mut().zip(&occ) {
            *b = next;
            next += w.count_ones();
        }
        l.slots(&occ, &base, [0; 3]);
        let mut acc = vec![0u32; 6 * SLOT_WORDS];
        l.add_to(&mut acc, 0, 6);
        // the total weight is the triangle's area, 2 voxels²
        let total: f64 = (0..6)
            .map(|s| {
                let w = &acc[s * SLOT_WORDS..][..3];
                ((w[2] as i32 as i128) << 64 | (w[1] as i128) << 32 | w[0] as i128) as f64 / SCALE
            })
            .sum();
        assert!((total - 2.0).abs() < 1e-12, "{total}");
    }
}
