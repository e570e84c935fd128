//! Clipped areas column by column: the weight and interpolation point of every voxel a triangle
//! marks, i.e. [`crate::clipped_area`] factored along the depth axis, with closed forms for the
//! common cases. Sutherland & Hodgman, "Reentrant polygon clipping", CACM 1974, for the general
//! case; the factoring follows the column loop of Rauwendaal & Bailey, JCGT 2(1) 2013 (Appendix).
//!
//! In swizzled coordinates (depth axis z last, `n_z > 0`) the part of the triangle above the
//! column `[x, x+1] × [y, y+1]` is computed once per column; each voxel of the column then only
//! clips that polygon to its depth slab `[z, z+1]`. Three kinds of column:
//! * **Triangle**: the triangle lies inside the column; the column polygon is the triangle.
//! * **Square** (fast path): the column's square lies inside the triangle's dominant projection
//!   (the three edge functions are `≥ 0` at its four corners). The column polygon is the square
//!   lifted to the plane `z(x, y) = (d − n_x x − n_y y) / n_z`, no edge clipping needed; when the
//!   plane stays inside one voxel over the square, its area is `|n| / n_z` exactly and its
//!   centroid the lifted square centre (closed form, no clipping at all).
//! * **General**: the triangle clipped by the four side planes, in the order of `clipped_area`
//!   (x−, x+, y−, y+); the x-slab after the first two is kept for the columns of the same x.
//!
//! When the column polygon's z-range lies inside the voxel's slab (one voxel per column, the
//! usual case for thin voxelization and shallow triangles), its area and centroid are computed
//! once per column and reused. Otherwise the depth slab is clipped per voxel.
//!
//! The results equal [`crate::clipped_area`] up to rounding (below 1e-12 relative on the random
//! triangles of `tests/column.rs`, which checks 1e-9). A Square with a voxel boundary within
//! `TIE` (1e-7) of one of its corners could produce a zero-area piece whose centroid (the mean of its
//! vertices) depends on how exactly it is cut, so it takes the general path. With the fast paths
//! off (`ChunkVoxelizer::set_fast_paths(false)`), every polygon is the one `clipped_area` clips,
//! and the results are bit-identical to it.

use crate::clip::{area_scale, Poly};
use crate::overlap::TriSetup;

/// A Square whose plane passes within this distance (voxels) of a voxel boundary at a corner
/// goes to the general path.
const TIE: f64 = 1e-7;

/// What the polygon of the current column is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// The triangle itself (it lies inside the column).
    Triangle,
    /// The column's square lifted to the plane (it lies inside the triangle's projection).
    Square,
    /// The triangle clipped to the column.
    General,
}

/// The per-triangle state of the column-by-column clipping, and the current column.
pub(crate) struct Columns {
    fast: bool,
    tri: Poly,
    tmin: [f64; 3],
    tmax: [f64; 3],
    /// `|n| / n_z`: projected area to triangle area.
    scale: f64,
    /// The plane as `z = v0_z + gx·(x − v0_x) + gy·(y − v0_y)` (exact for an axis-aligned one).
    v0: [f64; 3],
    gx: f64,
    gy: f64,
    /// Inward edge functions of the dominant projection, shifted to the square's worst corner:
    /// the square at `(x, y)` lies inside the triangle iff `a·x + b·y + c ≥ 0` for all three.
    edge: [[f64; 3]; 3],
    // the current column
    kind: Kind,
    x: f64,
    y: f64,
    /// The x-slab of the General columns at `slab_x`: the triangle clipped to
    /// `[slab_x, slab_x+1]`, in `slab[i]` for `slab_at == Some(i)`, the triangle itself if `None`.
    slab_x: f64,
    slab: [Poly; 2],
    slab_at: Option<usize>,
    /// Polygon buffers: the General column polygon is `bufs[col]`, the others are scratch.
    bufs: [Poly; 3],
    col: usize,
    zlo: f64,
    zhi: f64,
    /// The plane's z at the Square's corners `(x, y)`, `(x+1, y)`, `(x+1, y+1)`, `(x, y+1)`.
    corner_z: [f64; 4],
    /// Area and centroid of the whole column polygon, once computed.
    whole: Option<(f64, Option<[f64; 3]>)>,
    /// The depth sweep of a column spanning several voxel layers (fast paths only).
    sweep: Sweep,
}

