//! A plainer small-triangle path, kept for the tests only as the reference of [`crate::small`]: [`split`] with its robust predicates and recursive cuts of the generic
//! [`Poly`], and `world::small_certain`, the filter that decided which small triangles of an
//! `add_world` are certain. [`crate::small`] must give the same decisions and the same
//! pieces bit for bit (its unit tests compare them on triangles at and near grid planes).

use crate::clip::{area_scale, Poly};
use crate::overlap::{cross_f64, dominant_axis, sign, swizzle, to_f64};
use crate::predicates::{orient2d, plane_side};
use crate::small::{Piece, Small};
use crate::world::Perturbation;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

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

/// Whether the small path ([`crate::small`]) decides triangle `v` (f32 grid coordinates,
/// `to_grid` of `world`) as the exact world coordinates would: every decision it makes is
/// certain under the [`Perturbation`] of `v`. Those decisions are the closed voxel range
/// (certain unless an end is on an integer: `to_grid` keeps comparisons with integers or makes
/// them ties), the signs of the normal's components and of the edge differences, and the
/// orient2d / orient3d signs at the one grid point `P` the range straddles; each is checked
/// here in f64 with its rounding bound plus the perturbation. `false` sends the triangle to the
/// general path, which decides exactly ([`crate::TriSetup::with_world`]).
pub(crate) fn small_certain(v: &[[f32; 3]; 3], world: &[[f32; 3]; 3]) -> bool {
    let o = v.map(|p| p.map(|c| c as f64));
    let pert = Perturbation::of(&o);
    let mut p = [0.0f64; 3];
    let mut split = [false; 3];
    for k in 0..3 {
        let mn = o[0][k].min(o[1][k]).min(o[2][k]);
        let mx = o[0][k].max(o[1][k]).max(o[2][k]);
        if mn == mn.floor() || mx == mx.floor() {
            return false;
        }
        let (a, b) = (mn.ceil() - 1.0, mx.floor());
        split[k] = b > a;
        p[k] = b;
    }
    let count = split.iter().filter(|&&s| s).count();
    if count == 0 {
        return true;
    }
    // edge differences: a zero in f32 must be a zero in the world values
    for e in 0..3 {
        let (a, b) = (e, (e + 1) % 3);
        for k in 0..3 {
            if o[b][k] - o[a][k] == 0.0 && world[b][k] != world[a][k] {
                return false;
            }
        }
    }
    let d1 = [0, 1, 2].map(|k| o[1][k] - o[0][k]);
    let d2 = [0, 1, 2].map(|k| o[2][k] - o[0][k]);
    // `(v1 − v0) × (v2 − v0)` as `overlap::cross_f64` computes it
    let n = [
        d1[1] * d2[2] - d1[2] * d2[1],
        d1[2] * d2[0] - d1[0] * d2[2],
        d1[0] * d2[1] - d1[1] * d2[0],
    ];
    let mut mag = [0.0; 3];
    for k in 0..3 {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        mag[k] = (d1[i] * d2[j]).abs() + (d1[j] * d2[i]).abs();
        if !(n[k].abs() > 5.0 * U * mag[k] + pert.dn) {
            return false;
        }
    }
    let planes: &[usize] = match count {
        1 => &[],
        2 => match split.iter().position(|&s| !s) {
            Some(0) => &[0],
            Some(1) => &[1],
            _ => &[2],
        },
        _ => &[0, 1, 2],
    };
    for &c in planes {
        let (i, j) = ((c + 1) % 3, (c + 2) % 3);
        for e in 0..3 {
            let (a, b) = (o[e], o[(e + 1) % 3]);
            let (ei, ej) = (b[i] - a[i], b[j] - a[j]);
            let (di, dj) = (p[i] - a[i], p[j] - a[j]);
            let f = ei * dj - ej * di;
            let bound = 8.0 * U * ((ei * dj).abs() + (ej * di).abs()) + pert.de + 1e-300;
            if !(f.abs() > bound) {
                return false;
            }
        }
    }
    if count == 3 {
        let d = [0, 1, 2].map(|k| p[k] - o[0][k]);
        let g = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
        let bound = 16.0
            * U
            * (0..3)
                .map(|k| (mag[k] + n[k].abs()) * d[k].abs())
                .sum::<f64>()
            + pert.dp(n)
            + 1e-300;
        if !(g.abs() > bound) {
            return false;
        }
    }
    true
}
