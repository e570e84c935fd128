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
//! All three cuts (the triangle into x-slabs, a slab into columns, a column polygon into depth
//! layers) are **sweeps** ([`Sweep`]): the scan visits slabs, columns and layers in increasing
//! order, so the cut at `c+1` is made once, into both sides ([`Poly::split_into`]), the side
//! above kept for the next slab, column or layer; and a clip that the polygon's bounds show to
//! cut nothing is skipped. Every part is still computed from the polygon it is cut from, with
//! the same planes in the same order as `clipped_area`, so the results are bit for bit those of
//! clipping each voxel separately (unit tests `sweeps_equal_clipped_area_bit_for_bit`,
//! `sweep_is_depth_clipping`).
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
    /// `[slab_x, slab_x+1]`.
    slab_x: f64,
    /// the x-sweep through the triangle, the part holding the slab at `slab_x`, and the slab's
    /// y bounds
    xs: Sweep<0>,
    slab: Part,
    slab_y: (f64, f64),
    /// the y-sweep through the slab, the part holding the General column's polygon
    ys: Sweep<1>,
    col: Part,
    /// Scratch polygons of the depth clipping without fast paths.
    bufs: [Poly; 2],
    zlo: f64,
    zhi: f64,
    /// The plane's z at the Square's corners `(x, y)`, `(x+1, y)`, `(x+1, y+1)`, `(x, y+1)`.
    corner_z: [f64; 4],
    /// Area and centroid of the whole column polygon, once computed.
    whole: Option<(f64, Option<[f64; 3]>)>,
    /// The same area for [`Columns::voxel_area`], once computed.
    whole_area: Option<f64>,
    /// The depth sweep of a column spanning several voxel layers (fast paths only).
    sweep: Sweep<2>,
}

/// A sweep along axis `K` through one polygon `P` (the triangle along x, an x-slab along y, a
/// column polygon along z), visiting the unit slabs `[c, c+1]` in increasing `c`: the part in
/// the slab `c` is `clip(clip(P, x_K ≥ c), x_K ≤ c+1)` as [`Poly::clip_column`] and
/// [`Poly::depth_area_centroid`] compute it, bit for bit, but a clip that `P`'s bounds on the
/// axis show to cut nothing is skipped, and where `P` starts in the slab the cut at `c+1` makes
/// both sides in one pass ([`Poly::split_into`]): the side below is this slab's part, the side
/// above (`clip(P, x_K ≥ c+1)`, computed from `P` itself, so bit for bit what the next slab's
/// first clip gives) is kept for the next slab, which the scan visits next.
#[derive(Clone, Copy)]
struct Sweep<const K: usize> {
    lower: Poly,
    upper: Poly,
    /// the level of `upper` (NaN: none for the current `P`)
    upper_at: f64,
    tmp: Poly,
}

/// Where a [`Sweep`]'s part is: `P` itself or one of the sweep's buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    Src,
    Lower,
    Upper,
    Tmp,
}

impl<const K: usize> Sweep<K> {
    const IDLE: Sweep<K> = Sweep {
        lower: Poly::EMPTY,
        upper: Poly::EMPTY,
        upper_at: f64::NAN,
        tmp: Poly::EMPTY,
    };

    /// Starts a new `P`.
    #[inline]
    fn reset(&mut self) {
        self.upper_at = f64::NAN;
    }

    /// The part of `src` (its exact vertex bounds on axis `K`: `[lo, hi]`) in the slab
    /// `[c, c+1]`, to be read with [`Sweep::get`]. [`Sweep::reset`] must have been called when
    /// `src` changed.
    #[inline]
    fn part(&mut self, src: &Poly, lo: f64, hi: f64, c: f64) -> Part {
        let Sweep {
            lower,
            upper,
            upper_at,
            tmp,
        } = self;
        // a = clip(src, x_K ≥ c): src itself iff no vertex lies below c
        let whole = lo >= c;
        let (a, ap): (Part, &Poly) = if whole {
            (Part::Src, src)
        } else if *upper_at == c {
            (Part::Upper, upper)
        } else if src.clip_into::<K, false>(c, tmp) {
            (Part::Tmp, tmp)
        } else {
            (Part::Src, src)
        };
        // clip(a, x_K ≤ c+1) cuts nothing iff no vertex of src lies above c+1 (a's other
        // vertices lie on c)
        if hi <= c + 1.0 {
            return a;
        }
        if whole {
            src.split_into::<K>(c + 1.0, lower, upper);
            *upper_at = c + 1.0;
            return Part::Lower;
        }
        if ap.clip_into::<K, true>(c + 1.0, lower) {
            Part::Lower
        } else {
            a
        }
    }

