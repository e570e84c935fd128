//! Factored triangle/voxel overlap tests: Rauwendaal & Bailey, "Hybrid Computational
//! Voxelization Using the Graphics Pipeline", JCGT 2(1) 2013, section 3.1 and the Appendix
//! (Figure 17 conservative, Figure 18 thin), after Schwarz & Seidel, "Fast Parallel Surface and
//! Solid Voxelization on GPUs", SIGGRAPH Asia 2010.
//!
//! Voxel `p` (integer grid coordinates) is the closed box `[p, p+1]³`. Everything is computed in
//! f64 from the f32 vertices. The triangle is swizzled so that its dominant axis (largest
//! `|n|` component) becomes the depth axis z; we iterate columns (x, y) of the dominant
//! projection, get the depth range from the plane, and test the two other projections.
//!
//! Deviations from the paper's pseudocode (typos there, derivations here):
//! * Figure 17/18 line 19 use `p_xy` for all projections; the YZ test uses `(p_y, p_z)` and the ZX
//!   test `(p_z, p_x)`.
//! * Figure 17 lines 16–17 iterate `floor(z_lo) ..= ceil(z_hi)`, one voxel too many above (and
//!   one too few below on exact ties). The voxels whose closed z-extent `[p_z, p_z+1]` meets the
//!   plane's z-range `[z_lo, z_hi]` over the column are `ceil(z_lo)-1 ..= floor(z_hi)`. We compute
//!   that range with a division and then settle it with the undivided predicates
//!   `n_z·(p_z+1) ≥ d_lo − n_x p_x − n_y p_y` and `n_z·p_z ≤ d_hi − n_x p_x − n_y p_y`, so the
//!   division's rounding never decides a tie.
//! * Figure 18 lines 16–17 likewise give two voxels per column; the thin test keeps the voxels
//!   whose z-extent contains `z_int` (the plane's height above the column centre): one voxel,
//!   two only when `z_int` is an integer. Same predicates with `d_lo = d_hi = d_cen`.
//! * Figure 18 lines 7–9 take `max(|n^XY|, |n^YZ|)`; the support of the 2D diamond
//!   `{x : |x − c|₁ ≤ ½}` along `n_e` is `½·max(|n_e,0|, |n_e,1|)` of that edge normal alone.
//! * `sign(0) = 0` (not Rust's `signum`): a projection of zero area gets zero edge normals and
//!   its edge tests pass; in that case those axes are parallel to the plane normal, which the
//!   depth test already covers.
//!
//! **Conservative** (26-separating): a voxel is marked iff the closed triangle and the closed box
//! intersect, i.e. no separating axis among the 13 of Akenine-Möller (box bbox, plane, 9 edge ×
//! axis products, the latter as the 2D edge tests of the three projections).
//!
//! **Thin** (6-separating): let `D_p = {x : |x − (p + ½)|₁ ≤ ½}` be the diamond (octahedron)
//! inscribed in voxel `p`. A voxel is marked iff it lies in the conservative bounding box, the
//! triangle's plane meets `D_p` (`|n·(c−v₀)| ≤ ½‖n‖∞`, the naive digital plane), and for each of
//! the three projections and each edge the edge's inner half-plane meets the projected 2D
//! diamond. Every condition is necessary for `T ∩ D_p ≠ ∅`, so the marked set contains
//! `{p : T ∩ D_p ≠ ∅}`, which is 6-separating for a closed surface: a 6-path of voxel centres from
//! outside to inside crosses the surface on a segment `c → c + e_a`, and every point of that
//! segment lies in `D` of one of its two end voxels. Each condition also implies its
//! conservative counterpart (`D_p ⊂ p`), so thin ⊆ conservative.

use crate::Mode;

/// `sign` with `sign(0) = 0`.
#[inline]
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The dominant axis of a normal: z if `|n_z|` is the largest (ties go to z), else x if
/// `|n_x| ≥ |n_y|`, else y.
#[inline]
pub fn dominant_axis(n: [f64; 3]) -> usize {
    let a = [n[0].abs(), n[1].abs(), n[2].abs()];
    if a[2] >= a[0] && a[2] >= a[1] {
        2
    } else if a[0] >= a[1] {
        0
    } else {
        1
    }
}

