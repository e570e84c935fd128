//! Small triangles without the scan and without the pair list: a triangle whose closed voxel
//! range spans at most two voxels per axis (conservative mode). Its voxel set is decided by
//! the separating axis tests of Rauwendaal & Bailey, "Hybrid Computational Voxelization Using
//! the Graphics Pipeline", JCGT 2(1) 2013 (Appendix), against the at most eight *octants* around
//! the one grid point `P` the range straddles, with Shewchuk's exact predicates
//! ([`crate::predicates`]); its weights are the clipped areas of [`crate::clipped_area`]
//! (Chajdas, Reitinger & Westermann, WSCG 2014, section 3), made by at most one plane cut per
//! axis instead of a clip per voxel. The chunk voxelizer adds the contributions at once, in
//! triangle order, without keeping the triangle or its (triangle, voxel) pairs
//! ([`crate::chunk`]).
//!
//! **The set.** On axis `k` the voxels whose closed box `[i, i+1]` meets the triangle's extent
//! `[mn, mx]` are `ceil(mn) − 1 ..= floor(mx)` (exact on the f64 images of the f32
//! coordinates). With at most two of them on every axis, let `A` be the axes with two (the
//! *split* axes) and `P_k = floor(mx_k)` the grid plane between them. The triangle lies inside
//! the two voxels' slab on every axis, so it meets the box of candidate voxel `s` (`s_k = −1`
//! for the lower voxel of a split axis, `+1` for the upper) exactly where it meets the closed
//! octant `{ s_k·(x_k − P_k) ≥ 0, k ∈ A }`:
//! * `A = ∅`: the one voxel whose open interior holds the triangle (as
//!   [`crate::overlap::interior_voxel`]).
//! * `|A| = 1`: both voxels (the extent reaches `P_k` from both sides, closed boxes).
//! * `|A| = 2` (axis `c` not split): the triangle's `c`-range is inside the voxels', so it meets
//!   the box iff its projection on the plane `⟂ c` meets the closed quadrant. Two convex sets,
//!   one compact, are disjoint iff a line parallel to an edge of one separates them; the
//!   quadrant's edge normals are the axes (the extents overlap there), so the quadrant is
//!   missed iff for some edge `v_p → v_q` with outward normal `m` the quadrant lies strictly
//!   outside: `m·(P − v_p) > 0` and `m` is non-negative along both of the quadrant's
//!   directions `s_i e_i`, `s_j e_j` (else the quadrant reaches past the edge's line).
//! * `|A| = 3`: the 13 axes of the box test for an octant: the coordinate axes (overlapping),
//!   the edge × axis ones, which are the quadrant tests of the three projections, and the
//!   normal `n`: the octant lies strictly on one side of the plane iff `n·(P − v_0)` is
//!   positive and `s_k n_k ≥ 0` for every `k` (the octant's least `n·x` is at `P`), or negative
//!   and `s_k n_k ≤ 0`.
//!
//! Every sign is exact: the edge differences of f32 values (their f64 difference has the exact
//! sign), `m·(P − v_p)` as `orient2d` and `n·(P − v_0)` as `orient3d` (the `robust` crate), and
//! the orientation of each projection (`n_k`) from the filter of [`crate::TriSetup::new`]
//! (`|n_k| > 5u·A_k`). A triangle with a component inside that band, or with a projection of
//! zero area where the tests above need its orientation, goes to the general path instead.
//!
//! **The weights** are those of [`crate::clipped_area`], bit for bit: the triangle swizzled to
//! its dominant axis, cut by the split planes in the order of the swizzled axes, each cut made
//! into both sides at once ([`Poly::split_into`], which gives each side what `clip_into` gives
//! it); the other planes of the six-plane clip cut nothing (every vertex is strictly inside
//! them), so each part is the polygon `clipped_area` makes for that voxel, and its area and
//! centroid come from the same [`Poly::area_centroid`]. Only the order in which a voxel's f32
//! sums receive these contributions changes (small triangles now add theirs in the marking
//! pass, the others in the attribute pass), which moves a record by at most the rounding bound
//! of `chunk::Acc`.

