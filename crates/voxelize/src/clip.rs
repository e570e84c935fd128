//! Exact area and centroid of a triangle inside a closed voxel box, by Sutherland–Hodgman
//! clipping (Sutherland & Hodgman, "Reentrant polygon clipping", CACM 1974). These are the
//! weights and interpolation points of the voxel attributes (see the crate docs).
//!
//! The clipping order is fixed so that the chunk voxelizer's factored clipping (the four side
//! planes once per column, the two depth planes per voxel) gives bit-identical results: the
//! triangle is swizzled to its dominant axis (as in [`crate::TriSetup`]) and clipped against
//! `x ≥ p_x`, `x ≤ p_x+1`, `y ≥ p_y`, `y ≤ p_y+1`, `z ≥ p_z`, `z ≤ p_z+1` in swizzled coordinates.

use crate::overlap::{cross_f64, dominant_axis, swizzle, to_f64, unswizzle};

/// Most vertices a triangle clipped by six planes can have.
pub const MAX_POLY: usize = 9;

/// A convex polygon of at most [`MAX_POLY`] vertices.
#[derive(Clone, Copy, Debug)]
pub struct Poly {
    /// Number of vertices in use.
    pub len: usize,
    /// Vertices; the first `len` are the polygon's.
    pub p: [[f64; 3]; MAX_POLY],
}

impl Poly {
    /// The polygon without vertices.
    pub const EMPTY: Poly = Poly {
        len: 0,
        p: [[0.0; 3]; MAX_POLY],
    };

    /// The triangle as a polygon.
    #[inline]
    pub fn triangle(v: &[[f64; 3]; 3]) -> Poly {
        let mut p = [[0.0; 3]; MAX_POLY];
        p[..3].copy_from_slice(v);
        Poly { len: 3, p }
    }

    /// The polygon's vertices.
    #[inline]
    pub fn vertices(&self) -> &[[f64; 3]] {
        &self.p[..self.len]
    }

    /// Keeps the part with `x[k] ≥ b` (`upper == false`) or `x[k] ≤ b` (`upper == true`).
    /// Points on the plane are inside; an intersection point is made only where an edge strictly
    /// crosses the plane, as `in + t·(out − in)` from the inside end (`t = d_in / (d_in − d_out)`,
    /// `d` the signed distance, positive inside), with coordinate `k` set to `b` exactly. When
    /// every vertex is inside the polygon is returned unchanged.
    #[inline]
    pub fn clip(&self, k: usize, b: f64, upper: bool) -> Poly {
        assert!(k < 3, "clip axis {k} is not 0, 1 or 2");
        let mut out = Poly::EMPTY;
        let clipped = match (k, upper) {
            (0, false) => self.clip_into::<0, false>(b, &mut out),
            (0, true) => self.clip_into::<0, true>(b, &mut out),
            (1, false) => self.clip_into::<1, false>(b, &mut out),
            (1, true) => self.clip_into::<1, true>(b, &mut out),
            (_, false) => self.clip_into::<2, false>(b, &mut out),
            (_, true) => self.clip_into::<2, true>(b, &mut out),
        };
        if clipped {
            out
        } else {
            *self
        }
    }

    /// [`Poly::clip`] on axis `K` writing into `out` (no copy, no temporary): returns `false`,
    /// leaving `out` untouched, when every vertex is inside (the result is `self`). The axis is
    /// a constant so that the intersection point is built in registers: a store at a dynamic
    /// offset into it stalls the load of the whole point that follows (store forwarding).
    #[inline(always)]
    pub(crate) fn clip_into<const K: usize, const UPPER: bool>(
        &self,
        b: f64,
        out: &mut Poly,
    ) -> bool {
        let mut d = [0.0f64; MAX_POLY];
        let mut all_in = true;
        for i in 0..self.len {
            d[i] = if UPPER {
                b - self.p[i][K]
            } else {
                self.p[i][K] - b
            };
            all_in &= d[i] >= 0.0;
        }
        if all_in {
            return false;
        }
        out.len = 0;
        for i in 0..self.len {
            let j = if i + 1 == self.len { 0 } else { i + 1 };
            let (da, dc) = (d[i], d[j]);
            if da >= 0.0 {
                out.push(self.p[i]);
            }
            if (da > 0.0 && dc < 0.0) || (da < 0.0 && dc > 0.0) {
                let (pin, pout, din, dout) = if da > 0.0 {
                    (self.p[i], self.p[j], da, dc)
                } else {
                    (self.p[j], self.p[i], dc, da)
                };
                let t = din / (din - dout);
                let at = |j: usize| {
                    if j == K {
                        b
                    } else {
                        pin[j] + t * (pout[j] - pin[j])
                    }
                };
                out.push([at(0), at(1), at(2)]);
            }
        }
        true
    }