/// The swizzle for a dominant axis: swizzled axis `k` is original axis `swizzle(axis)[k]`
/// (paper 3.3.1: x dominant → yzx, y dominant → zxy, z dominant → xyz). It is a cyclic
/// permutation, so cross products commute with it.
#[inline]
pub fn swizzle(axis: usize) -> [usize; 3] {
    match axis {
        0 => [1, 2, 0],
        1 => [2, 0, 1],
        _ => [0, 1, 2],
    }
}

/// Point `p` in swizzled coordinates (swizzle `swz`) back in original ones, as
/// [`TriSetup::unswizzle`] does.
#[inline]
pub(crate) fn unswizzle<T: Copy>(swz: [usize; 3], p: [T; 3]) -> [T; 3] {
    let inv = unswizzle_of(swz);
    [p[inv[0]], p[inv[1]], p[inv[2]]]
}

/// The inverse of a [`swizzle`] permutation.
#[inline]
fn unswizzle_of(swz: [usize; 3]) -> [usize; 3] {
    let mut inv = [0; 3];
    for (k, &j) in swz.iter().enumerate() {
        inv[j] = k;
    }
    inv
}

/// `(v1 − v0) × (v2 − v0)` in f64 (same formula as `Triangle::cross`).
#[inline]
pub(crate) fn cross_f64(v: &[[f64; 3]; 3]) -> [f64; 3] {
    let a = [v[1][0] - v[0][0], v[1][1] - v[0][1], v[1][2] - v[0][2]];
    let b = [v[2][0] - v[0][0], v[2][1] - v[0][1], v[2][2] - v[0][2]];
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(crate) fn to_f64(v: &[[f32; 3]; 3]) -> [[f64; 3]; 3] {
    v.map(|p| p.map(|c| c as f64))
}

/// The voxel whose open interior `(p, p+1)³` contains the whole triangle, if there is one (every
/// coordinate finite, and on every axis the triangle's extent strictly between two consecutive
/// integers). Such a triangle meets no other closed voxel box, so its conservative voxel set is
/// exactly `{p}`, without the overlap test (on scans, where triangles are much smaller than
/// voxels, most triangles are such). Not so for thin voxelization: the triangle may miss the
/// diamond inscribed in `p`.
#[inline]
pub fn interior_voxel(v: &[[f32; 3]; 3]) -> Option<[i32; 3]> {
    let mut p = [0i32; 3];
    for k in 0..3 {
        // in f64, so that `f + 1.0` is exact; every comparison is false for a NaN, and one
        // is for an infinity
        let c = [v[0][k] as f64, v[1][k] as f64, v[2][k] as f64];
        let f = c[0].floor();
        let inside = c.iter().all(|&c| c > f && c < f + 1.0);
        if !(inside && f >= i32::MIN as f64 && f < i32::MAX as f64) {
            return None;
        }
        p[k] = f as i32;
    }
    Some(p)
}

/// Per-triangle setup of the factored overlap test (paper 3.1.2). All vectors are in swizzled
/// coordinates (depth axis last).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriSetup {
    pub mode: Mode,
    /// Dominant axis in original coordinates (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// Swizzled axis `k` is original axis `swz[k]`; see [`swizzle`].
    pub swz: [usize; 3],
    /// The inverse permutation: original axis `j` is swizzled axis `unswz[j]`.
    unswz: [usize; 3],
    /// Swizzled vertices.
    pub v: [[f64; 3]; 3],
    /// Swizzled normal `(v1−v0)×(v2−v0)`, negated if needed so that `n[2] > 0`.
    pub n: [f64; 3],
    /// Inward edge normals `ne[plane][i]` of edge `e_i = v_{i+1} − v_i`; plane 0 = XY with
    /// coordinates `(x, y)`, 1 = YZ with `(y, z)`, 2 = ZX with `(z, x)`. Zero for a projection of
    /// zero area.
    pub ne: [[[f64; 2]; 3]; 3],
    /// Edge distances: the edge test of voxel `p` passes iff
    /// `ne[k][i][0]·p_a + ne[k][i][1]·p_b + de[k][i] ≥ 0` with `(p_a, p_b)` the projection's
    /// coordinates of the voxel's minimum corner.
    pub de: [[f64; 3]; 3],
    /// Depth test: voxel `p` meets the plane iff `n_z·(p_z+1) ≥ d_lo − n_x p_x − n_y p_y` and
    /// `n_z·p_z ≤ d_hi − n_x p_x − n_y p_y`. Conservative: `d_min`, `d_max`; thin: both `d_cen`.
    pub d_lo: f64,
    pub d_hi: f64,
    /// Closed voxel bounding box (swizzled): voxels `i` with `[i, i+1]` meeting the triangle's
    /// bounding box, `ceil(min) − 1 ..= floor(max)`, clamped to the i32 range.
    pub bmin: [i32; 3],
    pub bmax: [i32; 3],
}