use crate::clip::{area_centroid_of, area_of, area_scale, split_vertices_into, Poly, Vertices};
use crate::overlap::{dominant_axis, sign, swizzle, to_f64};
use crate::predicates::{orient2d, plane_side};
use crate::world::Perturbation;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// One voxel of a small triangle: its grid position, the area of the triangle inside its box
/// (voxel²) and the centroid of that part in swizzled `(x, y)` (`None`: the computed part is
/// empty, the voxel only touched).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Piece {
    pub voxel: [i32; 3],
    pub w: f64,
    pub q: Option<[f64; 2]>,
}

/// The cut polygons of [`cut`]: a binary tree in an array, node `i`'s lower side at `2i + 1`
/// and its upper side at `2i + 2`, the triangle at 0, one level per split axis (at most
/// three: 15 nodes; nodes 0–2 are not used, the first cut goes to small arrays). Kept in
/// [`Small`] so that no polygon is made (zeroed) per triangle.
const NODES: usize = 15;

/// The voxels of one small triangle ([`split`]): up to eight [`Piece`]s, or, if `interior`,
/// the one voxel `pieces[0].voxel` whose open interior holds the whole triangle (the chunk
/// voxelizer gives it the whole triangle's contribution).
#[derive(Clone, Debug)]
pub(crate) struct Small {
    /// the triangle's vertices swizzled to its dominant axis (for the interpolation; not set
    /// for an `interior` triangle)
    pub sv: [[f64; 3]; 3],
    /// its normal `(v1 − v0) × (v2 − v0)` (f64, original axes) and `|n|`, as
    /// `chunk::face` computes them
    pub n: [f64; 3],
    pub norm: f64,
    /// set by the caller: only the areas are needed (a triangle with flat attributes), not the
    /// centroids (`Piece::q` is then `None`)
    pub area_only: bool,
    pub interior: bool,
    pub len: usize,
    pub pieces: [Piece; 8],
    /// scratch: the polygons of [`cut`]
    polys: [Poly; NODES],
}

impl Default for Small {
    fn default() -> Small {
        Small {
            sv: [[0.0; 3]; 3],
            n: [0.0; 3],
            norm: 0.0,
            area_only: false,
            interior: false,
            len: 0,
            pieces: [Piece::default(); 8],
            polys: [Poly::EMPTY; NODES],
        }
    }
}

impl Small {
    pub(crate) fn pieces(&self) -> &[Piece] {
        &self.pieces[..self.len]
    }
}

/// A triangle inside the open interior of one voxel of the chunk ([`interior`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Interior {
    /// the voxel
    pub voxel: [i32; 3],
    /// the normal `(v1 − v0) × (v2 − v0)` (f64) and `|n|`, as [`split`] computes them
    pub n: [f64; 3],
    pub norm: f64,
}

/// The one voxel whose open interior holds triangle `v` (grid coordinates), if there is one
/// inside `[lo, hi]` and the triangle has a finite nonzero normal: exactly the triangles that
/// [`split`] takes as `interior` (most of a fine scan's), decided with the fewest operations
/// (no [`Small`] written). Certain for the exact grid coordinates of the world positions too:
/// `to_grid` keeps strict comparisons with integers (a monotone rounding, integers below 2²⁴
/// are f32 values).
#[inline(always)]
pub(crate) fn interior(v: &[[f32; 3]; 3], lo: [i32; 3], hi: [i32; 3]) -> Option<Interior> {
    let mut voxel = [0i32; 3];
    for k in 0..3 {
        // in f64, so that `f + 1.0` is exact; every comparison is false for a NaN, and one is
        // for an infinity: the open interior `(f, f + 1)` of voxel `f`
        let c = [v[0][k] as f64, v[1][k] as f64, v[2][k] as f64];
        let f = c[0].floor();
        let inside = (c[0] > f)
            & (c[1] > f)
            & (c[2] > f)
            & (c[0] < f + 1.0)
            & (c[1] < f + 1.0)
            & (c[2] < f + 1.0);
        if !(inside && f >= lo[k] as f64 && f <= hi[k] as f64) {
            return None;
        }
        voxel[k] = f as i32;
    }
    let o = to_f64(v);
    let d1 = [o[1][0] - o[0][0], o[1][1] - o[0][1], o[1][2] - o[0][2]];
    let d2 = [o[2][0] - o[0][0], o[2][1] - o[0][1], o[2][2] - o[0][2]];
    let n = [
        d1[1] * d2[2] - d1[2] * d2[1],
        d1[2] * d2[0] - d1[0] * d2[2],
        d1[0] * d2[1] - d1[1] * d2[0],
    ];
    let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(nn > 0.0 && nn.is_finite()) {
        return None;
    }
    Some(Interior {
        voxel,
        n,
        norm: nn.sqrt(),
    })
}