    /// Both sides of the plane `x[K] = b` in one pass: `lo` = the part with `x[K] ≤ b`, `hi` =
    /// the part with `x[K] ≥ b`, each bit for bit what [`Poly::clip_into`] gives
    /// (`clip_into::<K, true>(b, lo)` and `clip_into::<K, false>(b, hi)`: the same vertex order,
    /// each intersection point computed from that side's inside end), except that a side with
    /// every vertex inside receives a copy of `self`.
    #[inline(always)]
    pub(crate) fn split_into<const K: usize>(&self, b: f64, lo: &mut Poly, hi: &mut Poly) {
        split_vertices_into::<K>(&self.p[..self.len], b, lo.out(), hi.out())
    }

    /// The polygon as the output of [`split_vertices_into`].
    #[inline(always)]
    pub(crate) fn out(&mut self) -> Vertices<'_> {
        Vertices {
            p: &mut self.p,
            len: &mut self.len,
        }
    }

    /// Area and centroid ([`Poly::area_centroid`]) of the part in the slab `z ∈ [z, z+1]`
    /// ([`Poly::clip_depth`]), with `t1`, `t2` as scratch space.
    #[inline]
    pub(crate) fn depth_area_centroid(
        &self,
        z: f64,
        area_scale: f64,
        t1: &mut Poly,
        t2: &mut Poly,
    ) -> (f64, Option<[f64; 3]>) {
        let a = if self.clip_into::<2, false>(z, t1) {
            &*t1
        } else {
            self
        };
        let b = if a.clip_into::<2, true>(z + 1.0, t2) {
            &*t2
        } else {
            a
        };
        b.area_centroid(area_scale)
    }

    #[inline]
    fn push(&mut self, q: [f64; 3]) {
        debug_assert!(self.len < MAX_POLY);
        if self.len < MAX_POLY {
            self.p[self.len] = q;
            self.len += 1;
        }
    }

    /// Per-axis minimum and maximum over the vertices.
    #[inline]
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for q in self.vertices() {
            for k in 0..3 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        (lo, hi)
    }

    /// Minimum and maximum z over the vertices.
    #[inline]
    pub fn bounds_z(&self) -> (f64, f64) {
        let (lo, hi) = self.bounds();
        (lo[2], hi[2])
    }

    /// Clips to the column `[x, x+1] × [y, y+1]` (axes 0 and 1).
    #[inline]
    pub fn clip_column(&self, x: f64, y: f64) -> Poly {
        let mut out = *self;
        let mut t = Poly::EMPTY;
        if out.clip_into::<0, false>(x, &mut t) {
            out = t;
        }
        if out.clip_into::<0, true>(x + 1.0, &mut t) {
            out = t;
        }
        if out.clip_into::<1, false>(y, &mut t) {
            out = t;
        }
        if out.clip_into::<1, true>(y + 1.0, &mut t) {
            out = t;
        }
        out
    }

    /// Clips to the slab `z ∈ [z, z+1]` (axis 2).
    #[inline]
    pub fn clip_depth(&self, z: f64) -> Poly {
        self.clip(2, z, false).clip(2, z + 1.0, true)
    }

    /// The area of [`Poly::area_centroid`] alone, bit for bit (the same shoelace fan in the same
    /// order), without the centroid's sums and division: the weight of a contribution whose
    /// values do not depend on the point (a triangle with flat attributes, [`crate::single`]).
    #[inline]
    pub fn area(&self, area_scale: f64) -> f64 {
        area_of(self.vertices(), area_scale)
    }

    /// Area and centroid of the polygon, which lies in a plane whose normal `n` has `n[2] ≠ 0`:
    /// the fan `p0, p_i, p_{i+1}` is measured in the xy projection (`a_i`, shoelace) and scaled
    /// by `area_scale = |n| / |n_z|`. Centroid = `Σ a_i (p0+p_i+p_{i+1})/3 / Σ a_i`. If the area
    /// is zero the centroid is the mean of the vertices, and `None` if there are none.
    #[inline]
    pub fn area_centroid(&self, area_scale: f64) -> (f64, Option<[f64; 3]>) {
        area_centroid_of(self.vertices(), area_scale)
    }
}