/// The depth sweep of one column polygon `P` spanning several voxel layers: the voxel `z`'s part
/// is `clip(clip(P, z ≥ z), z ≤ z+1)` as in [`Poly::depth_area_centroid`], bit for bit, but a
/// clip that the polygon's depth bounds show to cut nothing is skipped, and the cut at `z+1`
/// makes both sides in one pass ([`Poly::split_into`]): the side below is this voxel's part,
/// the side above (`clip(P, z ≥ z+1)`) is kept for the next voxel of the column, which the scan
/// visits next.
#[derive(Clone, Copy)]
struct Sweep {
    lower: Poly,
    upper: Poly,
    /// the level of `upper` (NaN: none for the current column)
    upper_z: f64,
    tmp: Poly,
}

impl Sweep {
    const IDLE: Sweep = Sweep {
        lower: Poly::EMPTY,
        upper: Poly::EMPTY,
        upper_z: f64::NAN,
        tmp: Poly::EMPTY,
    };

    /// Area and centroid of the part of `src` (depth bounds `[zlo, zhi]`) in the slab
    /// `[z, z+1]`; equal bit for bit to `src.depth_area_centroid(z, scale, ..)`. `upper` must
    /// have been reset (`upper_z = NaN`) when `src` changed.
    #[inline]
    fn layer(
        &mut self,
        src: &Poly,
        zlo: f64,
        zhi: f64,
        z: f64,
        scale: f64,
    ) -> (f64, Option<[f64; 3]>) {
        let Sweep {
            lower,
            upper,
            upper_z,
            tmp,
        } = self;
        // a = clip(src, z ≥ z): src itself iff no vertex lies below z
        let whole = zlo >= z;
        let a: &Poly = if whole {
            src
        } else if *upper_z == z {
            upper
        } else if src.clip_into::<2, false>(z, tmp) {
            tmp
        } else {
            src
        };
        // clip(a, z ≤ z+1) cuts nothing iff no vertex of src lies above z+1 (a's other
        // vertices lie on z)
        if zhi <= z + 1.0 {
            return a.area_centroid(scale);
        }
        if whole {
            src.split_into::<2>(z + 1.0, lower, upper);
            *upper_z = z + 1.0;
            return lower.area_centroid(scale);
        }
        if a.clip_into::<2, true>(z + 1.0, lower) {
            lower.area_centroid(scale)
        } else {
            a.area_centroid(scale)
        }
    }
}

/// Clips `src` to the slab `lo ≤ x[K] ≤ hi` ([`Poly::clip`] by `(K, lo, false)`, then
/// `(K, hi, true)`), writing into `a` or `b` instead of copying; returns which holds the result
/// (0 or 1), `None` if neither plane cut anything (the result is `src`).
#[inline]
fn clip_planes<const K: usize>(
    src: &Poly,
    lo: f64,
    hi: f64,
    a: &mut Poly,
    b: &mut Poly,
) -> Option<usize> {
    if src.clip_into::<K, false>(lo, a) {
        if a.clip_into::<K, true>(hi, b) {
            Some(1)
        } else {
            Some(0)
        }
    } else if src.clip_into::<K, true>(hi, a) {
        Some(0)
    } else {
        None
    }
}

/// `bufs[i]` and the two other buffers.
#[inline]
fn split3(bufs: &mut [Poly; 3], i: usize) -> (&Poly, &mut Poly, &mut Poly) {
    let [a, b, c] = bufs;
    match i {
        0 => (a, b, c),
        1 => (b, a, c),
        _ => (c, a, b),
    }
}

impl Columns {
    /// The clipping state of a triangle; `fast == false` turns the Square fast path off.
    pub(crate) fn new(s: &TriSetup, fast: bool) -> Columns {
        let mut c = Columns::idle(fast);
        c.set(s);
        c
    }

    /// A state with no triangle yet, to be [`Columns::set`] (and reused, so that the polygon
    /// buffers are not cleared for every triangle).
    pub(crate) fn idle(fast: bool) -> Columns {
        Columns {
            fast,
            tri: Poly::EMPTY,
            tmin: [0.0; 3],
            tmax: [0.0; 3],
            scale: 0.0,
            v0: [0.0; 3],
            gx: 0.0,
            gy: 0.0,
            edge: [[0.0; 3]; 3],
            kind: Kind::General,
            x: 0.0,
            y: 0.0,
            slab_x: f64::NAN,
            slab: [Poly::EMPTY; 2],
            slab_at: None,
            bufs: [Poly::EMPTY; 3],
            col: 0,
            zlo: 0.0,
            zhi: 0.0,
            corner_z: [0.0; 4],
            whole: None,
            sweep: Sweep::IDLE,
        }
    }