/// The exact voxel set and clipped areas of triangle `v` (grid coordinates) if its closed voxel
/// range spans at most two voxels per axis and lies inside `[lo, hi]` (the chunk), into `out`;
/// `false` (and `out` unspecified) for any other triangle, and for one the general path
/// decides (a non-finite coordinate, zero area, a normal component of uncertain sign, or a
/// projection of zero area that the set needs).
///
/// With `world` (the input's own f32 positions, of which `v` is `Grid::to_grid`; see
/// [`crate::world`]) the triangle is also refused unless every decision of the set is certain
/// for the exact grid coordinates of `world`, i.e. outside its rounding bound plus the
/// [`Perturbation`] of `v` (the filter a separate `small_certain` pass would apply, computed
/// here from the same numbers as the set, so they are computed once): no end of the voxel range on an integer, no zero edge
/// difference in `v` that is not one in `world`, every normal component and every `orient2d` /
/// `orient3d` value at the grid point outside its band. Those certain f64 signs then decide the
/// set (they are the exact signs, so the exact predicates are not called).
pub(crate) fn split(
    v: &[[f32; 3]; 3],
    world: Option<&[[f32; 3]; 3]>,
    lo: [i32; 3],
    hi: [i32; 3],
    out: &mut Small,
) -> bool {
    // without early exits (a branch per coordinate cost more than the test)
    let finite = v.iter().flatten().fold(true, |ok, c| ok & c.is_finite());
    if !finite {
        return false;
    }
    let o = to_f64(v);
    // `f64::min`/`max` for finite values (which these are) without their NaN handling
    let min = |a: f64, b: f64| if b < a { b } else { a };
    let max = |a: f64, b: f64| if b > a { b } else { a };
    // the closed voxel range per axis and the split plane
    let mut first = [0i32; 3];
    let mut split = [false; 3];
    // an end of the range on an integer (`to_grid` may have made it a tie: not certain)
    let mut on_integer = false;
    // the largest magnitude and extent (`Perturbation::of`)
    let (mut big, mut ext) = (0.0f64, 0.0f64);
    for k in 0..3 {
        let mn = min(min(o[0][k], o[1][k]), o[2][k]);
        let mx = max(max(o[0][k], o[1][k]), o[2][k]);
        let c = mn.ceil();
        let (a, b) = (c - 1.0, mx.floor());
        if b - a > 1.0 || a < lo[k] as f64 || b > hi[k] as f64 {
            return false;
        }
        first[k] = a as i32;
        split[k] = b > a;
        on_integer |= mn == c || mx == b;
        big = max(max(big, mn.abs()), mx.abs());
        ext = max(ext, mx - mn);
    }
    // `(v1 − v0) × (v2 − v0)` as `overlap::cross_f64` computes it
    let d1 = [o[1][0] - o[0][0], o[1][1] - o[0][1], o[1][2] - o[0][2]];
    let d2 = [o[2][0] - o[0][0], o[2][1] - o[0][1], o[2][2] - o[0][2]];
    let n = [
        d1[1] * d2[2] - d1[2] * d2[1],
        d1[2] * d2[0] - d1[0] * d2[2],
        d1[0] * d2[1] - d1[1] * d2[0],
    ];
    let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(nn > 0.0 && nn.is_finite()) {
        return false;
    }
    out.n = n;
    out.norm = nn.sqrt();
    if split == [false; 3] {
        // the whole triangle's contribution: no swizzle, no cut (`sv` is not read); certain
        // with `world` too (strict comparisons with integers survive `to_grid`)
        out.interior = true;
        out.len = 1;
        out.pieces[0] = Piece {
            voxel: first,
            w: 0.0,
            q: None,
        };
        return true;
    }
    let pert = match world {
        Some(w) => {
            if on_integer {
                return false;
            }
            // edge differences: a zero in f32 must be a zero in the world values
            for e in 0..3 {
                let (a, b) = (e, (e + 1) % 3);
                for k in 0..3 {
                    if v[b][k] == v[a][k] && w[b][k] != w[a][k] {
                        return false;
                    }
                }
            }
            Some(Perturbation::of_bounds(big, ext))
        }
        None => None,
    };
    // each normal component's sign certain (the filter of TriSetup::new, widened by the
    // perturbation with `world`), so that the dominant axis is TriSetup's and the projections'
    // orientations are exact
    let mut mag = [0.0; 3];
    for k in 0..3 {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        mag[k] = (d1[i] * d2[j]).abs() + (d1[j] * d2[i]).abs();
        let certain = match pert {
            Some(p) => n[k].abs() > 5.0 * U * mag[k] + p.dn,
            None => mag[k] == 0.0 || n[k].abs() > 5.0 * U * mag[k],
        };
        if !certain {
            return false;
        }
    }
    let swz = swizzle(dominant_axis(n));
    for i in 0..3 {
        for m in 0..3 {
            out.sv[i][m] = o[i][swz[m]];
        }
    }
    let ns = [n[swz[0]], n[swz[1]], n[swz[2]]];
    out.interior = false;
    let p = [
        (first[0] + split[0] as i32) as f64,
        (first[1] + split[1] as i32) as f64,
        (first[2] + split[2] as i32) as f64,
    ];
    let count = split.iter().filter(|&&s| s).count();
    let inside = if count == 1 {
        // both voxels, no test
        0xff
    } else {
        let signs = match pert {
            Some(pert) => certain_signs(&o, n, mag, split, count, p, &pert),
            None => exact_signs(&o, n, split, count, p),
        };
        let Some(s) = signs else {
            return false;
        };
        octants(&s, n, split, count)
    };
    cut(out, split, p, first, swz, area_scale(ns), inside);
    debug_assert!(out.len >= 1, "a small triangle meets at least one voxel");
    true
}