/// [`Poly::area`] of the polygon with vertices `p`.
#[inline]
pub(crate) fn area_of(p: &[[f64; 3]], area_scale: f64) -> f64 {
    if p.is_empty() {
        return 0.0;
    }
    let p0 = p[0];
    let mut a2 = 0.0;
    for i in 1..p.len().saturating_sub(1) {
        let u = [p[i][0] - p0[0], p[i][1] - p0[1]];
        let w = [p[i + 1][0] - p0[0], p[i + 1][1] - p0[1]];
        a2 += u[0] * w[1] - u[1] * w[0];
    }
    if a2 != 0.0 {
        0.5 * a2.abs() * area_scale
    } else {
        0.0
    }
}

/// [`Poly::area_centroid`] of the polygon with vertices `p`.
#[inline]
pub(crate) fn area_centroid_of(p: &[[f64; 3]], area_scale: f64) -> (f64, Option<[f64; 3]>) {
    if p.is_empty() {
        return (0.0, None);
    }
    let p0 = p[0];
    let mut a2 = 0.0;
    let mut c = [0.0; 3];
    for i in 1..p.len().saturating_sub(1) {
        let u = [p[i][0] - p0[0], p[i][1] - p0[1]];
        let w = [p[i + 1][0] - p0[0], p[i + 1][1] - p0[1]];
        let ai = u[0] * w[1] - u[1] * w[0];
        a2 += ai;
        for k in 0..3 {
            c[k] += ai * (p0[k] + p[i][k] + p[i + 1][k]);
        }
    }
    if a2 != 0.0 {
        let s = 1.0 / (3.0 * a2);
        (
            0.5 * a2.abs() * area_scale,
            Some([c[0] * s, c[1] * s, c[2] * s]),
        )
    } else {
        let inv = 1.0 / p.len() as f64;
        let mut m = [0.0; 3];
        for q in p {
            for k in 0..3 {
                m[k] += q[k] * inv;
            }
        }
        (0.0, Some(m))
    }
}

/// Where [`split_vertices_into`] writes one side: vertex storage (its length is the capacity,
/// [`MAX_POLY`] for a [`Poly`]) and the number of vertices in use. A vertex past the capacity
/// is dropped, as [`Poly`] drops one past [`MAX_POLY`] (which a convex polygon never reaches).
pub(crate) struct Vertices<'a> {
    pub p: &'a mut [[f64; 3]],
    pub len: &'a mut usize,
}

impl Vertices<'_> {
    #[inline(always)]
    fn push(&mut self, q: [f64; 3]) {
        debug_assert!(*self.len < self.p.len());
        if *self.len < self.p.len() {
            self.p[*self.len] = q;
            *self.len += 1;
        }
    }
}

/// [`Poly::split_into`] of the polygon with vertices `src` (at most [`MAX_POLY`]) into `lo`
/// and `hi`: a triangle given as its three vertices is cut without being copied into a
/// [`Poly`] first, with `src.len()` known the loops unroll, and the sides may be smaller
/// arrays than a [`Poly`] (a triangle cut once has at most four vertices per side).
#[inline(always)]
pub(crate) fn split_vertices_into<const K: usize>(
    src: &[[f64; 3]],
    b: f64,
    mut lo: Vertices,
    mut hi: Vertices,
) {
    debug_assert!(src.len() <= MAX_POLY);
    // du: distance inside the lower side (b − x), dl = −du: inside the upper side (x − b);
    // IEEE subtraction is sign-symmetric, so dl is what clip_into computes
    let mut du = [0.0f64; MAX_POLY];
    let mut dl = [0.0f64; MAX_POLY];
    for i in 0..src.len() {
        du[i] = b - src[i][K];
        dl[i] = src[i][K] - b;
    }
    *lo.len = 0;
    *hi.len = 0;
    for i in 0..src.len() {
        let j = if i + 1 == src.len() { 0 } else { i + 1 };
        if du[i] >= 0.0 {
            lo.push(src[i]);
        }
        if dl[i] >= 0.0 {
            hi.push(src[i]);
        }
        let (da, dc) = (du[i], du[j]);
        if (da > 0.0 && dc < 0.0) || (da < 0.0 && dc > 0.0) {
            // lo's point from the end below b, hi's from the end above
            let (pl, ph, dul, dlh) = if da > 0.0 {
                (src[i], src[j], da, dl[j])
            } else {
                (src[j], src[i], dc, dl[i])
            };
            let tl = dul / (dul - (b - ph[K]));
            let th = dlh / (dlh - (pl[K] - b));
            let at = |pin: [f64; 3], pout: [f64; 3], t: f64, j: usize| {
                if j == K {
                    b
                } else {
                    pin[j] + t * (pout[j] - pin[j])
                }
            };
            lo.push([at(pl, ph, tl, 0), at(pl, ph, tl, 1), at(pl, ph, tl, 2)]);
            hi.push([at(ph, pl, th, 0), at(ph, pl, th, 1), at(ph, pl, th, 2)]);
        }
    }
}