    /// Starts triangle `s`. Every field a column reads is set here or by [`Columns::begin`];
    /// the buffers' old contents are never read (a clip writes its length first).
    #[inline]
    pub(crate) fn set(&mut self, s: &TriSetup) {
        self.tri.len = 3;
        self.tri.p[..3].copy_from_slice(&s.v);
        let (tmin, tmax) = self.tri.bounds();
        let n = s.n;
        debug_assert!(n[2] > 0.0);
        // the triangle's own edge functions (not the mode-dependent ones of the overlap test)
        for (i, e) in self.edge.iter_mut().enumerate() {
            let [a, b] = s.ne[0][i];
            let v = s.v[i];
            *e = [a, b, -(a * v[0] + b * v[1]) + a.min(0.0) + b.min(0.0)];
        }
        self.tmin = tmin;
        self.tmax = tmax;
        self.scale = area_scale(n);
        self.v0 = s.v[0];
        (self.gx, self.gy) = (-n[0] / n[2], -n[1] / n[2]);
        self.kind = Kind::General;
        self.slab_x = f64::NAN;
        self.slab_at = None;
        self.col = 0;
        self.zlo = tmin[2];
        self.zhi = tmax[2];
        self.whole = None;
    }

    /// Starts the column `[x, x+1] × [y, y+1]` (swizzled).
    #[inline]
    pub(crate) fn begin(&mut self, x: f64, y: f64) {
        self.x = x;
        self.y = y;
        self.whole = None;
        self.sweep.upper_z = f64::NAN;
        let (tmin, tmax) = (self.tmin, self.tmax);
        if tmin[0] >= x && tmax[0] <= x + 1.0 && tmin[1] >= y && tmax[1] <= y + 1.0 {
            self.kind = Kind::Triangle;
            self.zlo = tmin[2];
            self.zhi = tmax[2];
        } else if self.fast && self.edge.iter().all(|e| e[0] * x + e[1] * y + e[2] >= 0.0) {
            let c = [
                self.z(x, y),
                self.z(x + 1.0, y),
                self.z(x + 1.0, y + 1.0),
                self.z(x, y + 1.0),
            ];
            // a voxel boundary (nearly) through a corner could cut off a zero-area piece, whose
            // centroid depends on how exactly it is cut: leave those ties to the general path
            if c.iter().all(|&z| (z - z.round()).abs() > TIE) {
                self.kind = Kind::Square;
                self.corner_z = c;
                self.zlo = c[0].min(c[1]).min(c[2]).min(c[3]);
                self.zhi = c[0].max(c[1]).max(c[2]).max(c[3]);
            } else {
                self.general(x, y);
            }
        } else {
            self.general(x, y);
        }
    }

    #[inline]
    fn general(&mut self, x: f64, y: f64) {
        self.kind = Kind::General;
        // Poly::clip_column, in its plane order x−, x+, y−, y+: the x-slab (the triangle clipped
        // by x− and x+) is kept for the following columns of the same x
        if x != self.slab_x {
            self.slab_x = x;
            let [s0, s1] = &mut self.slab;
            self.slab_at = clip_planes::<0>(&self.tri, x, x + 1.0, s0, s1);
        }
        let src = match self.slab_at {
            None => &self.tri,
            Some(i) => &self.slab[i],
        };
        let [b0, b1, _] = &mut self.bufs;
        self.col = match clip_planes::<1>(src, y, y + 1.0, b0, b1) {
            Some(i) => i,
            None => {
                self.bufs[0] = *src;
                0
            }
        };
        (self.zlo, self.zhi) = self.bufs[self.col].bounds_z();
    }

    /// The Square column's polygon: the square lifted to the plane.
    #[inline]
    fn square(&self) -> Poly {
        let (x, y) = (self.x, self.y);
        let c = self.corner_z;
        let mut sq = Poly::EMPTY;
        sq.len = 4;
        sq.p[0] = [x, y, c[0]];
        sq.p[1] = [x + 1.0, y, c[1]];
        sq.p[2] = [x + 1.0, y + 1.0, c[2]];
        sq.p[3] = [x, y + 1.0, c[3]];
        sq
    }

    #[inline]
    fn z(&self, x: f64, y: f64) -> f64 {
        self.v0[2] + self.gx * (x - self.v0[0]) + self.gy * (y - self.v0[1])
    }