    /// The polygon of a [`Part`] of `src`.
    #[inline]
    fn get<'a>(&'a self, src: &'a Poly, p: Part) -> &'a Poly {
        match p {
            Part::Src => src,
            Part::Lower => &self.lower,
            Part::Upper => &self.upper,
            Part::Tmp => &self.tmp,
        }
    }

    /// Area and centroid of the part of `src` (depth bounds `[zlo, zhi]`) in the slab
    /// `[z, z+1]`; equal bit for bit to `src.depth_area_centroid(z, scale, ..)`.
    #[inline]
    fn layer(
        &mut self,
        src: &Poly,
        zlo: f64,
        zhi: f64,
        z: f64,
        scale: f64,
    ) -> (f64, Option<[f64; 3]>) {
        let p = self.part(src, zlo, zhi, z);
        self.get(src, p).area_centroid(scale)
    }

    /// The area of [`Sweep::layer`] alone, bit for bit ([`Poly::area`]).
    #[inline]
    fn layer_area(&mut self, src: &Poly, zlo: f64, zhi: f64, z: f64, scale: f64) -> f64 {
        let p = self.part(src, zlo, zhi, z);
        self.get(src, p).area(scale)
    }
}

/// The General column's polygon: the part `col` of the x-slab, the part `slab` of the triangle.
#[inline]
fn col_ref<'a>(
    tri: &'a Poly,
    xs: &'a Sweep<0>,
    ys: &'a Sweep<1>,
    slab: Part,
    col: Part,
) -> &'a Poly {
    ys.get(xs.get(tri, slab), col)
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
            xs: Sweep::IDLE,
            slab: Part::Src,
            slab_y: (0.0, 0.0),
            ys: Sweep::IDLE,
            col: Part::Src,
            bufs: [Poly::EMPTY; 2],
            zlo: 0.0,
            zhi: 0.0,
            corner_z: [0.0; 4],
            whole: None,
            whole_area: None,
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
        self.xs.reset();
        self.slab = Part::Src;
        self.col = Part::Src;
        self.zlo = tmin[2];
        self.zhi = tmax[2];
        self.whole = None;
        self.whole_area = None;
    }

    /// Starts the column `[x, x+1] × [y, y+1]` (swizzled).
    #[inline]
    pub(crate) fn begin(&mut self, x: f64, y: f64) {
        self.x = x;
        self.y = y;
        self.whole = None;
        self.whole_area = None;
        self.sweep.reset();
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
        // by x− and x+) is kept for the following columns of the same x; both by sweeps (the
        // scan visits x, and y within x, in increasing order)
        if x != self.slab_x {
            self.slab_x = x;
            self.slab = self.xs.part(&self.tri, self.tmin[0], self.tmax[0], x);
            self.slab_y = if self.slab == Part::Src {
                (self.tmin[1], self.tmax[1])
            } else {
                let (lo, hi) = self.xs.get(&self.tri, self.slab).bounds();
                (lo[1], hi[1])
            };
            self.ys.reset();
        }
        let slab = self.xs.get(&self.tri, self.slab);
        self.col = self.ys.part(slab, self.slab_y.0, self.slab_y.1, y);
        (self.zlo, self.zhi) =
            col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col).bounds_z();
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
                Kind::General => col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col)
                    .area_centroid(self.scale),
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
                Kind::General => {
                    let col = col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col);
                    self.sweep.layer(col, lo, hi, z, scale)
                }
                Kind::Square => {
                    let sq = self.square();
                    self.sweep.layer(&sq, lo, hi, z, scale)
                }
            };
        }
        match self.kind {
            Kind::Triangle => {
                let [t1, t2] = &mut self.bufs;
                self.tri.depth_area_centroid(z, self.scale, t1, t2)
            }
            Kind::General => {
                let col = col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col);
                let [t1, t2] = &mut self.bufs;
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
                let [t1, t2] = &mut self.bufs;
                sq.depth_area_centroid(z, self.scale, t1, t2)
            }
        }
    }
}