/// `|n| / |n_z|` for a swizzled normal.
#[inline]
pub(crate) fn area_scale(n: [f64; 3]) -> f64 {
    (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() / n[2].abs()
}

/// Exact area of the triangle (grid units, voxel²) inside the closed voxel box `[p, p+1]³`,
/// and the centroid of that clipped polygon. If the clipped polygon has zero area the centroid is
/// the mean of its vertices; if the triangle misses the box (or has zero area or a non-finite
/// coordinate) the result is `(0.0, centroid of the triangle)`.
pub fn clipped_area(v: &[[f32; 3]; 3], voxel: [i32; 3]) -> (f64, [f64; 3]) {
    let o = to_f64(v);
    let tri_centroid = [
        (o[0][0] + o[1][0] + o[2][0]) / 3.0,
        (o[0][1] + o[1][1] + o[2][1]) / 3.0,
        (o[0][2] + o[1][2] + o[2][2]) / 3.0,
    ];
    let n = cross_f64(&o);
    if n == [0.0; 3] || !o.iter().flatten().all(|c| c.is_finite()) {
        return (0.0, tri_centroid);
    }
    let swz = swizzle(dominant_axis(n));
    let sw = |p: [f64; 3]| [p[swz[0]], p[swz[1]], p[swz[2]]];
    let tri = Poly::triangle(&[sw(o[0]), sw(o[1]), sw(o[2])]);
    let p = sw(voxel.map(|c| c as f64));
    let poly = tri.clip_column(p[0], p[1]).clip_depth(p[2]);
    let (area, c) = poly.area_centroid(area_scale(sw(n)));
    match c {
        Some(c) => (area, unswizzle(swz, c)),
        None => (0.0, tri_centroid),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_testkit::Rng;

    /// [`Poly::split_into`] gives, bit for bit, the two [`Poly::clip_into`] results (or the
    /// polygon itself where a side is uncut), on random triangles and their clipped polygons cut
    /// at random levels, at vertex levels (points on the plane) and at integers.
    #[test]
    fn split_is_two_clips() {
        let mut rng = Rng(7);
        let mut cases = 0;
        for _ in 0..20_000 {
            let v = [0, 1, 2].map(|_| rng.point(-3.0, 3.0));
            let mut poly = Poly::triangle(&v);
            if rng.below(2) == 0 {
                poly = poly.clip_column(-1.0, -1.0);
            }
            if poly.len == 0 {
                continue;
            }
            let b = match rng.below(3) {
                0 => rng.range(-3.0, 3.0),
                1 => poly.p[rng.index(poly.len)][2],
                _ => rng.int(-2, 2) as f64,
            };
            let (mut lo, mut hi) = (Poly::EMPTY, Poly::EMPTY);
            poly.split_into::<2>(b, &mut lo, &mut hi);
            let (mut l2, mut h2) = (Poly::EMPTY, Poly::EMPTY);
            if !poly.clip_into::<2, true>(b, &mut l2) {
                l2 = poly;
            }
            if !poly.clip_into::<2, false>(b, &mut h2) {
                h2 = poly;
            }
            for (a, r) in [(&lo, &l2), (&hi, &h2)] {
                assert_eq!(a.len, r.len);
                for (p, q) in a.vertices().iter().zip(r.vertices()) {
                    assert_eq!(p.map(f64::to_bits), q.map(f64::to_bits));
                }
            }
            cases += 1;
        }
        assert!(cases > 15_000);
    }
}
