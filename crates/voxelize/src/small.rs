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

use crate::clip::{area_scale, Poly};
use crate::overlap::{cross_f64, dominant_axis, sign, swizzle, to_f64};
use crate::predicates::{orient2d, plane_side};

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

/// The voxels of one small triangle ([`split`]): up to eight [`Piece`]s, or, if `interior`,
/// the one voxel `pieces[0].voxel` whose open interior holds the whole triangle (the chunk
/// voxelizer gives it the whole triangle's contribution).
#[derive(Clone, Debug, Default)]
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
}

impl Small {
    pub(crate) fn pieces(&self) -> &[Piece] {
        &self.pieces[..self.len]
    }
}

/// The exact voxel set and clipped areas of triangle `v` (grid coordinates) if its closed voxel
/// range spans at most two voxels per axis and lies inside `[lo, hi]` (the chunk), into `out`;
/// `false` (and `out` unspecified) for any other triangle, and for one the general path
/// decides (a non-finite coordinate, zero area, a normal component of uncertain sign, or a
/// projection of zero area that the set needs).
pub(crate) fn split(v: &[[f32; 3]; 3], lo: [i32; 3], hi: [i32; 3], out: &mut Small) -> bool {
    if !(v[0].iter().chain(&v[1]).chain(&v[2])).all(|c| c.is_finite()) {
        return false;
    }
    let o = to_f64(v);
    // the closed voxel range per axis and the split plane
    let mut first = [0i32; 3];
    let mut split = [false; 3];
    for k in 0..3 {
        let mn = o[0][k].min(o[1][k]).min(o[2][k]);
        let mx = o[0][k].max(o[1][k]).max(o[2][k]);
        let (a, b) = (mn.ceil() - 1.0, mx.floor());
        if b - a > 1.0 || a < lo[k] as f64 || b > hi[k] as f64 {
            return false;
        }
        first[k] = a as i32;
        split[k] = b > a;
    }
    let n = cross_f64(&o);
    let nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if !(nn > 0.0 && nn.is_finite()) {
        return false;
    }
    out.n = n;
    out.norm = nn.sqrt();
    if split == [false; 3] {
        // the whole triangle's contribution: no swizzle, no cut (`sv` is not read)
        out.interior = true;
        out.len = 1;
        out.pieces[0] = Piece {
            voxel: first,
            w: 0.0,
            q: None,
        };
        return true;
    }
    let swz = swizzle(dominant_axis(n));
    let sw = |p: [f64; 3]| [p[swz[0]], p[swz[1]], p[swz[2]]];
    out.sv = [sw(o[0]), sw(o[1]), sw(o[2])];
    // each normal component's sign certain (the filter of TriSetup::new), so that the dominant
    // axis is TriSetup's and the projections' orientations are exact
    let d1 = [o[1][0] - o[0][0], o[1][1] - o[0][1], o[1][2] - o[0][2]];
    let d2 = [o[2][0] - o[0][0], o[2][1] - o[0][1], o[2][2] - o[0][2]];
    for k in 0..3 {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let mag = (d1[i] * d2[j]).abs() + (d1[j] * d2[i]).abs();
        if mag != 0.0 && n[k].abs() <= 5.0 * U * mag {
            return false;
        }
    }
    out.interior = false;
    let p = [
        (first[0] + split[0] as i32) as f64,
        (first[1] + split[1] as i32) as f64,
        (first[2] + split[2] as i32) as f64,
    ];
    let Some(inside) = octants(&o, n, split, p) else {
        return false;
    };
    let g = Cut {
        split,
        p,
        first,
        swz,
        scale: area_scale(sw(n)),
        inside,
    };
    out.len = 0;
    let tri = Poly::triangle(&out.sv);
    part(out, &g, &tri, 0, 0);
    debug_assert!(out.len >= 1, "a small triangle meets at least one voxel");
    true
}