impl Columns {
    /// The area of [`Columns::voxel`] alone, bit for bit: the weight of a triangle whose values
    /// do not depend on the interpolation point (flat attributes, [`crate::single`]), for the
    /// pairs that still need a clip (voxels with two or more contributions). The same polygons
    /// are cut by the same sweeps; only the centroid's sums and division are left out
    /// ([`Poly::area`]).
    #[inline]
    pub(crate) fn voxel_area(&mut self, z: f64) -> f64 {
        if !self.fast {
            return self.voxel(z).0;
        }
        let (lo, hi, scale) = (self.zlo, self.zhi, self.scale);
        if lo >= z && hi <= z + 1.0 {
            if let Some(w) = self.whole_area {
                return w;
            }
            let w = match self.kind {
                Kind::Triangle => self.tri.area(scale),
                Kind::General => {
                    col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col).area(scale)
                }
                Kind::Square => scale,
            };
            self.whole_area = Some(w);
            return w;
        }
        match self.kind {
            Kind::Triangle => self.sweep.layer_area(&self.tri, lo, hi, z, scale),
            Kind::General => {
                let col = col_ref(&self.tri, &self.xs, &self.ys, self.slab, self.col);
                self.sweep.layer_area(col, lo, hi, z, scale)
            }
            Kind::Square => {
                let sq = self.square();
                self.sweep.layer_area(&sq, lo, hi, z, scale)
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
            let mut sweep = Sweep::<2>::IDLE;
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

    /// [`Columns::voxel_area`] equals the area of [`Columns::voxel`] bit for bit, column by
    /// column in scan order, with and without fast paths, on random triangles of every slope
    /// spanning up to 12 voxels per axis and small ones (Triangle, Square and General columns,
    /// one and several layers), a quarter of them with vertices on voxel planes (ties).
    #[test]
    fn voxel_area_is_the_area_of_voxel_bit_for_bit() {
        let mut rng = Rng(17);
        let mut seen = [0u32; 3];
        for i in 0..3_000 {
            // every third triangle small (mostly inside one column: Triangle columns)
            let (c, r) = if i % 3 == 1 {
                (rng.point(1.0, 11.0), 0.4)
            } else {
                ([6.0; 3], 6.0)
            };
            let v: [[f32; 3]; 3] = [0, 1, 2].map(|_| {
                let d = rng.point(-r, r);
                let p = [0, 1, 2].map(|k| (c[k] + d[k]) as f32);
                if i % 4 == 0 {
                    p.map(|c| c.round())
                } else {
                    p
                }
            });
            let Some(s) = TriSetup::new(&v, crate::Mode::Conservative) else {
                continue;
            };
            for fast in [true, false] {
                let (mut a, mut b) = (Columns::new(&s, fast), Columns::new(&s, fast));
                s.scan(s.swizzle([-1; 3]), s.swizzle([14; 3]), |p, first| {
                    if first {
                        a.begin(p[0] as f64, p[1] as f64);
                        b.begin(p[0] as f64, p[1] as f64);
                        seen[a.kind as usize] += 1;
                    }
                    let z = p[2] as f64;
                    let want = a.voxel(z).0;
                    assert_eq!(b.voxel_area(z).to_bits(), want.to_bits(), "{v:?} at {p:?}");
                });
            }
        }
        assert!(seen.iter().all(|&n| n > 500), "columns per kind {seen:?}");
    }

    /// Without fast paths every column polygon comes from the x- and y-sweeps and the depth
    /// clipping, and must equal [`crate::clipped_area`] (which clips every voxel from the
    /// triangle, plane by plane) bit for bit, on random triangles spanning up to 6 voxels per
    /// axis, with vertices on voxel planes for a quarter of them (ties).
    #[test]
    fn sweeps_equal_clipped_area_bit_for_bit() {
        let mut rng = Rng(5);
        let mut voxels = 0;
        for i in 0..3_000 {
            let v: [[f32; 3]; 3] = [0, 1, 2].map(|_| {
                let p = rng.point(0.0, 6.0).map(|c| c as f32);
                if i % 4 == 0 {
                    p.map(|c| c.round())
                } else {
                    p
                }
            });
            let Some(s) = TriSetup::new(&v, crate::Mode::Conservative) else {
                continue;
            };
            let mut cols = Columns::new(&s, false);
            s.scan(s.swizzle([-1; 3]), s.swizzle([8; 3]), |p, first| {
                if first {
                    cols.begin(p[0] as f64, p[1] as f64);
                }
                let (w, c) = cols.voxel(p[2] as f64);
                let g = s.unswizzle(p);
                let (wa, ca) = crate::clipped_area(&v, g);
                assert_eq!(w.to_bits(), wa.to_bits(), "{v:?} voxel {g:?}");
                if let Some(c) = c {
                    assert_eq!(s.unswizzle(c).map(f64::to_bits), ca.map(f64::to_bits));
                }
                voxels += 1;
            });
        }
        assert!(voxels > 50_000, "{voxels} voxels");
    }
}