/// The projections `⟂ c` whose two axes are both split: one for `|A| = 2`, three for `|A| = 3`.
#[inline]
fn planes(split: [bool; 3], count: usize) -> &'static [usize] {
    match count {
        2 => match split.iter().position(|&s| !s) {
            Some(0) => &[0],
            Some(1) => &[1],
            _ => &[2],
        },
        _ => &[0, 1, 2],
    }
}

/// The signs the octant test needs (`|A| ≥ 2`): per projection `c` and edge `e`, whether the
/// grid point `P` is strictly outside the edge (`σ_c·orient2d(v_e, v_{e+1}, P) < 0`) and the
/// signs of the edge's outward normal `σ_c·(d_j, −d_i)`; for `|A| = 3` the side of `P` against
/// the plane (`orient3d`).
struct Signs {
    outside: [[bool; 3]; 3],
    normal: [[[f64; 2]; 3]; 3],
    side: f64,
}

/// [`Signs`] from the exact predicates (`None` if a projection the test needs has zero area).
fn exact_signs(
    o: &[[f64; 3]; 3],
    n: [f64; 3],
    split: [bool; 3],
    count: usize,
    p: [f64; 3],
) -> Option<Signs> {
    let sigma = n.map(sign);
    let planes = planes(split, count);
    if planes.iter().any(|&c| sigma[c] == 0.0) {
        return None;
    }
    let mut s = Signs {
        outside: [[false; 3]; 3],
        normal: [[[0.0f64; 2]; 3]; 3],
        side: 0.0,
    };
    for &c in planes {
        let (i, j) = ((c + 1) % 3, (c + 2) % 3);
        let pr = |w: [f64; 3]| [w[i], w[j]];
        for e in 0..3 {
            let (a, b) = (o[e], o[(e + 1) % 3]);
            s.outside[c][e] = sigma[c] * orient2d(pr(a), pr(b), pr(p)) < 0.0;
            s.normal[c][e] = [sigma[c] * sign(b[j] - a[j]), -sigma[c] * sign(b[i] - a[i])];
        }
    }
    if count == 3 {
        s.side = sign(plane_side(o, p));
    }
    Some(s)
}