impl TriSetup {
    /// The setup of triangle `v` (grid coordinates); `None` if a coordinate is not finite or the
    /// area is exactly zero in f64.
    pub fn new(v: &[[f32; 3]; 3], mode: Mode) -> Option<TriSetup> {
        if !v.iter().flatten().all(|c| c.is_finite()) {
            return None;
        }
        let o = to_f64(v);
        let n_o = cross_f64(&o);
        if n_o == [0.0; 3] || !n_o.iter().all(|c| c.is_finite()) {
            return None;
        }
        let axis = dominant_axis(n_o);
        let swz = swizzle(axis);
        let sw = |p: [f64; 3]| [p[swz[0]], p[swz[1]], p[swz[2]]];
        let v = [sw(o[0]), sw(o[1]), sw(o[2])];
        let n = sw(n_o);
        debug_assert!(n[2] != 0.0);
        let s = [sign(n[0]), sign(n[1]), sign(n[2])];

        let mut ne = [[[0.0; 2]; 3]; 3];
        let mut de = [[0.0; 3]; 3];
        for i in 0..3 {
            let a = v[i];
            let b = v[(i + 1) % 3];
            let e = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            // (normal, projected vertex) per plane: XY (x,y), YZ (y,z), ZX (z,x)
            let planes = [
                ([s[2] * -e[1], s[2] * e[0]], [a[0], a[1]]),
                ([s[0] * -e[2], s[0] * e[1]], [a[1], a[2]]),
                ([s[1] * -e[0], s[1] * e[2]], [a[2], a[0]]),
            ];
            for (k, (nk, vk)) in planes.into_iter().enumerate() {
                // avoid -0.0 so the setup is bit-stable
                let nk = [nk[0] + 0.0, nk[1] + 0.0];
                let base = -(nk[0] * vk[0] + nk[1] * vk[1]);
                de[k][i] = match mode {
                    // most interior corner of the unit square
                    Mode::Conservative => base + nk[0].max(0.0) + nk[1].max(0.0),
                    // most interior vertex of the diamond inscribed in the unit square
                    Mode::Thin => base + 0.5 * (nk[0] + nk[1]) + 0.5 * nk[0].abs().max(nk[1].abs()),
                };
                ne[k][i] = nk;
            }
        }

        let n = if n[2] < 0.0 { [-n[0], -n[1], -n[2]] } else { n };
        let dp = n[0] * v[0][0] + n[1] * v[0][1] + n[2] * v[0][2];
        let (d_lo, d_hi) = match mode {
            Mode::Conservative => (
                dp - n[0].max(0.0) - n[1].max(0.0),
                dp - n[0].min(0.0) - n[1].min(0.0),
            ),
            Mode::Thin => {
                let c = dp - 0.5 * n[0] - 0.5 * n[1];
                (c, c)
            }
        };

        let mut bmin = [0i32; 3];
        let mut bmax = [0i32; 3];
        for k in 0..3 {
            let mn = v[0][k].min(v[1][k]).min(v[2][k]);
            let mx = v[0][k].max(v[1][k]).max(v[2][k]);
            bmin[k] = clamp_i32(mn.ceil() - 1.0);
            bmax[k] = clamp_i32(mx.floor());
        }
        Some(TriSetup {
            mode,
            axis,
            swz,
            unswz: unswizzle_of(swz),
            v,
            n,
            ne,
            de,
            d_lo,
            d_hi,
            bmin,
            bmax,
        })
    }

    /// Swizzles a point or voxel given in original coordinates.
    #[inline]
    pub fn swizzle<T: Copy>(&self, p: [T; 3]) -> [T; 3] {
        [p[self.swz[0]], p[self.swz[1]], p[self.swz[2]]]
    }