    /// Area (voxel², of the triangle, not its projection) and centroid (swizzled) of the
    /// current column's part in the voxel slab `[z, z+1]`; the centroid is `None` if that part is
    /// empty (see [`Poly::area_centroid`]).
    #[inline]
    pub(crate) fn voxel(&mut self, z: f64) -> (f64, Option<[f64; 3]>) {
        if self.zlo >= z && self.zhi <= z + 1.0 {
            if let Some(w) = self.whole {
                return w;
            }
            let w = match self.kind {
                Kind::Triangle => self.tri.area_centroid(self.scale),
                Kind::General => self.bufs[self.col].area_centroid(self.scale),
                Kind::Square => {
                    let (cx, cy) = (self.x + 0.5, self.y + 0.5);
                    (self.scale, Some([cx, cy, self.z(cx, cy)]))
                }
            };
            self.whole = Some(w);
            return w;
        }
        if self.fast {
            let (lo, hi, scale) = (self.zlo, self.zhi, self.scale);
            return match self.kind {
                Kind::Triangle => self.sweep.layer(&self.tri, lo, hi, z, scale),
                Kind::General => self.sweep.layer(&self.bufs[self.col], lo, hi, z, scale),
                Kind::Square => {
                    let sq = self.square();
                    self.sweep.layer(&sq, lo, hi, z, scale)
                }
            };
        }
        match self.kind {
            Kind::Triangle => {
                let [t1, t2, _] = &mut self.bufs;
                self.tri.depth_area_centroid(z, self.scale, t1, t2)
            }
            Kind::General => {
                let (col, t1, t2) = split3(&mut self.bufs, self.col);
                col.depth_area_centroid(z, self.scale, t1, t2)
            }
            Kind::Square => {
                let (x, y) = (self.x, self.y);
                let c = self.corner_z;
                let mut sq = Poly::EMPTY;
                sq.len = 4;
                sq.p[0] = [x, y, c[0]];
                sq.p[1] = [x + 1.0, y, c[1]];
                sq.p[2] = [x + 1.0, y + 1.0, c[2]];
                sq.p[3] = [x, y + 1.0, c[3]];
                let [_, t1, t2] = &mut self.bufs;
                sq.depth_area_centroid(z, self.scale, t1, t2)
            }
        }
    }
}

/// Area and centroid of triangle `v` (grid coordinates) inside every voxel that the overlap test
/// of `mode` marks within `[bmin, bmax]` (inclusive, unswizzled), computed column by column with
/// the fast paths: calls `emit(voxel, area, centroid)` in the order of
/// [`crate::voxelize_triangle`]. The centroid is unswizzled; for an empty part it is the
/// triangle's centroid, as in [`crate::clipped_area`]. Zero-area and non-finite triangles emit
/// nothing.
pub fn voxel_areas(
    v: &[[f32; 3]; 3],
    bmin: [i32; 3],
    bmax: [i32; 3],
    mode: crate::Mode,
    emit: &mut impl FnMut([i32; 3], f64, [f64; 3]),
) {
    let Some(s) = TriSetup::new(v, mode) else {
        return;
    };
    let tri_centroid = [0, 1, 2].map(|k| (v[0][k] as f64 + v[1][k] as f64 + v[2][k] as f64) / 3.0);
    let mut cols = Columns::new(&s, true);
    s.scan(s.swizzle(bmin), s.swizzle(bmax), |p, first| {
        if first {
            cols.begin(p[0] as f64, p[1] as f64);
        }
        let (w, c) = cols.voxel(p[2] as f64);
        let c = c.map_or(tri_centroid, |c| s.unswizzle(c));
        emit(s.unswizzle(p), w, c);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxlod_testkit::Rng;

    /// [`Sweep::layer`] over the voxels of a column, bottom to top as the scan visits them
    /// (also starting one layer below the polygon, a tie), equals
    /// [`Poly::depth_area_centroid`] bit for bit, on steep random triangles clipped to a column.
    #[test]
    fn sweep_is_depth_clipping() {
        let mut rng = Rng(11);
        let mut layered = 0;
        for _ in 0..5_000 {
            let v = [0, 1, 2].map(|_| rng.point(-2.0, 2.0));
            let src = Poly::triangle(&v).clip_column(rng.int(-2, 1) as f64, rng.int(-2, 1) as f64);
            if src.len == 0 {
                continue;
            }
            let (zlo, zhi) = src.bounds_z();
            let (mut t1, mut t2) = (Poly::EMPTY, Poly::EMPTY);
            let mut sweep = Sweep::IDLE;
            let first = zlo.floor() as i32 - rng.int(0, 1) as i32;
            for z in first..=zhi.floor() as i32 {
                let z = z as f64;
                let got = sweep.layer(&src, zlo, zhi, z, 1.25);
                let want = src.depth_area_centroid(z, 1.25, &mut t1, &mut t2);
                assert_eq!(got.0.to_bits(), want.0.to_bits());
                assert_eq!(
                    got.1.map(|c| c.map(f64::to_bits)),
                    want.1.map(|c| c.map(f64::to_bits))
                );
            }
            layered += (zhi.floor() - zlo.floor() >= 2.0) as u32;
        }
        assert!(layered > 100, "{layered} columns of three or more layers");
    }
}