/// [`Signs`] from f64 values whose sign is certain for the exact grid coordinates of the world
/// vertices: each value outside its rounding bound plus the perturbation `pert` (the bounds of
/// `world::small_certain`); `None` if any is not. `mag` are the magnitudes of the normal's
/// products (`|d1_i·d2_j| + |d1_j·d2_i|`); every normal component is certain (nonzero).
fn certain_signs(
    o: &[[f64; 3]; 3],
    n: [f64; 3],
    mag: [f64; 3],
    split: [bool; 3],
    count: usize,
    p: [f64; 3],
    pert: &Perturbation,
) -> Option<Signs> {
    let sigma = n.map(sign);
    let mut s = Signs {
        outside: [[false; 3]; 3],
        normal: [[[0.0f64; 2]; 3]; 3],
        side: 0.0,
    };
    for &c in planes(split, count) {
        let (i, j) = ((c + 1) % 3, (c + 2) % 3);
        for e in 0..3 {
            let (a, b) = (o[e], o[(e + 1) % 3]);
            let (ei, ej) = (b[i] - a[i], b[j] - a[j]);
            let (di, dj) = (p[i] - a[i], p[j] - a[j]);
            // orient2d(a, b, P) in the projection
            let f = ei * dj - ej * di;
            let bound = 8.0 * U * ((ei * dj).abs() + (ej * di).abs()) + pert.de + 1e-300;
            if !(f.abs() > bound) {
                return None;
            }
            s.outside[c][e] = sigma[c] * sign(f) < 0.0;
            s.normal[c][e] = [sigma[c] * sign(ej), -sigma[c] * sign(ei)];
        }
    }
    if count == 3 {
        let d = [0, 1, 2].map(|k| p[k] - o[0][k]);
        // plane_side(o, P)
        let g = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
        let bound = 16.0
            * U
            * (0..3)
                .map(|k| (mag[k] + n[k].abs()) * d[k].abs())
                .sum::<f64>()
            + pert.dp(n)
            + 1e-300;
        if !(g.abs() > bound) {
            return None;
        }
        s.side = sign(g);
    }
    Some(s)
}

/// Which candidate voxels the triangle meets (`|A| ≥ 2`): bit `b` of the result for candidate
/// `b`, whose bit `k` is 1 for the upper voxel on split axis `k` (0 on the other axes).
///
/// As sets of candidates (bit masks over the eight): candidate `s` is cut off by edge `e` of
/// projection `c` iff the edge has `P` strictly outside and `s_i·m_0 ≥ 0`, `s_j·m_1 ≥ 0` for its
/// outward normal `m`; `s_k·v ≥ 0` holds for the upper candidates on axis `k` if `v ≥ 0` and for
/// the lower ones if `v ≤ 0` (both for `v = 0`). The plane cuts off the one candidate with
/// `s_k = sign(n_k)` on every axis if `P` is on the positive side (`n·(P − v₀) > 0`), the one
/// with `s_k = −sign(n_k)` if on the negative side.
fn octants(s: &Signs, n: [f64; 3], split: [bool; 3], count: usize) -> u8 {
    // candidates with bit k set (UPPER[k]) / clear
    const UPPER: [u8; 3] = [0b1010_1010, 0b1100_1100, 0b1111_0000];
    let on = |k: usize, v: f64| -> u8 {
        (if v >= 0.0 { UPPER[k] } else { 0 }) | (if v <= 0.0 { !UPPER[k] } else { 0 })
    };
    // the candidates: bit 0 on every axis that is not split
    let mut valid = 0xffu8;
    for k in 0..3 {
        if !split[k] {
            valid &= !UPPER[k];
        }
    }
    let mut cut_off = 0u8;
    for &c in planes(split, count) {
        let (i, j) = ((c + 1) % 3, (c + 2) % 3);
        for e in 0..3 {
            if s.outside[c][e] {
                cut_off |= on(i, s.normal[c][e][0]) & on(j, s.normal[c][e][1]);
            }
        }
    }
    if s.side != 0.0 {
        // the candidate on the side the normal points to (s.side > 0) or away from it
        let mut cand = 0u8;
        for k in 0..3 {
            if s.side * n[k] > 0.0 {
                cand |= 1 << k;
            }
        }
        cut_off |= 1 << cand;
    }
    valid & !cut_off
}