    /// Inverse of [`TriSetup::swizzle`].
    #[inline]
    pub fn unswizzle<T: Copy>(&self, p: [T; 3]) -> [T; 3] {
        // a gather (dynamic loads, fixed stores) rather than a scatter: the caller reads the
        // result as a whole, and stores at dynamic offsets would stall its loads
        [p[self.unswz[0]], p[self.unswz[1]], p[self.unswz[2]]]
    }

    /// The appendix routine on swizzled coordinates: calls `emit(p, first)` for every overlapped
    /// voxel `p` in `[lo, hi]` (swizzled, inclusive) in order x, y, z; `first` is true for the
    /// first voxel of each (x, y) column.
    #[inline]
    pub fn scan(&self, lo: [i32; 3], hi: [i32; 3], mut emit: impl FnMut([i32; 3], bool)) {
        let lo = [
            lo[0].max(self.bmin[0]),
            lo[1].max(self.bmin[1]),
            lo[2].max(self.bmin[2]),
        ];
        let hi = [
            hi[0].min(self.bmax[0]),
            hi[1].min(self.bmax[1]),
            hi[2].min(self.bmax[2]),
        ];
        if lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2] {
            return;
        }
        let n = self.n;
        let inv_nz = 1.0 / n[2];
        let [xy, yz, zx] = self.ne;
        let [dxy, dyz, dzx] = self.de;
        for px in lo[0]..=hi[0] {
            let x = px as f64;
            // ZX edge functions without the z term
            let czx = [
                zx[0][1] * x + dzx[0],
                zx[1][1] * x + dzx[1],
                zx[2][1] * x + dzx[2],
            ];
            for py in lo[1]..=hi[1] {
                let y = py as f64;
                // dominant projection (paper line 15)
                if !(xy[0][0] * x + xy[0][1] * y + dxy[0] >= 0.0
                    && xy[1][0] * x + xy[1][1] * y + dxy[1] >= 0.0
                    && xy[2][0] * x + xy[2][1] * y + dxy[2] >= 0.0)
                {
                    continue;
                }
                // depth range from the plane (lines 16-17, corrected)
                let a = -(n[0] * x + n[1] * y);
                let lo_rhs = a + self.d_lo; // need n_z (p_z + 1) >= lo_rhs
                let hi_rhs = a + self.d_hi; // need n_z p_z <= hi_rhs
                let zl = lo[2] as f64;
                let zh = hi[2] as f64;
                let mut z0 = ((lo_rhs * inv_nz).ceil() - 1.0).clamp(zl - 1.0, zh + 1.0);
                while z0 > zl - 1.0 && n[2] * z0 >= lo_rhs {
                    z0 -= 1.0;
                }
                while z0 <= zh && n[2] * (z0 + 1.0) < lo_rhs {
                    z0 += 1.0;
                }
                let mut z1 = (hi_rhs * inv_nz).floor().clamp(zl - 1.0, zh + 1.0);
                while z1 < zh + 1.0 && n[2] * (z1 + 1.0) <= hi_rhs {
                    z1 += 1.0;
                }
                while z1 >= zl && n[2] * z1 > hi_rhs {
                    z1 -= 1.0;
                }
                let z0 = z0.max(zl) as i32;
                let z1 = z1.min(zh) as i32;
                // the other two projections (line 19, with the right coordinates)
                let cyz = [
                    yz[0][0] * y + dyz[0],
                    yz[1][0] * y + dyz[1],
                    yz[2][0] * y + dyz[2],
                ];
                let mut first = true;
                for pz in z0..=z1 {
                    let z = pz as f64;
                    if yz[0][1] * z + cyz[0] >= 0.0
                        && yz[1][1] * z + cyz[1] >= 0.0
                        && yz[2][1] * z + cyz[2] >= 0.0
                        && zx[0][0] * z + czx[0] >= 0.0
                        && zx[1][0] * z + czx[1] >= 0.0
                        && zx[2][0] * z + czx[2] >= 0.0
                    {
                        emit([px, py, pz], first);
                        first = false;
                    }
                }
            }
        }
    }

    // ---- The three per-voxel predicates (issue 13). A voxel `p` of the bounding box
    // `[bmin, bmax]` is marked iff `column_inside(p_x, p_y)`, `p_z` lies in `column_depth(p_x,
    // p_y, ..)` and `side_inside(p)`: the set `scan` enumerates. `crate::scanline` decides
    // membership only through these. This block is the f64 evaluation of `scan`, expression by
    // expression (same rounding, so the same sets); it is meant to be replaced by exact versions
    // (filtered f64 with an exact fallback).

    /// Dominant-projection (XY) edge tests of column `(x, y)` (swizzled).
    #[inline]
    pub fn column_inside(&self, x: i32, y: i32) -> bool {
        let (x, y) = (x as f64, y as f64);
        let xy = &self.ne[0];
        let dxy = &self.de[0];
        xy[0][0] * x + xy[0][1] * y + dxy[0] >= 0.0
            && xy[1][0] * x + xy[1][1] * y + dxy[1] >= 0.0
            && xy[2][0] * x + xy[2][1] * y + dxy[2] >= 0.0
    }

    /// The voxels `z` of column `(x, y)` whose box (conservative) / diamond (thin) meets the
    /// plane, clamped to `[zlo, zhi]`; `None` if that is empty.
    #[inline]
    pub fn column_depth(&self, x: i32, y: i32, zlo: i32, zhi: i32) -> Option<(i32, i32)> {
        let n = self.n;
        let (x, y) = (x as f64, y as f64);
        let a = -(n[0] * x + n[1] * y);
        let lo_rhs = a + self.d_lo; // need n_z (p_z + 1) >= lo_rhs
        let hi_rhs = a + self.d_hi; // need n_z p_z <= hi_rhs
        let inv_nz = 1.0 / n[2];
        let zl = zlo as f64;
        let zh = zhi as f64;
        let mut z0 = ((lo_rhs * inv_nz).ceil() - 1.0).clamp(zl - 1.0, zh + 1.0);
        while z0 > zl - 1.0 && n[2] * z0 >= lo_rhs {
            z0 -= 1.0;
        }
        while z0 <= zh && n[2] * (z0 + 1.0) < lo_rhs {
            z0 += 1.0;
        }
        let mut z1 = (hi_rhs * inv_nz).floor().clamp(zl - 1.0, zh + 1.0);
        while z1 < zh + 1.0 && n[2] * (z1 + 1.0) <= hi_rhs {
            z1 += 1.0;
        }
        while z1 >= zl && n[2] * z1 > hi_rhs {
            z1 -= 1.0;
        }
        let z0 = z0.max(zl);
        let z1 = z1.min(zh);
        (z0 <= z1).then_some((z0 as i32, z1 as i32))
    }

    /// The YZ and ZX edge tests of voxel `p = (x, y, z)` (swizzled).
    #[inline]
    pub fn side_inside(&self, p: [i32; 3]) -> bool {
        let [x, y, z] = p.map(|c| c as f64);
        let [_, yz, zx] = &self.ne;
        let [_, dyz, dzx] = &self.de;
        yz[0][1] * z + (yz[0][0] * y + dyz[0]) >= 0.0
            && yz[1][1] * z + (yz[1][0] * y + dyz[1]) >= 0.0
            && yz[2][1] * z + (yz[2][0] * y + dyz[2]) >= 0.0
            && zx[0][0] * z + (zx[0][1] * x + dzx[0]) >= 0.0
            && zx[1][0] * z + (zx[1][1] * x + dzx[1]) >= 0.0
            && zx[2][0] * z + (zx[2][1] * x + dzx[2]) >= 0.0
    }
}

#[inline]
fn clamp_i32(x: f64) -> i32 {
    x.clamp(i32::MIN as f64, i32::MAX as f64) as i32
}

/// The appendix routine: calls `emit(voxel)` for every voxel in `[bmin, bmax]` (inclusive, grid
/// coordinates, unswizzled) that the triangle overlaps under `mode`, in the deterministic order
/// swizzled x, then y, then z (depth axis innermost). Zero-area and non-finite triangles emit
/// nothing.
pub fn voxelize_triangle(
    v: &[[f32; 3]; 3],
    bmin: [i32; 3],
    bmax: [i32; 3],
    mode: Mode,
    emit: &mut impl FnMut([i32; 3]),
) {
    let Some(s) = TriSetup::new(v, mode) else {
        return;
    };
    s.scan(s.swizzle(bmin), s.swizzle(bmax), |p, _| {
        emit(s.unswizzle(p))
    });
}