/// Which candidate voxels the triangle meets: bit `b` of the result for candidate `b`, whose
/// bit `k` is 1 for the upper voxel on split axis `k` (0 on the other axes). `None` if a
/// projection the test needs has zero area.
fn octants(o: &[[f64; 3]; 3], n: [f64; 3], split: [bool; 3], p: [f64; 3]) -> Option<u8> {
    let sigma = n.map(sign);
    let count = split.iter().filter(|&&s| s).count();
    // the projections ⟂ c whose two axes are both split: one for |A| = 2, three for |A| = 3
    let planes: &[usize] = match count {
        1 => return Some(0xff),
        2 => match split.iter().position(|&s| !s) {
            Some(0) => &[0],
            Some(1) => &[1],
            _ => &[2],
        },
        _ => &[0, 1, 2],
    };
    if planes.iter().any(|&c| sigma[c] == 0.0) {
        return None;
    }
    // per projection and edge: σ·orient2d(v_p, v_q, P) (negative: P strictly outside the
    // edge) and the outward normal's signs σ·(d_j, −d_i)
    let mut outside = [[false; 3]; 3];
    let mut normal = [[[0.0f64; 2]; 3]; 3];
    for &c in planes {
        let (i, j) = ((c + 1) % 3, (c + 2) % 3);
        let pr = |w: [f64; 3]| [w[i], w[j]];
        for e in 0..3 {
            let (a, b) = (o[e], o[(e + 1) % 3]);
            outside[c][e] = sigma[c] * orient2d(pr(a), pr(b), pr(p)) < 0.0;
            normal[c][e] = [sigma[c] * sign(b[j] - a[j]), -sigma[c] * sign(b[i] - a[i])];
        }
    }
    let side = if count == 3 {
        sign(plane_side(o, p))
    } else {
        0.0
    };
    let mut inside = 0u8;
    for cand in 0..8u8 {
        if (0..3).any(|k| !split[k] && cand >> k & 1 == 1) {
            continue;
        }
        let s = [0, 1, 2].map(|k| if cand >> k & 1 == 1 { 1.0 } else { -1.0 });
        let by_edge = planes.iter().any(|&c| {
            let (i, j) = ((c + 1) % 3, (c + 2) % 3);
            (0..3).any(|e| {
                outside[c][e] && s[i] * normal[c][e][0] >= 0.0 && s[j] * normal[c][e][1] >= 0.0
            })
        });
        let by_plane = (side > 0.0 && (0..3).all(|k| s[k] * sigma[k] >= 0.0))
            || (side < 0.0 && (0..3).all(|k| s[k] * sigma[k] <= 0.0));
        if !(by_edge || by_plane) {
            inside |= 1 << cand;
        }
    }
    Some(inside)
}

/// What the cuts ([`part`]) need besides the polygon: the split axes and planes, the candidates' first
/// voxel, the swizzle, `|n|/|n_z|` and the candidates the triangle meets.
struct Cut {
    split: [bool; 3],
    p: [f64; 3],
    first: [i32; 3],
    swz: [usize; 3],
    scale: f64,
    inside: u8,
}

/// The clipped parts of the candidates the triangle meets ([`octants`]) into `out`: the
/// swizzled triangle cut by the split planes, swizzled axis 0 first, both sides of each cut
/// kept. `poly` is the part of the candidates with bits `bits` (original axes) on the swizzled
/// axes before `m`: it is cut on the next split axis from `m`, or, past the last, added to
/// `out` if the triangle meets its voxel.
fn part(out: &mut Small, g: &Cut, poly: &Poly, m: usize, bits: u8) {
    let Some(m) = (m..3).find(|&m| g.split[g.swz[m]]) else {
        if g.inside >> bits & 1 == 1 {
            let (w, q) = if out.area_only {
                (poly.area(g.scale), None)
            } else {
                let (w, c) = poly.area_centroid(g.scale);
                (w, c.map(|c| [c[0], c[1]]))
            };
            out.pieces[out.len] = Piece {
                voxel: [0, 1, 2].map(|k| g.first[k] + (bits >> k & 1) as i32),
                w,
                q,
            };
            out.len += 1;
        }
        return;
    };
    let k = g.swz[m];
    let (mut lo, mut hi) = (Poly::EMPTY, Poly::EMPTY);
    match m {
        0 => poly.split_into::<0>(g.p[k], &mut lo, &mut hi),
        1 => poly.split_into::<1>(g.p[k], &mut lo, &mut hi),
        _ => poly.split_into::<2>(g.p[k], &mut lo, &mut hi),
    }
    part(out, g, &lo, m + 1, bits);
    part(out, g, &hi, m + 1, bits | 1 << k);
}

#[cfg(test)]
mod tests {
    use super::*;
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
}