/// The clipped parts of the candidates the triangle meets (`inside`, [`octants`]) into `out`:
/// the swizzled triangle `out.sv` cut by the split planes `x_k = p_k`, swizzled axis 0 first,
/// both sides of each cut kept ([`Poly::split_into`]: the first cut into two small arrays,
/// the second into nodes 3–6 of `out.polys`, the third into nodes 7–14); then, in the order
/// lower side before upper side (the order of a recursive cut), each part whose candidate (bits over
/// `first`) the triangle meets becomes a [`Piece`] with its area (`scale = |n|/|n_z|`) and,
/// unless `out.area_only`, its centroid ([`Poly::area_centroid`]).
fn cut(
    out: &mut Small,
    split: [bool; 3],
    p: [f64; 3],
    first: [i32; 3],
    swz: [usize; 3],
    scale: f64,
    inside: u8,
) {
    // the split axes in swizzled order
    let mut ms = [0usize; 3];
    let mut count = 0;
    for m in 0..3 {
        if split[swz[m]] {
            ms[count] = m;
            count += 1;
        }
    }
    let Small {
        sv,
        area_only,
        len,
        pieces,
        polys,
        ..
    } = out;
    *len = 0;
    let mut put = |part: &[[f64; 3]], bits: u8| {
        if inside >> bits & 1 == 1 {
            let voxel = [
                first[0] + (bits & 1) as i32,
                first[1] + (bits >> 1 & 1) as i32,
                first[2] + (bits >> 2 & 1) as i32,
            ];
            push_piece(pieces, len, *area_only, part, voxel, scale);
        }
    };
    // the first cut, of the triangle itself: both sides in small arrays (a triangle cut once
    // has at most four vertices per side)
    let (m, k) = (ms[0], swz[ms[0]]);
    let (mut lp, mut hp) = ([[0.0f64; 3]; 4], [[0.0f64; 3]; 4]);
    let (mut ll, mut hl) = (0usize, 0usize);
    let lo = Vertices {
        p: &mut lp,
        len: &mut ll,
    };
    let hi = Vertices {
        p: &mut hp,
        len: &mut hl,
    };
    match m {
        0 => split_vertices_into::<0>(&sv[..], p[k], lo, hi),
        1 => split_vertices_into::<1>(&sv[..], p[k], lo, hi),
        _ => split_vertices_into::<2>(&sv[..], p[k], lo, hi),
    }
    let first_cut: [(&[[f64; 3]], u8); 2] = [(&lp[..ll], 0), (&hp[..hl], 1 << k)];
    if count == 1 {
        // (the most common case after the interior one) both voxels met
        for (part, bits) in first_cut {
            put(part, bits);
        }
        return;
    }
    // the second cut of both sides, into nodes 3..7 (node 3 + 2·side + its side)
    let (m, k) = (ms[1], swz[ms[1]]);
    let mut bits = [0u8; NODES];
    for (side, (src, b0)) in first_cut.into_iter().enumerate() {
        let i = 3 + 2 * side;
        let (lo, hi) = polys[i..i + 2].split_at_mut(1);
        let (lo, hi) = (lo[0].out(), hi[0].out());
        match m {
            0 => split_vertices_into::<0>(src, p[k], lo, hi),
            1 => split_vertices_into::<1>(src, p[k], lo, hi),
            _ => split_vertices_into::<2>(src, p[k], lo, hi),
        }
        bits[i] = b0;
        bits[i + 1] = b0 | 1 << k;
    }
    if count == 2 {
        for i in 3..7 {
            put(polys[i].vertices(), bits[i]);
        }
        return;
    }
    // the third cut of the four, into nodes 7..15
    let (m, k) = (ms[2], swz[ms[2]]);
    let (src, rest) = polys.split_at_mut(7);
    for i in 3..7 {
        let j = 2 * (i - 3);
        let (lo, hi) = rest[j..j + 2].split_at_mut(1);
        let (lo, hi) = (&mut lo[0], &mut hi[0]);
        match m {
            0 => src[i].split_into::<0>(p[k], lo, hi),
            1 => src[i].split_into::<1>(p[k], lo, hi),
            _ => src[i].split_into::<2>(p[k], lo, hi),
        }
        put(lo.vertices(), bits[i]);
        put(hi.vertices(), bits[i] | 1 << k);
    }
}

