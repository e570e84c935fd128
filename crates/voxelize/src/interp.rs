//! Per-triangle attribute interpolation for the chunk voxelizer ([`crate::chunk`]): the
//! normal and colour of a contribution at its interpolation point, as affine functions of the
//! point in the triangle's dominant projection (the barycentrics of the crate docs; Rauwendaal &
//! Bailey, JCGT 2(1) 2013, for the swizzle to the dominant axis).

use voxlod_geom::{Triangle, TRI_HAS_NORMALS};
use voxlod_texture::TextureSet;

use crate::overlap::{cross_f64, to_f64, TriSetup};
use crate::texcolor::{linear_color, TexAt};

/// Per-triangle attribute interpolation (see the crate docs): the barycentrics are affine in
/// the point, and every interpolation point lies in the triangle's plane, so each attribute is
/// an affine function of the point's swizzled `(x, y)`, the dominant projection:
/// `a(q) = a₀ + g_x·(q_x − v0_x) + g_y·(q_y − v0_y)` with per-triangle gradients. This equals
/// `Σ λ_k a_k` with the crate docs' barycentrics up to rounding (relative 1e-15 for a
/// non-degenerate triangle: `|n_z| ≥ |n|/√3` on the dominant axis).
pub(crate) struct Interp<'a> {
    o: [f64; 2],
    /// colours (r, g, b, a) at v0 and their gradients
    c0: [f64; 4],
    cx: [f64; 4],
    cy: [f64; 4],
    /// vertex normals (unswizzled) at v0 and their gradients, if the triangle has them
    vn: Option<[[f64; 3]; 3]>,
    /// unit face normal `n/|n|` (unswizzled, sign of the winding)
    face: [f64; 3],
    /// the swizzled `(x, y)` of the triangle's centroid (the point of an empty part)
    pub(crate) centroid: [f64; 2],
    /// a build with textures: colours in linear light ([`crate::texcolor`]), and this
    /// triangle's texture if it has one
    linear: bool,
    tex: Option<TexAt<'a>>,
}

impl<'a> Interp<'a> {
    pub(crate) fn new(t: &Triangle, s: &TriSetup, textures: Option<&'a TextureSet>) -> Interp<'a> {
        Self::from_swizzled(t, &s.v, textures)
    }

    /// [`Interp::new`] from the triangle's vertices swizzled to its dominant axis (`TriSetup::v`).
    pub(crate) fn from_swizzled(
        t: &Triangle,
        v: &[[f64; 3]; 3],
        textures: Option<&'a TextureSet>,
    ) -> Interp<'a> {
        let n = cross_f64(&to_f64(&t.v));
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        Self::from_swizzled_normal(t, v, n, len, textures)
    }

    /// [`Interp::from_swizzled`] with the normal `n = (v1 − v0) × (v2 − v0)` of the triangle's
    /// grid vertices and `|n|` already computed (as there, bit for bit): `t.v` is not read, so
    /// `t` may hold the world positions of the triangle whose grid vertices `v` are.
    pub(crate) fn from_swizzled_normal(
        t: &Triangle,
        v: &[[f64; 3]; 3],
        n: [f64; 3],
        len: f64,
        textures: Option<&'a TextureSet>,
    ) -> Interp<'a> {
        let [p0, p1, p2] = *v;
        let e1 = [p1[0] - p0[0], p1[1] - p0[1]];
        let e2 = [p2[0] - p0[0], p2[1] - p0[1]];
        // the dominant projection's signed doubled area: never 0 for a triangle TriSetup took
        let inv = 1.0 / (e1[0] * e2[1] - e1[1] * e2[0]);
        // a(d) = a0 + (a1 − a0)·λ1 + (a2 − a0)·λ2, λ1 = (d×e2)_z/det, λ2 = (e1×d)_z/det
        let grad = |a: [f64; 3]| {
            let (d1, d2) = (a[1] - a[0], a[2] - a[0]);
            (
                (d1 * e2[1] - d2 * e1[1]) * inv,
                (d2 * e1[0] - d1 * e2[0]) * inv,
            )
        };
        let mut c0 = [0.0; 4];
        let mut cx = [0.0; 4];
        let mut cy = [0.0; 4];
        for k in 0..4 {
            let a = [t.c[0][k] as f64, t.c[1][k] as f64, t.c[2][k] as f64];
            c0[k] = a[0];
            (cx[k], cy[k]) = grad(a);
        }
        let vn = (t.flags & TRI_HAS_NORMALS != 0).then(|| {
            let (mut a0, mut gx, mut gy) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for k in 0..3 {
                let a = [t.n[0][k] as f64, t.n[1][k] as f64, t.n[2][k] as f64];
                a0[k] = a[0];
                (gx[k], gy[k]) = grad(a);
            }
            [a0, gx, gy]
        });
        let face = [n[0] / len, n[1] / len, n[2] / len];
        let centroid = [(p0[0] + p1[0] + p2[0]) / 3.0, (p0[1] + p1[1] + p2[1]) / 3.0];
        let tex = textures.and_then(|set| TexAt::new(t, set, grad, len));
        Interp {
            o: [p0[0], p0[1]],
            c0,
            cx,
            cy,
            vn,
            face,
            centroid,
            linear: textures.is_some(),
            tex,
        }
    }

    /// The accumulated values `[n_x, n_y, n_z, 1, r, g, b, a]` at the swizzled point `(x, y)`
    /// of a part of `w` voxel².
    #[inline]
    pub(crate) fn at(&self, x: f64, y: f64, w: f64) -> [f32; 8] {
        let (dx, dy) = (x - self.o[0], y - self.o[1]);
        let normal = match &self.vn {
            Some([a, gx, gy]) => {
                let m = [
                    a[0] + gx[0] * dx + gy[0] * dy,
                    a[1] + gx[1] * dx + gy[1] * dy,
                    a[2] + gx[2] * dx + gy[2] * dy,
                ];
                unit_or(m, self.face)
            }
            None => self.face,
        };
        // written out: `[0, 1, 2, 3].map(..)` here compiled to a call (core's try_map, 2–3 %
        // of a build's profile)
        let (c0, cx, cy) = (&self.c0, &self.cx, &self.cy);
        let mut c = [
            c0[0] + cx[0] * dx + cy[0] * dy,
            c0[1] + cx[1] * dx + cy[1] * dy,
            c0[2] + cx[2] * dx + cy[2] * dy,
            c0[3] + cx[3] * dx + cy[3] * dy,
        ];
        if self.linear {
            c = linear_color(c, self.tex.as_ref().map(|t| t.sample(dx, dy, w)));
        }
        values(normal, c)
    }
}

/// `m / |m|`, or `fallback` if that is zero or not finite.
#[inline]
pub(crate) fn unit_or(m: [f64; 3], fallback: [f64; 3]) -> [f64; 3] {
    let len = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        let inv = 1.0 / len;
        m.map(|c| c * inv)
    } else {
        fallback
    }
}

#[inline]
pub(crate) fn values(n: [f64; 3], c: [f64; 4]) -> [f32; 8] {
    [
        n[0] as f32,
        n[1] as f32,
        n[2] as f32,
        1.0,
        c[0] as f32,
        c[1] as f32,
        c[2] as f32,
        c[3] as f32,
    ]
}