/// Appends the piece of `voxel` whose part of the triangle has vertices `part` to
/// `pieces[..len]`: its area (`scale = |n|/|n_z|`) and, unless `area_only`, its centroid
/// ([`Poly::area_centroid`]).
#[inline(always)]
fn push_piece(
    pieces: &mut [Piece; 8],
    len: &mut usize,
    area_only: bool,
    part: &[[f64; 3]],
    voxel: [i32; 3],
    scale: f64,
) {
    let (w, q) = if area_only {
        (area_of(part, scale), None)
    } else {
        let (w, c) = area_centroid_of(part, scale);
        (w, c.map(|c| [c[0], c[1]]))
    };
    pieces[*len] = Piece { voxel, w, q };
    *len += 1;
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_geom::Grid;
    use voxlod_testkit::Rng;

    /// [`area`] is the area of [`Poly::area_centroid`] bit for bit, on random triangles and
    /// their clipped parts.
    #[test]
    fn area_is_area_centroid_area() {
        let mut rng = Rng(11);
        for _ in 0..20_000 {
            let v = [0, 1, 2].map(|_| rng.point(-2.0, 2.0));
            let mut poly = Poly::triangle(&v);
            if rng.below(2) == 0 {
                poly = poly
                    .clip_column(-1.0, -1.0)
                    .clip_depth(rng.int(-2, 1) as f64);
            }
            let s = rng.range(1.0, 1.8);
            assert_eq!(poly.area(s).to_bits(), poly.area_centroid(s).0.to_bits());
        }
    }

    /// `x` moved by `k` f32 ulps (towards +∞ for `k > 0`).
    fn ulps(x: f32, k: i32) -> f32 {
        let mut y = x;
        for _ in 0..k.abs() {
            y = if k > 0 { y.next_up() } else { y.next_down() };
        }
        y
    }

    /// A world triangle around the corner `c` (grid units) of `grid`: vertices within `r`
    /// voxels of it, on its grid planes (the world value of the plane rounded to f32), nudged
    /// by ulps across them, tiny ones at it, edges through it; a quarter around the centre of
    /// the voxel above it instead.
    fn near_corner(rng: &mut Rng, grid: &Grid, c: [f64; 3], kind: u64) -> [[f32; 3]; 3] {
        let s = grid.voxel_size;
        let on = |k: usize, g: f64| (grid.origin[k] + g * s) as f32;
        let r = match kind % 4 {
            0 => 0.95,
            1 => 0.5,
            2 => 1e-4,
            _ => 0.3,
        };
        // every fourth around the voxel's centre instead (mostly inside its interior)
        let c = if kind % 4 == 3 { c.map(|x| x + 0.5) } else { c };
        let mut v = [[0.0f32; 3]; 3];
        for p in &mut v {
            for k in 0..3 {
                p[k] = match rng.below(5) {
                    // on the plane, or a few ulps off it
                    0 => on(k, c[k]),
                    1 => ulps(on(k, c[k]), rng.int(-3, 3) as i32),
                    _ => on(k, c[k] + rng.range(-r, r)),
                };
            }
        }
        if kind % 7 == 6 {
            // two vertices symmetric about the corner: an edge through it, up to rounding
            for k in 0..3 {
                v[1][k] = on(k, 2.0 * c[k] - (v[0][k] as f64 - grid.origin[k]) / s);
            }
        }
        v
    }

    /// The small path against the reference path (`crate::small_reference`: robust predicates,
    /// recursive cuts of the generic `Poly`, a separate certainty filter): on triangles
    /// at and near the grid planes of voxel corners, given in world coordinates of grids whose
    /// corners are not exact (`add_world`: `split` with the world positions against the
    /// reference's `split` and `small_certain`) and in grid coordinates (`add`), for flat and
    /// interpolated attributes: the same decision (small or not, interior or not), and for a
    /// small triangle the same normal, swizzled vertices, voxels, weights and centroids bit for
    /// bit. [`interior`] takes exactly the triangles the reference's `split` takes as interior. Coverage
    /// of every case (interior, one, two and three split axes, refused by the set's range, by
    /// the world filter) is asserted.
    #[test]
    fn same_decisions_and_pieces_as_main() {
        use crate::small_reference as reference;
        let grids = [
            Grid::new([0.1, -0.37, 12.3], 7.3, 1024).unwrap(),
            Grid::new(
                [
                    -1.146_080_970_764_160_2,
                    -0.775_283_157_825_47,
                    -1.160_307_526_588_44,
                ],
                11.188_545_227_050_781,
                1024,
            )
            .unwrap(),
            Grid::new([0.0, 0.0, 0.0], 256.0, 256).unwrap(),
        ];
        let mut rng = Rng(30);
        // taken: [interior, |A| = 1, 2, 3]; refused: [by the reference's split, by the world filter]
        let mut taken = [0u32; 4];
        let mut refused = [0u32; 2];
        let (mut a, mut b) = (Small::default(), Small::default());
        for i in 0..400_000u64 {
            let grid = &grids[(i % 3) as usize];
            // a corner inside the chunk [0, 255]³ or on its border
            let c = [0, 1, 2].map(|_| match rng.below(8) {
                0 => 0.0,
                1 => 256.0,
                _ => rng.int(1, 255) as f64,
            });
            let world = near_corner(&mut rng, grid, c, i);
            let with_world = i % 5 != 0;
            let gv = world.map(|p| grid.to_grid(p));
            let (lo, hi) = ([0; 3], [255; 3]);
            let area_only = i % 2 == 0;
            a.area_only = area_only;
            b.area_only = area_only;
            let split_ref = reference::split(&gv, lo, hi, &mut a);
            let want = split_ref && (!with_world || reference::small_certain(&gv, &world));
            if !split_ref {
                refused[0] += 1;
            } else if !want {
                refused[1] += 1;
            }
            let w = with_world.then_some(&world);
            let (got, interior_taken) = match interior(&gv, lo, hi) {
                Some(it) => {
                    b.n = it.n;
                    b.norm = it.norm;
                    b.interior = true;
                    b.len = 1;
                    b.pieces[0].voxel = it.voxel;
                    (true, true)
                }
                None => (split(&gv, w, lo, hi, &mut b), false),
            };
            assert_eq!(
                got, want,
                "triangle {world:?} (grid {gv:?}), world {with_world}"
            );
            if !want {
                continue;
            }
            assert_eq!(a.interior, interior_taken, "{gv:?}: interior");
            assert_eq!(a.interior, b.interior, "{gv:?}: interior");
            assert_eq!(
                a.n.map(f64::to_bits),
                b.n.map(f64::to_bits),
                "{gv:?}: normal"
            );
            assert_eq!(a.norm.to_bits(), b.norm.to_bits(), "{gv:?}: |n|");
            if a.interior {
                assert_eq!(a.pieces[0].voxel, b.pieces[0].voxel, "{gv:?}: voxel");
                taken[0] += 1;
                continue;
            }
            let count = (0..3)
                .filter(|&k| {
                    let mn = gv.iter().map(|p| p[k] as f64).fold(f64::INFINITY, f64::min);
                    let mx = gv
                        .iter()
                        .map(|p| p[k] as f64)
                        .fold(f64::NEG_INFINITY, f64::max);
                    mx.floor() > mn.ceil() - 1.0
                })
                .count();
            taken[count] += 1;
            assert_eq!(
                a.sv.map(|p| p.map(f64::to_bits)),
                b.sv.map(|p| p.map(f64::to_bits))
            );
            assert_eq!(a.len, b.len, "{gv:?}: pieces");
            for (p, q) in a.pieces().iter().zip(b.pieces()) {
                assert_eq!(p.voxel, q.voxel, "{gv:?}: voxels");
                assert_eq!(
                    p.w.to_bits(),
                    q.w.to_bits(),
                    "{gv:?}: weight of {:?}",
                    p.voxel
                );
                assert_eq!(
                    p.q.map(|q| q.map(f64::to_bits)),
                    q.q.map(|q| q.map(f64::to_bits)),
                    "{gv:?}: centroid of {:?}",
                    p.voxel
                );
            }
        }
        eprintln!("taken {taken:?}, refused {refused:?}");
        assert!(taken.iter().all(|&t| t > 2_000), "taken {taken:?}");
        assert!(refused.iter().all(|&t| t > 2_000), "refused {refused:?}");
    }
}
